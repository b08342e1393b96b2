"""The Foxglove layout against a real bag (issue 33): every topic and message path it names exists
in a bag that ``biped-sim simulate --record`` writes, the torso angle has a plot of its own (beside
the ~3 rad leg angles its ~0.3 rad swing read as a flat line), and the 3D panel follows a frame that
the bag's ``/tf`` moves with the robot (a fixed camera lost it at t ~ 5-6 s). Bags are read back by
``rosbags``."""
import json
import re
from pathlib import Path

import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from biped_sim.cli import main as biped_sim

LAYOUT = Path(__file__).resolve().parents[2] / "foxglove" / "biped_sim_layout.json"


@pytest.fixture(scope="module")
def walk_bag(tmp_path_factory):
    """{topic: [(t_ns, message decoded by rosbags)]}, {topic: (type, schema text, type hash, first CDR)}
    of a 1 s walk recorded by ``biped-sim simulate --scene walk --record`` (markers on)."""
    folder = tmp_path_factory.mktemp("walk")
    assert biped_sim(["simulate", "--scene", "walk", "--duration", "1", "--record", str(folder)]) == 0
    bag = next(p for p in folder.iterdir() if p.is_dir())
    store = get_typestore(Stores.ROS2_JAZZY)
    messages, channels, first_raw = {}, {}, {}
    with Reader(bag) as reader:
        for conn, t_ns, raw in reader.messages():
            first_raw.setdefault(conn.topic, raw)
            messages.setdefault(conn.topic, []).append((t_ns, store.deserialize_cdr(raw, conn.msgtype)))
        for conn in reader.connections:
            channels[conn.topic] = (conn.msgtype, conn.msgdef.data, conn.digest, first_raw.get(conn.topic))
    return messages, channels


def _panels():
    return json.loads(LAYOUT.read_text())["configById"]


def _resolve(msg, path: str):
    """The value at a Foxglove message path's field part (``wrench.force.y``, ``position[4]``), or
    raise AttributeError / IndexError where the message has no such field or element."""
    value = msg
    for name, index in re.findall(r"([A-Za-z_]\w*)(?:\[(\d+)\])?", path):
        value = getattr(value, name)
        if index:
            value = value[int(index)]
    return value


def test_every_topic_and_field_the_layout_names_is_in_a_recorded_bag(walk_bag):
    messages, channels = walk_bag
    first = {topic: msgs[0][1] for topic, msgs in messages.items()}
    panels = _panels()
    named = set(panels["3D!biped"]["topics"])
    named |= {c["topicPath"] for k, c in panels.items() if k.startswith("RawMessages!")}
    paths = [p["value"] for k, c in panels.items() if k.startswith("Plot!") for p in c["paths"]]
    named |= {p.split(".", 1)[0] for p in paths}
    assert named - set(channels) == set(), f"the layout names topics the bag does not have: {named - set(channels)}"
    assert named - set(first) == set(), "a named topic has no message in a 1 s walk"
    for path in paths:
        topic, field = path.split(".", 1)
        value = _resolve(first[topic], field)
        assert isinstance(value, float), (path, value)


def test_the_3d_panel_follows_a_frame_the_bags_tf_moves_with_the_hip(walk_bag):
    messages, channels = walk_bag
    panel = _panels()["3D!biped"]
    assert panel["followMode"] in ("follow-position", "follow-pose"), panel["followMode"]
    followed = panel["followTf"]
    assert channels["/tf"][0] == "tf2_msgs/msg/TFMessage"
    transforms = [(t_ns, tf) for t_ns, msg in messages["/tf"] for tf in msg.transforms]
    assert {tf.child_frame_id for _t, tf in transforms} == {followed}
    assert {tf.header.frame_id for _t, tf in transforms} == {"world"}         # the markers' frame
    assert [t for t, _tf in transforms] == [t for t, _m in messages["/markers"]]    # one with each drawing
    hip = {t: msg.position[:2] for t, msg in messages["/joint_states"]}
    for t_ns, tf in transforms:
        stamp = tf.header.stamp.sec * 1_000_000_000 + tf.header.stamp.nanosec
        assert stamp == t_ns
        tr, rot = tf.transform.translation, tf.transform.rotation
        assert (tr.x, tr.y, tr.z) == (hip[t_ns][0], 0.0, hip[t_ns][1])        # the hip, drawn in x-z
        assert (rot.x, rot.y, rot.z, rot.w) == (0.0, 0.0, 0.0, 1.0)
    assert transforms[-1][1].transform.translation.x > transforms[0][1].transform.translation.x + 0.5   # it walks


def test_the_tf_channel_carries_the_ros2_definition_and_hash_of_tfmessage(walk_bag):
    from rosidl_generator_type_description import calculate_type_hash

    from biped_sim.recording.bagformat import _share_dir
    messages, channels = walk_bag
    type_name, schema, digest, raw = channels["/tf"]
    # the schema alone decodes the messages (a reader without tf2_msgs, as Foxglove reads a bag)
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(schema, type_name))
    (tf,) = store.deserialize_cdr(raw, type_name).transforms
    expected = messages["/tf"][0][1].transforms[0].transform.translation
    assert tf.child_frame_id == "hip"
    assert (tf.transform.translation.x, tf.transform.translation.z) == (expected.x, expected.z)
    assert "MSG: geometry_msgs/TransformStamped" in schema and "MSG: std_msgs/Header" in schema
    # Jazzy's RIHS01 hash, computed from the type description as rosidl does
    stamped = json.loads((_share_dir("geometry_msgs") / "msg" / "TransformStamped.json").read_text())
    description = stamped["type_description_msg"]
    refs = sorted([description["type_description"]] + description["referenced_type_descriptions"],
                  key=lambda r: r["type_name"])
    tf = {"type_description": {"type_name": type_name, "fields": [
        {"name": "transforms", "default_value": "",
         "type": {"type_id": 145, "capacity": 0, "string_capacity": 0,        # unbounded sequence of a nested type
                  "nested_type_name": "geometry_msgs/msg/TransformStamped"}}]},
          "referenced_type_descriptions": refs}
    assert digest == calculate_type_hash(tf)


def test_the_torso_angle_has_a_plot_of_its_own():
    plots = {k: [p["value"] for p in c["paths"]] for k, c in _panels().items() if k.startswith("Plot!")}
    (torso,) = [paths for paths in plots.values() if "/joint_states.position[4]" in paths]
    assert torso == ["/joint_states.position[4]"]
