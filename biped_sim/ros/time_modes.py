"""The run loops of ``sim_node``'s three time modes, and their clocks.

Owns when the node steps and publishes: ``lockstep`` (each command steps once: the loop only
spins), ``fast`` (step as fast as possible) and ``realtime`` (simulated time t is due at wall time
``start + t / rate_factor``: :class:`RealtimePacer` sleeps until then, says when the loop falls
behind, resynchronises after a stall, and measures the achieved rate). Both publish at
``publish_rate`` in simulated time, whatever the control period (:class:`PublishSchedule`). The loops drive a
:class:`biped_sim.ros.sim_node.SimNode` through its ``check_timeout``, ``step`` and
``publish_state``; the pacing and the schedule are plain Python.
"""
from __future__ import annotations

import contextlib
import math
import threading
import time

#: a loop that is behind says so at most this often (wall s)
LAG_REPORT_INTERVAL = 2.0
#: time.sleep overshoots by ~0.1 ms here: sleep until this much before the deadline, then spin
SLEEP_MARGIN = 1.5e-4
#: a realtime wait looks at the stop signals at least this often (wall s)
STOP_CHECK_INTERVAL = 0.1
MAX_PUBLICATION_TIMES = 1_000_000
#: a control period that takes this much wall time more than it should is a stall (the process was
#: stopped, SIGSTOP or a suspended machine, or starved): the clock resynchronises instead of replaying it
STALL_BOUND = 0.5


class PublishSchedule:
    """The states to publish: the first at or after each multiple of 1 / ``publish_rate`` (simulated s)."""

    def __init__(self, publish_rate: float):
        self.period = 1.0 / publish_rate
        self.next = self.period

    def restart(self, t: float):
        """Publish from the first multiple of the period after ``t`` (after a pause, a step or a reset)."""
        self.next = (math.floor(t / self.period + 1e-9) + 1) * self.period

    def due(self, t: float) -> bool:
        """True if the state at ``t`` is to be published (and the next one scheduled)."""
        if t < self.next - 1e-12:
            return False
        self.next = (math.floor(t / self.period + 1e-9) + 1) * self.period
        return True


