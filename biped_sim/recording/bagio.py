"""Reading our bags back: the MCAP file of a bag directory, its run parameters, its messages.

Owns the read side used by ``replay``, ``resim``, ``inspect`` and ``recover`` (the tests use the
independent readers, ``rosbags`` and ``mcap_ros2``). Messages come in log-time order (ties in file
order) as ``(topic, type, log_time_ns, cdr_bytes)``; :func:`decode` turns the bytes into the
rclpy message. A bag whose writer was killed (no summary) is read up to its last whole chunk.

Also owns what a tool checks before it reads: that the file is MCAP at all (:func:`mcap_path`),
whether it is complete or cut short (:func:`cut_short`), and whether a bag writer holds it right
now (:func:`being_written`: the writer process holds an advisory ``flock`` on the file while it
writes; the kernel releases it when the writer ends, also when it is killed).
"""
from __future__ import annotations

import fcntl
import json
from pathlib import Path

MAGIC = b"\x89MCAP0\r\n"     # the first and the last 8 bytes of an MCAP file (the MCAP specification)


def mcap_path(bag) -> Path:
    """The .mcap of a bag directory (or the file itself); ValueError if there is none or it is not MCAP."""
    p = Path(bag)
    if not p.is_file():
        if not p.is_dir():
            raise ValueError(f"no bag at {p}: give a bag directory (with metadata.yaml and a .mcap) or a .mcap file")
        files = sorted(p.glob("*.mcap"))
        if not files:
            raise ValueError(f"{p} holds no .mcap file: give a bag directory or a .mcap file")
        p = files[0]
    with open(p, "rb") as f:
        head = f.read(len(MAGIC))
    if head != MAGIC:
        what = "it is empty" if not head else (
            f"it is {len(head)} bytes long" if len(head) < len(MAGIC) else "it does not start with the MCAP magic")
        raise ValueError(f"{p} is not an MCAP file ({what}): give a bag recorded by biped_sim (sim_node, "
                         "biped-sim simulate --record) or by 'ros2 bag record -s mcap'")
    return p


def cut_short(bag) -> str:
    """Why the MCAP of ``bag`` is incomplete ('' if it is whole): a writer killed before it wrote the
    summary and the closing magic (SIGKILL of the writer, power loss), or one writing it right now."""
    from mcap.reader import make_reader
    p = mcap_path(bag)
    size = p.stat().st_size
    with open(p, "rb") as f:
        if size >= 2 * len(MAGIC):
            f.seek(size - len(MAGIC))
            if f.read(len(MAGIC)) == MAGIC:
                f.seek(0)
                try:
                    make_reader(f).get_summary()
                    return ""
                except Exception:  # noqa: BLE001 - a damaged summary: read it as cut short
                    pass
    return f"cut short at {size} bytes (no summary: its writer did not finish it)"


def being_written(bag) -> bool:
    """Whether a bag writer process holds the MCAP of ``bag`` right now (its advisory lock)."""
    with open(mcap_path(bag), "rb") as f:
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        fcntl.flock(f.fileno(), fcntl.LOCK_UN)
    return False


def lock_for_writing(f) -> None:
    """Hold an exclusive advisory lock on the open file ``f`` until it is closed (the bag writer:
    ``recover`` refuses a file in use). The kernel releases it when the process ends, even by SIGKILL."""
    fcntl.flock(f.fileno(), fcntl.LOCK_EX)


def read_metadata(bag) -> dict:
    """{record name: {key: value}} of the MCAP metadata records (``biped_sim``, ``rosbag2``)."""
    from mcap.reader import make_reader
    out = {}
    with open(mcap_path(bag), "rb") as f:
        try:
            for m in make_reader(f).iter_metadata():
                out[m.name] = dict(m.metadata)
        except Exception:  # noqa: BLE001 - a truncated file: scan it
            f.seek(0)
            out = _scan_metadata(f)
    return out


def _scan_metadata(f):
    from mcap.records import Metadata
    from mcap.stream_reader import StreamReader
    out = {}
    try:
        for rec in StreamReader(f, emit_chunks=True).records:
            if isinstance(rec, Metadata):
                out[rec.name] = dict(rec.metadata)
    except Exception:  # noqa: BLE001
        pass
    return out


def run_parameters(bag) -> dict:
    """The run's checked parameters (the ``biped_sim`` metadata record), or ValueError."""
    meta = read_metadata(bag).get("biped_sim")
    if not meta or "parameters" not in meta:
        cut = cut_short(bag)
        if cut and not any(True for _ in messages(bag)):
            raise ValueError(f"{bag} is {cut} and holds no complete record after its header: nothing to read")
        raise ValueError(f"{bag} has no biped_sim parameters record: it was not recorded by biped_sim")
    return json.loads(meta["parameters"])


