"""A slice of the hybrid loop's numerics written once: the candidate single source of issue 29's compiled loop.

The same text runs as Python, compiles with Cython (pure-Python mode: the annotations and decorators below,
kernels.pxd for the generated formulas) and with numba (``numba_binding.load``), and each must give the bits
of ``biped_sim/engine/_core.c`` (``step``, ``dense``/``dense_at``, ``height_at``, ``may_dip``,
``locate_crossing``, whose lines it follows operation for operation) and of the Python engine
(``integrators._ListRungeKutta.step``, ``_DOP853Interpolant.at``, ``grazing.dip_bracket``,
``guards.locate_crossing``: scipy's brentq).

One state: every quantity the slice reads or writes is an entry of one float64 array ``S`` at a fixed offset
(the parameter block P of kernels.py first, then the stepper, the dense rows and scratch room); no object
attribute is read by name, and the compiled code and the Python code share that memory.

Kept to what all the compilers take (translate.py's too): float and int scalars, indexing of ``S``, ``if``,
``while`` and ``for ... in range``, calls of the functions here and of the kernels (on S and offsets into it);
no Python objects, lists, exceptions or callables inside the loop.
"""
from __future__ import annotations

import cython
from cython.cimports.benchmarks.loop_compilers.kernels import k_dense, k_foot_positions, k_rhs, k_step, k_ulp, ptr
from cython.cimports.libc.math import fabs, isfinite, isnan, pow

# -- the layout of S (after the parameter block P, kernels.PN = 34 entries) ----------------------------
N = cython.declare(cython.const[cython.Py_ssize_t], 11)         # the floating base's state: q (5), dq (5), motor work
TAN_S = cython.declare(cython.const[cython.Py_ssize_t], 34)     # tan(slope)
RTOL = cython.declare(cython.const[cython.Py_ssize_t], 35)
ATOL = cython.declare(cython.const[cython.Py_ssize_t], 36)
MAX_STEP = cython.declare(cython.const[cython.Py_ssize_t], 37)
GRAZE_TOL = cython.declare(cython.const[cython.Py_ssize_t], 38)
EVENT_TOL = cython.declare(cython.const[cython.Py_ssize_t], 39)
L_LEG = cython.declare(cython.const[cython.Py_ssize_t], 40)
T = cython.declare(cython.const[cython.Py_ssize_t], 41)
T_BOUND = cython.declare(cython.const[cython.Py_ssize_t], 42)
H_ABS = cython.declare(cython.const[cython.Py_ssize_t], 43)
T_OLD = cython.declare(cython.const[cython.Py_ssize_t], 44)
H = cython.declare(cython.const[cython.Py_ssize_t], 45)
NFEV = cython.declare(cython.const[cython.Py_ssize_t], 46)
NREJECTED = cython.declare(cython.const[cython.Py_ssize_t], 47)
NACCEPTED = cython.declare(cython.const[cython.Py_ssize_t], 48)
FAIL_KIND = cython.declare(cython.const[cython.Py_ssize_t], 49)   # 1: the step size underflowed, 2: a non-finite state
FAIL_VALUE = cython.declare(cython.const[cython.Py_ssize_t], 50)
FAIL_T = cython.declare(cython.const[cython.Py_ssize_t], 51)
DENSE_READY = cython.declare(cython.const[cython.Py_ssize_t], 52)
RESULT = cython.declare(cython.const[cython.Py_ssize_t], 53)      # a located root, or a dip's bracket (2) and bound
Y = cython.declare(cython.const[cython.Py_ssize_t], 56)
F = cython.declare(cython.const[cython.Py_ssize_t], 67)
Y_OLD = cython.declare(cython.const[cython.Py_ssize_t], 78)
OUT = cython.declare(cython.const[cython.Py_ssize_t], 89)     # a trial step: y_new, f_new, err, stages (13 N)
STAGES = cython.declare(cython.const[cython.Py_ssize_t], 256)     # the accepted step's stages k0..k12 (13 N)
DENSE = cython.declare(cython.const[cython.Py_ssize_t], 399)      # its dense output, 8 per entry (N x 8)
TO_POWER_BASIS = cython.declare(cython.const[cython.Py_ssize_t], 487)     # _DOP853Interpolant.TO_POWER_BASIS (8 x 8)
COEF = cython.declare(cython.const[cython.Py_ssize_t], 551)       # may_dip's |coefficients| A (8 x 3)
QS = cython.declare(cython.const[cython.Py_ssize_t], 575)         # q on the dense output (5), the feet's positions (4)
PS = cython.declare(cython.const[cython.Py_ssize_t], 580)
STACK = cython.declare(cython.const[cython.Py_ssize_t], 584)     # may_dip's intervals: a, b, h(a), h(b), depth
SIZE = cython.declare(cython.const[cython.Py_ssize_t], 904)
MAX_DEPTH = cython.declare(cython.const[cython.int], 30)          # grazing.MAX_DEPTH


