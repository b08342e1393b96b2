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

DEGREE = 7
NODES = 0.5 - 0.5 * np.cos((2 * np.arange(DEGREE + 1) + 1) * np.pi / (2 * (DEGREE + 1)))   # in (0, 1)
_VANDERMONDE_INV = np.linalg.inv(np.vander(NODES, DEGREE + 1, increasing=True))
_K = np.arange(DEGREE + 1, dtype=float)
MAX_DEPTH = 30          # halvings: the width of a leaf is at least 2^-30 of the step


def _derivative_weights(b):
    """Row vectors w1, w2 with w1 @ |c| >= max |p'| and w2 @ |c| >= max |p''| over [0, b] (0 < b <= 1)
    for p(s) = sum c_k s^k."""
    return _K * b ** np.maximum(_K - 1, 0), _K * (_K - 1) * b ** np.maximum(_K - 2, 0)


_WEIGHTS_ON_0_1 = _derivative_weights(1.0)


def dip_bracket(st, to_phys, height_at, leg, stance_leg, fixed_base, l_leg, tan_slope, h0, h1, graze_tol):
    """(t_a, t_b) with the foot's height > 0 at t_a and <= 0 at t_b inside the last step, or None if
    no dip deeper than ``graze_tol`` exists there. ``height_at(t) -> float`` on the dense output;
    h0, h1: the heights at the step's ends (both > 0)."""
    t_old, h_step = st.t_old, st.t - st.t_old
    # the entries of the integrated state y the foot's height depends on
    cols = [leg - 1, 2, stance_leg - 1] if fixed_base else [1 + leg, 4, 0, 1]
    interpolant = st.dense_output()
    if hasattr(interpolant, "poly_coefficients"):
        C = interpolant.poly_coefficients(cols)
    else:
        C = _VANDERMONDE_INV @ np.array([np.asarray(interpolant(t_old + s * h_step))[cols] for s in NODES])
    # |coefficients| of: the swing leg's angle, then the stance leg's angle (fixed base) or the hip's
    # x and y (floating base)
    if fixed_base:   # y = (q1, q2, q3, dq...): the hip hangs from the pin by the stance leg
        A = np.abs(np.column_stack([C[:, 0] + C[:, 1], C[:, 2] + C[:, 1]]))
    else:            # y = (x, y, q1, q2, q3, ...)
        A = np.abs(np.column_stack([C[:, 0] + C[:, 1], C[:, 2], C[:, 3]]))
    lt = l_leg * (1 + abs(tan_slope))
    slack = 1.0 + 1e-6    # the coefficients carry roundoff

    def m2(b):
        w1, w2 = _WEIGHTS_ON_0_1 if b == 1.0 else _derivative_weights(b)
        d1, d2 = (w1 @ A).tolist(), (w2 @ A).tolist()
        if fixed_base:
            bound = lt * (d2[0] + d1[0] * d1[0] + d2[1] + d1[1] * d1[1])
        else:
            bound = lt * (d2[0] + d1[0] * d1[0]) + d2[2] + abs(tan_slope) * d2[1]
        return bound * slack

    def h_at(s):
        return h0 if s == 0.0 else h1 if s == 1.0 else height_at(t_old + s * h_step)

    stack = [(0.0, 1.0, h0, h1, 0)]
    while stack:
        a, b, ha, hb, depth = stack.pop()
        drop = m2(b) * (b - a) ** 2 / 8
        if min(ha, hb) - drop > 0 or drop <= graze_tol or depth >= MAX_DEPTH:
            continue
        mid = 0.5 * (a + b)
        hm = h_at(mid)
        if hm <= 0:
            return t_old + a * h_step, t_old + mid * h_step
        # the left half first: the earliest dip is the one that counts
        stack.append((mid, b, hm, hb, depth + 1))
        stack.append((a, mid, ha, hm, depth + 1))
    return None

