"""Bags written by the recorder, read back by independent readers (``rosbags``, ``mcap``/``mcap_ros2``).

Owns the recorder's contract tests (issue 4): the rosbag2 layout (metadata.yaml v9, one ros2-profile
MCAP with ros2msg schemas, cdr channels with QoS and type hashes, the rosbag2 record), counts equal
to what was published, monotonic times, decoded values equal to the published ones (decoded
messages are compared, never CDR bytes), bit-exact resim, the start-up errors, and bags left by
SIGTERM and SIGKILL (with ``biped-sim recover`` when the writer dies too).
"""
from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import pytest
import yaml

pytest.importorskip("rclpy")
from mcap.reader import make_reader  # noqa: E402
from mcap.records import Chunk  # noqa: E402
from mcap.stream_reader import StreamReader, breakup_chunk  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from rosbags.rosbag2 import Reader  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from biped_sim.config import parameters as P  # noqa: E402
from biped_sim.control.walking import WalkingController  # noqa: E402
from biped_sim.engine.model import BipedModel  # noqa: E402
from biped_sim.recording import frames  # noqa: E402
from biped_sim.recording.record_run import run_recorded  # noqa: E402
from biped_sim.recording.recorder import BagRecorder  # noqa: E402
from biped_sim.recording.resim import format_report, resim  # noqa: E402

BIN = Path(sys.executable).parent
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


class Tee:
    """A recorder that also keeps every (topic, message, t_ns) it is given: what was 'published'."""

    def __init__(self, rec):
        self.rec, self.sent, self.types = rec, [], {}

    def add_topic(self, topic, type_name, *a, **k):
        self.types[topic] = type_name
        self.rec.add_topic(topic, type_name, *a, **k)

    def _keep(self, topic, msg, t_ns):
        if isinstance(msg, bytes):   # pre-serialised (the commands, the state): what goes on the wire
            from rclpy.serialization import deserialize_message

            from biped_sim.recording.messages import message_class
            self.sent.append((topic, deserialize_message(msg, message_class(self.types[topic])), t_ns))
        else:
            self.sent.append((topic, msg, t_ns))

    def write(self, topic, msg, t_ns):
        self._keep(topic, msg, t_ns)
        self.rec.write(topic, msg, t_ns)

    def write_messages(self, t_ns, messages):
        for topic, data in messages:
            self._keep(topic, data, t_ns)
        self.rec.write_messages(t_ns, messages)


def walk_params(duration=1.0, **kw):
    ctrl = WalkingController(BipedModel())
    q0, dq0 = ctrl.initial_state()
    values = dict(scene="testwalk", time_mode="lockstep", duration=duration, control_period=0.002,
                  initial_q=[float(v) for v in q0], initial_dq=[float(v) for v in dq0])
    values.update(kw)
    return P.validate(values), ctrl


@pytest.fixture(scope="module")
def headless_bag(tmp_path_factory):
    params, ctrl = walk_params()
    path = tmp_path_factory.mktemp("bags") / "walk"
    tee = Tee(BagRecorder(path, parameters=params))
    sim = run_recorded(params, ctrl, tee)
    tee.rec.close()
    assert sim.status == "running" and sim.t == params["duration"] and sim.stats["impacts"] >= 2
    return path, tee.sent, params


# -- comparing decoded messages (any reader's objects) with the published rclpy ones -------------------
def stamp(m):
    return m.sec * 1_000_000_000 + m.nanosec


def plain(topic, m):
    """The values of a message as plain Python data (same for rclpy, rosbags and mcap_ros2 objects)."""
    if topic == "/joint_states":
        return (stamp(m.header.stamp), m.header.frame_id, list(m.name), [float(v) for v in m.position],
                [float(v) for v in m.velocity], [float(v) for v in m.effort])
    if topic == "/ground_reaction":
        f, tq = m.wrench.force, m.wrench.torque
        return stamp(m.header.stamp), m.header.frame_id, (f.x, f.y, f.z), (tq.x, tq.y, tq.z)
    if topic in ("/impact", "/diagnostics"):
        return stamp(m.header.stamp), [(s.name, s.message, s.hardware_id, [(kv.key, kv.value) for kv in s.values])
                                       for s in m.status]
    if topic == "/clock":
        return stamp(m.clock)
    if topic == "/hip_torque":
        return [float(v) for v in m.data]
    raise AssertionError(topic)


