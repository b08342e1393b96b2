"""The gait, sweep and basin tools for any robot: the section, the relabeling, stance states and the per-coordinate
columns as functions of the model (issue 31). The three-link biped given as a description must give the
BipedModel's numbers; RABBIT (7 coordinates, knees) has the sizes and the symmetry of its own description."""
import math

import numpy as np
import pytest

import biped_sim as bs
from biped_sim.analysis import gait as G
from biped_sim.config.models import generated_model

BIPED = bs.BipedModel()
THREE_LINK = generated_model("three_link")
RABBIT = bs.load_model("rabbit")


def test_stance_state_of_a_described_robot():
    """stance_state for a GeneratedModel: the three-link description gives the BipedModel's state (both stance
    legs, a foot off the origin); RABBIT's stance foot is at ``foot`` and at rest; a wrong length is one line
    that names the robot's joints."""
    joints, rates, foot = [3.0, 3.4, 0.2], [0.3, -0.5, 0.7], (0.3, -0.1)
    for leg in (1, 2):
        q_b, dq_b = bs.stance_state(BIPED, joints, rates, leg, foot=foot)
        q_g, dq_g = bs.stance_state(THREE_LINK, joints, rates, leg, foot=foot)
        assert np.max(np.abs(q_g - q_b)) < 1e-12 and np.max(np.abs(dq_g - dq_b)) < 1e-12
    for leg in (1, 2):
        q, dq = bs.stance_state(RABBIT, [3.3, 2.9, 0.2, 0.1, 0.1], [1.0, 2.0, 3.0, 4.0, 5.0], leg, foot=foot)
        assert q.shape == dq.shape == (7,) and q[2:].tolist() == [3.3, 2.9, 0.2, 0.1, 0.1]
        assert np.max(np.abs(RABBIT.contact_position(q, leg) - foot)) < 1e-12
        assert np.max(np.abs(RABBIT.contact_velocity(q, dq, leg))) < 1e-12
    with pytest.raises(ValueError) as err:
        bs.stance_state(RABBIT, [3.0, 3.4, 0.2], [0.0, 0.0, 0.0])
    assert str(err.value) == ("joints (q[2:] of rabbit: hip_1, hip_2, knee_1, knee_2, torso_pitch) must have shape "
                              "(5,), got shape (3,)")


def _height_gradient(model, joints, slope):
    """dh/dq[2:], exact: h = n . (p_2 - p_1) with the stance foot pinned, n = (tan(slope), 1)."""
    q, _ = bs.stance_state(model, joints, np.zeros(model.n - 2))
    if isinstance(model, bs.BipedModel):
        J1, J2 = model.foot_jacobian(q, 1), model.foot_jacobian(q, 2)
    else:
        J1, J2 = model.contact_jacobian(q, 1), model.contact_jacobian(q, 2)
    return np.array([math.tan(slope), 1.0]) @ (J2 - J1)[:, 2:]


def test_the_section_of_the_three_link_description_is_the_biped_models():
    """Section point, relabeling rows, height and tangent basis from the description of the three-link biped:
    the BipedModel's (RELABELED_ROWS, h, U) to 1e-12; the basis, by central differences of h (eps = 1e-7),
    to the roundoff of h over eps, and its gradient is the exact one."""
    assert G.section_rows(THREE_LINK) == G.section_rows(BIPED) == G.RELABELED_ROWS == [3, 2, 4, 8, 7, 9]
    assert G.section_size(THREE_LINK) == 6 and G.base_angle_index(THREE_LINK) == G.base_angle_index(BIPED) == 4
    assert G.actuated_coordinates(THREE_LINK) == G.actuated_coordinates(BIPED) == [2, 3]
    rng = np.random.default_rng(31)
    for _ in range(5):
        q, dq = rng.uniform(-1, 1, 5) + [0, 1, math.pi, math.pi, 0], rng.uniform(-2, 2, 5)
        assert np.array_equal(G.section_point(THREE_LINK, q, dq), G.section_point(BIPED, q, dq))
        R_q, R_dq = THREE_LINK.relabel(q, dq)
        assert np.array_equal(G.section_point(BIPED, q, dq), np.concatenate([R_q[2:], R_dq[2:]]))
        z = np.concatenate([q[2:], dq[2:]])
        for slope in (0.0, 0.0525):
            assert abs(G.section_height(THREE_LINK, z[:3], slope) - G.section_height(BIPED, z[:3], slope)) < 1e-12
            U_g, grad_g = G.section_basis(THREE_LINK, z, slope)
            U_b, grad_b = G.section_basis(BIPED, z, slope)
            assert U_g.shape == U_b.shape == (6, 5) and np.allclose(U_g.T @ U_g, np.eye(5), atol=1e-12)
            exact = _height_gradient(BIPED, z[:3], slope)
            assert np.max(np.abs(_height_gradient(THREE_LINK, z[:3], slope) - exact)) < 1e-12
            assert np.max(np.abs(grad_g - exact)) < 1e-8 and np.max(np.abs(grad_b - exact)) < 1e-8
            assert np.max(np.abs(U_g - U_b)) < 1e-8 and np.max(np.abs(U_g[:3].T @ exact)) < 1e-8


