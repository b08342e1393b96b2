"""What ``sim_node`` watches on the wall clock besides its run: the ROS graph and a silent controller.

Owns :class:`RunWatch`, a timer of the node that runs two checks every :data:`WATCH_PERIOD` s of
wall time (a steady clock, whatever the simulated time does), each a plain class that returns the
lines to log (the lockstep rule for a command tagged with the state it answers is
:func:`biped_sim.recording.node_run.stale_command`):

* :class:`GraphWatch`: another node of the same name (a call to its ``~/reset`` resets both), or
  another node on the node's topics -- a second publisher of ``hip_torque``
  (two controllers: in lockstep each command advances the run one period) or another publisher of
  ``joint_states`` (a second simulation on this domain: its controller answers both). Said once per
  new set of publishers, naming them (``get_publishers_info_by_topic``): such runs used to end
  later with a wrong physical diagnosis and no word about the cause.
* :class:`SilenceWatch`: in lockstep, no command for ``lockstep_warn_after`` s: a warning with the
  last command's simulated time and wall age, repeated after 2, 4, ... times as long (at most
  every :data:`MAX_REPEAT` s); the node keeps waiting (lockstep is deterministic) unless
  ``lockstep_timeout`` says to end the run.

* :class:`MarkerLoad`: the wall time the node spends drawing the robot (``markers``): beyond
  :data:`MARKER_SHARE_WARN` of the wall time, one warning naming ``marker_rate`` and a value this
  machine draws within :data:`MARKER_SHARE_ADVISED` (the lag warning of a realtime run names the
  loop's knobs; the markers, at a wall-time rate, are the cost none of those lowers).

And :class:`WarningBurst`, one warning that can come in bursts (refused pushes): the first said in
full, the rest summed up in one line per :data:`BURST_SUMMARY_INTERVAL` s (the watch timer says the
last summary of a burst).
"""
from __future__ import annotations

import math
import threading
import time

from rclpy.clock import Clock, ClockType
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

#: wall seconds between two checks (the graph query costs about 0.1 ms)
WATCH_PERIOD = 0.5
#: the longest interval (wall s) between two warnings about a silent controller
MAX_REPEAT = 60.0
#: drawing the markers (build, serialise, record, publish) above this share of the wall time is warned
MARKER_SHARE_WARN = 0.10
#: the share of the wall time the advised marker_rate costs (the default 30 Hz costs 1-2 % here)
MARKER_SHARE_ADVISED = 0.05
#: the shortest stretch of wall time (s) over which the markers' share is measured
MARKER_WINDOW = 1.0
#: wall seconds between two lines about one kind of refusal that comes in a burst
BURST_SUMMARY_INTERVAL = 2.0
#: lockstep: a run that has waited this long (wall s) for a command offers its newest state again to a
#: ``joint_states`` subscriber that appears with volatile durability (a controller with rclpy's default
#: QoS started after the node: it never received the state it must answer)
REOFFER_AFTER = 0.5


#: the node name rclpy gives an endpoint whose node is not discovered yet
UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"


def endpoint_name(info) -> str:
    """The fully qualified node name of a ``TopicEndpointInfo``."""
    ns = info.node_namespace.rstrip("/")
    return f"{ns}/{info.node_name}"


def best_effort(endpoints) -> list:
    """The names among ``endpoints`` ((name, QoS) pairs) that publish best effort: DDS does not match them
    with this node's reliable ``hip_torque`` subscription, so none of their commands arrive."""
    return sorted(name for name, qos in endpoints if qos.reliability == ReliabilityPolicy.BEST_EFFORT)


