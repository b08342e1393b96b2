"""What "completed" means, checked from a result's samples alone, independently of the engine's own
checks (``engine/invariants.py``): the stability suite and the tests judge runs with it.

At every sample: a finite state; every foot at or above the ground within ``ground_tol`` (a swing foot
passing through the ground may scuff down to ``scuff_depth``: the stated exception of
``touchdown_rule="front"``, under ``scuff_rule`` "forward" while it moves forward, under "behind" while it
is behind the stance foot);
in stance, the ground pushes (normal force >= -``force_tol``). The tolerances are the run's own
(``result.options``).
"""
from __future__ import annotations

import math

import numpy as np


def violations(model, result, upto=None, most=5) -> list[str]:
    """The samples (the first ``upto``, all by default) at which an invariant fails, in words; at most
    ``most`` of them."""
    opt = result.options
    slope = opt.slope if opt is not None else 0.0
    ground_tol = opt.ground_tol if opt is not None else 1e-9
    force_tol = opt.force_tol if opt is not None else 1e-6
    scuff_depth = opt.scuff_depth if opt is not None else math.inf
    front_tol = opt.front_tol if opt is not None else 1e-5
    behind_allowed = opt is None or opt.touchdown_rule == "front"
    forward_rule = opt is None or opt.scuff_rule == "forward"
    s, c, tn = math.sin(slope), math.cos(slope), math.tan(slope)
    out = []
    n = len(result.t) if upto is None else min(upto, len(result.t))
    for k in range(n):
        t, q, dq, leg = result.t[k], result.q[k], result.dq[k], int(result.stance_leg[k])
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(dq))):
            out.append(f"t={t:.9g} s: the state is not finite")
        feet = [model.foot_position(q, j) for j in (1, 2)]
        for j in (1, 2):
            if j == leg:
                continue
            height = feet[j - 1][1] + tn * feet[j - 1][0]
            if forward_rule:    # the foot passes through while it moves forward more than it sinks
                v = model.foot_velocity(q, dq, j)
                passing = leg and behind_allowed and v[0] > 0.0 and v[0] + v[1] + tn * v[0] >= 0.0
            else:
                passing = leg and behind_allowed and feet[j - 1][0] <= feet[leg - 1][0] + front_tol
            if height < (-scuff_depth if passing else -ground_tol):
                out.append(f"t={t:.9g} s: foot {j} is {-height:.3g} m below the ground"
                           + (" passing through it, deeper than scuff_depth" if passing else ""))
        if leg:
            normal = result.grf[k][0] * s + result.grf[k][1] * c
            if normal < -force_tol:
                out.append(f"t={t:.9g} s: the ground pulls on the stance foot (normal force {normal:.6g} N)")
        if len(out) >= most:
            break
    return out


def result_violations(model, result) -> list[str]:
    """The violations of a run, judged as the engine ends it: every sample of a completed run; all but
    the last of a run that stopped or failed (whose last sample is where it found what stopped it)."""
    upto = None if result.status == "completed" else max(0, len(result.t) - 1)
    return violations(model, result, upto)
