"""The ``markers`` topic over DDS (sim_node and walk_controller as separate processes), in the bag, and
``biped-sim animate`` on that bag; a scene without "markers" in its outputs has no such publisher."""
from __future__ import annotations

import contextlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from ros_helpers import BIN, Client, Control, ros_domain, ros_env, spin_while_running, start_node  # noqa: E402

pytest.importorskip("rclpy")
from mcap.reader import make_reader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from PIL import Image  # noqa: E402
from rosbags.rosbag2 import Reader  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

from biped_sim.config.scenes import load_scene  # noqa: E402
from biped_sim.engine.model import BipedModel  # noqa: E402
from biped_sim.recording import markers as MK  # noqa: E402

TYPES = {MK.LEG_1: Marker.LINE_STRIP, MK.LEG_2: Marker.LINE_STRIP, MK.TORSO: Marker.LINE_STRIP, MK.HIP: Marker.SPHERE,
         MK.FOOT_1: Marker.SPHERE, MK.FOOT_2: Marker.SPHERE, MK.FORCE: Marker.ARROW, MK.GROUND: Marker.LINE_STRIP,
         MK.FLASH: Marker.SPHERE}


def scene_args(name):
    return ["--ros-args", "--params-file", str(load_scene(name).path)]


def ns(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec


@pytest.fixture(scope="module")
def walk_run(tmp_path_factory):
    """The walk scene for 1 s: sim_node recording to a bag, walk_controller, both as processes."""
    bag_dir = tmp_path_factory.mktemp("bags")
    duration = 1.0
    with contextlib.ExitStack() as stack:
        dom = stack.enter_context(ros_domain())
        sim = stack.enter_context(start_node({"duration": duration, "bag_dir": str(bag_dir)}, dom,
                                             extra_args=scene_args("walk")))
        c = stack.enter_context(Client(dom))
        js = c.collect("/joint_states", JointState)
        arrays = c.collect("/markers", MarkerArray)
        c.wait_subscribed("/joint_states", proc=sim)
        c.wait_subscribed("/markers", proc=sim)
        ctl = stack.enter_context(start_node({}, dom, executable="walk_controller", extra_args=scene_args("walk")))
        # the last state, and the markers of the last state (always sent at the end of a run)
        spin_while_running(c, lambda: js and ns(js[-1].header.stamp) >= round(duration * 1e9) and arrays
                           and ns(arrays[-1].markers[0].header.stamp) >= round(duration * 1e9), 120,
                           "the state and the markers at the end of the run", (sim, ctl))
        assert sim.wait(30) == 0, sim.output()
        assert ctl.stop() == 0
    bags = [p for p in bag_dir.iterdir() if p.is_dir()]
    assert len(bags) == 1
    return dict(js=js, arrays=arrays, bag=bags[0], duration=duration, log=sim.output())


def test_the_walk_publishes_markers_that_draw_its_states(walk_run):
    arrays, js = walk_run["arrays"], walk_run["js"]
    assert len(arrays) >= 3
    model = BipedModel()
    state = {ns(m.header.stamp): m for m in js}
    matched = 0
    for arr in arrays:
        by_id = {m.id: m for m in arr.markers}
        assert {i: m.type for i, m in by_id.items()} == TYPES
        assert {m.header.frame_id for m in arr.markers} == {"world"} and {m.ns for m in arr.markers} == {"biped_sim"}
        t = ns(arr.markers[0].header.stamp)
        assert {ns(m.header.stamp) for m in arr.markers} == {t}
        m = state[t]         # every array draws a state that joint_states published, at the same stamp
        q = np.array(m.position)
        for mid, leg in ((MK.LEG_1, 1), (MK.LEG_2, 2)):
            hip, foot = ([p.x, p.z] for p in by_id[mid].points)
            assert hip == pytest.approx(q[:2], abs=1e-9)
            assert foot == pytest.approx(model.foot_position(q, leg), abs=1e-9)
            assert all(p.y == 0.0 for p in by_id[mid].points)
        stance = int(m.header.frame_id.split("_")[1])
        foot_marker = by_id[MK.FOOT_1 if stance == 1 else MK.FOOT_2]
        assert (foot_marker.color.r, foot_marker.color.g) == pytest.approx(MK.STANCE_FOOT_COLOUR[:2])
        assert by_id[MK.FORCE].action == Marker.ADD
        matched += 1
    assert matched == len(arrays)
    # the run's touchdown (t = 0.4716 s, foot 2) flashes in the array that follows it
    flashes = [a for a in arrays if {m.id: m for m in a.markers}[MK.FLASH].action == Marker.ADD]
    assert flashes
    first = min(flashes, key=lambda a: ns(a.markers[0].header.stamp))
    assert 0.4716 <= ns(first.markers[0].header.stamp) * 1e-9 < 0.4726


def test_the_bag_holds_the_markers_readable_by_rosbags_and_mcap_ros2(walk_run):
    bag, arrays = walk_run["bag"], walk_run["arrays"]
    ts = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as r:
        conns = [c for c in r.connections if c.topic == "/markers"]
        assert len(conns) == 1 and conns[0].msgtype == "visualization_msgs/msg/MarkerArray"
        got = [ts.deserialize_cdr(raw, c.msgtype) for c, _t, raw in r.messages(connections=conns)]
    assert len(got) == len(arrays)
    for rec, pub in zip(got, arrays):
        assert [(m.id, m.type, m.action) for m in rec.markers] == [(m.id, m.type, m.action) for m in pub.markers]
        assert [[(p.x, p.y, p.z) for p in m.points] for m in rec.markers] == \
            [[(p.x, p.y, p.z) for p in m.points] for m in pub.markers]
    # the schema the bag carries decodes it too (what Foxglove reads)
    mcap_file = next(bag.glob("*.mcap"))
    with open(mcap_file, "rb") as f:
        decoded = [(s.name, d) for s, ch, _m, d in make_reader(f, decoder_factories=[DecoderFactory()])
                   .iter_decoded_messages(topics=["/markers"])]
    assert len(decoded) == len(arrays) and decoded[0][0] == "visualization_msgs/msg/MarkerArray"
    assert [m.id for m in decoded[-1][1].markers] == list(range(1, 10))


def test_the_nodes_bag_records_the_hip_frame_on_tf_with_each_marker_array(walk_run):
    """sim_node records (does not publish: no tf2_msgs here) world -> hip at each array's stamp."""
    ts = get_typestore(Stores.ROS2_JAZZY)
    with Reader(walk_run["bag"]) as r:
        conns = [c for c in r.connections if c.topic == "/tf"]
        assert len(conns) == 1 and conns[0].msgtype == "tf2_msgs/msg/TFMessage"
        got = [ts.deserialize_cdr(raw, c.msgtype).transforms for c, _t, raw in r.messages(connections=conns)]
    arrays = walk_run["arrays"]
    assert len(got) == len(arrays)
    for (tf,), arr in zip(got, arrays):
        hip = {m.id: m for m in arr.markers}[MK.HIP].pose.position
        assert (tf.header.frame_id, tf.child_frame_id) == ("world", MK.FOLLOW_FRAME)
        assert ns(tf.header.stamp) == ns(arr.markers[0].header.stamp)
        assert (tf.transform.translation.x, tf.transform.translation.z) == (hip.x, hip.z)


def test_replay_of_the_bag_plays_its_topics_and_says_it_leaves_out_tf(walk_run):
    """tf2_msgs has no Python package here: replay plays the other topics and says so in one line."""
    with ros_domain() as dom:
        done = subprocess.run([str(BIN / "biped-sim"), "replay", str(walk_run["bag"]), "--rate", "100"],
                              env=ros_env(dom), capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "not playing /tf (tf2_msgs/msg/TFMessage): its message package is not installed here" in done.stderr
    assert "published" in done.stdout + done.stderr and "Traceback" not in done.stderr


def test_animate_the_recorded_bag(walk_run, tmp_path):
    out = tmp_path / "walk.gif"
    done = subprocess.run([str(BIN / "biped-sim"), "animate", str(walk_run["bag"]), "-o", str(out), "--fps", "10"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr and "11/11 frames" in done.stderr
    with Image.open(out) as im:
        assert im.n_frames == 11                       # 1 s at 10 fps
        frames = []
        for k in range(im.n_frames):
            im.seek(k)
            frames.append(np.asarray(im.convert("RGB")).astype(int))
    torso = np.array([round(255 * c) for c in MK.TORSO_COLOUR[:3]])
    assert all(np.sum(np.all(np.abs(f - torso) <= 8, axis=-1)) > 50 for f in frames)
    assert not np.array_equal(frames[0], frames[5])


def test_a_scene_without_markers_has_no_markers_publisher():
    assert "markers" not in load_scene("stance_fixed").outputs
    with ros_domain() as dom, start_node({"time_mode": "lockstep", "record": False}, dom,
                                         extra_args=scene_args("stance_fixed")) as sim, Client(dom) as c:
        pubs, _subs = c.wait_for_node_topics("biped_sim", publishers=("/joint_states", "/clock", "/diagnostics"),
                                             proc=sim)
        assert "/markers" not in pubs
        assert c.node.count_publishers("/markers") == 0


def test_markers_beyond_what_the_machine_draws_get_advice_naming_marker_rate(tmp_path):
    """Issue 34, round 3, item 4: a realtime run at the highest marker_rate fell behind and the advice
    ("lower publish_rate or rate_factor, raise control_period, or use time_mode fast") named every knob
    but marker_rate, the one whose cost (at a rate of wall time) none of those lowers."""
    outputs = ["joint_states", "clock", "markers"]
    params = dict(time_mode="realtime", rate_factor=5.0, duration=5.0, marker_rate=1000.0, outputs=outputs,
                  bag_dir=str(tmp_path))
    with ros_domain() as dom, Client(dom) as c:
        arrays = c.collect("/markers", MarkerArray)       # a viewer on the markers, as RViz would be
        with start_node(dict(params, start_paused=True), dom) as sim:   # runs once the viewer is there
            c.wait_subscribed("/markers", proc=sim)
            assert Control(c, sim).pause(False).success
            spin_while_running(c, lambda: sim.proc.poll() is not None, 60, "the end of the run", (sim,))
        assert sim.wait() == 0 and arrays, sim.output()
        advice = [ln for ln in sim.output().splitlines() if "markers: drawing the robot" in ln]
        assert len(advice) == 1 and "[WARN]" in advice[0] and "at marker_rate=1000 Hz took" in advice[0], sim.output()
        advised = float(advice[0].split("Set marker_rate:=")[1].split(" ")[0])
        assert 0.1 <= advised < 1000.0, advice[0]
        # the advised rate is one this machine draws: the same run says nothing about the markers
        with start_node(dict(params, marker_rate=advised, duration=2.5, record=False), dom) as again:
            assert again.wait(60) == 0, again.output()
        assert "markers: drawing the robot" not in again.output(), again.output()