class GraphWatch:
    """Other publishers on the command and the state topic; each new set is said once."""

    def __init__(self, node, command_topic: str, state_topic: str | None):
        self.node = node
        self.own = node.get_fully_qualified_name()
        self.command_topic, self.state_topic = command_topic, state_topic
        self.said = {command_topic: (), state_topic: ()}
        self.said_same_name = 1
        self.said_best_effort = ()

    def others(self, topic: str, own_publishers: int) -> list:
        """Names of the publishers of ``topic`` other than this node's ``own_publishers``."""
        names = sorted(endpoint_name(i) for i in self.node.get_publishers_info_by_topic(topic))
        for _ in range(own_publishers):
            if self.own in names:
                names.remove(self.own)
        return names

    def namesakes(self) -> int:
        """How many nodes (this one included) are named as this one. The graph's list of node names
        holds each name once, so they are counted by their publishers on the topics every node has."""
        return max(sum(1 for i in self.node.get_publishers_info_by_topic(topic) if endpoint_name(i) == self.own)
                   for topic in ("/rosout", "/parameter_events"))

    def endpoints(self, topic: str, publishers: bool) -> list:
        """(node name, QoS profile) of the publishers (or subscribers) of ``topic`` other than this node."""
        infos = (self.node.get_publishers_info_by_topic if publishers else
                 self.node.get_subscriptions_info_by_topic)(topic)
        return [(endpoint_name(i), i.qos_profile) for i in infos if endpoint_name(i) != self.own]

    def check(self) -> list:
        """The warnings about a set of publishers (or of nodes of this name) not said before."""
        lines = []
        same = self.namesakes()
        if same > 1 and same != self.said_same_name:
            lines.append(
                f"{same} nodes are named {self.own} on this ROS domain: a call to {self.own}/reset, "
                f"{self.own}/pause or {self.own}/step reaches each of them (one call resets, pauses or steps "
                "every run), and their parameters and logs cannot be told apart. Give each node its own name: "
                "sim_node --ros-args -r __node:=NAME (its services are then /NAME/reset, /NAME/pause, /NAME/step)")
        self.said_same_name = max(same, 1)
        commanders = self.others(self.command_topic, 0)
        if len(commanders) > 1 and tuple(commanders) != self.said[self.command_topic]:
            lines.append(
                f"{len(commanders)} nodes publish {self.command_topic}: {', '.join(commanders)}. Two controllers "
                "drive one run: in lockstep a command tagged with the state it answers is taken once (a second "
                "answer is stale and ignored), an untagged one advances the run every time; stop all but one")
        self.said[self.command_topic] = tuple(commanders) if len(commanders) > 1 else ()
        # rclpy's own warning of an incompatible QoS needs event handlers on the subscription, which the
        # realtime loop's command subscription does without (they kept the executor awake): said here
        unmatched = best_effort(self.endpoints(self.command_topic, publishers=True))
        if unmatched and tuple(unmatched) != self.said_best_effort:
            lines.append(
                f"{', '.join(unmatched)} publish{'es' if len(unmatched) == 1 else ''} {self.command_topic} best "
                "effort; this node's subscription is reliable, and DDS does not match the two: none of its commands "
                "arrive. Publish hip_torque reliable (rclpy's default QoS)")
        self.said_best_effort = tuple(unmatched)
        if self.state_topic is not None:
            sims = self.others(self.state_topic, 1)
            if sims and tuple(sims) != self.said[self.state_topic]:
                same = " (the same name as this node)" if self.own in sims else ""
                lines.append(
                    f"another node also publishes {self.state_topic}: {', '.join(sims)}{same}. Two simulations "
                    "on one ROS domain mix their states and their controllers' commands: give each its own "
                    "ROS_DOMAIN_ID (or namespace, -r __ns:=/name), or stop one")
            self.said[self.state_topic] = tuple(sims)
        return lines


class SilenceWatch:
    """Lockstep: how long since the last command, and what to say (or do) about it."""

    def __init__(self, warn_after: float, timeout: float, now: float | None = None):
        self.warn_after, self.timeout = warn_after, timeout
        self.last_wall = time.monotonic() if now is None else now
        self.last_t = None              # simulated time of the state the last command answered
        self.next_warning = warn_after
        self.warnings = 0

    def commanded(self, t: float | None, now: float | None = None):
        """A command advanced the run from simulated time ``t`` (None: the node waited for another
        reason, a pause: the time since the last command starts again, its ``t`` is kept)."""
        self.last_wall = time.monotonic() if now is None else now
        if t is not None:
            self.last_t = t
        self.next_warning = self.warn_after

    def silent_for(self, now: float | None = None) -> float:
        return (time.monotonic() if now is None else now) - self.last_wall

    def check(self, t: float, now: float | None = None, why=lambda: None) -> tuple:
        """(warning or None, end-of-run message or None) at simulated time ``t``; ``why()``: what the ROS
        graph says of the silence (or None), asked only when there is a warning to give."""
        silent = self.silent_for(now)
        last = ("no command since the start" if self.last_t is None else
                f"the last command answered the state at t={self.last_t:.6f} s")
        if self.timeout and silent >= self.timeout:
            return None, (f"lockstep: no hip_torque command for {silent:.1f} s (wall) at t={t:.6f} s, more than "
                          f"lockstep_timeout={self.timeout:g} s ({last}): the run ends")
        if self.warn_after and silent >= self.next_warning:
            self.warnings += 1
            self.next_warning = min(2 * self.next_warning, self.next_warning + MAX_REPEAT)
            cause = why() or "Is the controller running, on this ROS_DOMAIN_ID?"
            return (f"lockstep: waiting for a hip_torque command at t={t:.6f} s: {last}, {silent:.1f} s ago (wall). "
                    f"{cause} The run advances one control period per command and keeps waiting"
                    + (f" (lockstep_timeout={self.timeout:g} s)" if self.timeout else
                       " (set lockstep_timeout to end it)")), None
        return None, None