class RealtimePacer:
    """Holds a loop to the wall clock: simulated time t is due at ``start + t / rate_factor``.

    The figures count the stretches the loop ran paced (a segment: from a start or a
    :meth:`restart` to the last period waited for), not the pauses, ``~/step`` s and resets between
    them: after a reset to t = 0 the simulated time of the whole run is not ``t``, and a pause is
    neither jitter nor a slow real-time factor. A stall ends a segment too (see :meth:`wait_until`)."""

    def __init__(self, rate_factor: float, control_period: float, publish_period: float,
                 stall_bound: float = STALL_BOUND):
        self.rate = rate_factor
        self.stall_bound = stall_bound
        self.stalls, self.stalled_wall = 0, 0.0                 # the stalls left out of the figures
        self.lag_tolerance = max(control_period / rate_factor, 0.005)
        self.publish_period = publish_period / rate_factor      # wall s between publications
        self.start = time.monotonic()
        self.cpu_start = time.process_time()
        self.last_lag_report = self.start
        self.lag_reports = 0
        self.publication_times = [[]]                           # wall clock, one list per segment (figures)
        self.publications = 0
        self.segment_t, self.segment_wall = 0.0, self.start     # where the current segment began
        self.last_t, self.last_wall = 0.0, self.start           # the last period waited for
        self.earlier_t, self.earlier_wall = 0.0, 0.0            # the segments before it, summed

    def wait_until(self, t: float, should_stop=lambda: False) -> str | None:
        """Sleep until simulated time ``t`` is due; a warning if it is already late by more than a
        control period (at most one every LAG_REPORT_INTERVAL s), or if the loop stalled.

        A stall: the wall time since the last period waited for exceeds what the simulated time
        between them needs by more than ``stall_bound``, at once (a loop that falls behind a little
        each period is not one). Holding to the old clock would replay the stall as fast as the loop
        goes; instead ``t`` is due now: the simulated time goes on from where it was, and the stall
        is left out of the figures. Returns early, ``t`` not yet due, once ``should_stop()``."""
        warning = self._resync_if_stalled(t, time.monotonic())
        deadline = self.start + t / self.rate
        now = time.monotonic()
        if warning is None and now > deadline + self.lag_tolerance and now - self.last_lag_report > LAG_REPORT_INTERVAL:
            self.last_lag_report = now
            self.lag_reports += 1
            warning = (f"realtime: cannot keep up: simulated time {t:.3f} s is {(now - deadline) * self.rate:.3f} s "
                       f"behind the wall clock x rate_factor {self.rate:g} (achieved real-time factor "
                       f"{t / (now - self.start):.3g}); lower publish_rate or rate_factor, raise control_period, "
                       "or use time_mode fast")
        while not should_stop():
            left = deadline - time.monotonic()
            if left <= 2e-4:             # shorter sleeps are not worth their overshoot
                while time.monotonic() < deadline:
                    pass
                break
            # in slices: a period can be long (control_period 1 s at rate_factor 0.01 is 100 s of wall
            # time), and a stop signal only appends to a list, so one sleep held the node's end that long
            time.sleep(min(left - SLEEP_MARGIN, STOP_CHECK_INTERVAL))
        # stopped during the sleep: the period is published late, the next ones must not catch up
        warning = self._resync_if_stalled(t, time.monotonic()) or warning
        self.last_t, self.last_wall = t, time.monotonic()
        return warning

    def _resync_if_stalled(self, t: float, now: float) -> str | None:
        """If the loop stalled since the last period waited for: ``t`` is due at ``now``, the
        current segment ends at the last period, a new one begins; the warning line."""
        stalled = now - self.last_wall - (t - self.last_t) / self.rate
        if stalled <= self.stall_bound:
            return None
        self.stalls += 1
        self.stalled_wall += stalled
        self.earlier_t += self.last_t - self.segment_t
        self.earlier_wall += self.last_wall - self.segment_wall
        self.segment_t, self.segment_wall = self.last_t, now - (t - self.last_t) / self.rate
        self.last_t, self.last_wall = t, now
        self.start = now - t / self.rate
        if self.publication_times[-1]:
            self.publication_times.append([])
        return (f"realtime: the node stalled for {stalled:.3f} s of wall time before simulated time {t:.3f} s "
                f"(the process was stopped, e.g. SIGSTOP or a suspended machine, or starved of CPU); the clock is "
                f"resynchronised to now: the simulated time goes on from {t:.3f} s at rate_factor {self.rate:g} "
                f"without catching up (stall {self.stalls}, left out of the real-time factor)")

    def restart(self, t: float):
        """Simulated time ``t`` is due now (after a pause, a step or a reset: time stood still or went
        back): the current segment ends at the last period waited for, a new one begins."""
        now = time.monotonic()
        self.earlier_t += self.last_t - self.segment_t
        self.earlier_wall += self.last_wall - self.segment_wall
        self.segment_t = self.last_t = t
        self.segment_wall = self.last_wall = now
        self.start = now - t / self.rate
        if self.publication_times[-1]:
            self.publication_times.append([])

    def published(self):
        if self.publications < MAX_PUBLICATION_TIMES:
            self.publications += 1
            self.publication_times[-1].append(time.monotonic())

    def figures(self, t: float, control_periods: int) -> dict | None:
        """Achieved publish rate and period jitter (wall, within segments), real-time factor (simulated
        time paced over the wall time it took) and CPU time per control period of the run so far;
        None with fewer than 3 publications in a row."""
        segments = [walls for walls in self.publication_times if len(walls) >= 2]
        d = sorted(abs((b - a) - self.publish_period) for walls in segments for a, b in zip(walls, walls[1:]))
        if len(d) < 2:
            return None
        pick = lambda q: d[min(len(d) - 1, int(q * (len(d) - 1)))]  # noqa: E731
        paced_t = self.earlier_t + self.last_t - self.segment_t
        paced_wall = self.earlier_wall + self.last_wall - self.segment_wall
        return dict(publications=self.publications, rate=len(d) / sum(w[-1] - w[0] for w in segments),
                    jitter_p50=pick(0.5), jitter_p99=pick(0.99), rtf=paced_t / paced_wall if paced_wall > 0 else 0.0,
                    cpu=(time.process_time() - self.cpu_start) / max(1, control_periods),
                    stalls=self.stalls, stalled_wall=self.stalled_wall)

    def report(self, t: float, control_periods: int) -> str | None:
        """The figures in one line (``benchmarks/bench_node.py`` reads it after "realtime figures: ")."""
        f = self.figures(t, control_periods)
        if f is None:
            return None
        stalls = ""
        if f["stalls"]:
            stalls = (f" ({f['stalls']} stall{'s' if f['stalls'] > 1 else ''}, {f['stalled_wall']:.3f} s of wall "
                      "time, left out)")
        return (f"realtime figures: {f['publications']} states published at {f['rate']:.1f} Hz (wall; target "
                f"{1 / self.publish_period:.1f} Hz), period jitter p50 {f['jitter_p50'] * 1e6:.0f} us, "
                f"p99 {f['jitter_p99'] * 1e6:.0f} us, real-time factor {f['rtf']:.3f}{stalls}; CPU time of this "
                f"process {f['cpu'] * 1e3:.3f} ms per control period")


