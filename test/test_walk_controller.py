"""The walk_controller node with the sim node over DDS (real processes), and scenes on the node side."""
import re
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from ros_helpers import Client, ros_domain, start_node  # noqa: E402

from biped_sim.scenes import load_scene  # noqa: E402
from biped_sim.walk_controller_node import stance_from_state  # noqa: E402

pytest.importorskip("rclpy")
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402


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


def _lockstep_walk(dom, duration, extra=None):
    """sim_node (walk scene, lockstep) and walk_controller in two processes; the states received."""
    sim_params = {"duration": duration, "record": False}
    with start_node(sim_params, dom, extra_args=scene_args("walk")) as sim, Client(dom) as c:
        js = c.collect("/joint_states", JointState)
        cmds = c.collect("/hip_torque", Float64MultiArray, transient_local=False)
        c.wait_for_publisher("/joint_states", proc=sim)
        with start_node(extra, dom, executable="walk_controller", extra_args=scene_args("walk")) as ctl:
            c.spin_until(lambda: js and js[-1].header.stamp.sec + js[-1].header.stamp.nanosec * 1e-9 >= duration,
                         timeout=60, what=f"the state at t = {duration} s", proc=sim)
            c.spin_until(lambda: len(cmds) >= 1, timeout=5, what="commands")
            assert ctl.stop() == 0
            log = ctl.output()
        assert sim.wait(20) == 0, sim.output()
    return js, cmds, log


@pytest.mark.parametrize("source", ["auto", "state"])
def test_lockstep_walk_with_the_controller_node_matches_headless(source):
    duration = 1.0
    with ros_domain() as dom:
        js, cmds, log = _lockstep_walk(dom, duration, {"stance_source": source})
    ref = load_scene("walk").simulate(hold=True, t_final=duration)   # the same run headless
    assert len(ref.impacts) == 2
    last = js[-1]
    assert list(last.position) == ref.q[-1].tolist() and list(last.velocity) == ref.dq[-1].tolist()
    # every joint_states message answered exactly once (t = 0 .. 1 s: 1001 states; the last one ends the run)
    m = re.search(r"after (\d+) commands \((\d+) duplicate", log)
    assert m and int(m.group(1)) == round(duration / 0.001) + 1 and int(m.group(2)) == 0, log
    assert "stance_source='%s'" % source in log


def test_controller_refuses_unknown_parameters():
    with ros_domain() as dom:
        with start_node({"kq": 1.0}, dom, executable="walk_controller") as ctl:
            assert ctl.wait(20) == 2
            out = ctl.output()
    assert "unknown parameter(s) ['kq']" in out and "kp (double in" in out


def _node_publishers(dom, scene, params):
    with start_node(dict(params, record=False), dom, extra_args=scene_args(scene)) as sim, Client(dom) as c:
        c.wait_for_node("biped_sim", proc=sim)
        c.spin_until(lambda: "/joint_states" in c.node_topics("biped_sim")[0], what="the node's publishers", proc=sim)
        pubs, _subs = c.node_topics("biped_sim")
    return set(pubs)


def test_node_builds_only_the_scene_topics():
    with ros_domain() as dom:
        fixed = _node_publishers(dom, "stance_fixed", {"time_mode": "lockstep"})
        walk = _node_publishers(dom, "walk", {"time_mode": "lockstep"})
    assert "/impact" not in fixed and "/ground_reaction" not in fixed and {"/joint_states", "/clock"} <= fixed
    assert {"/impact", "/ground_reaction", "/joint_states", "/clock"} <= walk


def test_only_declared_topics_are_recorded(tmp_path):
    from biped_sim import bagio
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