def round_down_125(x: float) -> float:
    """The largest 1, 2 or 5 times a power of ten that is at most ``x`` (x > 0): a rate to type."""
    power = 10.0 ** math.floor(math.log10(x))
    return next(m * power for m in (5, 2, 1) if m * power <= x * (1 + 1e-9))


class MarkerLoad:
    """The wall time spent drawing markers, measured over stretches of at least MARKER_WINDOW s of a
    running (not paused) run; said once, with a ``marker_rate`` this machine draws within
    MARKER_SHARE_ADVISED of the wall time, when a stretch (or the last, shorter one of a run that
    ends) went above MARKER_SHARE_WARN."""

    def __init__(self, rate: float):
        self.rate = rate
        self.lock = threading.Lock()      # drawn in the run's thread, checked in the watch timer's
        self.begin = None                 # the stretch begins at its first array: not at a start or a pause
        self.drawn = 0
        self.busy = 0.0
        self.said = False

    def drew(self, seconds: float):
        """One MarkerArray drawn (built, serialised, published, recorded) in ``seconds`` of wall time."""
        with self.lock:
            if self.begin is None:
                self.begin = time.monotonic() - seconds
            self.drawn += 1
            self.busy += seconds

    def check(self, now: float | None = None, final: bool = False, paused: bool = False) -> str | None:
        """The warning, once per run, if the stretch that ends now (at least MARKER_WINDOW s long, or
        any length if ``final``) took more than MARKER_SHARE_WARN of the wall time drawing markers.
        ``paused``: the run draws nothing, the stretch is dropped (a pause is not a cheap marker)."""
        now = time.monotonic() if now is None else now
        with self.lock:
            if self.begin is None:
                return None
            span, drawn, busy = now - self.begin, self.drawn, self.busy
            if span < MARKER_WINDOW and not (final or paused):
                return None
            self.begin, self.drawn, self.busy = None, 0, 0.0
        if paused or self.said or drawn < 10 or span <= 0 or busy / span < MARKER_SHARE_WARN:
            return None
        self.said = True
        share, each = busy / span, busy / drawn
        advised = max(0.1, round_down_125(min(MARKER_SHARE_ADVISED / each, 0.999 * self.rate)))
        return (f"markers: drawing the robot at marker_rate={self.rate:g} Hz took {share:.0%} of the wall time "
                f"({drawn} MarkerArrays in {span:.1f} s, {each * 1e3:.2f} ms each, built, serialised, sent "
                "and recorded), time the simulation loop needs (a realtime run falls behind, fast and lockstep runs "
                f"slow down; lowering publish_rate or rate_factor does not lower it). Set marker_rate:={advised:g} "
                f"(about {advised * each:.0%} of the wall time here), or leave markers out of outputs")


class WarningBurst:
    """A warning that can come many times a second (a publisher of bad pushes): the first is said in
    full; the ones after it, within :data:`BURST_SUMMARY_INTERVAL` s of the last line, are counted and
    said in one summary line (with the last one's text) once the interval is over -- by the next one
    or by :meth:`flush`, which the watch timer calls and the node calls before its final status."""

    def __init__(self, warn, what: str, interval: float = BURST_SUMMARY_INTERVAL):
        self.warn, self.what, self.interval = warn, what, interval
        self.total = 0          # all of them, said or not
        self.unsaid = 0         # since the last line
        self.last_text = None
        self.last_line = -float("inf")
        self.lock = threading.Lock()    # added to by the executor, flushed also by the run's thread

    def add(self, text: str, now: float | None = None):
        """One more; ``text`` says what and why (without the count)."""
        now = time.monotonic() if now is None else now
        with self.lock:
            self.total += 1
            if self.unsaid == 0 and now - self.last_line >= self.interval:
                self.last_line = now
                self.warn(f"{text} ({self.total} {self.what} so far)")
                return
            self.unsaid += 1
            self.last_text = text
        self.flush(now)

    def flush(self, now: float | None = None, final: bool = False):
        """Say the ones not said yet, if the interval since the last line is over (or ``final``)."""
        now = time.monotonic() if now is None else now
        with self.lock:
            if not self.unsaid or (not final and now - self.last_line < self.interval):
                return
            self.warn(f"{self.unsaid} more {self.what} in the last {now - self.last_line:.1f} s, the last: "
                      f"{self.last_text} ({self.total} {self.what} so far)")
            self.unsaid, self.last_line = 0, now


