"""Record a run to a rosbag2 bag directory holding one MCAP file, off the simulation's hot path.

Owns the on-disk format of a bag (what ``ros2 bag record -s mcap`` on Jazzy writes), so that
``ros2 bag info/play``, Foxglove and ``rosbags`` open it:

* ``<bag>/<bag name>_0.mcap``: profile ``ros2``; one ``ros2msg`` schema per type (the .msg text
  with its dependencies after ``=====...`` / ``MSG: pkg/Type`` lines, as rosbag2's
  message-definition cache builds it); one ``cdr`` channel per topic with the channel metadata
  ``offered_qos_profiles`` (YAML) and ``topic_type_hash`` (RIHS01); zstd-compressed chunks; the
  ``rosbag2`` metadata record (``serialized_metadata``) at the end, and a ``biped_sim`` metadata
  record (``parameters``: the run's checked parameters as JSON) at the start, so that ``resim``
  can rebuild the run.
* ``<bag>/metadata.yaml``: ``rosbag2_bagfile_information`` version 9 (rosbag2_storage/yaml.hpp).

Message times are simulation times in ns (log time = publish time = the stamp).

``write`` serialises the message (:mod:`biped_sim.recording.cdr`) and appends it to a buffer that a writer
process turns into chunks (see :class:`BagRecorder`); :func:`recover` turns a bag whose writer was
killed into a clean one.
"""
from __future__ import annotations

import atexit
import errno
import json
import os
import re
import shutil
import struct
import sys
import threading
import time
from datetime import datetime, timezone
from pathlib import Path

from biped_sim.recording.cdr import _HEAD as _CDR_HEAD

ROS_DISTRO = "jazzy"
METADATA_VERSION = 9
INFINITE = {"sec": 9223372036, "nsec": 854775807}   # rmw's infinite duration, as rosbag2 writes it
MIN_FREE_BYTES = 64 * 1024 * 1024
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
               "int32", "uint32", "int64", "uint64", "string", "wstring"}
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")


# -- type information: definitions and hashes from the installed interface packages ----------------
def _share_dir(package: str) -> Path:
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory(package))
    except Exception:  # noqa: BLE001 - fall back to the venv's share folder
        p = Path(sys.prefix) / "share" / package
        if p.is_dir():
            return p
        raise LookupError(f"interface package '{package}' is not installed (no share/{package} folder)")


def _split(type_name: str):
    parts = type_name.split("/")
    if len(parts) == 2:
        return parts[0], "msg", parts[1]
    if len(parts) == 3:
        return parts
    raise ValueError(f"message type must look like 'pkg/msg/Name', got {type_name!r}")


def message_definition(type_name: str) -> str:
    """The ``ros2msg`` schema text of a type: its .msg, then each dependency (depth first, sorted)."""
    seen = set()

    def text_of(name):
        pkg, ns, typ = _split(name)
        path = _share_dir(pkg) / ns / f"{typ}.msg"
        if not path.is_file():
            raise LookupError(f"no message definition {path} for {type_name}")
        text = path.read_text()
        deps = set()
        for m in _FIELD_TYPE.finditer(text):
            t = m.group(1)
            if t in _PRIMITIVES:
                continue
            deps.add(t if "/" in t else f"{pkg}/{t}")
        out = text
        for dep in sorted(deps):
            if dep not in seen:
                seen.add(dep)
                out += "\n" + "=" * 80 + "\nMSG: " + dep + "\n" + text_of(dep)
        return out
    return text_of(type_name)


def type_hash(type_name: str) -> str:
    """The RIHS01 type-description hash of a type (from its generated ``.json`` description)."""
    pkg, ns, typ = _split(type_name)
    path = _share_dir(pkg) / ns / f"{typ}.json"
    full = f"{pkg}/{ns}/{typ}"
    try:
        for entry in json.loads(path.read_text())["type_hashes"]:
            if entry["type_name"] == full:
                return entry["hash_string"]
    except (OSError, KeyError, ValueError):
        pass
    return ""


