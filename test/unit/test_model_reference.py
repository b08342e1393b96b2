"""Every number of MODEL.md "Reference values", to the digits printed there, through the public API."""
import math

import numpy as np
import pytest

from biped_sim.engine.dynamics import delta, impact_map, relabel, stance_dynamics
from biped_sim.engine.model import BipedModel

DEG = math.pi / 180
CONF = {
    1: (np.array([0.5, math.sqrt(3) / 2, 150 * DEG, 120 * DEG, 30 * DEG]),
        np.array([-0.8049, -0.4430, 0.0938, 0.9150, 0.9298])),
    2: (np.array([0.3420, 0.9397, 170 * DEG, 20 * DEG, 30 * DEG]),
        np.array([-0.1225, -0.2369, 0.5310, 0.5904, 0.6263])),
}
REFERENCE = {
    1: dict(p1=[0.5000, -0.1340], J1=[[1, 0, -1, 0, -1], [0, 1, 0, 0, 0]],
            Jdot1=[[0, 0, 0, 0, 0], [0, 0, 1.0236, 0, 1.0236]],
            F=[0.287777, 167.157808], ddq=[0.383703, -1.047757, -5.845258, 0.504494, 6.228961]),
    2: dict(p1=[-2.0143e-05, 7.3792e-06], J1=[[1, 0, -0.9397, 0, -0.9397], [0, 1, 0.3420, 0, 0.3420]],
            Jdot1=[[0, 0, 0.3958, 0, 0.3958], [0, 0, 1.0875, 0, 1.0875]],
            F=[43.568726, 139.592154], ddq=[1.528961, -1.981796, -1.870022, 3.178204, 3.984590]),
}
Q_MINUS = np.array([0.3827, 0.9239, 3.0107, 2.2253, 0.5236])
DQ_MINUS = np.array([1.4782, -0.6123, 1.6, -1.6, 0])
DQ_PLUS = [0.903768, 0.374346, -1.221851, -0.546073, 1.524302]
F_IMP = [-11.146436, 14.119568]


def assert_digits(actual, printed):
    """Equal to the digits printed: |a - p| <= half a unit of the last printed digit."""
    for a, p in zip(np.ravel(actual), np.ravel(printed)):
        text = f"{p}"
        if "e" in text.lower():
            mant, exp = text.lower().split("e")
            decimals = len(mant.split(".")[1]) if "." in mant else 0
            tol = 0.5 * 10.0 ** (int(exp) - decimals)
        else:
            decimals = len(text.split(".")[1]) if "." in text else 0
            tol = 0.5 * 10.0 ** (-decimals) if decimals else 0.5e-4  # integers printed in J: 4 digits
        assert abs(a - p) <= tol * (1 + 1e-9), f"{a} differs from the printed {p} (tolerance {tol})"


@pytest.fixture(scope="module")
def model():
    return BipedModel()


@pytest.mark.parametrize("k", [1, 2])
def test_stance_foot_jacobian_and_its_derivative(model, k):
    q, dq = CONF[k]
    ref = REFERENCE[k]
    assert_digits(model.foot_position(q, 1), ref["p1"])
    assert_digits(model.foot_jacobian(q, 1), ref["J1"])
    assert_digits(model.foot_jacobian_dot(q, dq, 1), ref["Jdot1"])


@pytest.mark.parametrize("k", [1, 2])
@pytest.mark.parametrize("base", ["floating"])
def test_stance_force_and_accelerations(model, k, base):
    q, dq = CONF[k]
    ddq, F = stance_dynamics(model, q, dq, np.zeros(2), stance_leg=1, base=base)
    assert_digits(F, REFERENCE[k]["F"])
    assert_digits(ddq, REFERENCE[k]["ddq"])


