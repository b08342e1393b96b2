"""What "completed" means, checked from a result's samples alone (independently of the engine's own
checks): shared by the hybrid-edge tests and the property-based tests."""
import math

import numpy as np


def assert_invariants(model, r, slope, ground_tol=1e-9, force_tol=1e-6, scuff_depth=3e-3):
    """Every sample: finite; each foot at or above the ground (a scuff behind the stance foot within
    scuff_depth excepted); in stance, the ground pushes."""
    assert np.all(np.isfinite(r.q)) and np.all(np.isfinite(r.dq))
    s, c, tn = math.sin(slope), math.cos(slope), math.tan(slope)
    for k in range(len(r.t)):
        feet = [model.foot_position(r.q[k], leg) for leg in (1, 2)]
        heights = [p[1] + tn * p[0] for p in feet]
        leg = int(r.stance_leg[k])
        for j in (1, 2):
            if j == leg:
                continue
            behind = leg and feet[j - 1][0] <= feet[leg - 1][0] + 1e-5
            floor = -scuff_depth if behind else -ground_tol
            assert heights[j - 1] >= floor, (k, r.t[k], j, heights[j - 1])
        if leg:
            n = r.grf[k][0] * s + r.grf[k][1] * c
            assert n >= -force_tol, (k, r.t[k], n)
