"""Record a run to a rosbag2 bag directory holding one MCAP file, off the simulation's hot path.

Owns the recording process's side of a bag: :class:`BagRecorder` serialises each message
(:mod:`biped_sim.recording.cdr`), queues it and hands the queue to a writer process
(:mod:`biped_sim.recording.writer`'s protocol), which writes the MCAP file
(:mod:`biped_sim.recording.mcapfile`) and ends the bag. The bag is what ``ros2 bag record -s mcap`` on Jazzy writes
(:mod:`biped_sim.recording.bagformat`), so that ``ros2 bag info/play``, Foxglove and ``rosbags``
open it:

* ``<bag>/<bag name>_0.mcap``: profile ``ros2``; one ``ros2msg`` schema per type; one ``cdr``
  channel per topic with the channel metadata ``offered_qos_profiles`` (YAML) and
  ``topic_type_hash`` (RIHS01); zstd-compressed chunks; a ``biped_sim`` metadata record
  (``parameters``: the run's checked parameters as JSON) at the start, so that ``resim`` can
  rebuild the run, and the ``rosbag2`` metadata record (``serialized_metadata``) at the end.
* ``<bag>/metadata.yaml``: ``rosbag2_bagfile_information`` version 9.

Message times are simulation times in ns (log time = publish time = the stamp). :func:`recover`
(:mod:`biped_sim.recording.recover`) turns a bag whose writer was killed into a clean one.
"""
from __future__ import annotations

import atexit
import errno
import json
import os
import shutil
import sys
import threading
from datetime import datetime, timezone
from pathlib import Path

from biped_sim.recording.bagformat import message_definition, qos_dict, type_hash
from biped_sim.recording.frames import FrameBuffer
from biped_sim.recording.recover import recover

__all__ = ["BagRecorder", "default_bag_path", "recover", "MIN_FREE_BYTES"]

MIN_FREE_BYTES = 64 * 1024 * 1024
#: the pipe to the writer process: Linux's limit for an unprivileged process (/proc/sys/fs/pipe-max-size)
PIPE_BYTES = 1024 * 1024
#: each of the frame buffer's two buffers, allocated before the run: 0.1 s of a fast node run (about
#: 45 000 periods a wall second, 380 bytes a period) is 1.7 MB; more grows the buffer as needed
BUFFER_BYTES = 4 * 1024 * 1024


def default_bag_path(bag_dir="bags", scene="custom", now=None) -> Path:
    """``<bag_dir>/<scene>-<UTC time>`` (e.g. bags/walk-20261122T024500Z); ValueError for a scene
    name that is a path (it would choose another folder than ``bag_dir``)."""
    from biped_sim.config.parameters import check_file_name
    check_file_name(str(scene), "the scene name")
    now = now or datetime.now(timezone.utc)
    return Path(bag_dir) / f"{scene}-{now.strftime('%Y%m%dT%H%M%S')}{now.microsecond // 1000:03d}Z"


def _widen_pipe(f):
    """Let the pipe ``f`` hold PIPE_BYTES (Linux; elsewhere, or refused, it keeps its size).

    A hand-over of a fast run is about 2 MB. Through the default 64 KiB pipe the sender thread blocked,
    and the writer process woke it, 21-74 times in 13 000 periods appended at a fast run's pace (0.24
    s), 11-13 times with 1 MiB. On a 2-vCPU VM those wake-ups cost the simulating thread more than
    their CPU: in four alternated comparisons the recording overhead of a fast node run was 5.4-18.8 %
    with 64 KiB and 3.7-12.2 % with 1 MiB, lower in each (docs/performance.md, "Recording")."""
    try:
        import fcntl
        fcntl.fcntl(f.fileno(), fcntl.F_SETPIPE_SZ, PIPE_BYTES)
    except (ImportError, AttributeError, OSError):
        pass


