"""The frames a recording process hands its bag writer process through a pipe, and the buffer that makes them.

Owns the protocol between :class:`biped_sim.recording.recorder.BagRecorder` and the writer process
(:mod:`biped_sim.recording.writer`). A frame is ``FRAME`` (kind, payload length) then the payload.
Kinds: ``T`` a topic (JSON: id, name, type, qos, hash, definition), ``P`` the run's parameters record
(JSON), ``M`` messages, ``C`` close. An ``M`` payload is records, each ``RECORD`` (t_ns, channel id,
CDR length) then the CDR; the writer process numbers each topic's messages 1, 2, ...

:class:`PyFrameBuffer` appends frames and records to one buffer that a sender thread writes to the
pipe (``write_to``) every 0.1 s; ``FrameBuffer`` is its compiled twin (``_frames.c``, the same bytes), used
when it was built: a period's messages then cost the simulating thread one C call and leave no object
behind for the cyclic collector (docs/performance.md, "Recording"). ``BIPED_SIM_PURE_PYTHON=1``
forces the Python one.
"""
from __future__ import annotations

import os
import struct
import threading

FRAME = struct.Struct("<cI")          # kind, payload length
RECORD = struct.Struct("<QHI")        # t_ns, channel id, CDR length (then the CDR), inside an M frame
MESSAGES = b"M"
MAX_PAYLOAD = 0xFFFFFFFF


class PyFrameBuffer:
    """Frames for the writer process, appended by the simulating thread and taken by the sender thread.

    ``channels``: {topic: channel id 1..65535}, the caller's dict (a topic added to it later is known
    from then on). ``capacity``: bytes the compiled twin allocates and touches at once for each of its
    two buffers, so that filling them does not page fault during the run (the Python twin ignores it).

    ``message``/``messages`` append records to the open ``M`` frame, ``frame`` a frame of its own (it
    ends the open ``M`` frame), ``take()`` returns everything so far and empties the buffer,
    ``write_to(fd)`` writes it to a file descriptor and empties it. A call checks everything it is
    given before it appends anything: a refused call (unknown topic, CDR not bytes, a negative time)
    changes nothing. Each call holds a lock, so that the sender thread sees whole calls (the compiled
    twin needs none: a C call holds the interpreter lock).
    """

    def __init__(self, channels: dict, capacity: int = 0):
        if not isinstance(channels, dict):
            raise TypeError(f"channels must be a dict, not {type(channels).__name__}")
        if capacity < 0:
            raise ValueError("capacity must be >= 0")
        self.channels = channels
        self._buf = bytearray()
        self._open = -1            # offset of the open M frame's header, or -1
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._buf)

    def _record(self, t_ns: int, topic, data) -> bytes:
        cid = self.channels.get(topic)
        if cid is None:
            raise ValueError(f"unknown topic {topic!r}: call add_topic first")
        if not 1 <= cid <= 65535:
            raise ValueError(f"the channel id of {topic!r} must be 1..65535, got {cid}")
        if not isinstance(data, bytes):
            raise TypeError(f"the CDR of a message on {topic!r} must be bytes, not {type(data).__name__}")
        if len(data) > MAX_PAYLOAD - RECORD.size:
            raise ValueError(f"a message on {topic!r} is larger than a frame can hold")
        return RECORD.pack(t_ns, cid, len(data)) + data

    def _close_frame(self):
        if self._open >= 0:
            FRAME.pack_into(self._buf, self._open, MESSAGES, len(self._buf) - self._open - FRAME.size)
            self._open = -1

    def _append_records(self, records):
        for rec in records:
            if self._open >= 0 and len(self._buf) - self._open - FRAME.size + len(rec) > MAX_PAYLOAD:
                self._close_frame()
            if self._open < 0:
                self._open = len(self._buf)
                self._buf += FRAME.pack(MESSAGES, 0)
            self._buf += rec

    def message(self, t_ns: int, topic: str, data: bytes):
        """One message record (in the open M frame)."""
        rec = self._record(_check_time(t_ns), topic, data)
        with self._lock:
            self._append_records((rec,))

    def messages(self, t_ns: int, messages):
        """The records of ``messages`` ([(topic, CDR bytes), ...]) at one time: all or none."""
        t = _check_time(t_ns)
        if not isinstance(messages, (list, tuple)):
            raise TypeError("messages must be a list of (topic, CDR bytes)")
        for m in messages:
            if type(m) is not tuple or len(m) != 2:
                raise TypeError("messages must be a list of (topic, CDR bytes)")
        records = [self._record(t, topic, data) for topic, data in messages]
        with self._lock:
            self._append_records(records)

    def frame(self, kind: bytes, payload: bytes):
        """A frame of its own (``T``, ``P``, ``C``): it ends the open M frame."""
        if type(kind) is not bytes or len(kind) != 1 or not isinstance(payload, bytes):
            raise TypeError("frame(kind, payload): kind one byte, payload bytes")
        if len(payload) > MAX_PAYLOAD:
            raise ValueError("a frame's payload must be shorter than 4 GiB")
        with self._lock:
            self._close_frame()
            self._buf += FRAME.pack(kind, len(payload)) + payload

    def take(self) -> bytes:
        """Everything appended so far, as bytes; the buffer empties."""
        with self._lock:
            self._close_frame()
            out = bytes(self._buf)
            del self._buf[:]
            return out

    def write_to(self, fd) -> int:
        """Everything appended so far written to ``fd`` (a file descriptor or an object with ``fileno``);
        the buffer empties. Returns the number of bytes. (The compiled twin writes without the
        interpreter lock and keeps the written buffer for the next messages.)"""
        fd = fd if isinstance(fd, int) else fd.fileno()
        if fd < 0:
            raise ValueError("file descriptor cannot be a negative integer")
        data = self.take()
        view, done = memoryview(data), 0
        while done < len(data):
            done += os.write(fd, view[done:])
        return len(data)