def _reader_and_summary(f):
    """An MCAP reader of ``f`` and its summary, or None for a file cut short (no summary section)."""
    from mcap.reader import make_reader
    r = make_reader(f)
    try:
        return r, r.get_summary()
    except Exception:  # noqa: BLE001  (a truncated file raises from deep inside the reader)
        return r, None


def channels(bag) -> dict:
    """{topic: type} of the bag."""
    with open(mcap_path(bag), "rb") as f:
        _r, s = _reader_and_summary(f)
        if s is not None:
            return {c.topic: s.schemas[c.schema_id].name for c in s.channels.values()}
    out = {}
    for topic, typ, _t, _d in messages(bag):
        out.setdefault(topic, typ)
    return out


def messages(bag, topics=None, start_ns=None, log_time_order=True):
    """Yield (topic, type, log_time_ns, data) in log-time order; a truncated file up to its last chunk.
    ``log_time_order=False``: a whole file in the order of its chunks and records, one chunk in memory
    at a time (half the time: no merge of the chunks' messages by time; a truncated file is read in
    log-time order still)."""
    with open(mcap_path(bag), "rb") as f:
        r, summary = _reader_and_summary(f)
        if summary is None:
            yield from _scan_messages(f, topics, start_ns)
            return
        if not log_time_order and summary.chunk_indexes:
            yield from _file_order_messages(f, summary, topics, start_ns)
            return
        for schema, channel, msg in r.iter_messages(topics=topics, start_time=start_ns, log_time_order=True):
            yield channel.topic, schema.name, msg.log_time, msg.data


def _file_order_messages(f, summary, topics, start_ns):
    """The messages of a whole file in the order of its chunks (by offset) and of the records in each,
    one chunk decompressed at a time (mcap's reader in insert order decompresses every chunk before it
    yields a message)."""
    from mcap.data_stream import ReadDataStream
    from mcap.records import Chunk, Message
    from mcap.stream_reader import breakup_chunk
    channels = {cid: (c.topic, summary.schemas[c.schema_id].name if c.schema_id else "")
                for cid, c in summary.channels.items()}
    for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        f.seek(index.chunk_start_offset + 1 + 8)       # past the record's opcode and length
        for rec in breakup_chunk(Chunk.read(ReadDataStream(f)), validate_crc=False):
            if isinstance(rec, Message):
                topic, type_name = channels[rec.channel_id]
                if (topics is None or topic in topics) and (start_ns is None or rec.log_time >= start_ns):
                    yield topic, type_name, rec.log_time, rec.data


def _scan_messages(f, topics, start_ns):
    """The messages of a file without a summary, in log-time order, holding about one chunk at a time:
    a message is yielded once a chunk that starts after it has been read (chunks start in time order
    in a recorded bag; ties keep the file order). Memory does not grow with the file."""
    import heapq

    from mcap.records import Channel, Chunk, Message, Schema
    from mcap.stream_reader import StreamReader, breakup_chunk
    f.seek(0)
    schemas, chans, pending = {}, {}, []    # pending: a heap of (log time, file order, message)
    order = 0
    records = iter(StreamReader(f, emit_chunks=True).records)
    while True:
        try:
            rec = next(records)
        except StopIteration:
            break
        except Exception:  # noqa: BLE001 - the truncated tail
            break
        if isinstance(rec, Chunk):
            while pending and pending[0][0] < rec.message_start_time:
                yield heapq.heappop(pending)[2]
            recs = breakup_chunk(rec)
        else:
            recs = [rec]
        for r in recs:
            if isinstance(r, Schema):
                schemas[r.id] = r
            elif isinstance(r, Channel):
                chans[r.id] = r
            elif isinstance(r, Message):
                c = chans[r.channel_id]
                if (topics is None or c.topic in topics) and (start_ns is None or r.log_time >= start_ns):
                    heapq.heappush(pending, (r.log_time, order, (c.topic, schemas[c.schema_id].name, r.log_time,
                                                                 r.data)))
                    order += 1
    while pending:
        yield heapq.heappop(pending)[2]


_classes = {}


def decode(type_name, data):
    """CDR bytes -> the rclpy message."""
    from rclpy.serialization import deserialize_message
    cls = _classes.get(type_name)
    if cls is None:
        from biped_sim.recording.messages import message_class
        cls = _classes[type_name] = message_class(type_name)
    return deserialize_message(data, cls)


def find_topic(topics, suffix):
    """The topic among ``topics`` whose last name component is ``suffix`` (namespaced runs), or None."""
    for t in topics:
        if t == suffix or t.endswith("/" + suffix.lstrip("/")):
            return t
    return None
