"""NodeRun: the node's rules of a run (command check, period, event routing, state messages) written once
and used by sim_node, simulate --record and resim."""
import math

import pytest

from biped_sim.config import parameters as P
from biped_sim.control.walking import WalkingController
from biped_sim.engine.model import BipedModel
from biped_sim.recording.node_run import NodeRun, event_output, stale_command
from biped_sim.recording.record_run import run_recorded


def walk_params(**kw):
    ctrl = WalkingController(BipedModel())
    q0, dq0 = ctrl.initial_state()
    values = dict(scene="testwalk", time_mode="lockstep", duration=0.2, control_period=0.002,
                  initial_q=[float(v) for v in q0], initial_dq=[float(v) for v in dq0])
    values.update(kw)
    return P.validate(values), ctrl


@pytest.mark.parametrize("action, data, taken", [
    ("reject", [1.0, -2.0], [1.0, -2.0]),
    ("reject", [1.0], None),
    ("reject", [1.0, 2.0, 3.0], None),
    ("reject", [math.nan, 0.0], None),
    ("reject", [0.0, -math.inf], None),
    ("reject", [60.0, 0.0], None),
    ("clip", [60.0, -70.0], [50.0, -50.0]),
    ("clip", [math.nan, 0.0], None),
])
def test_a_command_is_taken_clipped_or_refused_with_its_reason(action, data, taken):
    run = NodeRun(walk_params(torque_limit=50.0, torque_limit_action=action)[0])
    run.u = [3.0, 4.0]
    u, why = run.take_command(data)
    assert u == taken
    assert run.u == (taken if taken is not None else [3.0, 4.0])      # a refused command holds the last
    assert (why is None) == (taken == data)
    assert run.counts == dict(rejected=int(taken is None), clipped=int(taken is not None and taken != data))


def test_a_recorded_run_holds_the_torque_the_node_would_hold_beyond_torque_limit():
    """simulate --record checks each command of its controller as the node checks a message: a command
    beyond torque_limit (reject) is refused and the last one held, so the recorded run is the node's."""
    params, _ = walk_params(torque_limit=50.0)

    def too_strong(t, q, dq, stance_leg):
        return [80.0, 0.0] if t >= 0.1 else [1.0, -1.0]

    def held(t, q, dq, stance_leg):
        return [1.0, -1.0]

    a = run_recorded(params, too_strong, None)
    b = run_recorded(params, held, None)
    assert a.t == b.t == params["duration"]
    assert a.q.tolist() == b.q.tolist() and a.dq.tolist() == b.dq.tolist()


def test_the_run_ends_once_finished_or_stopped_and_events_are_routed_by_kind():
    params, ctrl = walk_params(duration=0.6)
    run = NodeRun(params)
    ends, outputs = [], set()
    while run.running:
        run.take_command(run.sim.command(ctrl))
        events, ended = run.advance()
        outputs.update((ev.kind, event_output(ev)) for ev in events)
        ends.append(ended)
    assert [e for e in ends if e] == ["finished"] and ends[-1] == "finished"
    assert ("touchdown", "impact") in outputs
    assert all(out == ("impact" if kind in ("touchdown", "double_touchdown") else "diagnostics")
               for kind, out in outputs)
    topics = [label for label, _ in run.state_messages()]
    assert topics == ["joint_states", "ground_reaction", "clock"]
    run.restart()
    assert run.sim.t == 0.0 and run.running


def test_a_stale_lockstep_answer_is_named_for_what_it_answers():
    assert stale_command(None, 5) is None and stale_command(5, 5) is None
    assert "older one" in stale_command(4_000_000, 5_000_000)
    assert "has not published" in stale_command(6_000_000, 5_000_000)
    assert "before the ~/reset" in stale_command(6_000_000, 5_000_000, before_reset_ns=7_000_000)


# -- issue 31, item 2: names and sizes from the robot's description ----------------------------------------
def _joint_state(data):
    from rosbags.typesys import Stores, get_typestore  # an independent CDR reader
    return get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(data, "sensor_msgs/msg/JointState")


def test_the_joint_layout_of_a_robot_comes_from_its_description(tmp_path):
    from biped_sim.config.joints import joint_layout
    from biped_sim.config.models import ROBOTS_DIR, load_description
    from biped_sim.recording.messages import JOINT_NAMES
    three = joint_layout("three_link")
    assert three.coordinates == JOINT_NAMES and three.actuated == ("hip_1", "hip_2")
    assert three.effort([1.5, -2.5]) == [0.0, 0.0, 1.5, -2.5, 0.0]
    assert joint_layout("compass_gait").coordinates == ("base_x", "base_y", "hip_1", "hip_2", "hip_pitch")
    rabbit = joint_layout("rabbit")
    assert rabbit.coordinates == load_description("rabbit").coordinates
    assert rabbit.actuated == ("hip_1", "hip_2", "knee_1", "knee_2")
    assert rabbit.effort([1.0, 2.0, 3.0, 4.0]) == [0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 0.0]
    mine = tmp_path / "mine.yaml"                    # a description file: its names, read from the file
    mine.write_text((ROBOTS_DIR / "rabbit.yaml").read_text().replace("knee_", "kn_").replace("actuated: [hip_1, "
                                                                                              "hip_2, ", "actuated: ["))
    layout = joint_layout(str(mine))
    assert layout.coordinates[4:6] == ("kn_1", "kn_2") and layout.actuated == ("kn_1", "kn_2")
    assert layout.effort([7.0, 8.0]) == [0.0, 0.0, 0.0, 0.0, 7.0, 8.0, 0.0]


def test_a_runs_joint_states_carry_its_robots_names_and_the_three_link_bytes_are_unchanged():
    from biped_sim.recording.cdr import StateSerializer
    from biped_sim.recording.messages import JOINT_NAMES
    three = NodeRun(walk_params()[0])
    three.take_command([1.5, -2.5])
    old = StateSerializer(JOINT_NAMES).period(0, "foot_1", *three.sim.state_lists(), [1.5, -2.5],
                                              three.sim.ground_force)
    assert three.state_messages() == old
    cg = NodeRun(P.validate(dict(robot="compass_gait", initial_q=[0.0, 1.0, math.pi, math.pi, 0.0])))
    cg.take_command([1.0, -2.0])
    label, data = cg.state_messages()[0]
    msg = _joint_state(data)
    assert label == "joint_states" and list(msg.name) == ["base_x", "base_y", "hip_1", "hip_2", "hip_pitch"]
    assert msg.effort.tolist() == [0.0, 0.0, 1.0, -2.0, 0.0] and msg.position.tolist() == [0.0, 1.0, math.pi,
                                                                                         math.pi, 0.0]


def test_a_command_of_another_length_is_refused_naming_the_actuated_joints():
    run = NodeRun(walk_params()[0])
    u, why = run.take_command([1.0, 2.0, 3.0])
    assert u is None and why == "3 values instead of 2, one per actuated joint (hip_1, hip_2)"
    assert run.u == [0.0, 0.0]
