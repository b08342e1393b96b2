"""A dip of the swing foot below the ground inside one step, found with a guarantee.

A step whose two ends have the swing foot above the ground can still hide a dip below it (a graze
of tens of micrometres at a few cm/s). The integrator's dense output over the step is a polynomial
in s = (t - t_old) / h of degree at most 7 (DOP853's; DOPRI5's is 4, the Hermite and scipy's
interpolants lower): its power-basis coefficients come from the interpolant itself
(``poly_coefficients``), or exactly (to roundoff) from its values at 8 Chebyshev points.
The foot's height along it is not a polynomial (sines and cosines of the leg angles), but its second
derivative in s is bounded on any [a, b] from the polynomials' derivative bounds:

    |h''| <= |y''| + |tan(slope)| |x''| + l (1 + |tan(slope)|) (|theta''| + theta'^2)

(hip (x, y), the foot's leg angle theta; on the fixed base the hip's terms become those of the
stance leg's angle). Then h >= min(h(a), h(b)) - M2 (b - a)^2 / 8 on [a, b]: an interval where that is
positive holds no dip; the others are halved, down to the width at which M2 (b - a)^2 / 8 <= graze_tol.
So a dip of the dense output's foot height deeper than ``graze_tol`` inside a step is always found,
and its crossing is returned as a bracket for the root finder.
"""
from __future__ import annotations

import numpy as np

from biped_sim.engine import loop_rules as rules
from biped_sim.engine.loop_state import COEF, FIXED_BASE, GRAZE_TOL, L_LEG, RESULT, TAN_S, new_state

DEGREE = 7
NODES = 0.5 - 0.5 * np.cos((2 * np.arange(DEGREE + 1) + 1) * np.pi / (2 * (DEGREE + 1)))   # in (0, 1)
_VANDERMONDE_INV = np.linalg.inv(np.vander(NODES, DEGREE + 1, increasing=True))


def _guard(S, height_at, t):
    """A Python function of t as the rules call a guard: g(S, ctx, t), ctx the function."""
    return height_at(t)


def dip_bracket(st, to_phys, height_at, leg, stance_leg, fixed_base, l_leg, tan_slope, h0, h1, graze_tol):
    """(t_a, t_b) with the foot's height > 0 at t_a and <= 0 at t_b inside the last step, or None if
    no dip deeper than ``graze_tol`` exists there. ``height_at(t) -> float`` on the dense output;
    h0, h1: the heights at the step's ends (both > 0). The search and its bound are the rule
    ``loop_rules.ev_dip_search``; on the floating base, the coefficients of a dop853 or dopri5 step are
    ``loop_rules.ev_dip_coefficients``' (the compiled loop's rules, the same bits)."""
    dense_state = None if fixed_base else getattr(st, "dense_state", None)
    interpolant = None if dense_state is not None else st.dense_output()
    S = dense_state() if dense_state is not None else getattr(interpolant, "state", None)
    if S is not None and not fixed_base:     # dop853's or dopri5's rows, in the stepper's or interpolant's state
        rules.ev_dip_coefficients(S, leg)
    else:
        t_old, h_step = st.t_old, st.t - st.t_old
        # the entries of the integrated state y the foot's height depends on
        cols = [leg - 1, 2, stance_leg - 1] if fixed_base else [1 + leg, 4, 0, 1]
        if hasattr(interpolant, "poly_coefficients"):
            C = interpolant.poly_coefficients(cols)
        else:
            C = _VANDERMONDE_INV @ np.array([np.asarray(interpolant(t_old + s * h_step))[cols] for s in NODES])
        # |coefficients| of: the swing leg's angle, then the stance leg's angle (fixed base) or the hip's
        # x and y (floating base)
        if fixed_base:   # y = (q1, q2, q3, dq...): the hip hangs from the pin by the stance leg
            A = np.abs(np.column_stack([C[:, 0] + C[:, 1], C[:, 2] + C[:, 1], np.zeros(8)]))
        else:            # y = (x, y, q1, q2, q3, ...)
            A = np.abs(np.column_stack([C[:, 0] + C[:, 1], C[:, 2], C[:, 3]]))
        S = new_state(t_old=st.t_old, t=st.t)
        S[COEF:COEF + 24] = A.ravel().tolist()
    S[FIXED_BASE], S[L_LEG], S[TAN_S], S[GRAZE_TOL] = float(fixed_base), l_leg, tan_slope, graze_tol
    if rules.ev_dip_search(S, _guard, height_at, h0, h1):
        return S[RESULT], S[RESULT + 1]
    return None