def by_topic(items):
    out = {}
    for topic, value, t_ns in items:
        out.setdefault(topic, []).append((t_ns, value))
    return out


def test_rosbags_reads_the_bag_with_the_published_counts_times_and_values(headless_bag):
    path, sent, params = headless_bag
    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap" and meta["ros_distro"] == "jazzy"
    assert meta["relative_file_paths"] == ["walk_0.mcap"] and meta["files"][0]["path"] == "walk_0.mcap"
    assert meta["message_count"] == len(sent) == meta["files"][0]["message_count"]
    assert meta["duration"]["nanoseconds"] == round(params["duration"] * 1e9)
    for tm in meta["topics_with_message_count"]:
        md = tm["topic_metadata"]
        assert md["serialization_format"] == "cdr" and md["type_description_hash"].startswith("RIHS01_")
        assert md["offered_qos_profiles"][0]["reliability"] == "reliable"
    published = by_topic([(t, plain(t, m), ns) for t, m, ns in sent])
    got = []
    with Reader(path) as reader:
        assert reader.message_count == len(sent)
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert counts == {t: len(v) for t, v in published.items()} | {
            t: 0 for t in counts if t not in published}
        for conn, t_ns, raw in reader.messages():
            got.append((conn.topic, plain(conn.topic, TYPESTORE.deserialize_cdr(raw, conn.msgtype)), t_ns))
    assert by_topic(got) == published
    for topic, items in by_topic(got).items():
        times = [t for t, _ in items]
        assert times == sorted(times), f"{topic}: times not monotonic"
    js = by_topic(got)["/joint_states"]
    assert [t for t, _ in js] == [v[0] for _, v in js]      # log time = header stamp = simulation time
    assert len(js) == round(params["duration"] / params["control_period"]) + 1