class RunWatch:
    """The node's watch timer: logs what :class:`GraphWatch` finds; in lockstep, what
    :class:`SilenceWatch` finds, and ends the run (``node.fault``) after ``lockstep_timeout``."""

    def __init__(self, node):
        self.node = node
        self.graph = GraphWatch(node, node.sub.topic_name, node.pub_js.topic_name if node.pub_js else None)
        self.silence = (SilenceWatch(node.params["lockstep_warn_after"], node.params["lockstep_timeout"])
                        if node.mode == "lockstep" else None)
        self.markers = MarkerLoad(node.params["marker_rate"]) if node.markers is not None else None
        self.offered = set()    # the volatile joint_states subscribers seen (lockstep: offered the state)
        node.create_timer(WATCH_PERIOD, self.check, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def check_markers(self, final: bool = False):
        """The markers' share of the wall time (``final``: at the end of the run, before its figures)."""
        if self.markers is None:
            return
        control = getattr(self.node, "control", None)
        warning = self.markers.check(final=final, paused=control is not None and control.paused)
        if warning:
            self.node.get_logger().warning(warning)

    def commanded(self, t: float):
        if self.silence is not None:
            self.silence.commanded(t)

    def offer_state_to_late_subscribers(self):
        """Lockstep: the newest state published again (not recorded) when a volatile ``joint_states``
        subscriber appeared while the run waits for a command: it could not have received it."""
        node = self.node
        if node.pub_js is None:
            return
        volatile = {name for name, qos in self.graph.endpoints(node.pub_js.topic_name, publishers=False)
                    if qos.durability == DurabilityPolicy.VOLATILE}
        new, self.offered = volatile - self.offered, volatile
        if new and self.silence.silent_for() >= REOFFER_AFTER:
            node.offer_state_again()
            # (a subscription can be discovered before its node's name: rclpy says _NODE_NAME_UNKNOWN_)
            names = sorted("a node not yet named" if UNKNOWN_NODE in name else name for name in new)
            node.get_logger().info(
                f"lockstep: {', '.join(names)} subscribed to {node.pub_js.topic_name} (volatile) after the "
                f"state at t={node.sim.t:.6f} s was published: offered it again (the run waits for its answer)")

    def silence_cause(self):
        """What the graph says of a silent lockstep controller: a ``joint_states`` subscriber is there (the
        controller runs on this domain) but no ``hip_torque`` publisher, or one whose QoS cannot reach the
        node's reliable subscription."""
        node = self.node
        if node.pub_js is None:
            return None
        listeners = sorted({name for name, _ in self.graph.endpoints(node.pub_js.topic_name, publishers=False)})
        if not listeners:
            return None
        topic = node.sub.topic_name
        commanders = self.graph.endpoints(topic, publishers=True)
        here = (f"{', '.join(listeners)} subscribe{'s' if len(listeners) == 1 else ''} to "
                f"{node.pub_js.topic_name} (so the controller runs on this ROS domain)")
        if not commanders:
            return (f"{here}, but no node publishes {topic}: does the controller publish its command there "
                    "(std_msgs/Float64MultiArray, data [u1, u2])? Check the topic name and remappings.")
        unmatched = best_effort(commanders)
        if unmatched:
            return (f"{here}; {', '.join(unmatched)} publish{'es' if len(unmatched) == 1 else ''} {topic} best "
                    "effort, which this node's reliable subscription does not match: publish it reliable "
                    "(rclpy's default QoS).")
        return (f"{here}, and {', '.join(sorted({n for n, _ in commanders}))} publish {topic}, but no command has "
                "come: a lockstep controller publishes one command for each joint_states message it receives.")

    def check(self):
        node = self.node
        log = node.get_logger()
        for line in self.graph.check():
            log.warning(line)
        node.control.refused_pushes.flush()
        self.check_markers()
        if self.silence is None or node.finished or node.stopped or node.fault:
            return
        control = getattr(node, "control", None)
        if control is not None and control.paused:     # ~/pause holds the run: the controller is not silent
            self.silence.commanded(None)
            return
        self.offer_state_to_late_subscribers()
        warning, end = self.silence.check(node.sim.t, why=self.silence_cause)
        if warning:
            log.warning(warning)
        if end:
            log.error(end)
            node.fault = ("stopped", end)