def _check_time(t_ns) -> int:
    if not isinstance(t_ns, int):
        raise TypeError(f"t_ns must be an int (nanoseconds), not {type(t_ns).__name__}")
    if t_ns < 0:
        raise ValueError("t_ns must be >= 0")
    if t_ns >= 1 << 64:
        raise OverflowError("t_ns does not fit in 64 bits")
    return t_ns


def records(payload: bytes):
    """The (t_ns, channel id, CDR bytes) of an M frame's payload, in order (ValueError if it is cut short)."""
    off, end, unpack, head = 0, len(payload), RECORD.unpack_from, RECORD.size
    while off < end:
        if end - off < head:
            raise ValueError("a message record cut short in an M frame")
        t_ns, cid, size = unpack(payload, off)
        off += head
        if end - off < size:
            raise ValueError("a message record cut short in an M frame")
        yield t_ns, cid, payload[off:off + size]
        off += size


def add_numbered(add_message, payload: bytes, channels: dict, sequences: dict):
    """The messages of an ``M`` frame's payload, each ``add_message(channel id, t_ns, data, t_ns,
    sequence)``: ``channels`` {topic id: channel id}, ``sequences`` {topic id: the last sequence number},
    updated (a topic's messages are numbered 1, 2, ..., modulo 2**32). KeyError for a topic id not in
    both. The writer process's loop in Python; ``McapFileWriter.add_records`` runs its compiled twin."""
    for t_ns, topic_id, data in records(payload):
        channel_id = channels[topic_id]
        sequence = sequences[topic_id] = (sequences[topic_id] + 1) & 0xFFFFFFFF
        add_message(channel_id, t_ns, data, t_ns, sequence)


def _compiled_twins():
    """(the _frames module or None, why not)."""
    if os.environ.get("BIPED_SIM_PURE_PYTHON", "") not in ("", "0"):
        return None, "BIPED_SIM_PURE_PYTHON is set"
    try:
        from biped_sim.recording import _frames
    except ImportError:
        return None, ("the compiled twin biped_sim/recording/_frames was not built: install gcc and the Python "
                      "headers, then make venv")
    return _frames, ""


_twins, WHY_PYTHON = _compiled_twins()
_twin = _twins.FrameBuffer if _twins else None
#: the buffer ``BagRecorder`` uses: the compiled twin if it was built, else :class:`PyFrameBuffer`
FrameBuffer = _twin or PyFrameBuffer
#: ``_frames.append_messages`` (the compiled twin of :func:`add_numbered`'s loop for McapFileWriter), or None
append_messages = _twins.append_messages if _twins else None
IMPLEMENTATION = "C" if _twins else "Python"
