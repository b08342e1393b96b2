"""The single-foot impact map in closed form (generated ``impact_map_1/2``, what ``impact_map`` and the compiled
loop use) against the plain KKT solve of docs/model.md "Impact" (``constrained_impulse_response``, which
still serves pushes and double impacts), at random states (hypothesis)."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from biped_sim.engine.dynamics import constrained_impulse_response, impact_map
from biped_sim.engine.model import BipedModel

MODELS = (BipedModel(), BipedModel(m_leg=3.7, l_leg=0.83, I_torso=1.9, g=1.62))
angle = st.floats(-7.0, 7.0)          # over two turns: the closed form holds anywhere
rate = st.floats(-20.0, 20.0)


@settings(max_examples=300, deadline=None)
@given(q=st.lists(angle, min_size=5, max_size=5), dq=st.lists(rate, min_size=5, max_size=5),
       leg=st.sampled_from([1, 2]), which=st.sampled_from([0, 1]))
def test_the_closed_form_is_the_kkt_solution(q, dq, leg, which):
    model = MODELS[which]
    q, dq = np.array(q), np.array(dq)
    dq_plus, impulse = impact_map(model, q, dq, leg)
    J = model.foot_jacobian(q, leg)
    ref_plus, ref_impulse = constrained_impulse_response(model.mass_matrix(q), J, dq)
    speed = 1.0 + np.abs(dq).max()
    # relative to the scale of the problem: the speeds, and the momentum they carry
    np.testing.assert_allclose(dq_plus, ref_plus, rtol=0, atol=1e-12 * speed)
    np.testing.assert_allclose(impulse, ref_impulse, rtol=0, atol=1e-12 * speed * model.total_mass)
    np.testing.assert_allclose(J @ dq_plus, 0.0, rtol=0, atol=1e-12 * speed)


@pytest.mark.parametrize("leg", [1, 2])
def test_a_foot_already_at_rest_changes_nothing(leg):
    """J dq- = 0: no jump and no impulse (the impulse is computed on the differences dq+ - dq-)."""
    model = MODELS[0]
    rng = np.random.default_rng(leg)
    q, dq = rng.uniform(-3, 3, 5), rng.uniform(-2, 2, 5)
    J = model.foot_jacobian(q, leg)
    dq[:2] = -J[:, 2:] @ dq[2:]
    dq_plus, impulse = impact_map(model, q, dq, leg)
    np.testing.assert_allclose(dq_plus, dq, rtol=0, atol=1e-14)
    np.testing.assert_allclose(impulse, 0.0, rtol=0, atol=1e-12)
