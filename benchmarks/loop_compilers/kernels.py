"""The generated formulas as the probe's rules call them, in Python: the twins of glue.h's entry points.

Under Cython, ``from cython.cimports.benchmarks.loop_compilers.kernels import ...`` finds kernels.pxd (the C
glue); run as Python, the same import finds this module. Each function reads and writes the state array S
at the offsets it is given (as the C does through pointers into it) and performs the generated Python
code's operations (the twins of the C kernels, bit for bit: test/test_compiled.py).

The parameter block P (the first PN entries of the probe's state array): the stance leg (1.0 or 2.0), the
held torque (u1, u2), the constants of stance_floating_1 (22) and of foot_positions (9).
"""
from __future__ import annotations

import math

from biped_sim.engine._gen import closed_forms as gen, rk_steps as rk

LEG, U, K_STANCE, K_POS = 0, 1, 3, 25
PN = 34
N = 11


def _rhs(P):
    leg, u = P[LEG], [float(P[U]), float(P[U + 1])]
    k = [float(v) for v in P[K_STANCE:K_STANCE + 22]]
    stance = gen.stance_floating_1 if leg == 1.0 else gen.stance_floating_2

    def fun(t, y):
        ddq, _ = stance(y[:5], y[5:10], u, k)
        return y[5:10] + ddq + [u[0] * y[7] + u[1] * y[8]]
    return fun


def k_rhs(S, t, y, dy):
    """S[dy:dy + N] = the right-hand side at (t, S[y:y + N])."""
    S[dy:dy + N] = _rhs(S)(t, [float(v) for v in S[y:y + N]])


def k_step(S, t, y, f, h, rtol, atol, out):
    """One unrolled dop853 step from (t, S[y:y + N]), S[f:f + N] its derivative: S[out:...] = y_new (N),
    f_new (N), err, stages k0..k12 (13 N)."""
    y_new, f_new, err, stages = rk.dop853_step_11(_rhs(S), float(t), [float(v) for v in S[y:y + N]],
                                                  [float(v) for v in S[f:f + N]], float(h), float(rtol), float(atol))
    S[out:out + N] = y_new
    S[out + N:out + 2 * N] = f_new
    S[out + 2 * N] = err
    S[out + 2 * N + 1:out + 2 * N + 1 + 13 * N] = [v for k in stages for v in k]


def k_dense(S, t_old, h, y_old, y, k, dense):
    """S[dense:dense + 8 N] = dop853's dense output rows of the step from the stages at S[k:k + 13 N]."""
    stages = [[float(v) for v in S[k + N * j:k + N * j + N]] for j in rk.DOP853_DENSE_STAGES]
    rows = rk.dop853_dense_11(_rhs(S), float(t_old), float(h), [float(v) for v in S[y_old:y_old + N]],
                              [float(v) for v in S[y:y + N]], *stages)
    S[dense:dense + 8 * N] = [v for row in rows for v in row]


def k_foot_positions(S, q, p):
    """S[p:p + 4] = the feet's positions at S[q:q + 5]."""
    S[p:p + 4] = gen.foot_positions([float(v) for v in S[q:q + 5]], [float(v) for v in S[K_POS:K_POS + 9]])


def k_ulp(x):
    return math.ulp(x)


def ptr(S):
    """The state array as the rules' internal functions take it (the C: a pointer to its first entry)."""
    return S
