"""RABBIT's walking law (biped_sim/control/rabbit_walking.py) and its scene (msg_configs/rabbit.yaml).

docs/models.md, "RABBIT walking". The law's torques are checked through the robot's own stance dynamics
(``GeneratedModel.stance_dynamics``): they make the outputs obey y'' = -kp y - kd dy, with y' and y'' taken
by finite differences of the outputs along the motion, not from the law's own Jacobian.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import biped_sim as bs
from biped_sim.config.models import generated_model
from biped_sim.config.scenes import load_scene, make_controller, validate_controller
from biped_sim.control.rabbit_walking import RabbitWalkingController

RABBIT = bs.load_model("rabbit")
#: u's entries swapped left for right: [hip_1, hip_2, knee_1, knee_2] -> [hip_2, hip_1, knee_2, knee_1]
SWAP_U = [1, 0, 3, 2]


def near_gait_states(ctrl, count=6, seed=5):
    """States around the gait: a start on the gait at a random phase and rate, every angle and rate moved."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        leg = int(rng.integers(1, 3))
        q, dq = ctrl.state_on_gait(rng.uniform(0.6, 1.4), leg, theta=rng.uniform(-0.25, 0.25))
        q[2:] += rng.uniform(-0.05, 0.05, 5)
        dq[2:] += rng.uniform(-0.5, 0.5, 5)
        out.append((q, dq, leg))
    return out


def test_the_torques_are_four_finite_numbers_on_both_legs_and_in_flight():
    ctrl = RabbitWalkingController(RABBIT)
    for q, dq, _leg in near_gait_states(ctrl):
        for stance in (1, 2, 0):
            u = ctrl(0.0, q.tolist(), dq.tolist(), stance)     # the engine gives lists
            assert np.shape(u) == (4,) and np.all(np.isfinite(u)) and np.all(np.abs(u) <= ctrl.torque_limit)
    q, dq, _ = near_gait_states(ctrl, 1)[0]
    assert np.allclose(ctrl(0.0, q, dq, 0), np.clip(-ctrl.kd * dq[2:6], -150, 150))   # flight: damped joints


def test_the_computed_torque_makes_the_outputs_obey_the_pd_law_through_the_stance_dynamics():
    """At states off the constraints, on both stance legs: the torques, through stance_dynamics, give
    y'' = -kp y - kd y', where y' and y'' are central differences of y(q(t)) with q(t) = q + t dq + t^2/2 ddq."""
    ctrl = RabbitWalkingController(RABBIT, torque_limit=1e9)
    h = 1e-4
    for q, dq, leg in near_gait_states(ctrl):
        u = ctrl(0.0, q, dq, leg)
        ddq, F = RABBIT.stance_dynamics(q, dq, u, leg)
        y = [ctrl.outputs(q + t * dq + 0.5 * t * t * ddq, dq, leg)[0] for t in (-h, 0.0, h)]
        dy = (y[2] - y[0]) / (2 * h)
        ddy = (y[2] - 2 * y[1] + y[0]) / (h * h)
        target = -ctrl.kp * y[1] - ctrl.kd * dy
        assert np.max(np.abs(ddy - target)) < 1e-4 * (1.0 + np.max(np.abs(target))), (leg, ddy, target)
        assert np.allclose(ctrl.outputs(q, dq, leg)[1], dy, atol=1e-6)       # the law's own y' = H dq


def test_stance_leg_2_is_stance_leg_1_mirrored():
    """u(q, dq, leg 2) = swap(u(R q, R dq, leg 1)), R the model's relabeling (legs swapped)."""
    ctrl = RabbitWalkingController(RABBIT)
    for q, dq, _leg in near_gait_states(ctrl, seed=9):
        Rq, Rdq = RABBIT.relabel(q, dq)
        mirrored = np.asarray(ctrl(0.0, Rq, Rdq, 1))[SWAP_U]
        assert np.allclose(ctrl(0.0, q, dq, 2), mirrored, rtol=1e-10, atol=1e-9)
        assert np.allclose(ctrl(0.0, q, dq, 0), np.asarray(ctrl(0.0, Rq, Rdq, 0))[SWAP_U])
        y, dy, _H, _bias = ctrl.outputs(q, dq, 2)
        assert np.allclose(y, ctrl.outputs(Rq, Rdq, 1)[0], atol=1e-12)
        assert np.allclose(ctrl.pd_torques(y, dy, 2), ctrl.pd_torques(y, dy, 1)[SWAP_U])     # the PD term too