@pytest.mark.parametrize("k", [1, 2])
def test_stance_solution_solves_the_literal_kkt_system(model, k):
    """The closed form must equal a plain solve of [D -J^T; J 0][ddq; F] = [-C dq - G + B u; -Jdot dq]."""
    q, dq = CONF[k]
    u = np.array([3.0, -7.0])
    D, C, G = model.mass_matrix(q), model.coriolis(q, dq), model.gravity(q)
    J, Jd = model.foot_jacobian(q, 1), model.foot_jacobian_dot(q, dq, 1)
    K = np.block([[D, -J.T], [J, np.zeros((2, 2))]])
    sol = np.linalg.solve(K, np.concatenate([-C @ dq - G + model.B @ u, -Jd @ dq]))
    ddq, F = stance_dynamics(model, q, dq, u)
    np.testing.assert_allclose(ddq, sol[:5], rtol=0, atol=1e-11)
    np.testing.assert_allclose(F, sol[5:], rtol=0, atol=1e-10)


def test_impact_map_reference(model):
    dq_plus, impulse = impact_map(model, Q_MINUS, DQ_MINUS, impact_leg=2)
    assert_digits(dq_plus, DQ_PLUS)
    assert_digits(impulse, F_IMP)


def test_delta_is_impact_then_relabeling(model):
    q_plus, dq_plus = delta(model, Q_MINUS, DQ_MINUS)
    dq_imp, _ = impact_map(model, Q_MINUS, DQ_MINUS, 2)
    np.testing.assert_array_equal(q_plus, Q_MINUS[[0, 1, 3, 2, 4]])
    np.testing.assert_array_equal(dq_plus, dq_imp[[0, 1, 3, 2, 4]])


def test_matrices_are_consistent_with_the_energies(model):
    """D is the Hessian of T; D is symmetric positive definite; Ddot - 2C is skew; G = dV/dq."""
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = rng.uniform(-3, 3, 5)
        dq = rng.uniform(-2, 2, 5)
        D = model.mass_matrix(q)
        assert np.allclose(D, D.T)
        assert np.all(np.linalg.eigvalsh(D) > 0)
        assert math.isclose(model.kinetic_energy(q, dq), 0.5 * dq @ D @ dq, rel_tol=1e-12)
        eps = 1e-6
        Ddot = sum((model.mass_matrix(q + eps * e) - model.mass_matrix(q - eps * e)) / (2 * eps) * dq[i]
                   for i, e in enumerate(np.eye(5)))
        N = Ddot - 2 * model.coriolis(q, dq)
        np.testing.assert_allclose(N, -N.T, atol=1e-7)
        G_fd = [(model.potential_energy(q + eps * e) - model.potential_energy(q - eps * e)) / (2 * eps)
                for e in np.eye(5)]
        np.testing.assert_allclose(model.gravity(q), G_fd, atol=1e-6)
        np.testing.assert_allclose(model.bias_forces(q, dq), model.coriolis(q, dq) @ dq + model.gravity(q),
                                   atol=1e-12)


def test_relabel_is_an_involution():
    q, dq = CONF[1]
    q2, dq2 = relabel(*relabel(q, dq))
    np.testing.assert_array_equal(q2, q)
    np.testing.assert_array_equal(dq2, dq)
    from biped_sim.engine.dynamics import R
    np.testing.assert_array_equal(R @ R, np.eye(5))


def test_stance_on_leg_2_is_stance_on_leg_1_relabeled(model):
    q, dq = CONF[2]
    u = np.array([1.5, -2.0])
    ddq2, F2 = stance_dynamics(model, q, dq, u, stance_leg=2)
    qr, dqr = relabel(q, dq)
    ddq1, F1 = stance_dynamics(model, qr, dqr, u[::-1], stance_leg=1)
    np.testing.assert_allclose(ddq2, ddq1[[0, 1, 3, 2, 4]], atol=1e-12)
    np.testing.assert_allclose(F2, F1, atol=1e-12)
    # and it enforces foot 2's constraint: J2 ddq + Jdot2 dq = 0
    J2, Jd2 = model.foot_jacobian(q, 2), model.foot_jacobian_dot(q, dq, 2)
    np.testing.assert_allclose(J2 @ ddq2 + Jd2 @ dq, 0, atol=1e-11)