@cython.cfunc
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def _begin(S: cython.p_double) -> cython.void:
    """A mode's start at S[T] from S[Y] (integrators._ListRungeKutta.restart): f = rhs(t, y)."""
    S[T_OLD] = S[T]
    i: cython.Py_ssize_t
    for i in range(N):
        S[Y_OLD + i] = S[Y + i]
    k_rhs(S, S[T], Y, F)
    S[NFEV] += 1
    S[DENSE_READY] = 0.0


@cython.cfunc
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def _step(S: cython.p_double) -> cython.int:
    """One accepted step (0), none at t_bound (1), or a failure (-1, S[FAIL_*] say which), with scipy's
    step control (integrators._ListRungeKutta.step, _core.c step)."""
    t: cython.double = S[T]
    remaining: cython.double = S[T_BOUND] - t
    if remaining <= 0:
        return 1
    min_step: cython.double = 10 * k_ulp(t) + 1e-300
    h_abs: cython.double = S[MAX_STEP] if S[MAX_STEP] < S[H_ABS] else S[H_ABS]
    exponent: cython.double = -1.0 / 8          # -1 / (error order 7 + 1)
    rejected: cython.int = 0
    h: cython.double
    err: cython.double
    s: cython.double
    factor: cython.double
    v: cython.double
    i: cython.Py_ssize_t
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
        k_step(S, t, Y, F, h, S[RTOL], S[ATOL], OUT)
        S[NFEV] += 12
        err = S[OUT + 2 * N]
        if err < 1.0:
            s = 0.0
            for i in range(N):
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
        rejected = 1
        S[NREJECTED] += 1
    S[NACCEPTED] += 1
    S[T_OLD] = t
    for i in range(N):
        S[Y_OLD + i] = S[Y + i]
    S[H] = h
    S[T] = t + h if h < remaining else S[T_BOUND]
    for i in range(2 * N):          # y_new, f_new: y and f are next to each other, as OUT's first 2 N
        S[Y + i] = S[OUT + i]
    for i in range(13 * N):
        S[STAGES + i] = S[OUT + 2 * N + 1 + i]
    S[DENSE_READY] = 0.0
    return 0


@cython.cfunc
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def _steps(S: cython.p_double, n: cython.int) -> cython.int:
    """Up to n steps (a run of quiet steps, for timing without a call per step): the last step's outcome."""
    rc: cython.int = 0
    _k: cython.int
    for _k in range(n):
        rc = _step(S)
        if rc != 0:
            break
    return rc


@cython.cfunc
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def _dense(S: cython.p_double) -> cython.void:
    """The last step's dense output rows, computed once (3 more evaluations)."""
    if S[DENSE_READY] != 0.0:
        return
    k_dense(S, S[T_OLD], S[H], Y_OLD, Y, STAGES, DENSE)
    S[NFEV] += 3
    S[DENSE_READY] = 1.0