def run_lockstep(node, should_stop, spin):
    """Spin until the duration is reached or the engine stops: the command callback steps and
    publishes. ``spin``: the node's :class:`~biped_sim.ros.one_topic_spin.OneTopicSpin` on ``hip_torque``."""
    while not (should_stop() or node.finished or node.stopped):
        spin.spin_once(0.1)


def run_fast(node, should_stop):
    schedule = PublishSchedule(node.params["publish_rate"])
    while not (node.stopped or node.finished or should_stop()):
        if node.control.between_periods(should_stop):      # paused, stepped or reset: go on from here
            schedule.restart(node.sim.t)
            continue
        node.check_timeout()
        node.step()
        if schedule.due(node.sim.t) or node.finished or node.stopped:
            node.publish_state()


def run_realtime(node, should_stop):
    schedule = PublishSchedule(node.params["publish_rate"])
    pacer = RealtimePacer(node.params["rate_factor"], node.period, schedule.period)
    periods = 0
    while not (node.stopped or node.finished or should_stop()):
        if node.control.between_periods(should_stop):      # paused, stepped or reset: the clock
            pacer.restart(node.sim.t)                        # starts again from the simulated time
            schedule.restart(node.sim.t)
            continue
        node.check_timeout()
        node.step()                      # compute ahead: the state at the end of this period
        periods += 1
        late = pacer.wait_until(node.sim.t, should_stop)
        if late:
            node.get_logger().warning(late)
        if schedule.due(node.sim.t) or node.finished or node.stopped:
            pacer.published()
            node.publish_state()
    report = pacer.report(node.sim.t, periods)
    if report:
        node.get_logger().info(report)


@contextlib.contextmanager
def spinning_in_background(executor):
    """The executor spinning in a second thread while the body runs: in realtime and fast the
    command callback only stores the command, so that waiting for commands costs the loop nothing."""
    done = threading.Event()

    def spin():
        while not done.is_set():
            executor.spin_once(timeout_sec=0.05)
    spinner = threading.Thread(target=spin, name="biped_sim-commands", daemon=True)
    spinner.start()
    try:
        yield
    finally:
        done.set()
        spinner.join(timeout=2.0)
