"""The progress of a long command (sweep, basin, accuracy, animate, replay) on stderr.

Owns how progress is shown, not what is counted: on a terminal a tqdm bar redrawn in place; on
anything else (a log file, a pipe, CI) a plain line now and then -- at every 10 % and at least every
10 s -- and never a carriage return, which a log would keep as one ever longer line
(``[1/256] ... ~866 s left   [2/256] ...``). tqdm is imported only on a terminal. A stream that
has gone (the terminal closed: SIGHUP, EIO) stops the display, never the work.
"""
from __future__ import annotations

import sys
import time

#: on a non-terminal: a line at every LINE_FRACTION of the total, and at least every LINE_SECONDS
LINE_FRACTION = 0.1
LINE_SECONDS = 10.0


class Progress:
    """``update(done, note)``: ``done`` of ``total`` (an absolute count) and a short note; ``close()`` at the end."""

    def __init__(self, total, label, unit="it", stream=None):
        self.total, self.label, self.unit = max(int(total), 1), label, unit
        self.stream = sys.stderr if stream is None else stream
        self.t0 = self.last_line = time.perf_counter()
        self.next_fraction = LINE_FRACTION
        self.done, self.note, self.closed = 0, "", False
        self.shown = 0                       # the count of the last line written (non-terminal)
        self.bar = None
        if _is_terminal(self.stream):
            from tqdm import tqdm
            self.bar = tqdm(total=self.total, desc=label, unit=unit, file=self.stream,
                            leave=True)

    def update(self, done, note=""):
        if self.closed:
            return
        self.done, self.note = done, note
        try:
            if self.bar is not None:
                if note:
                    self.bar.set_postfix_str(note, refresh=False)
                self.bar.update(done - self.bar.n)
                return
            now = time.perf_counter()
            # the last count once (a caller may report it again, e.g. as it closes), a line every 10 %, or 10 s
            if (done >= self.total > self.shown or done / self.total >= self.next_fraction
                    or now - self.last_line >= LINE_SECONDS):
                while self.next_fraction <= done / self.total:
                    self.next_fraction += LINE_FRACTION
                self.last_line = now
                self._line(now)
        except OSError:
            self._gone()

    def close(self):
        """End the display (a last line on a non-terminal if the last count was not shown)."""
        if self.closed:
            return
        try:
            if self.bar is not None:
                self.bar.close()
            elif self.shown != self.done:
                self._line(time.perf_counter())
        except OSError:
            pass
        self.closed = True

    def _line(self, now):
        elapsed = now - self.t0
        left = elapsed / self.done * (self.total - self.done) if self.done else float("nan")
        text = f"[{self.label}] {self.done}/{self.total} {self.unit} ({100 * self.done / self.total:.0f} %), " \
               f"{elapsed:.0f} s elapsed" + (f", ~{left:.0f} s left" if self.done < self.total and self.done else "")
        self.stream.write(text + (f"; {self.note}" if self.note else "") + "\n")
        self.stream.flush()
        self.shown = self.done

    def _gone(self):
        self.closed = True
        if self.bar is not None:
            try:
                self.bar.disable = True
            except Exception:  # noqa: BLE001 - the display only
                pass


def _is_terminal(stream) -> bool:
    try:
        return stream.isatty()
    except (AttributeError, ValueError, OSError):
        return False
