"""The generated derivatives of any described robot (config/codegen.py, GeneratedModel's ``*_jacobian``
methods, issue 32): each against central differences of the method it differentiates, for the four shipped
robots, and for the three-link against the closed-form derivatives of ``_gen/derivatives.py``."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from biped_sim.config import models
from biped_sim.engine._gen import closed_forms as cf, derivatives as dgen
from biped_sim.engine.model import BipedModel
from biped_sim.engine.sensitivity import Linearization

ROBOTS = {name: models.generated_model(name) for name in models.SHIPPED}
EPS = 1e-5   # (truncation ~EPS^2 |f'''| / 6, rounding ~1e-16 |f| / EPS: both near 1e-11 of the terms here)


def rel(a, b):
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def central(fun, x, eps=EPS):
    """Central differences of fun at x: the derivative by x_k in the last axis, k = 0.. len(x) - 1."""
    x = np.asarray(x, float)
    return np.stack([(np.asarray(fun(x + eps * e)) - np.asarray(fun(x - eps * e))) / (2 * eps)
                     for e in np.eye(len(x))], axis=-1)


def state(model, rng):
    """A state of ``model`` (a base, joint angles anywhere, rates and torques of walking size)."""
    n, m = model.n, model.B.shape[1]
    q = np.concatenate([[rng.uniform(-0.5, 0.5), rng.uniform(0.5, 1.2)], rng.uniform(-np.pi, np.pi, n - 2)])
    return q, rng.normal(size=n) * 1.5, rng.normal(size=m) * 20


def check_phase_jacobians(model, q, dq, u, tol=1e-7):
    """Every phase Jacobian of ``model`` at (q, dq, u) against central differences of its phase."""
    n = model.n
    A_q, A_dq, A_u = model.flight_dynamics_jacobian(q, dq, u)
    assert rel(A_q, central(lambda v: model.flight_dynamics(v, dq, u), q)) < tol
    assert rel(A_dq, central(lambda v: model.flight_dynamics(q, v, u), dq)) < tol
    assert rel(A_u, central(lambda v: model.flight_dynamics(q, dq, v), u)) < tol
    for contact in (1, 2):
        def stance(q_, dq_, u_):
            return np.concatenate(model.stance_dynamics(q_, dq_, u_, contact))
        A_q, A_dq, A_u, F_q, F_dq, F_u = model.stance_dynamics_jacobian(q, dq, u, contact)
        assert rel(np.vstack([A_q, F_q]), central(lambda v: stance(v, dq, u), q)) < tol
        assert rel(np.vstack([A_dq, F_dq]), central(lambda v: stance(q, v, u), dq)) < tol
        assert rel(np.vstack([A_u, F_u]), central(lambda v: stance(q, dq, v), u)) < tol

        def impact(q_, dq_):
            return np.concatenate(model.impact_map(q_, dq_, contact))
        P_q, P_dq, I_q, I_dq = model.impact_map_jacobian(q, dq, contact)
        assert rel(np.vstack([P_q, I_q]), central(lambda v: impact(v, dq), q)) < tol
        assert rel(np.vstack([P_dq, I_dq]), central(lambda v: impact(q, v), dq)) < tol

        v_q, v_dq = model.contact_velocity_jacobian(q, dq, contact)
        assert rel(v_q, central(lambda v: model.contact_velocity(v, dq, contact), q)) < tol
        assert rel(v_dq, central(lambda v: model.contact_velocity(q, v, contact), dq)) < tol
        assert v_q.shape == v_dq.shape == (2, n)


@pytest.mark.parametrize("name", models.SHIPPED)
def test_each_robots_generated_terms_are_the_derivatives_of_its_terms(name):
    """dD/dq_k, d(C dq + G)/d(q, dq), dJ_c/dq_k, d(Jdot_c dq)/d(q, dq) of the generated module."""
    model = ROBOTS[name]
    rng = np.random.default_rng(7)
    for _ in range(2):
        q, dq, _u = state(model, rng)
        assert rel(np.moveaxis(model.mass_matrix_jacobian(q), 0, -1), central(model.mass_matrix, q)) < 1e-8
        dhq, dhv = model.bias_forces_jacobian(q, dq)
        assert rel(dhq, central(lambda v: model.bias_forces(v, dq), q)) < 1e-8
        assert rel(dhv, central(lambda v: model.bias_forces(q, v), dq)) < 1e-8
        for contact in model.contacts:
            dJ = model.contact_jacobian_jacobian(q, contact)
            assert rel(np.moveaxis(dJ, 0, -1), central(lambda v: model.contact_jacobian(v, contact), q)) < 1e-8
            jb, jbq, jbv = model.contact_bias_jacobian(q, dq, contact)
            assert np.allclose(jb, model.contact_jacobian_dot(q, dq, contact) @ dq, rtol=1e-13, atol=1e-12)
            assert rel(jbq, central(lambda v: model.contact_jacobian_dot(v, dq, contact) @ dq, q)) < 1e-8
            assert rel(jbv, central(lambda v: model.contact_jacobian_dot(q, v, contact) @ v, dq)) < 1e-8


@pytest.mark.parametrize("name", models.SHIPPED)
def test_each_robots_phase_jacobians_are_the_derivatives_of_its_phases(name):
    """Flight, stance on each contact (ddq and F), the impact of each contact and the contact velocity: d/dq,
    d/ddq, d/du against central differences of the method differentiated, to 1e-7 relative."""
    model = ROBOTS[name]
    rng = np.random.default_rng(11)
    for _ in range(2):
        check_phase_jacobians(model, *state(model, rng))


@settings(max_examples=30, deadline=None, derandomize=True)
@given(st.sampled_from(models.SHIPPED), st.integers(0, 2 ** 32 - 1))
def test_the_phase_jacobians_hold_at_any_state(name, seed):
    """The same as a property over states (a base anywhere, joint angles on the whole circle)."""
    model = ROBOTS[name]
    check_phase_jacobians(model, *state(model, np.random.default_rng(seed)))


def test_the_three_link_description_has_the_closed_forms_derivatives():
    """For the three-link biped the generated terms and phase Jacobians are the closed forms' (_gen/derivatives.py,
    engine/sensitivity.py's Linearization) to 1e-10: two derivations of one robot."""
    g, m = ROBOTS["three_link"], BipedModel()
    k = {name: constants(m.p) for name, constants in dgen.CONSTANTS.items()}
    lin = Linearization(m)
    rng = np.random.default_rng(3)
    for _ in range(3):
        q, dq, u = state(g, rng)
        ql, dql = q.tolist(), dq.tolist()
        dD = np.array(dgen.mass_matrix_jacobian(ql, k["mass_matrix_jacobian"])).reshape(5, 5, 5)
        assert rel(g.mass_matrix_jacobian(q), dD) < 1e-10
        dh = np.array(dgen.bias_forces_jacobian(ql, dql, k["bias_forces_jacobian"])).reshape(2, 5, 5)
        assert rel(np.array(g.bias_forces_jacobian(q, dq)), dh) < 1e-10
        for leg in (1, 2):
            dJ = np.array(getattr(dgen, f"foot_jacobian_jacobian_{leg}")(ql, k[f"foot_jacobian_jacobian_{leg}"]))
            assert rel(g.contact_jacobian_jacobian(q, leg), dJ.reshape(5, 2, 5)) < 1e-10
            jb = np.array(getattr(dgen, f"foot_bias_jacobian_{leg}")(ql, dql, k[f"foot_bias_jacobian_{leg}"]))
            assert rel(np.concatenate([a.ravel() for a in g.contact_bias_jacobian(q, dq, leg)]), jb) < 1e-10
            assert rel(g.contact_jacobian(q, leg), np.array(cf.foot_jacobian_1(ql, m.k["foot_jacobian_1"]) if leg == 1
                                                            else cf.foot_jacobian_2(ql, m.k["foot_jacobian_2"])
                                                            ).reshape(2, 5)) < 1e-12
            s, dsq, dsv, dsu, _ = lin.accelerations(q, dq, u, leg)
            A_q, A_dq, A_u, F_q, F_dq, F_u = g.stance_dynamics_jacobian(q, dq, u, leg)
            assert rel(np.vstack([A_q, F_q]), dsq) < 1e-10 and rel(np.vstack([A_dq, F_dq]), dsv) < 1e-10
            assert rel(np.vstack([A_u, F_u]), dsu) < 1e-10
            dqp, imp, Rq, Rv, _ = lin.impact(q, dq, leg)
            P_q, P_dq, _I_q, _I_dq = g.impact_map_jacobian(q, dq, leg)
            assert rel(P_q, Rq) < 1e-10 and rel(P_dq, Rv) < 1e-10
        _s, dsq, dsv, dsu, _ = lin.accelerations(q, dq, u, 0)
        A_q, A_dq, A_u = g.flight_dynamics_jacobian(q, dq, u)
        assert rel(A_q, dsq) < 1e-10 and rel(A_dq, dsv) < 1e-10 and rel(A_u, dsu) < 1e-10