# -- QoS as rosbag2 writes it (metadata v9) ---------------------------------------------------------
def _duration(d):
    if d is None:
        return dict(INFINITE)
    if isinstance(d, dict):
        return {"sec": int(d["sec"]), "nsec": int(d["nsec"])}
    ns = int(getattr(d, "nanoseconds", d))
    if ns <= 0 or ns >= 2**63 - 1:  # unspecified / infinite
        return dict(INFINITE)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def qos_dict(qos=None) -> dict:
    """One offered QoS profile as a rosbag2 v9 dict; ``qos`` is None, a dict or an rclpy QoSProfile."""
    out = {"history": "keep_last", "depth": 10, "reliability": "reliable", "durability": "volatile",
           "deadline": dict(INFINITE), "lifespan": dict(INFINITE), "liveliness": "automatic",
           "liveliness_lease_duration": dict(INFINITE), "avoid_ros_namespace_conventions": False}
    if qos is None:
        return out
    if isinstance(qos, dict):
        out.update(qos)
        return out

    def name(v):
        return getattr(v, "name", str(v)).lower()
    out.update(history=name(qos.history), depth=int(qos.depth), reliability=name(qos.reliability),
               durability=name(qos.durability), liveliness=name(qos.liveliness),
               deadline=_duration(qos.deadline), lifespan=_duration(qos.lifespan),
               liveliness_lease_duration=_duration(qos.liveliness_lease_duration),
               avoid_ros_namespace_conventions=bool(qos.avoid_ros_namespace_conventions))
    return out


def _yaml(obj) -> str:
    import yaml
    return yaml.safe_dump(obj, default_flow_style=False, sort_keys=False)


def bag_metadata(mcap_name, topics, start_ns, end_ns, custom_data=None) -> dict:
    """The ``rosbag2_bagfile_information`` mapping (version 9).

    ``topics``: list of dicts with name, type, qos (list of dicts), hash, count.
    """
    count = sum(t["count"] for t in topics)
    start = int(start_ns) if count else 0
    duration = max(0, int(end_ns) - int(start_ns)) if count else 0
    return {
        "version": METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": count,
        "topics_with_message_count": [
            {"topic_metadata": {"name": t["name"], "type": t["type"], "serialization_format": "cdr",
                                "offered_qos_profiles": t["qos"], "type_description_hash": t["hash"]},
             "message_count": t["count"]} for t in topics],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [mcap_name],
        "files": [{"path": mcap_name, "starting_time": {"nanoseconds_since_epoch": start},
                   "duration": {"nanoseconds": duration}, "message_count": count}],
        "custom_data": custom_data or None,
        "ros_distro": ROS_DISTRO,
    }


def write_metadata_yaml(bag_dir: Path, info: dict):
    tmp = Path(bag_dir) / "metadata.yaml.tmp"
    tmp.write_text(_yaml({"rosbag2_bagfile_information": info}))
    os.replace(tmp, Path(bag_dir) / "metadata.yaml")


def default_bag_path(bag_dir="bags", scene="custom", now=None) -> Path:
    """``<bag_dir>/<scene>-<UTC time>`` (e.g. bags/walk-20261122T024500Z)."""
    now = now or datetime.now(timezone.utc)
    return Path(bag_dir) / f"{scene}-{now.strftime('%Y%m%dT%H%M%S')}{now.microsecond // 1000:03d}Z"