def test_the_pd_term_pushes_every_output_back():
    """The PD term (the law where H A is singular): an output error e_i gives torques whose effect on y'' through
    the stance dynamics, H A u, is a matrix -M of eigenvalues in the left half-plane (each output pulled back,
    none pushed away by the others), on both legs around the gait."""
    ctrl = RabbitWalkingController(RABBIT)
    for q, dq, leg in near_gait_states(ctrl, count=8, seed=11):
        _y, _dy, H, _bias = ctrl.outputs(q, dq, leg)
        _a, A = ctrl.stance_affine(q, dq, leg)
        response = np.column_stack([H @ A @ ctrl.pd_torques(np.eye(4)[i], np.zeros(4), leg) for i in range(4)])
        assert np.all(np.diag(response) < 0) and np.all(np.linalg.eigvals(response).real < 0), (leg, response)


def test_the_gaits_impact_lands_on_the_outputs():
    """The impact blend: from the gait at the touchdown (y = 0, y' = 0), the rigid impact of the swing foot
    (GeneratedModel.impact_map) leaves the new stance leg's outputs and their rates at zero."""
    ctrl = RabbitWalkingController(RABBIT)
    q, dq = ctrl.state_on_gait(1.1, 1, theta=ctrl.step_angle)
    assert abs(RABBIT.contact_position(q, 2)[1]) < 1e-12 and RABBIT.contact_position(q, 2)[0] > 0.3
    dq_plus, impulse = RABBIT.impact_map(q, dq, 2)
    y, dy, _H, _bias = ctrl.outputs(q, dq_plus, 2)
    assert impulse[1] > 0 and RABBIT.contact_velocity(q, dq_plus, 1)[1] > 0    # the old stance foot lifts
    assert np.max(np.abs(y)) < 1e-12 and np.max(np.abs(dy)) < 1e-12, (y, dy)


@pytest.mark.parametrize("arguments, message", [
    (dict(step_angle=0.0), "step_angle must be positive, got 0.0"),
    (dict(kp=-1.0), "kp must be >= 0, got -1.0"),
    (dict(impact_blend=1.0), r"impact_blend must be in \(0, 1\)"),
    (dict(swing_knee=float("nan")), "swing_knee must be a finite number, got nan"),
    (dict(stance_knee=-0.1), r"stance_knee and swing_knee must be in \[0, pi\)"),
    (dict(torque_limit="150"), "torque_limit must be a finite number, got '150'"),
])
def test_bad_parameters_are_refused_in_one_line(arguments, message):
    with pytest.raises(ValueError, match=message) as err:
        RabbitWalkingController(RABBIT, **arguments)
    assert "\n" not in str(err.value)


def test_a_robot_without_knees_is_refused_in_one_line():
    with pytest.raises(ValueError, match=r"needs a five-link biped with knees .*got 'three_link'") as err:
        RabbitWalkingController(generated_model("three_link"))
    assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match="got a BipedModel$"):
        RabbitWalkingController(bs.BipedModel())


def test_the_scene_loads_builds_its_controller_and_starts_on_the_gait():
    scene = load_scene("rabbit")
    assert scene.robot == "rabbit" and scene.phases == {"stance", "impact"} and scene.duration == 10.0
    assert scene.controller_params["law"] == "rabbit_walking"
    ctrl = scene.controller()
    assert isinstance(ctrl, RabbitWalkingController) and ctrl.model.name == "rabbit"
    assert bs.RabbitWalkingController is RabbitWalkingController
    assert (ctrl.step_angle, ctrl.swing_knee, ctrl.kp) == (0.25, 1.0, 400.0)
    q, dq = np.array(scene.params["initial_q"]), np.array(scene.params["initial_dq"])
    y, dy, _H, _bias = ctrl.outputs(q, dq, scene.params["initial_stance_leg"])
    assert np.max(np.abs(y)) < 1e-12 and np.max(np.abs(dy)) < 1e-12
    assert np.max(np.abs(RABBIT.contact_position(q, 1))) < 1e-12                      # the stance foot
    assert np.max(np.abs(RABBIT.contact_velocity(q, dq, 1))) < 1e-12                  # at rest
    assert abs(RABBIT.contact_position(q, 2)[1]) < 1e-12 and RABBIT.contact_position(q, 2)[0] < -0.3


