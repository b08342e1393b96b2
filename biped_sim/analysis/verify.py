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

from biped_sim.engine.guards import foot_states, passes_through
from biped_sim.engine.options import Options


def violations(model, result, upto=None, most=5) -> list[str]:
    """The samples (the first ``upto``, all by default) at which an invariant fails, in words; at most
    ``most`` of them."""
    opt = result.options if result.options is not None else Options()
    behind_allowed = opt.touchdown_rule == "front"
    s, c, tn = math.sin(opt.slope), math.cos(opt.slope), math.tan(opt.slope)
    out = []
    n = len(result.t) if upto is None else min(upto, len(result.t))
    for k in range(n):
        t, q, dq, leg = result.t[k], result.q[k], result.dq[k], int(result.stance_leg[k])
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(dq))):
            out.append(f"t={t:.9g} s: the state is not finite")
        feet = foot_states(model, q.tolist(), dq.tolist(), tn)
        for j in (1, 2):
            if j == leg:
                continue
            height = feet[j - 1].height
            # the scuff rule's own test (guards.passes_through), from the sample alone
            passing = leg and behind_allowed and passes_through(feet[j - 1], feet[leg - 1], opt)
            if height < (-opt.scuff_depth if passing else -opt.ground_tol):
                out.append(f"t={t:.9g} s: foot {j} is {-height:.3g} m below the ground"
                           + (" passing through it, deeper than scuff_depth" if passing else ""))
        if leg:
            normal = result.grf[k][0] * s + result.grf[k][1] * c
            if normal < -opt.force_tol:
                out.append(f"t={t:.9g} s: the ground pulls on the stance foot (normal force {normal:.6g} N)")
        if len(out) >= most:
            break
    return out


def result_violations(model, result) -> list[str]:
    """The violations of a run, judged as the engine ends it: every sample of a completed run; all but
    the last of a run that stopped or failed (whose last sample is where it found what stopped it)."""
    upto = None if result.status == "completed" else max(0, len(result.t) - 1)
    return violations(model, result, upto)