def test_mcap_reader_sees_a_ros2_bag_with_schemas_qos_hashes_and_records(headless_bag):
    path, sent, params = headless_bag
    with open(path / "walk_0.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary.statistics.message_count == len(sent) and summary.statistics.chunk_count >= 1
        assert all(ci.compression == "zstd" for ci in summary.chunk_indexes)
        schemas = {s.name: s for s in summary.schemas.values()}
        js = schemas["sensor_msgs/msg/JointState"]
        assert js.encoding == "ros2msg"
        text = js.data.decode()
        assert "float64[] position" in text and "\n" + "=" * 80 + "\nMSG: std_msgs/Header\n" in text
        assert "MSG: builtin_interfaces/Time" in text
        for ch in summary.channels.values():
            assert ch.message_encoding == "cdr"
            assert yaml.safe_load(ch.metadata["offered_qos_profiles"])[0]["history"] == "keep_last"
            assert ch.metadata["topic_type_hash"].startswith("RIHS01_")
        records = {m.name: m.metadata for m in reader.iter_metadata()}
        bag_meta = yaml.safe_load(records["rosbag2"]["serialized_metadata"])
        assert bag_meta["version"] == 9 and bag_meta["message_count"] == len(sent)
        assert json.loads(records["biped_sim"]["parameters"]) == params
        got = [(ch.topic, plain(ch.topic, dec), msg.log_time)
               for _s, ch, msg, dec in reader.iter_decoded_messages(log_time_order=False)]
    assert by_topic(got) == by_topic([(t, plain(t, m), ns) for t, m, ns in sent])


def test_resim_reproduces_a_lockstep_run_exactly_and_names_the_first_difference(headless_bag, tmp_path):
    path, sent, params = headless_bag
    rep = resim(path)
    assert rep["identical"] and rep["max_q"] == 0.0 and rep["max_dq"] == 0.0, format_report(rep)
    assert rep["states"] == sum(t == "/joint_states" for t, _, _ in sent)
    assert rep["commands"] == sum(t == "/hip_torque" for t, _, _ in sent) and len(rep["impacts_recorded"]) >= 2
    # a bag whose recorded settings are not the run's: resim finds the first state that differs
    run_params, ctrl = walk_params(0.2)
    told, _ = walk_params(0.2, **{"model.m_torso": 10.001})
    rec = BagRecorder(tmp_path / "other", parameters=told)
    run_recorded(run_params, ctrl, rec)
    rec.close()
    rep = resim(tmp_path / "other")
    assert not rep["identical"] and rep["first"]["topic"] == "/joint_states" and rep["first"]["index"] >= 1
    out = subprocess.run([str(BIN / "biped-sim"), "resim", str(tmp_path / "other")], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 1 and "DIFFERENT: first at /joint_states message #" in out.stdout


def test_unwritable_path_full_disk_and_used_directory_fail_at_start(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        if os.access(ro, os.W_OK):   # root ignores permissions: use a path that cannot be created
            bad = Path("/proc/biped_sim_bag")
        else:
            bad = ro / "bag"
        with pytest.raises(OSError, match="bag"):
            BagRecorder(bad)
    finally:
        ro.chmod(0o700)
    with pytest.raises(OSError, match="not enough free disk space"):
        BagRecorder(tmp_path / "full", min_free_bytes=1 << 62)
    used = tmp_path / "used"
    used.mkdir()
    (used / "x").write_text("x")
    with pytest.raises(ValueError, match="not an empty directory"):
        BagRecorder(used)


# -- signals -------------------------------------------------------------------------------------------
def start_recording(folder):
    # radau (scipy's implicit integrator, about 1000 periods a wall second here) keeps the bag small: the
    # compiled loop records some 40 000 messages a wall second, which the readers then decode for tens of s
    proc = subprocess.Popen([str(BIN / "biped-sim"), "simulate", "--scene", "walk", "--duration", "3600",
                             "--method", "radau", "--record", str(folder)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    line = proc.stdout.readline()
    assert line.startswith("recording to "), line
    bag = Path(line.split("recording to ", 1)[1].strip())
    mcap = bag / f"{bag.name}_0.mcap"
    end = time.monotonic() + 60
    while count_complete(mcap)[0] < 1300:     # some chunks on disk: 300 periods and more (4 messages each)
        assert proc.poll() is None and time.monotonic() < end, "the recording did not start"
        time.sleep(0.2)
    return proc, bag


def count_complete(mcap):
    """(messages, chunks) in the complete chunks of a (possibly cut) MCAP file, by the mcap stream reader."""
    n = chunks = 0
    try:
        with open(mcap, "rb") as f:
            for rec in StreamReader(f, emit_chunks=True).records:
                if isinstance(rec, Chunk):
                    chunks += 1
                    n += sum(1 for r in breakup_chunk(rec) if type(r).__name__ == "Message")
    except Exception:  # noqa: BLE001 - the cut tail
        pass
    return n, chunks


def read_all(bag):
    """Messages per topic by rosbags, checked against metadata.yaml; plus the same through mcap_ros2."""
    with Reader(bag) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        got = {}
        for conn, _t_ns, raw in reader.messages():
            TYPESTORE.deserialize_cdr(raw, conn.msgtype)
            got[conn.topic] = got.get(conn.topic, 0) + 1
    assert {t: n for t, n in counts.items() if n} == got
    with open(next(Path(bag).glob("*.mcap")), "rb") as f:
        n = sum(1 for _ in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages())
    assert n == sum(got.values())
    return got


def wait_for(path, timeout=30):
    end = time.monotonic() + timeout
    while not path.exists():
        assert time.monotonic() < end, f"{path} did not appear"
        time.sleep(0.1)


def writer_pid(pid):
    children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    assert children, "no writer process"
    return int(children[0])


def test_sigterm_and_sigkill_of_a_recording_process_leave_readable_bags(tmp_path):
    # SIGTERM: the run stops, the recorder closes the bag; the run was cut short: exit code 128 + SIGTERM
    proc, bag = start_recording(tmp_path)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(60) == 143
    got = read_all(bag)
    assert got["/joint_states"] >= 100 and got["/hip_torque"] == got["/joint_states"] - 1
    assert resim(bag)["identical"]
    # SIGKILL of the recording process: the writer process sees its input end and finalises the bag
    proc, bag = start_recording(tmp_path)
    on_disk, _ = count_complete(bag / f"{bag.name}_0.mcap")
    proc.kill()
    proc.wait(10)
    wait_for(bag / "metadata.yaml")
    got = read_all(bag)
    assert sum(got.values()) >= on_disk
    assert resim(bag)["identical"]


def test_the_python_frame_buffer_records_the_same_bag_as_the_compiled_one(tmp_path):
    """BIPED_SIM_PURE_PYTHON=1 (no compiled twin, e.g. no C compiler): the same run gives a bag with the
    same messages, decoded, in the same order, and it replays identically."""
    bags = {}
    for name, env in (("C", {}), ("Python", {"BIPED_SIM_PURE_PYTHON": "1"})):
        which = subprocess.run([sys.executable, "-c", "from biped_sim.recording import frames; "
                                "print(frames.IMPLEMENTATION)"], env=dict(os.environ, **env),
                               capture_output=True, text=True, timeout=60).stdout.strip()
        assert which == (name if frames.IMPLEMENTATION == "C" else "Python"), which
        out = subprocess.run([str(BIN / "biped-sim"), "simulate", "--duration", "0.3", "--control-period", "0.002",
                              "--record", str(tmp_path / name)], env=dict(os.environ, **env),
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stdout + out.stderr
        bags[name] = bag = next((tmp_path / name).iterdir())
        assert read_all(bag)["/joint_states"] == 151
        assert resim(bag)["identical"]
    decoded = {}
    for name, bag in bags.items():
        with Reader(bag) as reader:
            decoded[name] = [(conn.topic, t_ns, plain(conn.topic, TYPESTORE.deserialize_cdr(raw, conn.msgtype)))
                             for conn, t_ns, raw in reader.messages()]
    assert decoded["Python"] == decoded["C"]


def test_sigkill_of_process_and_writer_keeps_every_chunk_and_recover_repairs_the_bag(tmp_path):
    proc, bag = start_recording(tmp_path)
    writer = writer_pid(proc.pid)
    os.kill(writer, signal.SIGKILL)
    proc.kill()
    proc.wait(10)
    mcap = bag / f"{bag.name}_0.mcap"
    assert not (bag / "metadata.yaml").exists()
    kept, chunks = count_complete(mcap)
    assert kept >= 300 and chunks >= 1
    out = subprocess.run([str(BIN / "biped-sim"), "recover", str(bag)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    got = read_all(bag)
    assert sum(got.values()) == kept                     # every message of every complete chunk
    assert (bag / f"{mcap.name}.truncated").exists()
    rep = resim(bag)                                      # the parameters record survives too
    assert rep["identical"] and rep["states"] == got["/joint_states"]


def test_fast_cdr_decodes_like_the_message_it_encodes():
    from geometry_msgs.msg import WrenchStamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from biped_sim.recording import messages as M
    from biped_sim.recording.cdr import serializer
    q = [0.1, 1.0000001, 3.3, 3.2, -0.15]
    cases = [("sensor_msgs/msg/JointState", "/joint_states", M.joint_state_message(1.234567891, q, q, [1.5, -2.5], 1)),
             ("sensor_msgs/msg/JointState", "/joint_states", M.joint_state_message(0.0, q, q, [0, 0], 0)),
             ("sensor_msgs/msg/JointState", "/joint_states", JointState(name=["a"], position=[1.0])),
             ("geometry_msgs/msg/WrenchStamped", "/ground_reaction", M.wrench_message(3.5, [1.5, -2.5], 2)),
             ("geometry_msgs/msg/WrenchStamped", "/ground_reaction", WrenchStamped()),
             ("rosgraph_msgs/msg/Clock", "/clock", M.clock_msg(12.000000001)),
             ("std_msgs/msg/Float64MultiArray", "/hip_torque", M.torque_msg([3.0, -4.5])),
             ("std_msgs/msg/Float64MultiArray", "/hip_torque", Float64MultiArray(data=[]))]
    for typ, topic, msg in cases:
        decoded = TYPESTORE.deserialize_cdr(serializer(typ)(msg), typ)
        assert plain(topic, decoded) == plain(topic, msg), (typ, msg)


def test_a_command_read_from_its_cdr_is_the_command_rclpy_decodes():
    """The realtime node reads hip_torque's CDR itself (SimNode.take_commands): the values and labels of any
    Float64MultiArray rclpy serialises, tagged or not, with dims and a data offset."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

    from biped_sim.recording import messages as M
    from biped_sim.recording.cdr import read_float64_multi_array
    dims = [MultiArrayDimension(label="a", size=1, stride=1), MultiArrayDimension(label="bcd", size=3, stride=3)]
    cases = [M.torque_msg([3.0, -4.5]), M.torque_msg([1e300, -0.0], answers_ns=472_000_000), Float64MultiArray(),
             Float64MultiArray(data=[1.0, 2.0, float("nan")], layout=MultiArrayLayout(dim=dims, data_offset=5))]
    for msg in cases:
        values, labels = read_float64_multi_array(serialize_message(msg))
        assert [repr(v) for v in values] == [repr(v) for v in msg.data]
        assert labels == [d.label for d in msg.layout.dim]
    assert read_float64_multi_array(b"\x00\x00\x00\x00" + serialize_message(cases[0])[4:]) is None   # big-endian


def test_the_state_serializer_gives_the_messages_the_node_published_before():
    # sim_node publishes and records StateSerializer's bytes: they decode (rclpy) to the messages of
    # joint_state_message, wrench_message and clock_msg, and equal the recorder's CDR of those messages
    import numpy as np
    from rclpy.serialization import deserialize_message

    from biped_sim.recording import messages as M
    from biped_sim.recording.cdr import StateSerializer, serializer
    cdr = StateSerializer(M.JOINT_NAMES)
    q, dq = np.array([0.1, 1.0000001, 3.3, 3.2, -0.15]), np.array([1.0, -2.0, 0.5, 0.0, 7.25])
    force = np.array([-3.5, 196.2])
    for t in (0.0, 1.234567891, 12.000000001):
        sec, nanosec = divmod(M.to_ns(t), 1_000_000_000)
        for leg in (0, 1, 2):
            frame, u = M.foot_frame(leg), [1.5, -2.5]
            cases = [(cdr.joint_state(sec, nanosec, frame, q.tolist(), dq.tolist(), [0.0, 0.0, u[0], u[1], 0.0]),
                      M.joint_state_message(t, q, dq, u, leg), "sensor_msgs/msg/JointState"),
                     (cdr.wrench_stamped(sec, nanosec, frame, force), M.wrench_message(t, force, leg),
                      "geometry_msgs/msg/WrenchStamped"),
                     (cdr.clock(sec, nanosec), M.clock_msg(t), "rosgraph_msgs/msg/Clock")]
            for data, msg, typ in cases:
                assert deserialize_message(data, type(msg)) == msg, (typ, t, leg)
                assert data == serializer(typ)(msg), (typ, t, leg)


@pytest.mark.parametrize("compression", ["lz4", "none"])
def test_small_chunks_and_each_compression_give_a_bag_both_readers_index_alike(tmp_path, compression):
    # many chunks: the chunk and message indexes, the statistics and the summary offsets of our MCAP
    # writer (biped_sim.recording.mcapfile) are what mcap's indexed reader and rosbags rely on
    params, ctrl = walk_params(0.3)
    tee = Tee(BagRecorder(tmp_path / "bag", parameters=params, compression=compression, chunk_size=4096))
    run_recorded(params, ctrl, tee)
    tee.rec.close()
    published = by_topic([(t, plain(t, m), ns) for t, m, ns in tee.sent])
    with open(tmp_path / "bag" / "bag_0.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary.statistics.chunk_count == len(summary.chunk_indexes) > 10
        assert {ci.compression for ci in summary.chunk_indexes} == {"" if compression == "none" else compression}
        assert summary.statistics.message_count == len(tee.sent)
        assert dict(summary.statistics.channel_message_counts) == {
            cid: len(published[ch.topic]) for cid, ch in summary.channels.items() if ch.topic in published}
        got = [(ch.topic, plain(ch.topic, dec), msg.log_time)
               for _s, ch, msg, dec in reader.iter_decoded_messages(log_time_order=True)]
    assert by_topic(got) == published
    assert [t for _, _, t in got] == sorted(t for _, _, t in got)
    with open(tmp_path / "bag" / "bag_0.mcap", "rb") as f:      # every record and chunk CRC checks out
        n = sum(1 for rec in StreamReader(f, emit_chunks=False, validate_crcs=True).records
                if type(rec).__name__ == "Message")
    assert n == len(tee.sent)
    data = (tmp_path / "bag" / "bag_0.mcap").read_bytes()      # the footer's CRC of the summary section
    _op, _len, summary_start, _offsets, crc = struct.unpack("<BQQQI", data[-37:-8])
    assert crc == zlib.crc32(data[summary_start:-12])
    with Reader(tmp_path / "bag") as reader:
        got = [(c.topic, plain(c.topic, TYPESTORE.deserialize_cdr(raw, c.msgtype)), t)
               for c, t, raw in reader.messages()]
    assert by_topic(got) == published


def test_the_recording_package_uses_no_private_api_of_a_dependency():
    # issue 13: no name-mangled members (obj._Class__name) and no private modules of mcap or rosbags
    import re

    import biped_sim.recording
    folder = Path(biped_sim.recording.__file__).parent
    private = re.compile(r"\._[A-Za-z0-9]*__\w|\bfrom (mcap|rosbags)\S*\._|\bimport (mcap|rosbags)\S*\._")
    hits = [f"{p.name}:{i}: {line.strip()}" for p in sorted(folder.glob("*.py"))
            for i, line in enumerate(p.read_text().splitlines(), 1) if private.search(line)]
    assert not hits, "\n".join(hits)


def test_resim_of_a_bag_cut_between_an_impact_and_the_next_state_is_identical(tmp_path):
    # a killed recording can be cut (then recovered) anywhere, also after an impact's message and
    # before the state that follows it: resim compares the impacts up to the last state compared
    from biped_sim.recording import bagio
    params, ctrl = walk_params(1.0)
    rec = BagRecorder(tmp_path / "whole", parameters=params)
    try:
        run_recorded(params, ctrl, rec)
    finally:
        rec.close()
    whole = list(bagio.messages(tmp_path / "whole"))
    cut = next(i for i, m in enumerate(whole) if m[0] == "/impact") + 1   # the first impact, no state after it
    rec = BagRecorder(tmp_path / "cut", parameters=params)
    try:
        for topic, typ in bagio.channels(tmp_path / "whole").items():
            rec.add_topic(topic, typ)
        for topic, _typ, t_ns, data in whole[:cut]:
            rec.write(topic, data, t_ns)
    finally:
        rec.close()
    rep = resim(tmp_path / "cut")
    assert rep["identical"], format_report(rep)
    assert rep["states"] == sum(1 for m in whole[:cut] if m[0] == "/joint_states")


def test_the_packed_message_index_is_mcaps_record():
    # McapFileWriter packs each chunk's MessageIndex records itself (the writer process's hot path)
    from mcap.data_stream import RecordBuilder
    from mcap.records import MessageIndex

    from biped_sim.recording.mcapfile import _log_times, _message_index_bytes
    for records in ([], [(7, 0)], [(1_000_000_000 + i, 60 * i) for i in range(1000)], [(2**64 - 1, 2**63)]):
        builder = RecordBuilder()
        MessageIndex(channel_id=3, records=records).write(builder)
        pairs = bytearray(b"".join(struct.pack("<QQ", *record) for record in records))   # as the chunk keeps them
        assert _message_index_bytes(3, pairs) == builder.end()
        assert list(_log_times(pairs)) == [t for t, _ in records]


def test_a_killed_writer_is_told_to_on_error_once_and_raised_by_the_next_checked_write(tmp_path):
    # sim_node's hot path (append_period) does not check the recorder: the sender thread tells on_error
    from biped_sim.recording.cdr import float64_multi_array_data
    from biped_sim.recording.recorder import BagRecorder
    rec = BagRecorder(tmp_path / "bag", send_interval=0.01)
    rec.add_topic("/hip_torque", "std_msgs/msg/Float64MultiArray")
    heard = []
    rec.on_error = heard.append
    assert rec.wait_ready(30)
    data = float64_multi_array_data([1.0, -1.0])
    os.kill(rec.writer_pid, signal.SIGKILL)
    deadline = time.monotonic() + 30
    k = 0
    while not heard and time.monotonic() < deadline:
        rec.append_period(k, [("/hip_torque", data)])     # unchecked: goes on until the sender finds the pipe broken
        k += 1
        time.sleep(0.001)
    assert len(heard) == 1 and isinstance(heard[0], OSError) and "writer process is gone" in str(heard[0])
    with pytest.raises(OSError, match="writer process is gone"):
        rec.write_messages(k, [("/hip_torque", data)])     # the checked call raises it
    for _ in range(20):
        rec.append_period(k, [("/hip_torque", data)])
    time.sleep(0.1)
    assert len(heard) == 1                                  # told once
    with pytest.raises(OSError):
        rec.close()
    assert len(heard) == 1


def test_on_error_set_after_the_writer_failed_hears_of_it_at_once(tmp_path):
    # the recorder's threads run from its constructor on: an owner that sets on_error later is told then
    from biped_sim.recording.cdr import float64_multi_array_data
    from biped_sim.recording.recorder import BagRecorder
    rec = BagRecorder(tmp_path / "bag", send_interval=0.01)
    rec.add_topic("/hip_torque", "std_msgs/msg/Float64MultiArray")
    assert rec.wait_ready(30)
    data = float64_multi_array_data([1.0, -1.0])
    os.kill(rec.writer_pid, signal.SIGKILL)
    deadline = time.monotonic() + 30
    failed = None
    while failed is None and time.monotonic() < deadline:
        try:
            rec.write("/hip_torque", data, 0)
        except OSError as exc:
            failed = exc
        time.sleep(0.01)
    assert failed is not None and "writer process is gone" in str(failed)
    heard = []
    rec.on_error = heard.append
    assert len(heard) == 1 and "writer process is gone" in str(heard[0]) and rec.on_error == heard.append
    rec.on_error = None                 # clearing it tells nothing
    assert len(heard) == 1
    with pytest.raises(OSError):
        rec.close()
    rec.on_error = heard.append         # a closed recorder keeps no handler and tells nothing
    assert rec.on_error is None and len(heard) == 1


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="F_GETPIPE_SZ is Linux's")
def test_the_pipe_to_the_writer_holds_a_hand_over(tmp_path):
    # a fast run's hand-over (about 2 MB) goes through in few wake-ups of the sender thread
    import fcntl

    from biped_sim.recording.recorder import PIPE_BYTES, BagRecorder
    rec = BagRecorder(tmp_path / "bag")
    try:
        assert fcntl.fcntl(rec._proc.stdin.fileno(), fcntl.F_GETPIPE_SZ) == PIPE_BYTES
    finally:
        rec.close()
