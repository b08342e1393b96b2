"""The walk_controller node with the sim node over DDS (real processes), and scenes on the node side."""
import contextlib
import re
import sys
import time
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from biped_sim.config.scenes import load_scene  # noqa: E402

from ros_helpers import Client, bag_messages, ros_domain, start_node  # noqa: E402

pytest.importorskip("rclpy")
from sensor_msgs.msg import JointState  # noqa: E402

from biped_sim.ros.walk_controller import stance_from_state  # noqa: E402


def scene_args(name):
    return ["--ros-args", "--params-file", str(load_scene(name).path)]


def test_stance_from_state_agrees_with_the_engine():
    """The state-derived rule (the foot on the ground and at rest) along walking runs, impacts included."""
    for name in ("walk", "slope", "drop"):
        s = load_scene(name)
        r = s.simulate(hold=False, t_final=2.0)
        model, slope = s.engine_arguments()["model"], s.params["slope"]
        legs = [stance_from_state(model, q, dq, slope) for q, dq in zip(r.q, r.dq)]
        assert legs == r.stance_leg.tolist(), name


def _spin_all(clients, predicate, timeout, what, procs=()):
    end = time.monotonic() + timeout
    while not predicate():
        for p in procs:
            code = p.proc.poll()
            assert code in (None, 0) or predicate(), f"a process failed ({code}) waiting for {what}:\n{p.output()}"
        assert time.monotonic() < end, f"timed out waiting for {what}\n" + "\n".join(p.output() for p in procs)
        for c in clients:
            c.spin_once(0.02)


def _t(m):
    return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9


def test_lockstep_walk_with_the_controller_node_matches_headless():
    """sim_node (walk scene, lockstep) and walk_controller in two processes, once with the stance leg from
    the frame id (auto) and once from the state, side by side in two ROS domains."""
    duration, sources = 0.6, ("auto", "state")
    with contextlib.ExitStack() as stack:
        runs = []
        for source in sources:
            dom = stack.enter_context(ros_domain())
            sim = stack.enter_context(start_node({"duration": duration, "record": False}, dom,
                                                 extra_args=scene_args("walk")))
            c = stack.enter_context(Client(dom))
            js = c.collect("/joint_states", JointState)
            # matched before the controller starts: the lockstep run takes about a second, less than
            # discovery may take, and the node exits at its end
            c.wait_subscribed("/joint_states", proc=sim)
            ctl = stack.enter_context(start_node({"stance_source": source}, dom, executable="walk_controller",
                                                 extra_args=scene_args("walk")))
            runs.append((sim, ctl, c, js))
        procs = [p for r in runs for p in r[:2]]
        _spin_all([r[2] for r in runs], lambda: all(r[3] and _t(r[3][-1]) >= duration for r in runs), 90,
                  f"the state at t = {duration} s in both runs", procs)
        logs = []
        for sim, ctl, _c, _js in runs:
            assert ctl.stop() == 0
            logs.append(ctl.output())
            assert sim.wait(20) == 0, sim.output()
    ref = load_scene("walk").simulate(hold=True, t_final=duration)   # the same run headless
    assert len(ref.impacts) == 1 and ref.impacts[0].time < 0.5   # the stance leg changes on the way
    for source, (_s, _ctl, _c, js), log in zip(sources, runs, logs):
        last = js[-1]
        assert list(last.position) == ref.q[-1].tolist() and list(last.velocity) == ref.dq[-1].tolist(), source
        # every joint_states message answered exactly once (t = 0 .. 0.6 s: 601 states; the last ends the run)
        m = re.search(r"after (\d+) commands \((\d+) duplicate", log)
        assert m and int(m.group(1)) == round(duration / 0.001) + 1 and int(m.group(2)) == 0, log
        assert f"stance_source='{source}'" in log


def test_a_lockstep_walk_whose_swing_foot_scuffs_deep_runs_to_its_end_as_headless():
    """The scuff rule of round 3 through the node: the reference law with its mid-stance graze 0.15 rad
    behind the stance foot (lag -0.15: the swing foot scuffs 3.8 mm deep), torques held 2 ms in
    lockstep. Round 2's rule (scuff_rule behind, scuff_depth 3 mm: the node's parameters) stops it at
    0.082 s; with the defaults it walks to its end, the same run as headless."""
    duration = 1.5
    overrides = {"control_period": 0.002, "duration": duration}
    ref = load_scene("walk", overrides={**overrides, "lag": -0.15}).simulate()
    assert ref.status == "completed" and len(ref.impacts) == 3 and ref.stats["deepest_scuff"] > 3e-3
    round2 = load_scene("walk", overrides={**overrides, "lag": -0.15, "scuff_rule": "behind",
                                           "scuff_depth": 0.003}).simulate()
    assert round2.status == "stopped" and round2.t[-1] < 0.1, round2.message
    with ros_domain() as dom:
        with start_node({**overrides, "record": False}, dom, extra_args=scene_args("walk")) as sim, \
                Client(dom) as c:
            js = c.collect("/joint_states", JointState)
            c.wait_subscribed("/joint_states", proc=sim)
            with start_node({"lag": -0.15}, dom, executable="walk_controller", extra_args=scene_args("walk")) as ctl:
                _spin_all([c], lambda: js and _t(js[-1]) >= duration - 1e-9, 120,
                          f"the state at t = {duration} s", [sim, ctl])
                assert ctl.stop() == 0
            assert sim.wait(20) == 0, sim.output()
    assert list(js[-1].position) == ref.q[-1].tolist() and list(js[-1].velocity) == ref.dq[-1].tolist()
    assert "duration 1.5 s reached: the run ends" in sim.output(), sim.output()