class BagRecorder:
    """Records messages to a rosbag2/MCAP bag directory; ``write`` is cheap, another process does the IO.

    ``BagRecorder(path, parameters=dict)`` creates the directory (it must not exist or be empty)
    and raises ``OSError``/``ValueError`` with a clear message at once if the path is unwritable or
    the disk has less than ``min_free_bytes`` free. ``add_topic`` then ``write(topic, msg, t_ns)``;
    ``close()`` (idempotent; also run at interpreter exit) finalises the MCAP and writes
    metadata.yaml.

    ``write`` serialises the message (:mod:`biped_sim.recording.cdr` for the hot types, else rclpy's
    serialiser) and appends it to a buffer; a sender
    thread hands the buffer every ``send_interval`` s to a writer process (``python -m
    biped_sim.recording.recorder --writer``), which builds and compresses the chunks, so neither the
    chunking nor the compression takes the simulation's interpreter lock. The writer process runs in
    its own session: when the recording process dies (even by SIGKILL) the writer sees the end of
    its input and finalises the bag. It also closes a chunk at least every ``flush_interval`` s, so
    if both die, everything older survives (see :func:`recover`). A failure of the writer (e.g.
    the disk fills up) is raised by the next ``write`` or by ``close``, never swallowed.
    """

    def __init__(self, path, parameters=None, compression="zstd", chunk_size=1024 * 1024,
                 flush_interval=0.5, send_interval=0.1, min_free_bytes=MIN_FREE_BYTES):
        import subprocess
        self.path = Path(path)
        if compression not in ("zstd", "lz4", "none"):
            raise ValueError(f"compression must be zstd, lz4 or none, got {compression!r}")
        if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
            raise ValueError(f"bag path {self.path} exists and is not an empty directory; "
                             "choose a new bag path")
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OSError(exc.errno, f"cannot create the bag directory {self.path}: {exc.strerror}") from None
        if not os.access(self.path, os.W_OK):
            raise OSError(errno.EACCES, f"the bag directory {self.path} is not writable")
        free = shutil.disk_usage(self.path).free
        if free < min_free_bytes:
            raise OSError(errno.ENOSPC, f"not enough free disk space for the bag {self.path}: "
                                        f"{free / 1e6:.1f} MB free, at least {min_free_bytes / 1e6:.0f} MB needed")
        self.mcap_name = f"{self.path.name}_0.mcap"
        try:
            with open(self.path / self.mcap_name, "wb"):
                pass
        except OSError as exc:
            raise OSError(exc.errno, f"cannot write the bag file {self.path / self.mcap_name}: {exc.strerror}") from None
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "biped_sim.recording.recorder", "--writer", str(self.path), self.mcap_name, compression,
             str(int(chunk_size)), repr(float(flush_interval))],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, start_new_session=True, bufsize=0)
        self._topics = {}          # name -> [id, type, seq, serialiser]
        self._state_plans = {}     # write_state's packers, per set of topics and shape
        self._buf = bytearray()
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._error = None
        self._status = None
        self._closed = False
        self._closing = False
        self.send_interval = float(send_interval)
        if parameters is not None:
            from biped_sim import __version__
            self._frame(b"P", json.dumps({
                "parameters": json.dumps(dict(parameters), sort_keys=True), "version": str(__version__),
                "created": datetime.now(timezone.utc).isoformat()}).encode())
        self._sender = threading.Thread(target=self._send_loop, name=f"bag-sender {self.path.name}", daemon=True)
        self._reader = threading.Thread(target=self._read_loop, name=f"bag-status {self.path.name}", daemon=True)
        self._sender.start()
        self._reader.start()
        atexit.register(self.close)

    # -- the caller's side (the simulation thread) --------------------------------------------
    def _frame(self, kind: bytes, payload: bytes):
        with self._lock:
            self._buf += _FRAME.pack(kind, len(payload))
            self._buf += payload

    def add_topic(self, topic: str, type_name: str, qos=None):
        """Declare a topic (full name, e.g. ``/joint_states``) of ``type_name`` (``pkg/msg/Name``)."""
        self._check()
        if topic in self._topics:
            return
        from rclpy.serialization import serialize_message

        from biped_sim.recording.cdr import serializer
        from biped_sim.recording.messages import message_class
        serialize_message(message_class(type_name)())   # load the type support now, not in the run
        info = dict(name=topic, type=type_name, qos=[qos_dict(qos)], hash=type_hash(type_name),
                    definition=message_definition(type_name), id=len(self._topics) + 1)
        self._topics[topic] = [info["id"], type_name, 0, serializer(type_name)]
        self._frame(b"T", json.dumps(info).encode())

    def write(self, topic: str, msg, t_ns: int):
        """Queue one message (an rclpy message object, or its CDR bytes) at simulation time t_ns (int)."""
        self._hand_over(self._message_frame(topic, msg, t_ns))

    def write_state(self, t_ns: int, topics, frame_id: str, names, position, velocity, effort, force=None):
        """The state messages of one control period, packed in one call: ``topics`` = (joint_states,
        ground_reaction, clock) topic names, None for those not written (ground_reaction also when
        ``force`` is None). The bytes are those of the node's JointState(header
        (stamp t_ns, frame_id), names, position, velocity, effort), WrenchStamped(force; zero
        torque) and Clock, as three ``write`` calls would queue them; one pack instead of three
        serialisations keeps recording near 10 us a period (bench_record)."""
        js, grf, clk = topics
        if force is None:
            grf = None
        key = (js, grf, clk, frame_id, len(position))
        plan = self._state_plans.get(key)
        if plan is None:
            plan = self._state_plans[key] = self._state_plan(key, names)
        pack, entries = plan
        if self._error is not None or self._closed:
            self._check()
        sec, nsec = divmod(t_ns, 1_000_000_000)
        values = []
        for e, (kind, length, const) in entries:
            e[2] += 1
            values += (b"M", length, e[0], t_ns, e[2], _CDR_HEAD, sec, nsec)
            if kind == "js":
                n = len(position)
                values += (const, n, *position, n, *velocity, n, *effort)
            elif kind == "grf":
                values += (const, force[0], force[1], 0.0, 0.0, 0.0, 0.0)
        self._hand_over(pack(*values))

    def _state_plan(self, key, names):
        from biped_sim.recording.cdr import CLOCK_FORMAT, joint_state_format, wrench_stamped_format
        js, grf, clk, frame_id, n = key
        fmt, entries = "<", []
        for topic, kind in ((js, "js"), (grf, "grf"), (clk, "clock")):
            if topic is None:
                continue
            entry = self._topics.get(topic)
            if entry is None:
                raise ValueError(f"unknown topic {topic!r}: call add_topic first (topics: {sorted(self._topics)})")
            if kind == "js":
                part, const = joint_state_format(frame_id, names, n)
            elif kind == "grf":
                part, const = wrench_stamped_format(frame_id)
            else:
                part, const = CLOCK_FORMAT, None
            # the frame's length field counts the message header (_MSG) and the CDR payload
            fmt += _MSG_FRAME.format.lstrip("<") + part
            entries.append((entry, (kind, _MSG.size + struct.calcsize("<" + part), const)))
        return struct.Struct(fmt).pack, entries

    def _message_frame(self, topic, msg, t_ns):
        # the simulation thread pays for this at every message: one test for all the checks
        entry = self._topics.get(topic)
        if entry is None or self._error is not None or self._closed:
            self._check()
            raise ValueError(f"unknown topic {topic!r}: call add_topic first (topics: {sorted(self._topics)})")
        data = msg if type(msg) is bytes else (
            bytes(msg) if isinstance(msg, (bytearray, memoryview)) else entry[3](msg))
        entry[2] = seq = entry[2] + 1
        return _MSG_FRAME.pack(b"M", _MSG.size + len(data), entry[0], t_ns, seq) + data

    def _hand_over(self, frames):
        with self._lock:
            self._buf += frames
            if len(self._buf) > 1 << 20 and not self._wake.is_set():   # set once, not at every write
                self._wake.set()

    def close(self):
        """Finalise the MCAP (summary, rosbag2 metadata record) and write metadata.yaml. Idempotent.

        Raises OSError if the writer failed at any point of the run.
        """
        with self._lock:
            if self._closed:
                return
            self._closed = True
        try:
            atexit.unregister(self.close)
        except Exception:  # noqa: BLE001
            pass
        self._frame(b"C", b"")
        self._closing = True
        self._wake.set()
        self._sender.join()
        try:
            self._proc.wait(timeout=120)
        except Exception:  # noqa: BLE001
            self._proc.kill()
            self._error = self._error or "the bag writer did not finish within 120 s"
        self._reader.join(timeout=5)
        if self._error is None and self._proc.returncode != 0:
            self._error = f"the bag writer exited with code {self._proc.returncode}"
        if self._error is not None:
            raise OSError(errno.EIO, f"recording to {self.path} failed: {self._error}")

    @property
    def message_counts(self):
        """Messages written per topic (after ``close``: as counted by the writer)."""
        if self._status and "counts" in self._status:
            return dict(self._status["counts"])
        return {n: e[2] for n, e in self._topics.items()}

    def _check(self):
        if self._error is not None:
            raise OSError(errno.EIO, f"recording to {self.path} failed: {self._error}")
        if self._closed:
            raise ValueError(f"the recorder of {self.path} is closed")

    # -- threads: hand the buffer to the writer process, read its status -------------------------
    def _send_loop(self):
        out = self._proc.stdin
        while True:
            self._wake.wait(self.send_interval)
            self._wake.clear()
            with self._lock:
                data, self._buf = self._buf, bytearray()
            try:
                if data:
                    out.write(data)
            except (BrokenPipeError, OSError) as exc:
                self._error = self._error or f"the bag writer process is gone ({exc})"
            if self._closing:
                with self._lock:
                    rest, self._buf = self._buf, bytearray()
                try:
                    if rest:
                        out.write(rest)
                    out.close()
                except OSError:
                    pass
                return

    def _read_loop(self):
        for line in self._proc.stdout:
            try:
                status = json.loads(line)
            except ValueError:
                continue
            if status.get("error"):
                self._error = self._error or status["error"]
            if status.get("done"):
                self._status = status


