"""Over real DDS: ``replay`` into a subscriber in another process, and bags recorded by ``sim_node``.

Owns the issue-4 tests that need ROS processes: replay delivers every message of a bag, in order
and with its values; a lockstep node run's bag holds what the node published and received (read
by ``rosbags``) and re-simulates exactly; SIGKILL of a recording node leaves a readable bag.
"""
from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from ros_helpers import BIN, Client, bag_messages, complete_messages, ros_domain, ros_env, start_node

pytest.importorskip("rclpy")
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from biped_sim.config import parameters as P  # noqa: E402
from biped_sim.control.walking import WalkingController  # noqa: E402
from biped_sim.engine.model import BipedModel  # noqa: E402
from biped_sim.recording.record_run import run_recorded  # noqa: E402
from biped_sim.recording.recorder import BagRecorder  # noqa: E402
from biped_sim.recording.resim import format_report, resim  # noqa: E402


def ns(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec






def test_replay_delivers_every_message_in_order(tmp_path):
    ctrl = WalkingController(BipedModel())
    q0, dq0 = ctrl.initial_state()
    params = P.validate(dict(scene="replaytest", time_mode="lockstep", duration=0.6, control_period=0.01,
                             initial_q=[float(v) for v in q0], initial_dq=[float(v) for v in dq0]))
    rec = BagRecorder(tmp_path / "bag", parameters=params)
    run_recorded(params, ctrl, rec)
    rec.close()
    recorded = bag_messages(tmp_path / "bag")
    with ros_domain() as dom, Client(dom) as c:
        js = c.collect("/joint_states", JointState, transient_local=False)
        cmd = c.collect("/hip_torque", Float64MultiArray, transient_local=False)
        imp = c.collect("/impact", DiagnosticArray, transient_local=False)
        clk = c.collect("/clock", Clock, transient_local=False)
        t0 = time.monotonic()
        proc = subprocess.Popen([str(BIN / "biped-sim"), "replay", str(tmp_path / "bag"), "--rate", "2",
                                 "--wait-subscribers", "20",
                                 "--exclude", "/ground_reaction"], env=ros_env(dom), stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)
        try:
            c.spin_until(lambda: len(js) == len(recorded["/joint_states"]) and len(clk) == len(recorded["/clock"])
                         and len(cmd) == len(recorded["/hip_torque"]), timeout=40, what="every replayed message")
            assert proc.wait(20) == 0
        finally:
            if proc.poll() is None:
                proc.kill()
        wall = time.monotonic() - t0
        out = proc.stdout.read()
    assert "published" in out and "[replay] " in out and "; bag time " in out and "\r" not in out, out
    assert [(ns(m.header.stamp), list(m.position), list(m.velocity)) for m in js] == \
        [(ns(m.header.stamp), list(m.position), list(m.velocity)) for _, m in recorded["/joint_states"]]
    assert [list(m.data) for m in cmd] == [list(m.data) for _, m in recorded["/hip_torque"]]
    assert [ns(m.clock) for m in clk] == [ns(m.clock) for _, m in recorded["/clock"]]
    assert len(imp) == len(recorded["/impact"]) >= 1
    assert wall >= params["duration"] / 2       # original timing at rate 2: not faster than 0.3 s


def test_replay_publishes_a_rabbit_bag_as_recorded(tmp_path):
    """A bag of RABBIT (7 coordinates, 4 motors; written by the node's serializer for its joint layout) is
    published as it was recorded: joint_states of 7 names and values, commands of 4 torques."""
    from biped_sim.config.joints import joint_layout
    from biped_sim.recording import messages as M
    from biped_sim.recording.cdr import StateSerializer, float64_multi_array_data
    layout = joint_layout("rabbit")
    serializer = StateSerializer(layout.coordinates, labels={n: "/" + n for n in M.TOPIC_TYPES},
                                 effort=layout.effort_function())
    rec = BagRecorder(tmp_path / "bag", parameters=P.validate(dict(
        scene="rabbitreplay", robot="rabbit", initial_q=[0.0, 0.75, 3.3, 2.9, 0.35, 0.1, 0.2], initial_dq=[0.0] * 7)))
    for name in ("joint_states", "hip_torque"):
        rec.add_topic("/" + name, M.TOPIC_TYPES[name])
    q0 = np.array([0.0, 0.75, 3.3, 2.9, 0.35, 0.1, 0.2])
    for k in range(20):
        t_ns, u = k * 10_000_000, [0.1 * k, -1.0, 2.0, 0.5 * k]
        rec.write("/hip_torque", float64_multi_array_data(u), t_ns)
        rec.write_messages(t_ns, serializer.period(t_ns, "foot_1", (q0 + 0.01 * k).tolist(), [0.1 * k] * 7, u,
                                                   None, ground_reaction=False, clock=False))
    rec.close()
    recorded = bag_messages(tmp_path / "bag")
    with ros_domain() as dom, Client(dom) as c:
        js = c.collect("/joint_states", JointState, transient_local=False)
        cmd = c.collect("/hip_torque", Float64MultiArray, transient_local=False)
        proc = subprocess.Popen([str(BIN / "biped-sim"), "replay", str(tmp_path / "bag"), "--rate", "4", "-q",
                                 "--wait-subscribers", "20"], env=ros_env(dom), stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)
        try:
            c.spin_until(lambda: len(js) == 20 and len(cmd) == 20, timeout=40, what="every replayed message")
            assert proc.wait(20) == 0, proc.stdout.read()
        finally:
            if proc.poll() is None:
                proc.kill()
    assert tuple(js[0].name) == layout.coordinates and len(js[0].position) == 7
    assert [(list(m.position), list(m.velocity), list(m.effort)) for m in js] == \
        [(list(m.position), list(m.velocity), list(m.effort)) for _, m in recorded["/joint_states"]]
    assert list(js[5].effort) == [0.0, 0.0, 0.5, -1.0, 2.0, 2.5, 0.0]          # B u: each motor on its joint
    assert [list(m.data) for m in cmd] == [list(m.data) for _, m in recorded["/hip_torque"]]
    assert len(cmd[0].data) == 4


def test_node_lockstep_bag_holds_what_was_published_and_resims_exactly(tmp_path):
    ctrl = WalkingController(BipedModel())
    q0, dq0 = ctrl.initial_state()
    cp, duration = 0.01, 1.0
    params = dict(scene="nodebag", time_mode="lockstep", control_period=cp, duration=duration, record=True,
                  bag_dir=str(tmp_path), initial_q=[float(v) for v in q0], initial_dq=[float(v) for v in dq0])
    with ros_domain() as dom, start_node(params, dom) as proc, Client(dom) as c:
        js = c.collect("/joint_states", JointState)
        imp = c.collect("/impact", DiagnosticArray)
        clk = c.collect("/clock", Clock)
        pub = c.publisher("/hip_torque", Float64MultiArray)
        c.wait_matched(pub, proc=proc)
        c.spin_until(lambda: js, what="the state at t = 0", proc=proc)
        sent = []
        for _ in range(round(duration / cp)):
            m = js[-1]
            leg = int(m.header.frame_id.split("_")[1]) if m.header.frame_id.startswith("foot_") else 0
            u = [float(v) for v in ctrl(ns(m.header.stamp) * 1e-9, np.array(m.position), np.array(m.velocity), leg)]
            n = len(js)
            pub.publish(Float64MultiArray(data=u))
            sent.append(u)
            c.spin_until(lambda: len(js) > n, timeout=10, what="the next state", proc=proc)
        c.spin_until(lambda: len(clk) == len(js), timeout=10, what="every /clock", proc=proc)
        assert proc.wait(30) == 0, proc.output()
    bags = list(Path(tmp_path).glob("nodebag-*"))
    assert len(bags) == 1, bags
    assert (bags[0] / "metadata.yaml").exists(), list(bags[0].iterdir())
    got = bag_messages(bags[0])
    assert [(t, list(m.position), list(m.velocity), list(m.effort)) for t, m in got["/joint_states"]] == \
        [(ns(m.header.stamp), list(m.position), list(m.velocity), list(m.effort)) for m in js]
    assert [list(m.data) for _, m in got["/hip_torque"]] == sent
    assert [t for t, _ in got["/clock"]] == [ns(m.clock) for m in clk]
    assert len(got["/impact"]) == len(imp), (len(got["/impact"]), len(imp))
    assert len(imp) >= 2
    assert [[(kv.key, kv.value) for kv in m.status[0].values] for _, m in got["/impact"]] == \
        [[(kv.key, kv.value) for kv in m.status[0].values] for m in imp]
    for topic, items in got.items():
        assert [t for t, _ in items] == sorted(t for t, _ in items), topic
    rep = resim(bags[0])
    assert rep["identical"], format_report(rep)
    assert rep["states"] == len(js) and rep["commands"] == len(sent)


def test_sigkill_of_a_recording_node_leaves_a_readable_bag(tmp_path):
    params = dict(scene="killed", time_mode="fast", duration=0.0, record=True, bag_dir=str(tmp_path),
                  command_timeout=0.0)
    with ros_domain() as dom, start_node(params, dom) as proc:
        end = time.monotonic() + 40
        while complete_messages(tmp_path.glob("killed-*/*.mcap")) < 200:    # some chunks on disk
            assert proc.alive and time.monotonic() < end, proc.output()
            time.sleep(0.2)
        proc.stop(signal.SIGKILL)
    bag = list(tmp_path.glob("killed-*"))[0]
    end = time.monotonic() + 30
    while not (bag / "metadata.yaml").exists():     # the writer process finalises the bag
        assert time.monotonic() < end, "metadata.yaml did not appear"
        time.sleep(0.1)
    got = bag_messages(bag)
    assert len(got["/joint_states"]) > 10
    times = [t for t, _ in got["/joint_states"]]
    assert times == sorted(times) and times[0] == 0