def test_the_nodes_parameters_take_their_laws_defaults_as_the_scene_does():
    """The walk_controller node checks its parameters as the scene loader checks a walk_controller section: a
    rabbit_walking section's left-out parameters are RabbitWalkingController's defaults, not the three-link
    law's, and a parameter of the other law is refused in one line."""
    from biped_sim.config.scenes import validate_controller
    from biped_sim.ros.parameters import check_given
    from biped_sim.ros.startup import StartupError
    from biped_sim.ros.walk_controller import PARAMETERS, validate_parameters
    given = {"robot": "rabbit", "law": "rabbit_walking", "kp": 300.0}
    node = check_given(given, PARAMETERS, "walk_controller", validate_parameters)
    assert (node["kp"], node["kd"], node["torque_limit"], node["step_angle"]) == (300.0, 40.0, 150.0, 0.25)
    assert {k: node[k] for k in validate_controller(given)} == validate_controller(given)
    walking = check_given({}, PARAMETERS, "walk_controller", validate_parameters)
    assert (walking["law"], walking["kp"], walking["torque_limit"]) == ("walking", 200.0, 500.0)
    with pytest.raises(StartupError, match=r"parameter\(s\) clearance belong to another law") as err:
        check_given({"law": "rabbit_walking", "robot": "rabbit", "clearance": 0.5}, PARAMETERS, "walk_controller",
                    validate_parameters)
    assert "\n" not in str(err.value)


def test_controller_refuses_unknown_parameters():
    with ros_domain() as dom:
        with start_node({"kq": 1.0}, dom, executable="walk_controller") as ctl:
            assert ctl.wait(20) == 2
            out = ctl.output()
    assert "walk_controller: error: unknown parameter 'kq' for node 'walk_controller'" in out
    assert "kp (double in" in out and "Traceback" not in out


def test_node_builds_only_the_scene_topics():
    pubs = {}
    with contextlib.ExitStack() as stack:
        runs = []
        for scene in ("stance_fixed", "walk"):
            dom = stack.enter_context(ros_domain())
            sim = stack.enter_context(start_node({"time_mode": "lockstep", "record": False}, dom,
                                                 extra_args=scene_args(scene)))
            runs.append((scene, sim, stack.enter_context(Client(dom))))
        # discovery reports a node's publishers one by one: wait for every one each scene must have
        # (the last created, /diagnostics, included), not just the first
        expected = {"stance_fixed": {"/joint_states", "/clock", "/diagnostics"},
                    "walk": {"/impact", "/ground_reaction", "/joint_states", "/clock", "/diagnostics"}}
        _spin_all([r[2] for r in runs], lambda: all(("biped_sim", "/") in c.node.get_node_names_and_namespaces()
                                                    and expected[n] <= set(c.node_topics("biped_sim")[0])
                                                    for n, _p, c in runs), 60, "the nodes' publishers",
                  [r[1] for r in runs])
        for scene, _sim, c in runs:
            pubs[scene] = set(c.node_topics("biped_sim")[0])
    fixed, walk = pubs["stance_fixed"], pubs["walk"]
    assert "/impact" not in fixed and "/ground_reaction" not in fixed and {"/joint_states", "/clock"} <= fixed
    assert {"/impact", "/ground_reaction", "/joint_states", "/clock"} <= walk


def test_only_declared_topics_are_recorded(tmp_path):
    from biped_sim.recording import bagio
    with ros_domain() as dom:
        with start_node({"time_mode": "fast", "record": True, "bag_dir": str(tmp_path)}, dom,
                        extra_args=scene_args("stance_fixed")) as sim:
            assert sim.wait(60) == 0, sim.output()
    bags = [p for p in tmp_path.iterdir() if p.is_dir()]
    assert len(bags) == 1
    topics = set(bagio.channels(bags[0]))
    assert "/joint_states" in topics and "/clock" in topics
    assert "/impact" not in topics and "/ground_reaction" not in topics
    assert np.all([not t.endswith(("impact", "ground_reaction")) for t in topics])