_FRAME = struct.Struct("<cI")      # kind, payload length
_MSG = struct.Struct("<HqI")       # channel (recorder's topic id), time ns, sequence
_MSG_FRAME = struct.Struct("<cIHqI")


_MCAP_MESSAGE = struct.Struct("<BQHIQQ")   # opcode 0x05, record length, channel, sequence, log/publish time


def _fast_add(w, chunk_size):
    """``add(channel, t_ns, seq, data)``: ``Writer.add_message`` of mcap 1.6 in one ``struct.pack``.

    It does what ``Writer.add_message`` and ``ChunkBuilder.add_message`` do (statistics, chunk time
    range, message index, the Message record, closing a full chunk), a few times faster; if the
    mcap writer's internals are not the expected ones it falls back to ``add_message``.
    """
    from mcap.records import MessageIndex
    try:
        stats = w._Writer__statistics
        cb = w._Writer__chunk_builder
        finalize = w._Writer__finalize_chunk
        buf = cb.record_writer._buffer
        cb.message_indices, cb.num_messages, stats.channel_message_counts  # noqa: B018 - they exist
    except AttributeError:
        return lambda cid, t, seq, data: w.add_message(cid, log_time=t, data=data, publish_time=t, sequence=seq)
    pack = _MCAP_MESSAGE.pack

    def add(cid, t, seq, data):
        if stats.message_count == 0 or t < stats.message_start_time:
            stats.message_start_time = t
        if t > stats.message_end_time:
            stats.message_end_time = t
        stats.channel_message_counts[cid] += 1
        stats.message_count += 1
        if cb.num_messages == 0 or t < cb.message_start_time:
            cb.message_start_time = t
        if t > cb.message_end_time:
            cb.message_end_time = t
        idx = cb.message_indices.get(cid)
        if idx is None:
            idx = cb.message_indices[cid] = MessageIndex(channel_id=cid, records=[])
        b = cb.record_writer._buffer      # replaced by a new one when a chunk ends
        idx.records.append((t, b.tell()))
        cb.num_messages += 1
        b.write(pack(5, 22 + len(data), cid, seq, t, t))
        b.write(data)
        if b.tell() > chunk_size:
            finalize()
    return add


