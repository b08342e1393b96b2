"""The run loops of ``sim_node``'s three time modes, and their clocks.

Owns when the node steps and publishes: ``lockstep`` (each command steps once: the loop only
spins), ``fast`` (step as fast as possible) and ``realtime`` (simulated time t is due at wall time
``start + t / rate_factor``: :class:`RealtimePacer` sleeps until then, says when the loop is
late, resynchronises after a stall, and measures the achieved rate). Both publish at
``publish_rate`` in simulated time, whatever the control period (:class:`PublishSchedule`). The loops drive a
:class:`biped_sim.ros.sim_node.SimNode` through its ``take_commands``, ``check_timeout``, ``step`` and
``publish_state``; the pacing and the schedule are plain Python.
"""
from __future__ import annotations

import contextlib
import math
import threading
import time

#: a loop that is late says so at most this often (wall s)
LAG_REPORT_INTERVAL = 2.0
#: the loop "cannot keep up" once it has been late (see RealtimePacer.late_bound) at every control
#: period for this long (wall s): a late period that the loop catches up within it is jitter
LATE_FOR = 1.0
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
        # a period is late when it is due more than this long ago (wall s) when the loop reaches it
        self.late_bound = max(control_period / rate_factor, 0.005)
        self.late_since = None                                  # (wall, t) at the first late period in a row
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
        """Sleep until simulated time ``t`` is due; a warning if the loop cannot keep up (at most one
        every LAG_REPORT_INTERVAL s, see :meth:`_late`), or if the loop stalled.

        A stall: the wall time since the last period waited for exceeds what the simulated time
        between them needs by more than ``stall_bound``, at once (a loop that falls behind a little
        each period is not one). Holding to the old clock would replay the stall as fast as the loop
        goes; instead ``t`` is due now: the simulated time goes on from where it was, and the stall
        is left out of the figures. Returns early, ``t`` not yet due, once ``should_stop()``.

        The wait is one sleep to the deadline (in slices of at most STOP_CHECK_INTERVAL): Python's
        ``time.sleep`` sleeps with ``clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`` on the deadline
        it computes at the call, the clock of ``time.monotonic``; no spinning before the deadline."""
        now = time.monotonic()
        warning = self._resync_if_stalled(t, now)
        deadline = self.start + t / self.rate
        if warning is None:
            warning = self._late(t, now, now - deadline)
        while not should_stop():
            left = deadline - time.monotonic()
            if left <= 0.0:
                break
            # in slices: a period can be long (control_period 1 s at rate_factor 0.01 is 100 s of wall
            # time), and a stop signal only appends to a list, so one sleep held the node's end that long
            time.sleep(min(left, STOP_CHECK_INTERVAL))
        # stopped during the sleep: the period is published late, the next ones must not catch up
        warning = self._resync_if_stalled(t, time.monotonic()) or warning
        self.last_t, self.last_wall = t, time.monotonic()
        return warning

    def _late(self, t: float, now: float, lag: float) -> str | None:
        """The "cannot keep up" warning, if the loop has been late at every period for LATE_FOR s.

        ``lag``: how long ago (wall s) ``t`` was due when the loop reached it. A period is late when
        ``lag`` exceeds ``late_bound`` (a control period of wall time, at least 5 ms); one that is
        not ends the run of late periods. A run of them that lasts LATE_FOR s is a loop that cannot
        keep up; the warning gives the lag now and the real-time factor over that run."""
        if lag <= self.late_bound:
            self.late_since = None
            return None
        if self.late_since is None:
            self.late_since = (now, t)
            return None
        since_wall, since_t = self.late_since
        late_for = now - since_wall
        if late_for < LATE_FOR or now - self.last_lag_report <= LAG_REPORT_INTERVAL:
            return None
        self.last_lag_report = now
        self.lag_reports += 1
        return (f"realtime: cannot keep up: simulated time {t:.3f} s is reached {lag:.3f} s (wall) after it was "
                f"due, and every control period of the last {late_for:.1f} s was late by more than "
                f"{self.late_bound * 1e3:.0f} ms; real-time factor over them {(t - since_t) / late_for:.3g} against "
                f"rate_factor {self.rate:g}; lower "
                "publish_rate or rate_factor, raise control_period, or use time_mode fast")

    def _resync_if_stalled(self, t: float, now: float) -> str | None:
        """If the loop stalled since the last period waited for: ``t`` is due at ``now``, the
        current segment ends at the last period, a new one begins; the warning line."""
        stalled = now - self.last_wall - (t - self.last_t) / self.rate
        if stalled <= self.stall_bound:
            return None
        self.stalls += 1
        self.stalled_wall += stalled
        self.late_since = None
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
        self.late_since = None
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
        node.take_commands()
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
        node.take_commands()             # those received by the start of the period
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
    """The executor spinning in a second thread while the body runs (realtime and fast): the services,
    the timers and ``push``. Not ``hip_torque``, which the loop takes at each period's start
    (:class:`~biped_sim.ros.sim_node.TakenByTheLoop`): the thread sleeps in its wait set between them."""
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