def _rabbit_double_support(rng):
    """Joints of RABBIT with both feet on flat ground: leg 2 the mirror image of leg 1 about the vertical through
    the hip (femur_2 at pi - d - k, tibia_2 at pi - d, where leg 1 has pi + d and pi + d + k)."""
    d, k, t = rng.uniform(-0.4, 0.4), rng.uniform(0.0, 0.6), rng.uniform(-0.3, 0.3)
    return np.array([math.pi + d - t, math.pi - d - k - t, k, k, t])


def test_rabbits_section_relabeling_and_height():
    """RABBIT: R R = I, the section point of a state with leg 2 in stance is R's stance-1 state (its contact 1
    is the old contact 2, the mirror image), z has 10 entries, the basis is 10 x 9, and h = 0 on the states
    stance_state builds with both feet down (either leg in stance)."""
    R = G.relabeling(RABBIT)
    assert R == (0, 1, 3, 2, 5, 4, 6) and [R[i] for i in R] == list(range(7))
    assert G.section_size(RABBIT) == 10 and G.section_rows(RABBIT) == [3, 2, 5, 4, 6, 10, 9, 12, 11, 13]
    assert G.base_angle_index(RABBIT) == 6 and G.actuated_coordinates(RABBIT) == [2, 3, 4, 5]
    rng = np.random.default_rng(32)
    for _ in range(5):
        joints, rates = _rabbit_double_support(rng), rng.uniform(-2, 2, 5)
        assert abs(G.section_height(RABBIT, joints)) < 1e-12
        q, dq = bs.stance_state(RABBIT, joints, rates, stance_leg=2)     # leg 2 has touched down
        assert np.max(np.abs(RABBIT.contact_position(q, 1)[1])) < 1e-12  # both feet on the ground
        z = G.section_point(RABBIT, q, dq)
        Rq, Rdq = RABBIT.relabel(q, dq)
        assert np.array_equal(z, np.concatenate([Rq[2:], Rdq[2:]]))
        assert np.array_equal(np.concatenate(RABBIT.relabel(Rq, Rdq)), np.concatenate([q, dq]))
        assert np.max(np.abs(RABBIT.contact_position(Rq, 1) - RABBIT.contact_position(q, 2))) < 1e-12
        assert abs(G.section_height(RABBIT, z[:5])) < 1e-12
        q1, dq1 = bs.stance_state(RABBIT, z[:5], z[5:], stance_leg=1)   # the state the step map starts from
        assert np.max(np.abs(q1 - (Rq - [*RABBIT.contact_position(q, 2), 0, 0, 0, 0, 0]))) < 1e-12
        assert np.max(np.abs(dq1 - Rdq)) < 1e-12
        U, grad = G.section_basis(RABBIT, z)
        assert U.shape == (10, 9) and np.allclose(U.T @ U, np.eye(9), atol=1e-12)
        assert np.max(np.abs(grad - _height_gradient(RABBIT, z[:5], 0.0))) < 1e-8


def test_find_gait_takes_a_described_robot_as_far_as_the_engine_runs_it():
    """bs.find_gait(model, controller, z0) with a GeneratedModel: z0 sized 2 (n - 2) (a wrong one is one line
    naming RABBIT's joints), its exact Jacobian falls back to central differences and says so, and a robot the
    engine cannot run yet is refused in one line (the engine's) before any step."""
    def no_torque(t, q, dq, stance_leg):
        return [0.0] * 4
    with pytest.raises(ValueError, match=r"^z0 must be 10 finite numbers, the post-impact state \[hip_1, hip_2, "
                                         r"knee_1, knee_2, torso_pitch, dhip_1, .*\(leg 1 the new stance leg\), "
                                         r"got \[0\.0, 0\.0, 0\.0, 0\.0, 0\.0, 0\.0\]$"):
        bs.find_gait(RABBIT, no_torque, z0=np.zeros(6))
    assert G.exact_jacobian_unavailable(RABBIT) == G.EXACT_WAITS and G.exact_jacobian_unavailable(BIPED) == ""
    z0 = np.concatenate([_rabbit_double_support(np.random.default_rng(1)), np.zeros(5)])
    if hasattr(type(RABBIT), "engine_refusal"):
        with pytest.raises(ValueError) as err:
            bs.find_gait(RABBIT, no_torque, z0=z0)
        assert str(err.value) == RABBIT.engine_refusal and "\n" not in str(err.value)
    with pytest.raises(ValueError, match="waits for its derivatives"):
        G.StepMap(RABBIT, no_torque).sensitivity(z0)
    # what the gait of a described robot says of its Jacobian
    g = G.Gait(z=z0, step_length=0.4, step_period=0.5, speed=0.8, cost_of_transport=0.1, motor_work=1.0,
               eigenvalues=np.array([0.5] * 9), residual=1e-12, newton_iterations=3, max_torque=10.0, slope=0.0,
               jacobian_method=G.FINITE_DIFFERENCES, jacobian_note=G.EXACT_WAITS,
               step_map=G.StepMap(RABBIT, no_torque))
    text = G.format_gait(g)
    assert ("Jacobian  central differences of the step map (the exact Jacobian of a described robot waits for its "
            "derivatives)") in text
    assert "(hip_1, hip_2, knee_1, knee_2, torso_pitch and their rates after impact, leg 1 the new stance leg)" in text
    with pytest.raises(ValueError, match="^Gait.derivatives: the exact Jacobian of a described robot waits"):
        g.derivatives("controller.kp")
