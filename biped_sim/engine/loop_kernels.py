"""The generated formulas as the rules (``loop_rules.py``) call them when they run as Python: the twins of
``loop_kernels.pxd``'s C glue, with the same names and arguments.

Each function reads and writes the state S (a list, ``loop_state``) at the offsets it is given, as the C
does through pointers into it, and performs the generated Python code's operations (the twins of the C
kernels, bit for bit: test/unit/test_compiled.py). The right-hand side ``fun(t, y)`` takes and returns
lists; ``ctx`` is the stepper (``integrators._ListRungeKutta``), which knows the generated step and dense
output of its state's size. A field of NMAX entries holds a smaller state in its first entries; a trial step's
rows are S[N_Y] apart.
"""
from __future__ import annotations

import math

from biped_sim.engine.loop_state import K_ENERGY, K_FEET, K_IMPACT, K_POS, N_Y, NQ_MAX

ulp = math.ulp


def k_rhs(S, fun, ctx, t, y, dy):
    """S[dy:dy + n] = fun(t, S[y:y + n])."""
    n = int(S[N_Y])
    S[dy:dy + n] = fun(t, S[y:y + n])


def k_step(S, fun, ctx, t, y, f, h, rtol, atol, out):
    """One step of the stepper's Runge-Kutta pair from (t, S[y:]), S[f:] its derivative: S[out:] = y_new,
    f_new, err, stages k0..k12, rows n = S[N_Y] apart."""
    n = int(S[N_Y])
    y_new, f_new, err, stages = ctx.rk_step(fun, t, S[y:y + n], S[f:f + n], h, rtol, atol)
    S[out:out + n] = y_new
    S[out + n:out + 2 * n] = f_new
    S[out + 2 * n] = err
    at = out + 2 * n + 1
    for k in stages:
        S[at:at + n] = k
        at += n


def k_dense(S, fun, ctx, t_old, h, y_old, y, k, dense):
    """S[dense:] = the dense output's rows of the step (t_old, t_old + h) from its stages at S[k:], rows n = S[N_Y]
    apart (a row of 8 values an entry for dop853, 5 for dopri5, one after the other)."""
    n = int(S[N_Y])
    stages = [S[k + n * j:k + n * j + n] for j in range(ctx.N_STAGES + 1)]
    rows = ctx.rk_dense_rows(fun, t_old, h, S[y_old:y_old + n], S[y:y + n], stages)
    for i, row in enumerate(rows):
        w = len(row)
        S[dense + w * i:dense + w * i + w] = row


def k_foot_positions(S, q, p):
    """S[p:p + 4] = the feet's positions at q = S[q:q + 5]."""
    from biped_sim.engine.compiled import gen
    S[p:p + 4] = gen.foot_positions(S[q:q + 5], S[K_POS:K_POS + 9])


def k_impact_map(S, leg, q, dqm, out):
    """S[out:out + 5] = dq+ and S[out + NQ_MAX:out + NQ_MAX + 2] = the ground's impulse of foot leg's impact at
    q = S[q:q + 5], dq- = S[dqm:dqm + 5] (the closed forms impact_map_1 and impact_map_2, on the constants
    S[K_IMPACT])."""
    from biped_sim.engine.compiled import gen
    impact = gen.impact_map_2 if leg == 2 else gen.impact_map_1
    dq_plus, impulse = impact(S[q:q + 5], S[dqm:dqm + 5], S[K_IMPACT:K_IMPACT + 26])
    S[out:out + 5] = dq_plus
    S[out + NQ_MAX:out + NQ_MAX + 2] = impulse


def k_energy(S, q, dq, out):
    """S[out:out + 2] = (T, V) at q = S[q:q + 5], dq = S[dq:dq + 5]."""
    from biped_sim.engine.compiled import gen
    S[out:out + 2] = gen.energy(S[q:q + 5], S[dq:dq + 5], S[K_ENERGY:K_ENERGY + 9])


def k_foot_kinematics(S, q, dq, out):
    """S[out:out + 8] = the feet's positions p_1, p_2 and velocities dp_1/dt, dp_2/dt at q = S[q:q + 5],
    dq = S[dq:dq + 5]."""
    from biped_sim.engine.compiled import gen
    S[out:out + 8] = gen.foot_kinematics(S[q:q + 5], S[dq:dq + 5], S[K_FEET:K_FEET + 9])


def k_copy(S, dst, src, n):
    """S[dst:dst + n] = S[src:src + n]."""
    S[dst:dst + n] = S[src:src + n]


def k_ulp(x):
    return ulp(x)
