"""The generated formulas as the rules (``loop_rules.py``) call them when they run as Python: the twins of
``loop_kernels.pxd``'s C glue, with the same names and arguments.

The model's kernels (``k_foot_positions``, ``k_impact_map``, ``k_energy``, ``k_foot_kinematics``) are those of
the state's field ``model_kernels``: 0, the three-link's closed forms on the constants the state holds (the C
glue's, which the compiled loop runs); k > 0, the methods of the
:class:`~biped_sim.engine.generated_model.GeneratedModel` registered as k (:func:`register`), which take and
return lists in the three-link kernels' layouts, for N = S[N_Q] coordinates (the C glue calls the same robot's
compiled entry points, through the Loop's kernel table).

Each function reads and writes the state S (a list, ``loop_state``) at the offsets it is given, as the C
does through pointers into it, and performs the generated Python code's operations (the twins of the C
kernels, bit for bit: test/unit/test_compiled.py). The right-hand side ``fun(t, y)`` takes and returns
lists; ``ctx`` is the stepper (``integrators._ListRungeKutta``), which knows the generated step and dense
output of its state's size. A field of NMAX entries holds a smaller state in its first entries; a trial step's
rows are S[N_Y] apart.
"""
from __future__ import annotations

import itertools
import math
import weakref

from biped_sim.engine.loop_state import K_ENERGY, K_FEET, K_IMPACT, K_POS, MODEL_KERNELS, N_Q, N_Y, NQ_MAX

ulp = math.ulp

#: the generated models whose kernels a state may name (model_kernels = k), weakly held: a model's entry goes
#: with the model
_MODELS: dict = {}
_NEXT = itertools.count(1)


def register(model) -> int:
    """The index k > 0 under which the rules evaluate ``model``'s kernels (a state's ``model_kernels``), the same
    for the model's life."""
    k = getattr(model, "_kernel_index", None)
    if k is None or _MODELS.get(k, lambda: None)() is not model:
        k = next(_NEXT)
        _MODELS[k] = weakref.ref(model, lambda _, k=k: _MODELS.pop(k, None))
        model._kernel_index = k
    return k


def _model(S):
    """The generated model whose kernels S names."""
    return _MODELS[int(S[MODEL_KERNELS])]()


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
    """S[p:p + 4] = the feet's positions at q = S[q:q + N]."""
    if S[MODEL_KERNELS] != 0.0:
        S[p:p + 4] = _model(S).k_foot_positions(S[q:q + int(S[N_Q])])
        return
    from biped_sim.engine.compiled import gen
    S[p:p + 4] = gen.foot_positions(S[q:q + 5], S[K_POS:K_POS + 9])


def k_impact_map(S, leg, q, dqm, out):
    """S[out:out + N] = dq+ and S[out + NQ_MAX:out + NQ_MAX + 2] = the ground's impulse of foot leg's impact at
    q = S[q:q + N], dq- = S[dqm:dqm + N] (the three-link's closed forms impact_map_1 and impact_map_2, on the
    constants S[K_IMPACT])."""
    if S[MODEL_KERNELS] != 0.0:
        n = int(S[N_Q])
        dq_plus, impulse = _model(S).k_impact(S[q:q + n], S[dqm:dqm + n], leg - 1)
        S[out:out + n] = dq_plus
        S[out + NQ_MAX:out + NQ_MAX + 2] = impulse
        return
    from biped_sim.engine.compiled import gen
    impact = gen.impact_map_2 if leg == 2 else gen.impact_map_1
    dq_plus, impulse = impact(S[q:q + 5], S[dqm:dqm + 5], S[K_IMPACT:K_IMPACT + 26])
    S[out:out + 5] = dq_plus
    S[out + NQ_MAX:out + NQ_MAX + 2] = impulse


def k_energy(S, q, dq, out):
    """S[out:out + 2] = (T, V) at q = S[q:q + N], dq = S[dq:dq + N]."""
    if S[MODEL_KERNELS] != 0.0:
        n = int(S[N_Q])
        S[out:out + 2] = _model(S).k_energy(S[q:q + n], S[dq:dq + n])
        return
    from biped_sim.engine.compiled import gen
    S[out:out + 2] = gen.energy(S[q:q + 5], S[dq:dq + 5], S[K_ENERGY:K_ENERGY + 9])


def k_foot_kinematics(S, q, dq, out):
    """S[out:out + 8] = the feet's positions p_1, p_2 and velocities dp_1/dt, dp_2/dt at q = S[q:q + N],
    dq = S[dq:dq + N]."""
    if S[MODEL_KERNELS] != 0.0:
        n = int(S[N_Q])
        S[out:out + 8] = _model(S).k_foot_kinematics(S[q:q + n], S[dq:dq + n])
        return
    from biped_sim.engine.compiled import gen
    S[out:out + 8] = gen.foot_kinematics(S[q:q + 5], S[dq:dq + 5], S[K_FEET:K_FEET + 9])


def k_copy(S, dst, src, n):
    """S[dst:dst + n] = S[src:src + n]."""
    S[dst:dst + n] = S[src:src + n]


def k_ulp(x):
    return ulp(x)
