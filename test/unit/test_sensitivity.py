"""Exact linearisation (engine/sensitivity.py, issue 32): the phases' Jacobians against central differences
of the engine's own functions, and a run's state transition matrix against central differences of the run."""
import numpy as np
import pytest

from biped_sim.engine.dynamics import flight_fast, impact_map, stance_fixed_accel_fast, stance_floating_fast
from biped_sim.engine.model import BipedModel, BipedParameters
from biped_sim.engine.sensitivity import Linearization
from biped_sim.engine.simulate import stance_state

MODEL = BipedModel()
EPS = 1e-5   # (rounding ~1e-16 |f| / EPS, truncation ~EPS^2 |f'''|: both below 1e-9 here)


def rel(a, b):
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def central(fun, x, eps=EPS):
    """Central differences of fun at x, one column per coordinate."""
    x = np.asarray(x, float)
    return np.column_stack([(fun(x + eps * e) - fun(x - eps * e)) / (2 * eps) for e in np.eye(len(x))])


def with_parameters(p):
    return BipedModel(BipedParameters(*p))


def random_state(seed):
    rng = np.random.default_rng(seed)
    q = np.array([0.3, 0.9, np.pi + rng.uniform(-0.6, 0.6), np.pi + rng.uniform(-0.6, 0.6), rng.uniform(-0.5, 0.5)])
    return q, rng.normal(size=5), rng.normal(size=2) * 20


@pytest.mark.parametrize("leg", [1, 2, 0])
@pytest.mark.parametrize("seed", [0, 1])
def test_the_phase_jacobians_are_the_derivatives_of_the_engine_functions(leg, seed):
    """Stance on either foot (ddq and the ground force F) and flight: d/dq, d/ddq, d/du, d/dp to 1e-8."""
    q, dq, u = random_state(seed)
    lin = Linearization(MODEL)
    s, dsq, dsv, dsu, dsp = lin.accelerations(q, dq, u, leg, parameters=True)

    def solution(q, dq, u, model=MODEL):
        if leg:
            ddq, F = stance_floating_fast(model, list(q), list(dq), list(u), leg)
            return np.array(ddq + F)
        return np.array(flight_fast(model, list(q), list(dq), list(u)))

    assert rel(s, solution(q, dq, u)) < 1e-13
    assert rel(dsq, central(lambda v: solution(v, dq, u), q)) < 1e-8
    assert rel(dsv, central(lambda v: solution(q, v, u), dq)) < 1e-8
    assert rel(dsu, central(lambda v: solution(q, dq, v), u, eps=1e-3)) < 1e-8   # (linear in u)
    assert rel(dsp, central(lambda p: solution(q, dq, u, with_parameters(p)), MODEL.p)) < 1e-8


@pytest.mark.parametrize("leg", [1, 2])
def test_the_impact_map_guard_fixed_base_and_stance_state_derivatives(leg):
    q, dq, u = random_state(2)
    lin = Linearization(MODEL, slope=0.05)
    dqp, _L, Rq, Rv, Rp = lin.impact(q, dq, leg, parameters=True)

    def after(q, dq, model=MODEL):
        return impact_map(model, q, dq, leg)[0]

    assert rel(dqp, after(q, dq)) < 1e-13
    assert rel(Rq, central(lambda v: after(v, dq), q)) < 1e-8
    assert rel(Rv, central(lambda v: after(q, v), dq)) < 1e-8
    assert rel(Rp, central(lambda p: after(q, dq, with_parameters(p)), MODEL.p)) < 1e-8
    _g, gx, gp = lin.touchdown_guard(q, leg, parameters=True)
    assert rel(gx[:5], central(lambda v: np.array([lin.touchdown_guard(v, leg)[0]]), q)[0]) < 1e-8
    assert rel(gp, central(lambda p: np.array([Linearization(with_parameters(p), 0.05).touchdown_guard(q, leg)[0]]),
                           MODEL.p)[0]) < 1e-8
    qs, dqs = q[2:], dq[2:]
    a, aq, av, au = lin.fixed_base_jacobian(qs, dqs, u, leg)

    def chain(qs, dqs, u):
        return np.array(stance_fixed_accel_fast(MODEL, list(qs), list(dqs), list(u), leg))

    assert rel(a, chain(qs, dqs, u)) < 1e-13
    assert rel(aq, central(lambda v: chain(v, dqs, u), qs)) < 1e-8
    assert rel(av, central(lambda v: chain(qs, v, u), dqs)) < 1e-8
    assert rel(au, central(lambda v: chain(qs, dqs, v), u, eps=1e-3)) < 1e-8
    z = np.concatenate([qs, dqs])
    T = lin.stance_tangent(*stance_state(MODEL, qs, dqs, leg, foot=(0.2, 0.0)), leg)
    assert rel(T, central(lambda v: np.concatenate(stance_state(MODEL, v[:3], v[3:], leg, foot=(0.2, 0.0))), z)) < 1e-8