def _writer_main(path, mcap_name, compression, chunk_size, flush_interval):
    """The writer process: frames on stdin -> the MCAP file; status lines (JSON) on stdout."""
    import signal
    from mcap.writer import CompressionType, Writer
    signal.signal(signal.SIGINT, signal.SIG_IGN)     # the recording process decides when to stop
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        os.nice(10)       # on a busy machine the simulation gets the CPU first; the writer catches up
    except OSError:
        pass
    path = Path(path)
    inp = sys.stdin.buffer
    status = sys.stdout

    def report(**kw):
        try:
            status.write(json.dumps(kw) + "\n")
            status.flush()
        except OSError:
            pass
    ctype = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[compression]
    f = open(path / mcap_name, "wb")
    w = Writer(f, chunk_size=chunk_size, compression=ctype)
    w.start(profile="ros2", library="biped_sim recorder (mcap python)")
    add = _fast_add(w, chunk_size)
    topics, channels, schemas = {}, {}, {}
    start = end = None
    error = None
    dirty = False
    last_flush = time.monotonic()
    frame, msg = _FRAME, _MSG
    while True:
        head = inp.read(frame.size)
        if len(head) < frame.size:
            break                     # end of input: the recording process closed or died
        kind, n = frame.unpack(head)
        payload = inp.read(n) if n else b""
        if len(payload) < n:
            break
        if kind == b"C":
            break
        if error is not None:
            continue
        try:
            if kind == b"M":
                cid, t_ns, seq = msg.unpack_from(payload)
                add(channels[cid], t_ns, seq, payload[msg.size:])
                topics[cid]["count"] += 1
                if start is None or t_ns < start:
                    start = t_ns
                if end is None or t_ns > end:
                    end = t_ns
                dirty = True
            elif kind == b"T":
                info = json.loads(payload)
                if info["type"] not in schemas:
                    schemas[info["type"]] = w.register_schema(info["type"], "ros2msg", info["definition"].encode())
                channels[info["id"]] = w.register_channel(
                    info["name"], "cdr", schemas[info["type"]],
                    {"offered_qos_profiles": _yaml(info["qos"]).strip(), "topic_type_hash": info["hash"]})
                topics[info["id"]] = dict(name=info["name"], type=info["type"], qos=info["qos"], hash=info["hash"],
                                          count=0)
            elif kind == b"P":
                w.add_metadata("biped_sim", json.loads(payload))
                f.flush()
            now = time.monotonic()
            if dirty and now - last_flush >= flush_interval:
                w.flush()                 # close the chunk: everything so far survives a SIGKILL
                dirty = False
                last_flush = now
        except Exception as exc:  # noqa: BLE001 - e.g. the disk is full
            error = f"{type(exc).__name__}: {exc}"
            report(error=error)
    info = bag_metadata(mcap_name, list(topics.values()), start or 0, end or 0)
    try:
        if error is None:
            w.add_metadata("rosbag2", {"serialized_metadata": _yaml(info), "ros_distro": ROS_DISTRO})
            w.finish()
        f.flush()
        os.fsync(f.fileno())
        f.close()
        write_metadata_yaml(path, info)
    except Exception as exc:  # noqa: BLE001
        error = error or f"{type(exc).__name__}: {exc}"
        report(error=error)
    report(done=True, counts={t["name"]: t["count"] for t in topics.values()}, error=error)
    return 1 if error else 0


