"""The recorder's frame buffer: the compiled twin gives the Python one's bytes, refuses what it refuses, and
loses nothing to a sender thread that takes while the simulating thread appends."""
from __future__ import annotations

import os
import threading

import pytest
from hypothesis import given, settings, strategies as st

from biped_sim.recording import frames
from biped_sim.recording.frames import FRAME, MESSAGES, PyFrameBuffer, records

compiled = frames._twin
needs_c = pytest.mark.skipif(compiled is None, reason=f"no compiled frame buffer: {frames.WHY_PYTHON}")

TOPICS = ["/joint_states", "/ground_reaction", "/clock", "/unknown"]
CHANNELS = {"/joint_states": 1, "/ground_reaction": 2, "/clock": 7}

cdr = st.one_of(st.binary(max_size=300), st.just(bytearray(b"x")), st.just("text"))
time_ns = st.one_of(st.integers(0, 2**64 - 1), st.integers(-5, -1), st.just(2**64), st.just(1.5))
op = st.one_of(
    st.tuples(st.just("message"), time_ns, st.sampled_from(TOPICS), cdr),
    st.tuples(st.just("messages"), time_ns, st.one_of(
        st.lists(st.one_of(st.tuples(st.sampled_from(TOPICS), cdr), st.just(["/clock", b""]), st.just(("/clock",))),
                 max_size=4),
        st.just(iter([("/clock", b"")])), st.just(None))),
    st.tuples(st.just("frame"), st.sampled_from([b"T", b"P", b"C", b"TT", b""]), st.binary(max_size=50)),
    st.tuples(st.just("take")),
    st.tuples(st.just("write_to"), st.sampled_from([-1, 999])),   # not a descriptor; not open: OSError, emptied
)


def apply(buf, operation):
    """(what the call returned, or the type of the exception it raised; the buffer's length after)."""
    name, *args = operation
    try:
        out = getattr(buf, name)(*args)
    except (ValueError, TypeError, OverflowError, OSError) as exc:
        return type(exc), len(buf)
    return out, len(buf)


@needs_c
@settings(max_examples=300, deadline=None)
@given(st.lists(op, max_size=25), st.sampled_from([0, 16, 4096]))
def test_the_compiled_buffer_gives_the_python_buffers_bytes_and_refusals(operations, capacity):
    py, c = PyFrameBuffer(dict(CHANNELS), capacity), compiled(dict(CHANNELS), capacity=capacity)
    for operation in operations:
        assert apply(c, operation) == apply(py, operation), operation
    assert c.take() == py.take()
    assert len(c) == len(py) == 0


@pytest.mark.parametrize("make", [PyFrameBuffer, pytest.param(compiled, marks=needs_c)], ids=["Python", "C"])
def test_frames_and_records_read_back_in_order_and_a_refused_call_changes_nothing(make):
    channels = {"/a": 1}
    buf = make(channels)
    buf.frame(b"T", b"topic a")
    buf.message(5, "/a", b"one")
    before = len(buf)
    with pytest.raises(ValueError, match="unknown topic '/b'"):
        buf.messages(6, [("/a", b"two"), ("/b", b"three")])      # all or none
    with pytest.raises(TypeError, match="must be bytes"):
        buf.messages(6, [("/a", b"two"), ("/a", "three")])
    with pytest.raises(ValueError, match="t_ns must be >= 0"):
        buf.message(-1, "/a", b"two")
    assert len(buf) == before
    channels["/b"] = 2                                             # a topic added later is known from then on
    buf.messages(6, [("/a", b"two"), ("/b", b"three")])
    buf.frame(b"C", b"")
    data = buf.take()
    assert len(buf) == 0 and buf.take() == b""
    out, off = [], 0
    while off < len(data):
        kind, n = FRAME.unpack_from(data, off)
        payload = data[off + FRAME.size:off + FRAME.size + n]
        out.append((kind, list(records(payload)) if kind == MESSAGES else payload))
        off += FRAME.size + n
    assert out == [(b"T", b"topic a"), (MESSAGES, [(5, 1, b"one"), (6, 1, b"two"), (6, 2, b"three")]), (b"C", b"")]


def test_a_record_cut_short_is_an_error_not_a_shorter_message():
    buf = PyFrameBuffer({"/a": 1})
    buf.message(1, "/a", b"hello")
    payload = buf.take()[FRAME.size:]
    assert list(records(payload)) == [(1, 1, b"hello")]
    for cut in (3, len(payload) - 1):
        with pytest.raises(ValueError, match="cut short"):
            list(records(payload[:cut]))