def test_the_scenes_run_is_refused_by_todays_engine_and_walks_on_one_that_runs_rabbit():
    """The engine of today refuses the run in its one line, as any scene of a robot it cannot run; an engine
    that runs RABBIT (issue 31's generic engine) walks it, with the harness's touchdowns (its torques held over
    1 ms, as the scene says): foot 2 at 0.5889 s, foot 1 at 1.1776 s."""
    scene = load_scene("rabbit")
    try:
        r = scene.simulate(t_final=1.3)
    except ValueError as exc:
        assert str(exc).startswith("robot 'rabbit' (5 links, 7 coordinates) cannot be simulated yet"), exc
        assert "\n" not in str(exc)
        return
    assert r.status == "completed" and [e.leg for e in r.impacts] == [2, 1], (r.status, r.message)
    assert abs(r.impacts[0].time - 0.5889) < 1e-3 and abs(r.impacts[1].time - 1.1776) < 1e-3


def test_one_step_from_the_scene_returns_to_the_gait():
    """The scene's start is the periodic gait: one step (stance_dynamics, the touchdown of foot 2 in front,
    impact_map) ends on the same state, mirrored and a step ahead."""
    scene = load_scene("rabbit")
    ctrl = scene.controller()
    q0, dq0 = np.array(scene.params["initial_q"]), np.array(scene.params["initial_dq"])

    def rhs(t, x):
        ddq, _F = RABBIT.stance_dynamics(x[:7], x[7:], ctrl(t, x[:7], x[7:], 1), 1)
        return np.concatenate([x[7:], ddq])

    def touchdown(t, x):
        return RABBIT.contact_position(x[:7], 2)[1]
    touchdown.terminal, touchdown.direction = True, -1
    sol = solve_ivp(rhs, (0.0, 1.0), np.concatenate([q0, dq0]), method="DOP853", rtol=1e-10, atol=1e-10,
                    events=touchdown)
    assert sol.t_events[0].size == 1 and abs(sol.t_events[0][0] - 0.58896) < 1e-4
    q, dq = sol.y_events[0][0][:7], sol.y_events[0][0][7:]
    step = RABBIT.contact_position(q, 2)[0]
    assert abs(step - 0.39140) < 1e-4                                            # in front: a touchdown
    dq_plus, _ = RABBIT.impact_map(q, dq, 2)
    Rq, Rdq = RABBIT.relabel(q, dq_plus)
    Rq[0] -= step
    assert np.max(np.abs(Rq - q0)) < 1e-8 and np.max(np.abs(Rdq - dq0)) < 1e-8


def test_the_controller_section_names_its_law_and_takes_that_laws_parameters():
    rabbit = validate_controller({"robot": "rabbit", "law": "rabbit_walking", "kp": 300.0})
    made = make_controller(rabbit)
    assert isinstance(made, RabbitWalkingController) and made.kp == 300.0
    assert (made.kd, made.torque_limit, made.step_angle) == (40.0, 150.0, 0.25)     # the law's own defaults
    with pytest.raises(ValueError, match=r"parameter\(s\) clearance belong to another law than this section's \(law: "
                                         r"rabbit_walking\); rabbit_walking's parameters: torso_pitch, step_angle"):
        validate_controller({"robot": "rabbit", "law": "rabbit_walking", "clearance": 0.5})
    with pytest.raises(ValueError, match=r"parameter\(s\) swing_knee belong to another law than this section's \(law: "
                                         r"walking\)"):
        validate_controller({"swing_knee": 0.5})
    assert math.isclose(make_controller(validate_controller({})).step_angle, 0.2)      # walking: unchanged