@cython.cfunc
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def _dense_at(S: cython.p_double, i: cython.Py_ssize_t, tt: cython.double) -> cython.double:
    """Entry i of the dense output at tt (integrators._DOP853Interpolant.at)."""
    _dense(S)
    hi: cython.double = S[T] - S[T_OLD]
    x: cython.double = (tt - S[T_OLD]) / hi
    u: cython.double = 1.0 - x
    r: cython.Py_ssize_t = DENSE + 8 * i
    return ((((((S[r + 1] * x + S[r + 2]) * u + S[r + 3]) * x + S[r + 4]) * u + S[r + 5]) * x + S[r + 6]) * u
            + S[r + 7]) * x + S[r]


@cython.cfunc
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def _dense_state(S: cython.p_double, tt: cython.double) -> cython.void:
    """The whole state on the dense output at tt, into S[OUT:OUT + N] (free between steps)."""
    i: cython.Py_ssize_t
    for i in range(N):
        S[OUT + i] = _dense_at(S, i, tt)


@cython.cfunc
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def _height_at(S: cython.p_double, leg: cython.int, tt: cython.double) -> cython.double:
    """Foot leg's height across the slope on the dense output at tt (guards.foot_height)."""
    i: cython.Py_ssize_t
    for i in range(5):
        S[QS + i] = _dense_at(S, i, tt)
    k_foot_positions(S, QS, PS)
    return S[PS + 2 * leg - 1] + S[TAN_S] * S[PS + 2 * leg - 2]


@cython.cfunc
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def _may_dip(S: cython.p_double, leg: cython.int, h0: cython.double, h1: cython.double) -> cython.int:
    """grazing.dip_bracket on the floating base: 1 and the bracket in S[RESULT:RESULT + 2] where foot leg's
    height may dip deeper than graze_tol inside the step (both ends above the ground, heights h0, h1), else 0."""
    _dense(S)
    c: cython.Py_ssize_t
    p: cython.Py_ssize_t
    j: cython.Py_ssize_t
    k: cython.Py_ssize_t
    col: cython.Py_ssize_t
    r: cython.Py_ssize_t
    s: cython.double
    s0: cython.double
    # the power-basis coefficients of the swing leg's angle (its leg entry plus the torso's), the hip's x, y
    for p in range(8):
        for c in range(4):
            col = 1 + leg if c == 0 else 4 if c == 1 else c - 2
            r = DENSE + 8 * col
            s = 0.0
            for j in range(8):
                s += S[TO_POWER_BASIS + 8 * p + j] * S[r + j]
            if c == 0:
                s0 = s
            elif c == 1:
                S[COEF + 3 * p] = fabs(s0 + s)
            else:
                S[COEF + 3 * p + c - 1] = fabs(s)
    ta: cython.double = fabs(S[TAN_S])
    lt: cython.double = S[L_LEG] * (1 + ta)
    slack: cython.double = 1.0 + 1e-6           # the coefficients carry roundoff
    t_old: cython.double = S[T_OLD]
    h_step: cython.double = S[T] - S[T_OLD]
    top: cython.Py_ssize_t = 0
    a: cython.double
    b: cython.double
    ha: cython.double
    hb: cython.double
    depth: cython.int
    d1_0: cython.double
    d1_1: cython.double
    d1_2: cython.double
    d2_0: cython.double
    d2_1: cython.double
    d2_2: cython.double
    w1: cython.double
    w2: cython.double
    bound: cython.double
    drop: cython.double
    lo: cython.double
    mid: cython.double
    hm: cython.double
    S[RESULT + 2] = 0.0
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
        d1_0 = d1_1 = d1_2 = d2_0 = d2_1 = d2_2 = 0.0
        for k in range(8):
            # grazing._derivative_weights (on [0, 1] the powers of b are 1)
            # (exponents made floats: numba computes pow(float, int) by repeated multiplication, not libm's pow as
            # Python and C do, and its bits differ)
            if b == 1.0:
                w1 = k
                w2 = k * (k - 1)
            else:
                w1 = k * pow(b, 1.0 * (k - 1 if k - 1 > 0 else 0))
                w2 = k * (k - 1) * pow(b, 1.0 * (k - 2 if k - 2 > 0 else 0))
            d1_0 += w1 * S[COEF + 3 * k]
            d2_0 += w2 * S[COEF + 3 * k]
            d1_1 += w1 * S[COEF + 3 * k + 1]
            d2_1 += w2 * S[COEF + 3 * k + 1]
            d1_2 += w1 * S[COEF + 3 * k + 2]
            d2_2 += w2 * S[COEF + 3 * k + 2]
        # |h''| <= |y''| + |tan(slope)| |x''| + l (1 + |tan(slope)|) (|theta''| + theta'^2)
        bound = (lt * (d2_0 + d1_0 * d1_0) + d2_2 + ta * d2_1) * slack
        S[RESULT + 2] += bound      # (the sum of the bounds: compared between the compilers)
        drop = bound * (b - a) * (b - a) / 8
        lo = ha if ha < hb else hb
        if lo - drop > 0 or drop <= S[GRAZE_TOL] or depth >= MAX_DEPTH:
            continue
        mid = 0.5 * (a + b)
        hm = _height_at(S, leg, t_old + mid * h_step)
        if hm <= 0:
            S[RESULT] = t_old + a * h_step
            S[RESULT + 1] = t_old + mid * h_step
            return 1
        # the left half first: the earliest dip is the one that counts
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