@pytest.mark.parametrize("hand_over", ["take", "write_to"])
@pytest.mark.parametrize("make", [PyFrameBuffer, pytest.param(compiled, marks=needs_c)], ids=["Python", "C"])
def test_a_sender_thread_handing_over_meanwhile_loses_and_repeats_no_message(make, hand_over):
    buf = make({"/a": 1, "/b": 2})
    taken, done = [], threading.Event()
    if hand_over == "take":
        def send():
            taken.append(buf.take())
    else:             # through a pipe, read by a third thread, as the writer process reads it
        r, w = os.pipe()
        reader = threading.Thread(target=lambda: taken.extend(iter(lambda: os.read(r, 65536), b"")))
        reader.start()

        def send():
            assert buf.write_to(w) >= 0

    def sender():
        while not done.is_set():
            send()
        send()
    thread = threading.Thread(target=sender)
    thread.start()
    n = 20000
    for i in range(n):
        buf.messages(i, [("/a", i.to_bytes(4, "little")), ("/b", b"")])
    done.set()
    thread.join()
    if hand_over == "write_to":
        os.close(w)
        reader.join()
        os.close(r)
    data, got, off = b"".join(taken), [], 0
    while off < len(data):
        kind, size = FRAME.unpack_from(data, off)
        assert kind == MESSAGES
        got.extend(records(data[off + FRAME.size:off + FRAME.size + size]))
        off += FRAME.size + size
    assert got == [r for i in range(n) for r in ((i, 1, i.to_bytes(4, "little")), (i, 2, b""))]
    assert len(buf) == 0


@pytest.mark.parametrize("make", [PyFrameBuffer, pytest.param(compiled, marks=needs_c)], ids=["Python", "C"])
def test_write_to_a_closed_pipe_is_an_oserror(make):
    buf = make({"/a": 1})
    r, w = os.pipe()
    os.close(r)
    buf.message(1, "/a", b"x")
    with pytest.raises(BrokenPipeError):
        buf.write_to(w)
    os.close(w)
    buf.message(2, "/a", b"y")           # the buffer goes on (the recorder reports the failure)
    assert list(records(buf.take()[FRAME.size:])) == [(2, 1, b"y")]


@needs_c
@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 2**64 - 1), st.sampled_from([1, 2, 3, 9]), st.binary(max_size=120)),
                max_size=40),
       st.sampled_from([64, 300, 1 << 20]), st.sampled_from([0, 7, 2**32 - 2]), st.integers(0, 40))
def test_the_writer_process_loop_in_c_writes_the_python_loops_file(messages, chunk_size, first, cut):
    """McapFileWriter.add_records (C) and add_numbered with add_message (Python) on the same M frames:
    the same MCAP file, the same sequence numbers (wrapping at 2**32), the same refusal of topic id 9."""
    import io

    from biped_sim.recording.frames import add_numbered
    from biped_sim.recording.mcapfile import McapFileWriter
    buf = PyFrameBuffer({"/a": 1, "/b": 2, "/c": 3, "/x": 9})
    for i, (t, topic, data) in enumerate(messages):
        buf.message(t, "/" + "abc"[topic - 1] if topic < 9 else "/x", data)
        if i == cut:
            buf.frame(b"T", b"")           # two M frames
    data, payloads, off = buf.take(), [], 0
    while off < len(data):
        kind, n = FRAME.unpack_from(data, off)
        if kind == MESSAGES:
            payloads.append(data[off + FRAME.size:off + FRAME.size + n])
        off += FRAME.size + n
    out = {}
    for name in ("C", "Python"):
        f = io.BytesIO()
        w = McapFileWriter(f, "ros2", "test", compression="none", chunk_size=chunk_size)
        schema = w.add_schema("s", "ros2msg", b"")
        channels = {tid: w.add_channel(f"/{tid}", "cdr", schema, {}) for tid in (1, 2, 3)}
        sequences = {1: first, 2: first, 3: first, 9: 0}
        refused = []
        for payload in payloads:
            try:
                if name == "C":
                    w.add_records(payload, channels, sequences)
                else:
                    add_numbered(w.add_message, payload, channels, sequences)
            except KeyError as exc:
                refused.append(exc.args)
        w.finish()
        out[name] = f.getvalue(), sequences, refused
    assert out["C"] == out["Python"]