def test_fixed_base_matches_floating_base_when_the_foot_is_at_rest(model):
    rng = np.random.default_rng(7)
    for leg in (1, 2):
        for _ in range(5):
            q = rng.uniform(-3, 3, 5)
            dq = rng.uniform(-2, 2, 5)
            J = model.foot_jacobian(q, leg)
            dq[:2] = -J[:, 2:] @ dq[2:]        # foot at rest: J dq = 0
            u = rng.uniform(-20, 20, 2)
            a, F = stance_dynamics(model, q, dq, u, leg, base="floating")
            b, Fb = stance_dynamics(model, q, dq, u, leg, base="fixed")
            np.testing.assert_allclose(a, b, atol=1e-9)
            np.testing.assert_allclose(F, Fb, atol=1e-9)


def test_impact_properties(model):
    """J2 dq+ = 0, no kinetic energy added, angular momentum about the impact point conserved."""
    dq_plus, impulse = impact_map(model, Q_MINUS, DQ_MINUS, 2)
    J2 = model.foot_jacobian(Q_MINUS, 2)
    assert np.max(np.abs(J2 @ dq_plus)) < 1e-12
    assert model.kinetic_energy(Q_MINUS, dq_plus) <= model.kinetic_energy(Q_MINUS, DQ_MINUS)
    point = model.foot_position(Q_MINUS, 2)
    assert math.isclose(angular_momentum(model, Q_MINUS, dq_plus, point),
                        angular_momentum(model, Q_MINUS, DQ_MINUS, point), rel_tol=1e-12, abs_tol=1e-12)


def angular_momentum(model, q, dq, point):
    """Sum over links of (r - point) x m v + I w, from the link geometry of MODEL.md (a test oracle)."""
    p = model.parameters
    x, y, q1, q2, q3 = q
    dx, dy, dq1, dq2, dq3 = dq
    links = [(p.m_leg, p.I_leg, p.c_leg, q1 + q3, dq1 + dq3), (p.m_leg, p.I_leg, p.c_leg, q2 + q3, dq2 + dq3),
             (p.m_torso, p.I_torso, p.c_torso, q3, dq3)]
    H = 0.0
    for m, inertia, c, a, w in links:
        rx, ry = x + c * math.sin(a) - point[0], y + c * math.cos(a) - point[1]
        vx, vy = dx + c * math.cos(a) * w, dy - c * math.sin(a) * w
        H += m * (rx * vy - ry * vx) - inertia * w  # angle measured clockwise from up: w_z = -w
    return H


@pytest.mark.parametrize("bad, match", [
    (dict(q=np.zeros(4)), "q must have shape"),
    (dict(q=np.zeros((5, 1))), "q must have shape"),
    (dict(dq=np.array([0, 0, np.nan, 0, 0])), r"dq has non-finite entries at index \[2\]"),
    (dict(u=np.array([np.inf, 0])), "u has non-finite"),
    (dict(u=np.array([1.0, 2.0, 3.0])), "u must have shape"),
    (dict(stance_leg=3), "leg must be 1 or 2"),
])
def test_bad_input_is_a_clear_value_error(model, bad, match):
    args = dict(q=CONF[1][0], dq=CONF[1][1], u=np.zeros(2), stance_leg=1)
    args.update(bad)
    with pytest.raises(ValueError, match=match):
        stance_dynamics(model, args["q"], args["dq"], args["u"], args["stance_leg"])
    if "q" in bad or "dq" in bad:  # impact_map names its argument dq_minus
        with pytest.raises(ValueError, match=match.replace("dq has", "dq_minus has")):
            impact_map(model, args["q"], args["dq"], 2)


@pytest.mark.parametrize("override, match", [
    (dict(m_leg=0.0), "m_leg must be positive"), (dict(l_torso=-1.0), "l_torso must be >= 0"),
    (dict(I_torso=float("nan")), "I_torso must be a finite number"), (dict(leg_mass=1.0), "unknown model parameter"),
])
def test_bad_model_parameters(override, match):
    with pytest.raises(ValueError, match=match):
        BipedModel(**override)


def test_parameters_are_overridable():
    heavy = BipedModel(m_torso=20.0, l_leg=0.8)
    assert heavy.parameters.c_leg == 0.4 and heavy.total_mass == 30.0
    q, dq = CONF[1]
    assert not np.allclose(heavy.mass_matrix(q), BipedModel().mass_matrix(q))
    assert math.isclose(heavy.foot_position(q, 1)[1], q[1] + 0.8 * math.cos(q[2] + q[4]))