class BagRecorder:
    """Records messages to a rosbag2/MCAP bag directory; ``write`` is cheap, another process does the IO.

    ``BagRecorder(path, parameters=dict)`` creates the directory (it must not exist or be empty)
    and raises ``OSError``/``ValueError`` with a clear message at once if the path is unwritable or
    the disk has less than ``min_free_bytes`` free. ``add_topic`` then ``write(topic, msg, t_ns)``;
    ``close()`` (idempotent; also run at interpreter exit) finalises the MCAP and writes
    metadata.yaml.

    ``write`` serialises the message (:mod:`biped_sim.recording.cdr` for the hot types, else rclpy's
    serialiser), ``write_messages`` takes the CDR bytes it is given as they are; both append them to a
    :class:`~biped_sim.recording.frames.FrameBuffer` (one C call, no object kept), which a sender
    thread hands every ``send_interval`` s to a writer process (``python -m
    biped_sim.recording.writer``) in one write to its pipe; the writer process numbers, chunks and
    compresses the messages, so none of that takes the simulation's interpreter lock.
    The writer process runs in its own session: when the recording process dies (even by SIGKILL)
    the writer sees the end of its input and finalises the bag. It also closes a chunk at least
    every ``flush_interval`` s, so if both die, everything older survives (see :func:`recover`). A
    failure of the writer (e.g. the disk fills up) is raised by the next ``write`` or by ``close``,
    never swallowed; ``on_error`` (a callable, None by default) also hears of it at once, from the
    thread that found it (or from the assignment, if the failure came first), until ``close`` begins
    (close raises what it finds itself).
    ``append_period`` is ``write_messages`` without its checks, for a caller that learns of failures
    from ``on_error`` (``sim_node``: one C call a period, no Python frame).
    ``file_writer`` (``"module:Class"``): another MCAP file writer for the writer process than
    :class:`~biped_sim.recording.mcapfile.McapFileWriter` (the recording benchmark compares them).
    """

    def __init__(self, path, parameters=None, compression="zstd", chunk_size=1024 * 1024,
                 flush_interval=0.5, send_interval=0.1, min_free_bytes=MIN_FREE_BYTES, file_writer=None):
        import subprocess
        self.path = Path(path)
        if compression not in ("zstd", "lz4", "none"):
            raise ValueError(f"compression must be zstd, lz4 or none, got {compression!r}")
        if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
            raise ValueError(f"bag path {self.path} exists and is not an empty directory; "
                             "choose a new bag path")
        created = not self.path.exists()
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OSError(exc.errno, f"cannot create the bag directory {self.path}: {exc.strerror}") from None
        self.mcap_name = f"{self.path.name}_0.mcap"
        try:
            if not os.access(self.path, os.W_OK):
                raise OSError(errno.EACCES, f"the bag directory {self.path} is not writable")
            free = shutil.disk_usage(self.path).free
            if free < min_free_bytes:
                raise OSError(errno.ENOSPC, f"not enough free disk space for the bag {self.path}: {free / 1e6:.1f} "
                                            f"MB free, at least {min_free_bytes / 1e6:.0f} MB needed")
            try:
                with open(self.path / self.mcap_name, "wb"):
                    pass
            except OSError as exc:
                raise OSError(exc.errno,
                              f"cannot write the bag file {self.path / self.mcap_name}: {exc.strerror}") from None
        except OSError:
            if created:     # refused: leave no empty bag directory behind (a ~/reset tries the next name)
                try:
                    (self.path / self.mcap_name).unlink(missing_ok=True)
                    self.path.rmdir()
                except OSError:
                    pass
            raise
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "biped_sim.recording.writer", str(self.path), self.mcap_name, compression,
             str(int(chunk_size)), repr(float(flush_interval)), *([file_writer] if file_writer else [])],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, start_new_session=True, bufsize=0)
        _widen_pipe(self._proc.stdin)
        self._serializers = {}     # topic name -> its message's serialiser
        self._channel_ids = {}     # topic name -> id (1, 2, ...): the frame buffer reads it too
        # what the simulation hands over, in order: the frames for the writer process
        self._frames = FrameBuffer(self._channel_ids, capacity=BUFFER_BYTES)
        self.append_period = self._frames.messages      # (t_ns, [(topic, CDR bytes)]): write_messages unchecked
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._ready = threading.Event()     # the writer process has started (wait_ready)
        self._error = None
        self._on_error = None               # callable(OSError): the on_error property
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
        self._frames.frame(kind, payload)

    def add_topic(self, topic: str, type_name: str, qos=None):
        """Declare a topic (full name, e.g. ``/joint_states``) of ``type_name`` (``pkg/msg/Name``)."""
        self._check()
        if topic in self._channel_ids:
            return
        from rclpy.serialization import serialize_message

        from biped_sim.recording.cdr import BYTES_ONLY, serializer
        from biped_sim.recording.messages import message_class
        if type_name not in BYTES_ONLY:
            serialize_message(message_class(type_name)())   # load the type support now, not in the run
        info = dict(name=topic, type=type_name, qos=[qos_dict(qos)], hash=type_hash(type_name),
                    definition=message_definition(type_name), id=len(self._channel_ids) + 1)
        self._serializers[topic] = serializer(type_name)
        self._frame(b"T", json.dumps(info).encode())    # before any message of the topic can follow it
        self._channel_ids[topic] = info["id"]

    def write(self, topic: str, msg, t_ns: int):
        """Record one message (an rclpy message object, or its CDR bytes) at simulation time t_ns (int)."""
        # the simulation thread pays for this at every message: one test for all the checks
        serialize = self._serializers.get(topic)
        if serialize is None or self._error is not None or self._closed:
            self._check()
            raise ValueError(f"unknown topic {topic!r}: call add_topic first (topics: {sorted(self._serializers)})")
        self._frames.message(t_ns, topic, msg if type(msg) is bytes else (
            bytes(msg) if isinstance(msg, (bytearray, memoryview)) else serialize(msg)))

    def write_messages(self, t_ns: int, messages: list):
        """Record messages of one time, ``messages`` a list of ``(topic, CDR bytes)`` (the node's state
        messages of a period, serialised once for publishing and recording): all of them, or none and
        ``ValueError`` for a topic not added (``TypeError`` for CDR that is not bytes). This is the hot
        path: one C call, about 0.2 us for a period's three messages."""
        if self._error is not None or self._closed:
            self._check()
        self._frames.messages(t_ns, messages)

    def close(self):
        """Finalise the MCAP (summary, rosbag2 metadata record) and write metadata.yaml. Idempotent.

        Raises OSError if the writer failed at any point of the run.
        """
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._on_error = None         # from here close raises what goes wrong
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
            raise self._failure()

    @property
    def message_counts(self):
        """Messages written per topic, as the writer process counted them; known after ``close``
        (before: None, the writer numbers the messages as it receives them)."""
        if self._status and self._status.get("counts") is not None:
            return dict(self._status["counts"])
        return None

    def wait_ready(self, timeout: float = 10.0) -> bool:
        """Wait until the writer process has started (its imports and the open file: about 0.15 s of CPU
        here), so that its start-up does not compete with the first periods of the run on a machine
        with few cores; False if it did not say so within ``timeout`` s (``write`` works either way)."""
        return self._ready.wait(timeout)

    @property
    def writer_pid(self) -> int:
        """The process id of the writer process (the recording benchmark measures its CPU time)."""
        return self._proc.pid

    @property
    def on_error(self):
        """Called once with the ``OSError`` when the writer fails during the run (see the class docstring)."""
        return self._on_error

    @on_error.setter
    def on_error(self, handler):
        # the threads run from the constructor on: a failure they found before this assignment is told now
        with self._lock:
            self._on_error = None if self._closed else handler
            late = handler is not None and self._error is not None and not self._closed
        if late:
            self._tell(handler)

    def _check(self):
        if self._error is not None:
            raise self._failure()
        if self._closed:
            raise ValueError(f"the recorder of {self.path} is closed")

    def _failure(self) -> OSError:
        return OSError(errno.EIO, f"recording to {self.path} failed: {self._error}")

    def _fail(self, why: str):
        """The writer failed (a thread found it): kept for the next write and close, told to on_error."""
        with self._lock:
            first = self._error is None
            if first:
                self._error = why
            on_error = self._on_error if first else None
        if on_error is not None:
            self._tell(on_error)

    def _tell(self, on_error):
        try:
            on_error(self._failure())
        except Exception:  # noqa: BLE001 - the owner's handler must not end the thread; writes still raise
            pass

    # -- threads: hand the buffer to the writer process, read its status -------------------------
    def _send_loop(self):
        out = self._proc.stdin
        while True:
            self._wake.wait(self.send_interval)
            self._wake.clear()
            closing = self._closing       # read before taking the queue: a closing queue ends with its C frame
            try:
                self._frames.write_to(out)
            except (BrokenPipeError, OSError) as exc:
                self._fail(f"the bag writer process is gone ({exc})")
            if closing:
                try:
                    out.close()
                except OSError:
                    pass
                return

    def _read_loop(self):
        try:
            self._read_statuses()
        finally:
            self._ready.set()         # a writer that ended (or died) before it said so: nobody waits on

    def _read_statuses(self):
        for line in self._proc.stdout:
            try:
                status = json.loads(line)
            except ValueError:
                continue
            if status.get("ready"):
                self._ready.set()
            if status.get("error"):
                self._fail(status["error"])
            if status.get("done"):
                self._status = status