# -- recovery of a bag whose writer was killed ---------------------------------------------------------
def recover(bag_dir, compression="zstd") -> dict:
    """Rewrite a bag's MCAP cut short (SIGKILL, power loss) into a clean one; regenerate metadata.yaml.

    Reads records in file order until the first incomplete one: every chunk written before the
    kill is kept. The original file is kept as ``<name>.mcap.truncated``. Returns a summary dict.
    """
    from mcap.records import Channel, Chunk, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader, breakup_chunk
    from mcap.writer import CompressionType, Writer
    bag_dir = Path(bag_dir)
    files = sorted(bag_dir.glob("*.mcap"))
    if not files:
        raise ValueError(f"no .mcap file in {bag_dir}")
    src = files[0]
    schemas, channels, metadata, messages = {}, {}, [], []
    problem = ""

    def take(rec):
        if isinstance(rec, Schema):
            schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            channels[rec.id] = rec
        elif isinstance(rec, Message):
            messages.append(rec)

    with open(src, "rb") as f:
        reader = StreamReader(f, emit_chunks=True, validate_crcs=True)
        try:
            for rec in reader.records:
                if isinstance(rec, Chunk):
                    for r in breakup_chunk(rec, validate_crc=True):
                        take(r)
                elif isinstance(rec, Metadata):
                    if rec.name != "rosbag2":
                        metadata.append(rec)
                else:
                    take(rec)
        except Exception as exc:  # noqa: BLE001 - the truncated tail
            problem = f"{type(exc).__name__}: {exc}" if str(exc) else f"{type(exc).__name__} (cut at {f.tell()} bytes)"
    kept = src.with_name(src.name + ".truncated")
    os.replace(src, kept)
    ctype = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}[compression]
    topics = {}
    start = end = None
    with open(src, "wb") as out:
        w = Writer(out, compression=ctype)
        w.start(profile="ros2", library="biped_sim recover; mcap python")
        for m in metadata:
            w.add_metadata(m.name, m.metadata)
        sid, cid = {}, {}
        for s in schemas.values():
            sid[s.id] = w.register_schema(s.name, s.encoding, s.data)
        for c in channels.values():
            cid[c.id] = w.register_channel(c.topic, c.message_encoding, sid.get(c.schema_id, 0), dict(c.metadata))
            import yaml
            topics[c.id] = dict(name=c.topic, type=schemas[c.schema_id].name if c.schema_id in schemas else "",
                                qos=yaml.safe_load(c.metadata.get("offered_qos_profiles", "")) or [],
                                hash=c.metadata.get("topic_type_hash", ""), count=0)
        for m in messages:
            if m.channel_id not in cid:
                continue
            w.add_message(cid[m.channel_id], log_time=m.log_time, data=m.data, publish_time=m.publish_time,
                          sequence=m.sequence)
            topics[m.channel_id]["count"] += 1
            start = m.log_time if start is None else min(start, m.log_time)
            end = m.log_time if end is None else max(end, m.log_time)
        info = bag_metadata(src.name, list(topics.values()), start or 0, end or 0)
        w.add_metadata("rosbag2", {"serialized_metadata": _yaml(info), "ros_distro": ROS_DISTRO})
        w.finish()
    write_metadata_yaml(bag_dir, info)
    return dict(path=str(src), kept=str(kept), messages=len(messages), topics={t["name"]: t["count"] for t in topics.values()},
                end=problem)


if __name__ == "__main__":
    if len(sys.argv) == 7 and sys.argv[1] == "--writer":
        sys.exit(_writer_main(sys.argv[2], sys.argv[3], sys.argv[4], int(sys.argv[5]), float(sys.argv[6])))
    print("usage: python -m biped_sim.recording.recorder --writer BAG_DIR MCAP_NAME COMPRESSION CHUNK_SIZE FLUSH_INTERVAL "
          "(started by BagRecorder)", file=sys.stderr)
    sys.exit(2)