def test_a_compass_gait_lockstep_run_carries_its_robots_joint_names_and_the_controller_finds_them(tmp_path):
    """Issue 31, item 2: the compass gait scene (robot compass_gait: its base angle is 'hip_pitch') in
    lockstep with walk_controller (robot compass_gait, u = 0): joint_states carry the robot's names, the
    controller looks its joints up by them and answers every state, and the run is the headless one; the
    bag's joint_states, read back by rosbags, carry the same names."""
    from biped_sim.config.controllers import no_torque
    duration = 0.2
    overrides = {"time_mode": "lockstep", "duration": duration}
    ref = load_scene("compass_gait", overrides=overrides).simulate(controller=no_torque)
    names = ["base_x", "base_y", "hip_1", "hip_2", "hip_pitch"]
    with ros_domain() as dom:
        with start_node({**overrides, "record": True, "bag_dir": str(tmp_path)}, dom,
                        extra_args=scene_args("compass_gait")) as sim, Client(dom) as c:
            js = c.collect("/joint_states", JointState)
            c.wait_subscribed("/joint_states", proc=sim)
            with start_node({"robot": "compass_gait", "slope": 0.0525,
                             "controller": "biped_sim.config.controllers:no_torque"}, dom,
                            executable="walk_controller") as ctl:
                _spin_all([c], lambda: js and _t(js[-1]) >= duration - 1e-9, 90,
                          f"the state at t = {duration} s", [sim, ctl])
                assert ctl.stop() == 0
                log = ctl.output()
            assert sim.wait(20) == 0, sim.output()
    assert list(js[-1].name) == names and list(js[-1].position) == ref.q[-1].tolist()
    m = re.search(r"after (\d+) commands", log)
    assert m and int(m.group(1)) == round(duration / 0.001) + 1 and "without the joints" not in log, log
    (bag,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    recorded = bag_messages(bag)["/joint_states"]
    assert len(recorded) == len(js) and all(list(m.name) == names for _t_ns, m in recorded)


def test_both_nodes_name_their_robot_when_they_start():
    """The sim node and walk_controller each name their robot in their first line: the joint names are the same
    for every three-link robot, so the log is where a controller started for another robot shows."""
    with ros_domain() as dom:
        with start_node({"robot": "three_link_hip_mass"}, dom, executable="walk_controller") as ctl, \
                start_node({"robot": "three_link_hip_mass", "record": False, "time_mode": "fast", "duration": 0.05},
                           dom) as sim:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and not ("walk_controller: robot=" in ctl.output()
                                                       and "biped_sim: robot=" in sim.output()):
                time.sleep(0.2)
            ctl_out, sim_out = ctl.output(), sim.output()
    assert "walk_controller: robot='three_link_hip_mass', torso_pitch=" in ctl_out, ctl_out
    assert "biped_sim: robot=three_link_hip_mass, time_mode=fast" in sim_out, sim_out


def test_the_sim_node_runs_rabbit_and_its_bag_carries_rabbits_joints(tmp_path):
    """A described robot through the node (robot rabbit, fast, its initial state given, u = 0): the node starts
    naming the compiled loop, RABBIT falls over and foot 2 lands (an /impact message), and the bag's joint_states,
    read back by rosbags, carry RABBIT's 7 coordinates by name, ending where the headless run of the same periods
    ends."""
    from biped_sim.config.models import load_model
    from biped_sim.engine.hybrid import HybridSimulator
    q0 = [0.0997086196481708, 0.7935100972856273, 3.241592653589793, 2.941592653589793, -0.05, 0.5, 0.05]
    params = {"robot": "rabbit", "time_mode": "fast", "duration": 0.2, "initial_q": q0, "initial_dq": [0.0] * 7,
              "record": True, "bag_dir": str(tmp_path)}
    with ros_domain() as dom:
        with start_node(params, dom) as sim:
            assert sim.wait(60) == 0, sim.output()
            out = sim.output()
    assert "biped_sim: robot=rabbit" in out, out
    assert ", hybrid loop in C" in out, out
    (bag,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    got = bag_messages(bag)
    names = ["base_x", "base_y", "hip_1", "hip_2", "knee_1", "knee_2", "torso_pitch"]
    assert all(list(m.name) == names for _t_ns, m in got["/joint_states"])
    assert len(got["/impact"]) == 1
    ref = HybridSimulator(load_model("rabbit"), q0, [0.0] * 7, stance_leg=1)
    while ref.t < 0.2 - 1e-12:
        ref.advance_period(0.001, u=[0.0] * 4, t_final=0.2)
    assert [e.kind for e in ref.events] == ["touchdown"]
    np.testing.assert_allclose(list(got["/joint_states"][-1][1].position), ref.q, rtol=0, atol=1e-12)
