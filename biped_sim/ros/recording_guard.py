"""``sim_node``'s side of a recording that fails during the run (a full disk, the writer process gone).

Owns what happens between the node and its :class:`biped_sim.recording.recorder.BagRecorder` once
the bag cannot be written any more: :class:`GuardedRecorder` has the recorder's interface (``add_topic``,
``write``, ``write_messages``, ``wait_ready``, ``close``) and turns the first failure (an ``OSError`` of a
write, or the recorder's ``on_error`` from its threads as soon as they find the writer process failed,
see its docstring) into one call of the node's ``on_failure(exc)``; every later write is dropped. The
node then ends the run cleanly (its final status, exit code 1) instead of a traceback from inside a
callback, and the bag keeps what was written before the fault (closed by the writer, or repaired by
``biped-sim recover``).
:func:`failure_message` is the line the node logs: the bag, the cause, the free space.
"""
from __future__ import annotations

import shutil
import threading
from pathlib import Path


def free_space(path) -> str:
    """The free space on the file system of ``path`` (or of its nearest existing parent), in words."""
    p = Path(path)
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        return f"{shutil.disk_usage(p).free / 1e6:.1f} MB free on its file system"
    except OSError as exc:
        return f"free space unknown ({exc.strerror})"


def failure_message(path, exc: Exception, t: float) -> str:
    """What the node says when the recording to ``path`` failed at simulated time ``t``."""
    why = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
    if str(path) not in why:
        why = f"recording to {path} failed: {why}"
    disk_full = any(s in why for s in ("No space left", "Disk quota", "File too large"))
    return (f"{why} (at t={t:.6f} s; {free_space(path)}). The run stops here: the bag holds the run up to "
            f"about this time (if biped-sim inspect says it is cut short: biped-sim recover {path}). "
            + ("Free some space or set bag_dir to another disk (or record:=false), then start the run again"
               if disk_full else "Start the run again (record:=false runs it without a bag)"))


class GuardedRecorder:
    """A :class:`~biped_sim.recording.recorder.BagRecorder` whose first write failure calls
    ``on_failure(exc)`` (once, from whichever thread wrote) instead of raising; later writes are dropped."""

    def __init__(self, recorder, on_failure):
        self.recorder = recorder
        self.on_failure = on_failure
        self.failure = None              # the exception that ended the recording
        self._lock = threading.Lock()
        # the recorder's own methods until it fails, then ones that drop (no test at every write).
        # write_messages, a period's state (the node's hot path), is the recorder's unchecked C call:
        # a failure comes from on_error instead of an OSError of the next write
        self._write = recorder.write
        self.write_messages = recorder.append_period
        recorder.on_error = self._failed

    @property
    def path(self):
        return self.recorder.path

    def add_topic(self, topic, type_name, qos=None):
        if self.failure is None:
            try:
                self.recorder.add_topic(topic, type_name, qos=qos)
            except OSError as exc:
                self._failed(exc)

    def _failed(self, exc):
        with self._lock:
            first = self.failure is None
            if first:
                self.failure = exc
                self._write = self.write_messages = _drop
        if first:
            self.on_failure(exc)

    def wait_ready(self, timeout=10.0) -> bool:
        return self.recorder.wait_ready(timeout)

    def write(self, topic, msg, t_ns):
        try:
            self._write(topic, msg, t_ns)
        except OSError as exc:
            self._failed(exc)

    def close(self, logger=None, t: float = 0.0) -> bool:
        """Close the bag (the writer ends it); False if that failed. A failure not reported before (the
        last data could not be written) is logged with :func:`failure_message` (raised without a
        ``logger``, as :meth:`BagRecorder.close` raises it)."""
        try:
            self.recorder.close()
        except OSError as exc:
            if self.failure is None:
                self.failure = exc
                if logger is None:
                    raise
                logger.error(failure_message(self.path, exc, t))
            return False
        return self.failure is None


def _drop(*_args):
    """A write after the recording failed: dropped."""
