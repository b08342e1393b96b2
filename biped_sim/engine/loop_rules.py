# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The hybrid loop's rules, written once: the Runge-Kutta step with its error control, the dense output, a
foot's height on it, the dip search and the root finder, the witnesses' values and the test of their
crossing, arming, the projection onto the pinned foot, the invariants' predicates, the sample's thinning,
the scuffs' rules.

This file runs two ways. Imported, it is the Python loop's code (``integrators``, ``grazing``, ``guards``,
``witnesses``, ``locator``, ``modes``, ``invariants``, ``results`` call it). Compiled by Cython in its
pure-Python mode (``tools/generate_loop.py``: the signatures are in ``loop_rules.pxd``, the generated formulas
reached through ``loop_kernels.pxd``), it is the committed C ``_loop_rules.c``, which the compiled loop
(``_core.c``) includes and whose public functions it calls by name. Both perform the same IEEE operations
in the same order (the C built with ``-ffp-contract=off``, C division without Python's zero check), so a run
gives the same bits on both loops (test/unit/test_compiled_loop.py).

Everything a rule reads or writes is an entry of the state S (``loop_state``: a list as Python, a
``double *`` in C) at a named offset; besides S a rule takes only scalars, short vectors (q, dq, a foot's
row, a pin: a list or tuple as Python, a ``double *`` in C), the right-hand side ``fun`` (``fun(t, y) ->
list`` as Python, ``rhs_t`` with its context ``ctx`` in C) and a guard ``g(S, ctx, t) -> float``; the
witnesses', arming's and the invariants' rules take the scalars their Python callers have. Kept to what
both take: float and int scalars, indexing of S and of the vectors, ``if``,
``while``, ``for ... in range``, calls; a rule must never divide by zero (C would go on where
Python raises).
"""
from __future__ import annotations

import sys

# As Python the rules ask Cython only whether they are compiled: unless Cython is imported already, the shim
# answers, for this import only (Cython's shadow module takes 5 ms to import, and Cython is build-only)
if sys.modules.get("cython") is not None:
    import cython
else:
    from biped_sim.engine import _cython_shim
    _entry = sys.modules.pop("cython", _cython_shim)     # (None: an import of Cython is refused)
    sys.modules["cython"] = _cython_shim
    try:
        import cython
    finally:
        if _entry is _cython_shim:
            del sys.modules["cython"]
        else:
            sys.modules["cython"] = _entry

if not cython.compiled:
    from math import fabs, hypot, isfinite, isnan, nan as NAN, pow

    from biped_sim.engine.loop_kernels import (
        k_copy,
        k_dense,
        k_energy,
        k_foot_kinematics,
        k_foot_positions,
        k_impact_map,
        k_rhs,
        k_step,
        k_ulp,
    )
    from biped_sim.engine.loop_state import (
        ARMED,
        ATOL,
        CALLBACK_FAILED,
        CHAIN,
        CHAIN_LINKS,
        CHAIN_MAX,
        CHAIN_WIDTH,
        COEF,
        COEF_LENGTH,
        COEF_LINKS,
        COEF_WIDTH,
        COS_S,
        DEEPEST_SCUFF,
        DEEPEST_TRIAL,
        DENSE,
        DENSE_READY,
        DIP_D,
        DQ_MINUS,
        DQ_PLUS,
        ENERGY_AFTER,
        ENERGY_BEFORE,
        EVENT_TOL,
        FAIL_KIND,
        FAIL_T,
        FAIL_VALUE,
        FEET,
        FEET_AFTER,
        FEET_END,
        FEET_END_T,
        FIXED_BASE,
        FORCE_END,
        FORCE_END_T,
        FORWARD_RULE,
        FRONT_TOL,
        GRAZE_TOL,
        GROUND_TOL,
        GUARD_LEG,
        H_ABS,
        IMPACT_OLD_FOOT_SINKS,
        IMPACT_OUTSIDE_CONE,
        IMPACT_PULLS,
        IMPULSE,
        KINEMATICS,
        LAST_IMPACT,
        MAX_DEPTH,
        MAX_STEP,
        METHOD,
        MODE_EVENTS,
        MU,
        N_IMPACTS,
        N_Q,
        N_RECENT,
        N_Y,
        NACCEPTED,
        NFEV,
        NMAX,
        NREJECTED,
        OUT,
        PS,
        Q_IMPACT,
        QS,
        RECENT_IMPACTS,
        RESULT,
        RING,
        ROW_Q,
        ROW_T,
        RTOL,
        SCUFF,
        SCUFF_DEPTH,
        SCUFF_TRIAL,
        SCUFFING,
        SCUFFS,
        SIN_S,
        STACK,
        STAGES,
        STANCE_HOLDS,
        STANCE_LIFTS_OFF,
        STANCE_SLIPS,
        T_BOUND,
        T_OLD,
        TAN_S,
        TO_POWER_BASIS,
        TV,
        Y_OLD,
        F,
        H,
        T,
        Y,
    )


# -- the stepper (integrators._ListRungeKutta) ------------------------------------------------------------
def rk_begin(S, fun, ctx):
    """A mode's start at (S[T], S[Y]): the step's start there, f = fun(t, y) (one evaluation)."""
    S[T_OLD] = S[T]
    k_copy(S, Y_OLD, Y, NMAX)
    k_rhs(S, fun, ctx, S[T], Y, F)
    S[NFEV] += 1
    S[DENSE_READY] = 0.0


def rk_carried_step(h, max_step):
    """The step size a mode starts with: h, the one carried over from the mode before, capped by max_step
    (Python's min(h, max_step))."""
    return max_step if max_step < h else h


def rk_step(S, fun, ctx):
    """One accepted step (0), none at t_bound (1), or a failure (-1: S[FAIL_*] say which, the state
    unchanged) with scipy's step control (Hairer's: safety 0.9, factors 0.2 to 10)."""
    t: cython.double = S[T]
    remaining: cython.double = S[T_BOUND] - t
    if remaining <= 0:
        return 1
    min_step: cython.double = 10 * k_ulp(t) + 1e-300
    h_abs: cython.double = S[MAX_STEP] if S[MAX_STEP] < S[H_ABS] else S[H_ABS]
    dop853: cython.bint = S[METHOD] == 0.0
    exponent: cython.double = -1.0 / 8 if dop853 else -1.0 / 5     # -1 / (the error estimator's order + 1)
    evaluations: cython.double = 12.0 if dop853 else 6.0           # a step's (dopri5's last is the next f)
    stages: cython.Py_ssize_t = 13 if dop853 else 7                 # k0..k12, k0..k6
    rejected: cython.bint = False
    h: cython.double
    err: cython.double
    s: cython.double
    factor: cython.double
    v: cython.double
    i: cython.Py_ssize_t
    n: cython.Py_ssize_t = int(S[N_Y])
    while True:
        if h_abs < min_step:
            S[FAIL_KIND] = 1.0
            S[FAIL_VALUE] = h_abs
            S[FAIL_T] = t
            return -1
        h = h_abs
        if h >= remaining:
            h = remaining
            h_abs = remaining
        k_step(S, fun, ctx, t, Y, F, h, S[RTOL], S[ATOL], OUT)
        if S[CALLBACK_FAILED] != 0.0:   # the torque law failed inside (the Python law raises before this)
            S[FAIL_KIND] = 3.0
            return -1
        S[NFEV] += evaluations
        err = S[OUT + 2 * n]
        if err < 1.0:
            s = 0.0
            for i in range(n):
                s += S[OUT + i]
            if not isfinite(s):
                S[FAIL_KIND] = 2.0
                S[FAIL_VALUE] = t + h
                S[FAIL_T] = t
                return -1
            if err == 0.0:
                factor = 10.0
            else:
                factor = 0.9 * pow(err, exponent)
                factor = factor if factor < 10.0 else 10.0
            if rejected:
                factor = factor if factor < 1.0 else 1.0
            S[H_ABS] = h_abs * factor
            break
        if not isfinite(err):
            h_abs *= 0.2
        else:
            v = 0.9 * pow(err, exponent)
            h_abs *= v if v > 0.2 else 0.2
        rejected = True
        S[NREJECTED] += 1
    S[NACCEPTED] += 1
    S[T_OLD] = t
    k_copy(S, Y_OLD, Y, n)
    S[H] = h
    S[T] = t + h if h < remaining else S[T_BOUND]
    k_copy(S, Y, OUT, n)                                    # the trial step's rows are n apart (S[N_Y])
    k_copy(S, F, OUT + n, n)
    k_copy(S, STAGES, OUT + 2 * n + 1, stages * n)
    S[DENSE_READY] = 0.0
    return 0


def rk_dense(S, fun, ctx):
    """The last step's dense output rows, computed once a step (dop853: 3 more evaluations)."""
    if S[DENSE_READY] != 0.0:
        return
    k_dense(S, fun, ctx, S[T_OLD], S[H], Y_OLD, Y, STAGES, DENSE)
    if S[METHOD] == 0.0:
        S[NFEV] += 3
    S[DENSE_READY] = 1.0


def rk_dense_at(S, i, tt):
    """Entry i of the dense output at tt (rk_dense first): dop853's nested product in x and 1 - x, dopri5's
    y + h (((q4 x + q3) x + q2) x + q1) x, x = (tt - t_old) / h (scipy's, by Horner's rule)."""
    hi: cython.double = S[T] - S[T_OLD]
    x: cython.double = (tt - S[T_OLD]) / hi
    u: cython.double
    r: cython.Py_ssize_t
    if S[METHOD] == 0.0:
        u = 1.0 - x
        r = DENSE + 8 * i
        return ((((((S[r + 1] * x + S[r + 2]) * u + S[r + 3]) * x + S[r + 4]) * u + S[r + 5]) * x + S[r + 6]) * u
                + S[r + 7]) * x + S[r]
    r = DENSE + 5 * i
    return S[r] + hi * ((((S[r + 4] * x + S[r + 3]) * x + S[r + 2]) * x + S[r + 1]) * x)


def rk_dense_state(S, tt):
    """The whole state on the dense output at tt, into S[OUT:OUT + n] (rk_dense first)."""
    i: cython.Py_ssize_t
    n: cython.Py_ssize_t = int(S[N_Y])
    for i in range(n):
        S[OUT + i] = rk_dense_at(S, i, tt)


# -- a foot's height, the dip search and the root finder (grazing.py, guards.locate_crossing) ---------------
def ev_height_at(S, leg, tt):
    """Foot leg's height across the slope on the floating base's dense output at tt (guards.foot_height)."""
    i: cython.Py_ssize_t
    for i in range(int(S[N_Q])):
        S[QS + i] = rk_dense_at(S, i, tt)
    k_foot_positions(S, QS, PS)
    return ev_across(S[TAN_S], S[PS + 2 * leg - 2], S[PS + 2 * leg - 1])


def ev_height_guard(S, ctx, tt):
    """ev_height_at of foot S[GUARD_LEG], as a guard g(S, ctx, t)."""
    leg: cython.int = int(S[GUARD_LEG])
    return ev_height_at(S, leg, tt)


def ev_power_coefficient(S, r, p, w, hi):
    """The power-basis coefficient of x^p (x = (t - t_old) / h) of the dense output's row at S[r] (rk_dense first),
    the row w wide: dop853 (w 8): TO_POWER_BASIS times the row; dopri5 (w 5): y, h q1 .. h q4, then zeros."""
    j: cython.Py_ssize_t
    a: cython.double
    if w == 8:
        a = 0.0
        for j in range(8):
            a += S[TO_POWER_BASIS + 8 * p + j] * S[r + j]
        return a
    if p == 0:
        return S[r]
    if p < 5:
        return hi * S[r + p]
    return 0.0


def ev_dip_coefficients(S, leg):
    """S[COEF]: |power-basis coefficients| (ev_power_coefficient) of the floating base's x and y and of the absolute
    angle of each link of foot leg's chain (S[CHAIN]: the sum of its terms' entries of y, in their order), a row
    of COEF_WIDTH for each power 0 to 7; S[COEF_LINKS] and S[COEF_LENGTH] the chain's links and their lengths
    (rk_dense first). x, y and the first link's first two terms are taken in one pass over the dense rows (the
    three-link's chain is that link: its leg's entry and the torso's), the other terms one by one."""
    p: cython.Py_ssize_t
    c: cython.Py_ssize_t
    j: cython.Py_ssize_t
    e: cython.Py_ssize_t
    m: cython.Py_ssize_t
    row: cython.Py_ssize_t
    w: cython.Py_ssize_t = 8 if S[METHOD] == 0.0 else 5
    links: cython.Py_ssize_t = int(S[CHAIN_LINKS + leg - 1])
    chain: cython.Py_ssize_t = CHAIN + CHAIN_MAX * CHAIN_WIDTH * (leg - 1)
    m0: cython.Py_ssize_t = int(S[chain + 1]) if links > 0 else 0
    e0: cython.Py_ssize_t = int(S[chain + 2]) if m0 > 0 else 1
    e1: cython.Py_ssize_t = int(S[chain + 3]) if m0 > 1 else 1
    ra: cython.Py_ssize_t = DENSE + w * ((e0 if e0 > 0 else -e0) - 1)     # the rows of the first two terms, x and y
    rt: cython.Py_ssize_t = DENSE + w * ((e1 if e1 > 0 else -e1) - 1)
    rx: cython.Py_ssize_t = DENSE
    ry: cython.Py_ssize_t = DENSE + w
    hi: cython.double = S[T] - S[T_OLD]
    leg_and_torso: cython.bint = links == 1 and m0 == 2 and e0 > 0 and e1 > 0   # a chain of one link, two terms
    a: cython.double
    t: cython.double
    x: cython.double
    y: cython.double
    b: cython.double
    v: cython.double
    S[COEF_LINKS] = links
    for c in range(links):
        S[COEF_LENGTH + c] = S[chain + CHAIN_WIDTH * c]
    for p in range(8):
        if w == 8:
            a = t = x = y = 0.0
            for j in range(8):
                b = S[TO_POWER_BASIS + 8 * p + j]
                a += b * S[ra + j]
                t += b * S[rt + j]
                x += b * S[rx + j]
                y += b * S[ry + j]
        elif p == 0:
            a, t, x, y = S[ra], S[rt], S[rx], S[ry]
        elif p < 5:
            a, t, x, y = hi * S[ra + p], hi * S[rt + p], hi * S[rx + p], hi * S[ry + p]
        else:
            a = t = x = y = 0.0
        S[COEF + COEF_WIDTH * p] = fabs(x)
        S[COEF + COEF_WIDTH * p + 1] = fabs(y)
        if leg_and_torso:   # (the three-link's: its leg's angle plus the torso's)
            S[COEF + COEF_WIDTH * p + 2] = fabs(a + t)
            continue
        if links == 0:
            continue
        if e0 < 0:
            a = -a
        if m0 > 1:
            a = a + t if e1 > 0 else a - t
        if m0 > 2:
            for j in range(2, m0):
                e = int(S[chain + 2 + j])
                v = ev_power_coefficient(S, DENSE + w * ((e if e > 0 else -e) - 1), p, w, hi)
                a = a + v if e > 0 else a - v
        S[COEF + COEF_WIDTH * p + 2] = fabs(a)
        if links < 2:
            continue
        for c in range(1, links):
            row = chain + CHAIN_WIDTH * c
            m = int(S[row + 1])
            a = 0.0
            for j in range(m):
                e = int(S[row + 2 + j])
                v = ev_power_coefficient(S, DENSE + w * ((e if e > 0 else -e) - 1), p, w, hi)
                if j == 0:
                    a = v if e > 0 else -v
                elif e > 0:
                    a = a + v
                else:
                    a = a - v
            S[COEF + COEF_WIDTH * p + 2 + c] = fabs(a)


def ev_dip_search(S, g, ctx, h0, h1):
    """grazing.dip_bracket's search over the last step [t_old, t] (both ends above the ground: guard values h0,
    h1 > 0) with the |coefficients| in S[COEF] (ev_dip_coefficients): 1 and a bracket in S[RESULT:RESULT + 2]
    where the guard g(S, ctx, t) may dip deeper than graze_tol inside the step, else 0.

    The bound. The foot is the floating base's point plus one vector per link of its chain, each of fixed
    length l_k turning with the link's absolute angle a_k: p = (x, y) + sum_k l_k (sin(a_k + phi_k),
    cos(a_k + phi_k)). Its height across the ground is h = p_y + tan p_x, so in s = (t - t_old) / h
    h'' = y'' + tan x'' + sum_k l_k [(cos - tan sin)(.) a_k'' - (sin + tan cos)(.) a_k'^2], and as |sin|, |cos| <= 1:
    |h''| <= |y''| + |tan| |x''| + sum_k l_k (1 + |tan|) (|a_k''| + a_k'^2). Each of x, y and a_k is a
    polynomial in s with power-basis coefficients c_p, so on [0, b] |f'| <= sum_p p |c_p| b^(p-1) and
    |f''| <= sum_p p (p - 1) |c_p| b^(p-2) (the derivative weights). Fixed base (the three-link's): the hip hangs
    from the pin by the stance leg, so x, y give way to its angle: l (1 + |tan|) (|a''| + a'^2 + |a_st''| +
    a_st'^2). Then h >= min(h(a), h(b)) - M2 (b - a)^2 / 8 on [a, b] (M2 the bound): an interval where that is
    positive holds no dip; the others are halved, the left half searched first."""
    k: cython.Py_ssize_t
    c: cython.Py_ssize_t
    ta: cython.double = fabs(S[TAN_S])
    links: cython.Py_ssize_t = int(S[COEF_LINKS])
    lt: cython.double = S[COEF_LENGTH] * (1 + ta) if links > 0 else 0.0
    slack: cython.double = 1.0 + 1e-6           # the coefficients carry roundoff
    t_old: cython.double = S[T_OLD]
    h_step: cython.double = S[T] - S[T_OLD]
    fixed: cython.bint = S[FIXED_BASE] != 0.0
    top: cython.Py_ssize_t
    r: cython.Py_ssize_t
    a: cython.double
    b: cython.double
    ha: cython.double
    hb: cython.double
    depth: cython.int
    d1a: cython.double
    d2a: cython.double
    d1x: cython.double
    d2x: cython.double
    d2y: cython.double
    w1: cython.double
    w2: cython.double
    d1: cython.double
    bound: cython.double
    drop: cython.double
    lo: cython.double
    mid: cython.double
    hm: cython.double
    S[STACK] = 0.0
    S[STACK + 1] = 1.0
    S[STACK + 2] = h0
    S[STACK + 3] = h1
    S[STACK + 4] = 0.0
    top = 1
    while top:
        top -= 1
        a = S[STACK + 5 * top]
        b = S[STACK + 5 * top + 1]
        ha = S[STACK + 5 * top + 2]
        hb = S[STACK + 5 * top + 3]
        depth = int(S[STACK + 5 * top + 4])
        # the derivative bounds of x (d1x, d2x), y (d2y), the first link's angle (d1a, d2a) and, in S[DIP_D], the
        # other links' angles
        d1a = d2a = d1x = d2x = d2y = 0.0
        if links > 1:
            for c in range(3, 2 + links):
                S[DIP_D + c] = 0.0
                S[DIP_D + COEF_WIDTH + c] = 0.0
        for k in range(8):
            # the derivative weights over [0, b]: k b^(k-1) and k (k-1) b^(k-2) (on [0, 1] the powers are 1)
            if b == 1.0:
                w1 = k
                w2 = k * (k - 1)
            else:
                w1 = k * pow(b, 1.0 * (k - 1 if k - 1 > 0 else 0))
                w2 = k * (k - 1) * pow(b, 1.0 * (k - 2 if k - 2 > 0 else 0))
            r = COEF + COEF_WIDTH * k
            d1a += w1 * S[r + 2]
            d2a += w2 * S[r + 2]
            d1x += w1 * S[r]
            d2x += w2 * S[r]
            d2y += w2 * S[r + 1]
            if links > 1:
                for c in range(3, 2 + links):
                    S[DIP_D + c] += w1 * S[r + c]
                    S[DIP_D + COEF_WIDTH + c] += w2 * S[r + c]
        if fixed:   # (x's column holds the stance leg's angle)
            bound = lt * (d2a + d1a * d1a + d2x + d1x * d1x) * slack
        else:
            bound = lt * (d2a + d1a * d1a)
            if links > 1:
                for c in range(3, 2 + links):
                    d1 = S[DIP_D + c]
                    bound += S[COEF_LENGTH + c - 2] * (1 + ta) * (S[DIP_D + COEF_WIDTH + c] + d1 * d1)
            bound = (bound + d2y + ta * d2x) * slack
        drop = bound * (b - a) * (b - a) / 8
        lo = ha if ha < hb else hb
        if lo - drop > 0 or drop <= S[GRAZE_TOL] or depth >= MAX_DEPTH:
            continue
        mid = 0.5 * (a + b)
        hm = g(S, ctx, t_old + mid * h_step)
        if hm <= 0:
            S[RESULT] = t_old + a * h_step
            S[RESULT + 1] = t_old + mid * h_step
            return 1
        S[STACK + 5 * top] = mid
        S[STACK + 5 * top + 1] = b
        S[STACK + 5 * top + 2] = hm
        S[STACK + 5 * top + 3] = hb
        S[STACK + 5 * top + 4] = depth + 1
        top += 1
        S[STACK + 5 * top] = a
        S[STACK + 5 * top + 1] = mid
        S[STACK + 5 * top + 2] = ha
        S[STACK + 5 * top + 3] = hm
        S[STACK + 5 * top + 4] = depth + 1
        top += 1
    return 0


def ev_may_dip(S, fun, ctx, leg, h0, h1):
    """ev_dip_search of the floating base's foot leg on the last step (heights h0, h1 at its ends)."""
    rk_dense(S, fun, ctx)
    ev_dip_coefficients(S, leg)
    S[GUARD_LEG] = leg
    return ev_dip_search(S, ev_height_guard, ctx, h0, h1)


def ev_may_sink_in_step(h0, h1, ground_tol):
    """Whether a resting free foot (not armed) whose heights at the last step's ends are h0 and h1 may have gone
    deeper than ground_tol under the ground inside the step unseen: neither end is that deep (an end that is
    deeper is seen there), so its dip search runs on its height plus ground_tol, positive at both ends."""
    return h0 + ground_tol > 0 and h1 + ground_tol > 0


def ev_height_below_guard(S, ctx, tt):
    """The height of foot S[GUARD_LEG] plus S[GROUND_TOL] (ev_height_at): as a guard g(S, ctx, t), zero where the
    foot is ground_tol under the ground."""
    leg: cython.int = int(S[GUARD_LEG])
    return ev_height_at(S, leg, tt) + S[GROUND_TOL]


def ev_resting_foot_dips(S, fun, ctx, leg, h0, h1):
    """Whether the floating base's resting free foot leg (not armed; heights h0, h1 at the last step's ends)
    goes deeper than S[GROUND_TOL] under the ground inside the step: ev_dip_search of its height plus
    ground_tol (ev_may_sink_in_step first), its bracket in S[RESULT:RESULT + 2]. A foot the touchdown
    witness does not watch, found as the invariant 'feet at or above the ground' bounds it."""
    tol: cython.double = S[GROUND_TOL]
    if not ev_may_sink_in_step(h0, h1, tol):
        return 0
    rk_dense(S, fun, ctx)
    ev_dip_coefficients(S, leg)
    S[GUARD_LEG] = leg
    return ev_dip_search(S, ev_height_below_guard, ctx, h0 + tol, h1 + tol)


def ev_locate_crossing(S, g, ctx, ta, tb):
    """Where the guard g(S, ctx, t) (positive at ta, <= 0 at tb) crosses zero in [ta, tb]: 0 and the time in
    S[RESULT] (an end of the bracket where the guard is zero there already), or -1 where scipy's brentq
    raises (no sign change, a NaN, no convergence). brentq as scipy/optimize/Zeros/brentq.c, the same iterates:
    xtol S[EVENT_TOL], rtol 4 eps, 200 iterations."""
    ga: cython.double = g(S, ctx, ta)
    gb: cython.double = g(S, ctx, tb)
    if gb == 0.0:
        S[RESULT] = tb
        return 0
    if ga <= 0:
        S[RESULT] = ta
        return 0
    xtol: cython.double = S[EVENT_TOL]
    rtol: cython.double = 4 * 2.220446049250313e-16
    xpre: cython.double = ta
    xcur: cython.double = tb
    xblk: cython.double = 0.0
    fblk: cython.double = 0.0
    spre: cython.double = 0.0
    scur: cython.double = 0.0
    fpre: cython.double = g(S, ctx, xpre)
    fcur: cython.double = g(S, ctx, xcur)
    sbis: cython.double
    delta: cython.double
    stry: cython.double
    dpre: cython.double
    dblk: cython.double
    lim: cython.double
    tried: cython.bint
    _iteration: cython.int
    if isnan(fpre) or isnan(fcur):
        return -1
    if fpre == 0:
        S[RESULT] = xpre
        return 0
    if fcur == 0:
        S[RESULT] = xcur
        return 0
    if (fpre < 0) == (fcur < 0):
        return -1
    for _iteration in range(200):
        if fpre != 0 and fcur != 0 and (fpre < 0) != (fcur < 0):
            xblk = xpre
            fblk = fpre
            spre = scur = xcur - xpre
        if fabs(fblk) < fabs(fcur):
            xpre = xcur
            xcur = xblk
            xblk = xpre
            fpre = fcur
            fcur = fblk
            fblk = fpre
        delta = (xtol + rtol * fabs(xcur)) / 2
        sbis = (xblk - xcur) / 2
        if fcur == 0 or fabs(sbis) < delta:
            S[RESULT] = xcur
            return 0
        if fabs(spre) > delta and fabs(fcur) < fabs(fpre):
            # A zero denominator (equal values, or a product that underflows: a guard of 1e-150) gives scipy's
            # C an infinite or NaN trial step, which the test below refuses (a bisection): so does this, without
            # dividing (Python would raise where C goes on)
            tried = False
            if xpre == xblk:        # interpolate
                if fcur != fpre:
                    stry = -fcur * (xcur - xpre) / (fcur - fpre)
                    tried = True
            elif xpre != xcur and xblk != xcur:     # extrapolate
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                if dblk * dpre * (fblk - fpre) != 0:
                    stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
                    tried = True
            lim = 3 * fabs(sbis) - delta
            if tried and 2 * fabs(stry) < (fabs(spre) if fabs(spre) < lim else lim):
                spre = scur
                scur = stry
            else:
                spre = sbis
                scur = sbis
        else:
            spre = sbis
            scur = sbis
        xpre = xcur
        fpre = fcur
        if fabs(scur) > delta:
            xcur += scur
        else:
            xcur += delta if sbis > 0 else -delta
        fcur = g(S, ctx, xcur)
        if isnan(fcur):
            return -1
    return -1


def ev_locate_height_crossing(S, fun, ctx, leg, ta, tb):
    """ev_locate_crossing of the floating base's foot leg's height on the last step."""
    rk_dense(S, fun, ctx)
    S[GUARD_LEG] = leg
    return ev_locate_crossing(S, ev_height_guard, ctx, ta, tb)


# -- the witnesses (witnesses.py) --------------------------------------------------------------------------
def ev_triggered(w0, w1):
    """Whether a witness whose value is w0 at a step's start and w1 at its end fired in the step: the one
    direction of the model's witnesses, positive then non-positive (a NaN fires nothing)."""
    return w0 > 0 and w1 <= 0


def ev_across(tan_s, x, y):
    """The height across the sloped ground of a point at (x, y), or the rate across it of a velocity (x, y):
    y + tan(slope) x. The touchdown witness's value is its foot's height across the ground."""
    return y + tan_s * x


def ev_foot_states(p, i, tan_s, ft, j):
    """The feet's states laid out from their kinematics p[i:i + 8] (k_foot_kinematics': foot 1's (x, y), foot
    2's, then their velocities) into ft[j:j + 8]: per foot its x, its height across the ground, and their rates
    (the touchdown witness is a free foot's height)."""
    ft[j] = p[i]                                        # (written out: the Python loop calls it every step)
    ft[j + 1] = ev_across(tan_s, p[i], p[i + 1])
    ft[j + 2] = p[i + 4]
    ft[j + 3] = ev_across(tan_s, p[i + 4], p[i + 5])
    ft[j + 4] = p[i + 2]
    ft[j + 5] = ev_across(tan_s, p[i + 2], p[i + 3])
    ft[j + 6] = p[i + 6]
    ft[j + 7] = ev_across(tan_s, p[i + 6], p[i + 7])


def ev_foot_point(p, leg, point):
    """Foot leg's (x, y) (1 or 2) taken from the feet's positions p (k_foot_positions': foot 1's, then foot 2's)
    into point: the pin of a stance that starts on it."""
    point[0] = p[2 * leg - 2]
    point[1] = p[2 * leg - 1]


def ev_normal(sin_s, cos_s, fx, fy):
    """The normal component (into the ground line, up) of a ground force or impulse (fx, fy)."""
    return fx * sin_s + fy * cos_s


def ev_tangential(sin_s, cos_s, fx, fy):
    """The tangential component (along the ground line, forward) of a ground force or impulse (fx, fy)."""
    return fx * cos_s - fy * sin_s


def ev_slip_margin(mu, normal, tangential):
    """The slip witness's value, the margin inside the friction cone: mu F_n - |F_t|."""
    return mu * normal - fabs(tangential)


def ev_normal_force(S, fx, fy):
    """The liftoff witness's value: the normal component of the stance force (fx, fy) on S's ground."""
    return ev_normal(S[SIN_S], S[COS_S], fx, fy)


def ev_tangential_force(S, fx, fy):
    """The tangential component of the stance force (fx, fy) on S's ground."""
    return ev_tangential(S[SIN_S], S[COS_S], fx, fy)


def ev_cone_margin(S, fx, fy):
    """The slip witness's value for the stance force (fx, fy) on S's ground, under S's mu."""
    return ev_slip_margin(S[MU], ev_normal(S[SIN_S], S[COS_S], fx, fy), ev_tangential(S[SIN_S], S[COS_S], fx, fy))



def ev_ground_y(tan_s, x, height):
    """The y of a point at x whose height across the ground is height (ev_across's inverse), or the y rate of a
    velocity (x, its rate across the ground)."""
    return height - tan_s * x


# -- arming: a free foot's touchdown witness counts once the foot has been above the ground ------------------
def ev_arms(free, height, arm_height):
    """Whether a free foot (free: not the stance foot) whose touchdown witness is disarmed arms at a step's
    end: higher than arm_height above the ground. A reset disarms the feet it put on the ground or took off
    it (ev_disarmed_by_reset), whose witness, zero there, must not fire again at once."""
    return free and height > arm_height


def ev_disarmed_by_reset(leg, both, stance_before, stance_after):
    """Whether a reset disarms foot leg's touchdown witness: every foot after a double touchdown, else the
    stance feet before and after it (0: none, in flight); both: a double touchdown."""
    return both or leg == stance_before or leg == stance_after


# -- the projection onto the pinned stance foot (modes.project_onto_pin) -------------------------------------
def ev_pin_drift(foot, pin, tan_s):
    """|p - c|: the distance of the stance foot (foot: x, height across the ground, their rates) from its pin
    (x, y)."""
    return hypot(foot[0] - pin[0], ev_ground_y(tan_s, foot[0], foot[1]) - pin[1])


def ev_pin_drift_rate(foot):
    """|J dq|: the stance foot's speed (foot: x, height across the ground, their rates)."""
    return hypot(foot[2], foot[3])


def ev_project_onto_pin(q, dq, foot, pin, tan_s):
    """The floating-base stance state (q, dq, changed in place) projected back onto the constraints: the hip
    moved by the stance foot's drift from its pin, the base velocity set so that J dq = 0 (J = [I2 | A]:
    subtracting J dq from dq_base)."""
    q[0] += pin[0] - foot[0]
    q[1] += pin[1] - ev_ground_y(tan_s, foot[0], foot[1])
    dq[0] -= foot[2]
    dq[1] -= ev_ground_y(tan_s, foot[2], foot[3])


# -- the invariants' predicates (invariants.py) and the sample's thinning (results.Samples) -------------------
def ev_finite_state(q, dq, n):
    """The invariant 'finite state': the sum of q's n entries plus that of dq's is finite."""
    s: cython.double = 0.0
    sd: cython.double = 0.0
    i: cython.Py_ssize_t
    for i in range(n):
        s += q[i]
    for i in range(n):
        sd += dq[i]
    return isfinite(s + sd)


def ev_violated(value, tol):
    """Whether an invariant 'value >= 0' (a foot's height, the normal force, the friction-cone margin, a normal
    impulse) is violated beyond its tolerance tol."""
    return value < -tol


def ev_provisional(appended, every):
    """Whether the newest of appended samples will be overwritten by the next: thinned out, keeping the first,
    then every every-th (every 0: none but the events' and the last)."""
    return appended > 1 and (every == 0 or (appended - 1) % every != 0)

# -- the scuffs of touchdown_rule "front" (guards.py, locator.py) -------------------------------------------
def ev_swinging_through(dx, dheight):
    """A foot moving forward more than it sinks (a crossing at most 45 degrees steep)."""
    return dx > 0.0 and dx + dheight >= 0.0


def ev_starts_scuff(forward, front_tol, x, dx, dheight, x_stance):
    """Whether a swing foot (x, its rates dx, dheight) crossing the ground going down passes through it (a
    scuff): at or behind the stance foot (at x_stance; within front_tol counts as behind), and under scuff_rule
    "forward" (forward true) swinging through."""
    if x > x_stance + front_tol:
        return False
    return not forward or ev_swinging_through(dx, dheight)


def ev_start_scuff(scuff, i, t, scuffs):
    """A scuff that starts at t (a crossing that passes through the ground, ev_starts_scuff): its row
    scuff[i:i + 3] (t_start, the deepest dip so far, its time t_deepest) begun, and the count of the scuffs,
    scuffs, one more (returned)."""
    scuff[i] = t
    scuff[i + 1] = 0.0
    scuff[i + 2] = t
    return scuffs + 1


def ev_scuff_under_way(S, leg, t, depth):
    """A scuff of foot leg under way at t, the foot depth under the ground there (a start whose free foot the start
    check lets lie deeper than ground_tol because its crossing would be a scuff): the foot armed and in a scuff
    (ARMED, SCUFFING), as a crossing that passes through leaves it, its row SCUFF begun at t (ev_start_scuff) with
    depth its deepest dip so far, the scuffs counted (SCUFFS) and DEEPEST_SCUFF at least depth."""
    i: cython.Py_ssize_t = SCUFF + 3 * (leg - 1)
    S[ARMED + leg - 1] = 1.0
    S[SCUFFING + leg - 1] = 1.0
    S[SCUFFS] = ev_start_scuff(S, i, t, S[SCUFFS])
    S[i + 1] = depth
    S[DEEPEST_SCUFF] = ev_running_max(S[DEEPEST_SCUFF], depth)


def ev_passes_through(forward, front_tol, x, dx, dheight, x_stance):
    """Whether a swing foot under the ground still passes through it: under "forward" while it swings
    through, under "behind" while it is behind the stance foot."""
    if forward:
        return ev_swinging_through(dx, dheight)
    return x <= x_stance + front_tol


def ev_keep_feet_end(S, t, ft, i):
    """The feet at the step's end t (ft[i:i + 8], ev_foot_states' layout) kept in S (FEET_END, its time
    FEET_END_T) for the next step's start."""
    k: cython.Py_ssize_t
    S[FEET_END_T] = t
    for k in range(8):
        S[FEET_END + k] = ft[i + k]


def ev_keep_force_end(S, t, fx, fy):
    """The stance force (fx, fy) at the step's end t kept in S (FORCE_END, its time FORCE_END_T) for the next
    step's start."""
    S[FORCE_END_T] = t
    S[FORCE_END] = fx
    S[FORCE_END + 1] = fy


def ev_forget_feet_end(S):
    """The feet kept of the last step's end forgotten (FEET_END_T NaN): a reset changed the state they were of."""
    S[FEET_END_T] = NAN


def ev_forget_force_end(S):
    """The stance force kept of the last step's end forgotten (FORCE_END_T NaN)."""
    S[FORCE_END_T] = NAN


def ev_feet_kept_at(S, t):
    """Whether the feet kept are of time t (the step's start: the last step's end), so need not be computed."""
    return S[FEET_END_T] == t


def ev_force_kept_at(S, t):
    """Whether the stance force kept is of time t (the step's start)."""
    return S[FORCE_END_T] == t


def ev_within_step(t_old, t, tt):
    """Whether tt lies in the last step [t_old, t], where its dense output holds (an ended scuff's deepest point:
    the state there is recorded, else NaN)."""
    return t_old <= tt and tt <= t


def ev_track_scuff(S, feet_at, ctx, leg, stance_leg, t_end):
    """Follow foot leg's scuff (S[SCUFF_TRIAL]: t_start, deepest, t_deepest) over the last step up to t_end, on
    9 even points from max(t_start, t_old) (numpy.linspace's), the feet there by feet_at(S, ctx, t) into
    S[FEET]: its deepest dip, and S[DEEPEST_TRIAL] the deepest of any. 0: it goes on; 1: it ended (the foot
    above the ground at t_end); -1: at S[RESULT] the foot is S[RESULT + 1] under the ground and no longer
    passes through it (S[FEET] the feet there); -2: deeper than scuff_depth."""
    t0: cython.double = S[T_OLD] if S[T_OLD] > S[SCUFF_TRIAL] else S[SCUFF_TRIAL]
    step: cython.double = (t_end - t0) / 8
    tt: cython.double
    depth: cython.double
    i: cython.Py_ssize_t
    f: cython.Py_ssize_t = FEET + 4 * (leg - 1)
    st: cython.Py_ssize_t = FEET + 4 * (stance_leg - 1)
    for i in range(9):
        tt = i * step + t0 if i < 8 else t_end
        feet_at(S, ctx, tt)
        depth = -S[f + 1]
        if depth > S[SCUFF_TRIAL + 1]:
            S[SCUFF_TRIAL + 1] = depth
            S[SCUFF_TRIAL + 2] = tt
        if depth > 0 and not ev_passes_through(S[FORWARD_RULE] != 0.0, S[FRONT_TOL], S[f], S[f + 2], S[f + 3], S[st]):
            S[RESULT] = tt
            S[RESULT + 1] = depth
            return -1
    S[DEEPEST_TRIAL] = S[DEEPEST_TRIAL] if not S[SCUFF_TRIAL + 1] > S[DEEPEST_TRIAL] else S[SCUFF_TRIAL + 1]
    if S[SCUFF_TRIAL + 1] > S[SCUFF_DEPTH]:
        return -2
    return 1 if S[f + 1] > 0.0 else 0


# -- the touchdown: the impact and its checks (resets.py, invariants.py), the next stance's start (hybrid.py) --
def ev_outside_cone(mu, n, tg, tol):
    """Whether an impulse (or a force) with normal component n and tangential tg lies outside the friction cone
    by more than tol: |tg| - mu n > tol (tol 0: |tg| > mu n)."""
    return fabs(tg) - mu * n > tol


def ev_stays_down(dheight, tol):
    """Whether the old stance foot, its rate across the ground dheight after an impact, does not leave the ground
    faster than tol (tol 0: it moves into the ground)."""
    return dheight < tol


def ev_impulse_checks(has_mu, mu, n, tg):
    """The assumptions a ground impulse on a landing foot (normal n, tangential tg) violates, as the bits of
    loop_state.CODES: IMPACT_PULLS where it pulls the foot into the ground (n < 0), else IMPACT_OUTSIDE_CONE
    where, with a friction coefficient mu (has_mu), it lies outside the cone."""
    if ev_violated(n, 0.0):
        return IMPACT_PULLS
    if has_mu and ev_outside_cone(mu, n, tg, 0.0):
        return IMPACT_OUTSIDE_CONE
    return 0


def ev_impact(S, leg, old, has_mu):
    """The rigid plastic impact of foot leg (docs/model.md "Impact": the generated closed form, one foot) at
    q = S[Q_IMPACT], dq- = S[DQ_MINUS], old the stance foot before it (0 in flight): into S dq+ (DQ_PLUS), the
    ground's impulse on the foot (IMPULSE), T + V before and after (ENERGY_BEFORE, ENERGY_AFTER: the loss is
    their difference) and the feet after it (FEET_AFTER). Returns the bits of the assumptions it violates:
    ev_impulse_checks' on the impulse, and IMPACT_OLD_FOOT_SINKS where the old stance foot moves into the
    ground."""
    code: cython.int
    k_impact_map(S, leg, Q_IMPACT, DQ_MINUS, DQ_PLUS)
    k_energy(S, Q_IMPACT, DQ_MINUS, TV)
    S[ENERGY_BEFORE] = S[TV] + S[TV + 1]
    k_energy(S, Q_IMPACT, DQ_PLUS, TV)
    S[ENERGY_AFTER] = S[TV] + S[TV + 1]
    k_foot_kinematics(S, Q_IMPACT, DQ_PLUS, KINEMATICS)
    ev_foot_states(S, KINEMATICS, S[TAN_S], S, FEET_AFTER)
    code = ev_impulse_checks(has_mu, S[MU], ev_normal_force(S, S[IMPULSE], S[IMPULSE + 1]),
                             ev_tangential_force(S, S[IMPULSE], S[IMPULSE + 1]))
    if old != 0 and old != leg and ev_stays_down(S[FEET_AFTER + 4 * (old - 1) + 3], 0.0):
        code |= IMPACT_OLD_FOOT_SINKS
    return code


def ev_impact_loss(S):
    """The energy the impact ev_impact computed took: T + V before it minus after it."""
    return S[ENERGY_BEFORE] - S[ENERGY_AFTER]


def ev_stance_start(slip_watched, mu, n, tg):
    """How a stance starts (after an impact, at its first instant, where the held torque changes) under the ground
    force with normal component n and tangential tg: STANCE_LIFTS_OFF where the ground would pull (n < 0: the
    liftoff witness is past zero already), else STANCE_SLIPS where the slip witness is watched (a friction
    coefficient mu, the witness not latched) and the force lies outside the cone, else STANCE_HOLDS."""
    if n < 0.0:
        return STANCE_LIFTS_OFF
    if slip_watched and ev_slip_margin(mu, n, tg) < 0.0:
        return STANCE_SLIPS
    return STANCE_HOLDS


# -- the impact history: impacts that accumulate, the events' budget, an event loop (invariants.py, hybrid.py) -
def ev_impacts_close(n_before, t_before, t, interval):
    """Whether an impact at t comes less than interval after the one before it (at t_before; n_before impacts
    so far): a gap of a Zeno run (zeno_count of them in a row stop it)."""
    return n_before > 0 and t - t_before < interval


def ev_over_budget(n_events, max_events):
    """Whether n_events changes of mode (the scuffs not counted) reach the run's budget max_events."""
    return n_events >= max_events


def ev_event_loop(n_events, t_first, t_last):
    """Whether the last 50 of n_events changes of mode, the first of them at t_first and the last at t_last, came
    within 1e-9 s: an event loop, which stops the run instead of hanging."""
    return n_events >= 50 and t_last - t_first < 1e-9


def ev_count_impact(S, t):
    """An impact at t counted in the state's impact history: the last impact's time, their count, and the last
    four impacts' times (oldest first: the oldest leaves for the newest)."""
    n: cython.Py_ssize_t = int(S[N_RECENT])
    S[LAST_IMPACT] = t
    S[N_IMPACTS] += 1
    if n == 4:
        S[RECENT_IMPACTS] = S[RECENT_IMPACTS + 1]
        S[RECENT_IMPACTS + 1] = S[RECENT_IMPACTS + 2]
        S[RECENT_IMPACTS + 2] = S[RECENT_IMPACTS + 3]
    else:
        n += 1
        S[N_RECENT] = n
    S[RECENT_IMPACTS + n - 1] = t


def ev_ring_oldest(S):
    """The time of the change of mode 49 before the next one (the ring holds the last 49, event i at i % 49): the
    first of the 50 that ev_event_loop looks at."""
    m: cython.long = int(S[MODE_EVENTS])
    return S[RING + m % 49]


def ev_count_mode_event(S, t):
    """A change of mode at t counted: mode_events one more, its time in the ring over the oldest's."""
    m: cython.long = int(S[MODE_EVENTS])
    S[RING + m % 49] = t
    S[MODE_EVENTS] = m + 1


def ev_accumulating(times, n, t):
    """Whether a crossing at t continues a run of impacts that accumulate (times: the last n <= 4 impacts', oldest
    first): the last three gaps shrink, the last to at most half the first (a walk's steps settle far more
    slowly), and t comes sooner than the last gap. That is the Zeno limit, where a foot comes back to the ground
    at vanishing speed: such a crossing is an impact (whose check says Zeno), never a scuff."""
    if n < 4:
        return False
    g0: cython.double = times[1] - times[0]
    g1: cython.double = times[2] - times[1]
    g2: cython.double = times[3] - times[2]
    return g0 > g1 and g1 > g2 and g2 <= 0.5 * g0 and t - times[3] < g2


# -- a diverging state and the energy balance (hybrid.py: _integrate, _record) --------------------------------
def ev_diverging(dq, n, max_speed):
    """Whether a state diverges: its largest speed |dq_i| (of its n entries) exceeds max_speed. The largest as
    Python's max takes it: the first of equal ones, an entry replacing it only where greater (a NaN first hides
    the rest; the step's own check has refused a non-finite state before)."""
    top: cython.double = fabs(dq[0])
    v: cython.double
    i: cython.Py_ssize_t
    for i in range(1, n):
        v = fabs(dq[i])
        if v > top:
            top = v
    return top > max_speed


def ev_energy_lost_after(energy_lost, loss):
    """The energy the impacts took out so far (energy_lost) after one more impact, which took loss (ev_impact_loss)."""
    return energy_lost + loss


def ev_energy_residual(energy, e0, work, push_work, energy_lost):
    """The energy balance's residual E - E(0) - W - W_push + E_lost (docs/model.md): energy E = T + V now, e0 at
    the start, work W the motors', push_work the pushes', energy_lost what the impacts took so far. Zero up to
    the integration's error."""
    return energy - e0 - work - push_work + energy_lost


def ev_running_max(m, v):
    """A run's statistic m (the largest constraint drift, its rate, |residual| so far) after the value v: v where it
    is greater, else m (Python's max(m, v): a NaN v leaves m)."""
    return v if v > m else m


def ev_sample_slot(n, provisional, last_only):
    """The row a new sample goes to in a run's samples of n rows: the first (last_only: the last sample only kept),
    the newest's (provisional: thinned out, overwritten by the next), else a new one."""
    if last_only:
        return 0
    if provisional:
        return n - 1
    return n


def ev_sample_row(row, t, q, dq, leg, F, u, residual):
    """What a sample of the three-link biped holds, into row (results.Samples' row, loop_state.SAMPLE_ROW's
    layout): ev_sample_row_of with its 5 coordinates and 2 torques."""
    ev_sample_row_of(row, t, q, dq, 5, leg, F, u, 2, residual)


def ev_sample_row_of(row, t, q, dq, n, leg, F, u, m, residual):
    """What a sample holds, into row (loop_state.sample_row(n, m)'s layout): t, q (n), dq (n), the stance leg
    (0: flight), the ground force F on the stance foot (2), the torque u applied (m), the energy balance's
    residual."""
    i: cython.Py_ssize_t
    row[ROW_T] = t
    for i in range(n):
        row[ROW_Q + i] = q[i]
        row[ROW_Q + n + i] = dq[i]
    row[ROW_Q + 2 * n] = leg
    row[ROW_Q + 2 * n + 1] = F[0]
    row[ROW_Q + 2 * n + 2] = F[1]
    for i in range(m):
        row[ROW_Q + 2 * n + 3 + i] = u[i]
    row[ROW_Q + 2 * n + 3 + m] = residual


# -- the torque a law returns, or a run holds (modes.two_finite_floats, finite_floats; _core.c's m_finite) ---------
def ev_finite_torques(u0, u1):
    """Whether the torques (u0, u1) are taken: finite, and so is their sum (a NaN, inf - inf or 1e308 + 1e308
    makes it not)."""
    return isfinite(u0 + u1)


def ev_finite_sum(u, m):
    """Whether the m torques u are taken: finite, and so is their sum (ev_finite_torques for any count)."""
    s: cython.double = 0.0
    i: cython.Py_ssize_t
    for i in range(m):
        s += u[i]
    return isfinite(s)


def ev_actuated_power(u, dq, joints, m):
    """The motors' power u . (B^T dq) of a robot whose m actuators turn the joints of q's entries joints[i] (B a
    selection: a 1 a column): the integrand of the motor work W (ev_motor_power for any robot)."""
    p: cython.double = u[0] * dq[int(joints[0])]
    i: cython.Py_ssize_t
    for i in range(1, m):
        p += u[i] * dq[int(joints[i])]
    return p


def ev_motor_power(u, dq1, dq2):
    """The motors' power u . (dq1, dq2), the torques u on the hips times the legs' joint rates: the integrand of the
    motor work W, the last entry of every mode's state."""
    return u[0] * dq1 + u[1] * dq2

# -- the control periods (hybrid.advance_period, advance_periods) -------------------------------------------
def ev_period_index(t, period, k):
    """The index of the control period under way at t: the smallest j >= k (the periods begun so far) with
    (j + 1) period > t, where period j ends; -1 where t / period reaches 2^53, beyond which (j + 1) period no longer
    tells period j from its neighbours (the run refuses such a period).
    Found in a few operations, not counted from k: a run can start at a late t0."""
    lo: cython.long
    hi: cython.long
    mid: cython.long
    if (k + 1) * period > t:
        return k
    if not t / period < 9007199254740992.0:
        return -1
    # (j + 1) period, a rounded product, never decreases with j: bisect between lo, whose period ends at or before
    # t, and hi, whose period ends after it
    lo = k
    hi = int(t / period)
    if hi < k + 1:
        hi = k + 1
    while (hi + 1) * period <= t:
        lo = hi
        hi = 2 * hi
    while hi - lo > 1:
        mid = lo + (hi - lo) // 2
        if (mid + 1) * period <= t:
            lo = mid
        else:
            hi = mid
    return hi


def ev_period_end(j, period, t_final):
    """When control period j ends: at (j + 1) period, or at t_final (> 0; 0: no end) where that comes first or
    within 1e-9 of a period (the run's last period ends exactly at its end)."""
    t_next: cython.double = (j + 1) * period
    if t_final > 0 and t_next >= t_final - 1e-9 * period:
        return t_final
    return t_next


def ev_next_period_runs(t, t_final, t_stop, period):
    """Whether a run of control periods begins another at t: before t_final, and not at or after t_stop within 1e-9
    of a period (a push due then, applied between two periods)."""
    return t < t_final and t_stop > t + 1e-9 * period