@cython.cfunc
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def _locate_crossing(S: cython.p_double, leg: cython.int, ta: cython.double, tb: cython.double) -> cython.int:
    """Where foot leg's height crosses zero in [ta, tb] on the dense output (guards.locate_crossing: scipy's
    brentq, scipy/optimize/Zeros/brentq.c, xtol = event_tol, rtol = 4 eps, 200 iterations): 0 and the root in
    S[RESULT], or -1 where brentq raises (no sign change, a NaN, no convergence)."""
    _dense(S)
    ga: cython.double = _height_at(S, leg, ta)
    gb: cython.double = _height_at(S, leg, tb)
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
    fpre: cython.double = _height_at(S, leg, xpre)
    fcur: cython.double = _height_at(S, leg, xcur)
    sbis: cython.double
    delta: cython.double
    stry: cython.double
    dpre: cython.double
    dblk: cython.double
    lim: cython.double
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
            if xpre == xblk:        # interpolate
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:                   # extrapolate
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            lim = 3 * fabs(sbis) - delta
            if 2 * fabs(stry) < (fabs(spre) if fabs(spre) < lim else lim):
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
        fcur = _height_at(S, leg, xcur)
        if isnan(fcur):
            return -1
    return -1


# -- the entry points from Python: the state array as a typed memoryview, passed on as a pointer ----------


@cython.ccall
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def begin(S: cython.double[::1]) -> cython.void:
    """_begin on the state array S."""
    _begin(ptr(S))


@cython.ccall
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def step(S: cython.double[::1]) -> cython.int:
    """_step on the state array S."""
    return _step(ptr(S))


@cython.ccall
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def steps(S: cython.double[::1], n: cython.int) -> cython.int:
    """_steps on the state array S."""
    return _steps(ptr(S), n)


@cython.ccall
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def dense_at(S: cython.double[::1], i: cython.Py_ssize_t, tt: cython.double) -> cython.double:
    """_dense_at on the state array S."""
    return _dense_at(ptr(S), i, tt)


@cython.ccall
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def dense_state(S: cython.double[::1], tt: cython.double) -> cython.void:
    """_dense_state on the state array S."""
    _dense_state(ptr(S), tt)


@cython.ccall
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def height_at(S: cython.double[::1], leg: cython.int, tt: cython.double) -> cython.double:
    """_height_at on the state array S."""
    return _height_at(ptr(S), leg, tt)


@cython.ccall
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def may_dip(S: cython.double[::1], leg: cython.int, h0: cython.double, h1: cython.double) -> cython.int:
    """_may_dip on the state array S."""
    return _may_dip(ptr(S), leg, h0, h1)


@cython.ccall
@cython.boundscheck(False)
@cython.wraparound(False)
@cython.cdivision(True)
@cython.exceptval(check=False)
def locate_crossing(S: cython.double[::1], leg: cython.int, ta: cython.double, tb: cython.double) -> cython.int:
    """_locate_crossing on the state array S."""
    return _locate_crossing(ptr(S), leg, ta, tb)
