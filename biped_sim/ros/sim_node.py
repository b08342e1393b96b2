"""``sim_node``: the rclpy node (name ``biped_sim``) around the hybrid engine; no physics here.

Owns the ROS side of a run: the parameters (the table of :mod:`biped_sim.config.parameters`,
declared by :func:`biped_sim.ros.parameters.declare_from_table`; an unknown or ill-typed one stops
the start with exit code 2), the topics (``hip_torque`` in; ``joint_states``, ``ground_reaction``,
``impact``, ``diagnostics`` and ``/clock`` out), the three time modes (realtime, fast, lockstep), the
checks on incoming torque commands, the command timeout, the signals, and the calls to the recorder
(:mod:`biped_sim.recording.recorder`, optional). The state comes from the engine one control period
at a time; the messages are built by :mod:`biped_sim.recording.messages`.
"""
from __future__ import annotations

import gc
import os
import sys
import time
from datetime import datetime, timezone

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rclpy.callback_groups import CallbackGroup
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.subscription import Subscription
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

from biped_sim.config import parameters as P
from biped_sim.engine import compiled_loop
from biped_sim.engine.compiled import IMPLEMENTATION as GENERATED_CODE, WHY_PYTHON
from biped_sim.engine.guards import prepare_event_location
from biped_sim.recording.cdr import read_float64_multi_array
from biped_sim.recording.markers import TF_TOPIC, TF_TYPE, MarkerStream, hip_transform
from biped_sim.recording.messages import (
    TOPIC_TYPES,
    answered_ns,
    diagnostic_array,
    event_status,
    to_ns,
)
from biped_sim.recording.node_run import NodeRun, event_output, stale_command
from biped_sim.ros import params_files, run_watch, startup
from biped_sim.ros.one_topic_spin import OneTopicSpin
from biped_sim.ros.parameters import declare_from_table, usage_text, value_less_override_message
from biped_sim.ros.recording_guard import GuardedRecorder, failure_message
from biped_sim.ros.sim_control import SimControl
from biped_sim.ros.startup import StartupError
from biped_sim.ros.time_modes import run_fast, run_lockstep, run_realtime, spinning_in_background

QOS_DEPTH = 100
# reliable, and transient_local so that a subscriber that asks for it (a lockstep controller that
# starts after the node) still gets the last QOS_DEPTH messages, e.g. the state at t = 0
STATE_QOS = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)
COMMAND_QOS = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE)


class TakenByTheLoop(CallbackGroup):
    """The callback group of ``hip_torque``: the executor never waits on the subscription itself, whose
    messages the run loop takes (:meth:`SimNode.take_commands`, ``OneTopicSpin`` in lockstep); its QoS
    event handlers are served by the executor as in a reentrant group.

    A command that woke the executor's thread cost the realtime node about 0.2 ms of CPU a period
    (the executor's wait set of every entity built and torn down at each command, 1 kHz), and the
    command is needed only when the next period starts (docs/performance.md, "The node in realtime")."""

    def can_execute(self, entity) -> bool:
        return not isinstance(entity, Subscription)

    def beginning_execution(self, entity) -> bool:
        return self.can_execute(entity)

    def ending_execution(self, entity) -> None:
        pass


class SimNode(Node):
    """The node; ``run(should_stop, executor)`` drives it in the chosen time mode."""

    def __init__(self, context=None, argv=None):
        try:
            super().__init__("biped_sim", context=context, automatically_declare_parameters_from_overrides=True)
        except ValueError as exc:
            raise StartupError(value_less_override_message(exc) or exc) from None
        params_files.check_applies(self, sys.argv if argv is None else argv)
        self.params = prm = declare_from_table(self, P.PARAMETERS)
        try:
            # the run's rules (command check, period, events, state messages) are NodeRun's, shared with
            # simulate --record and resim; the node publishes as it goes (the engine keeps the last sample)
            self.run_rules = NodeRun(prm)
        except ValueError as exc:
            raise StartupError(f"cannot start the engine with these parameters: {exc}") from None
        # the root finder now, not at the first event: its import (~0.4 s) inside a control period stalls
        # a realtime run long enough for its command timeout to fire
        prepare_event_location()
        self.mode = prm["time_mode"]
        self.period = prm["control_period"]
        self.duration = prm["duration"]
        self.timeout = 0.0 if self.mode == "lockstep" else prm["command_timeout"]
        # a run without a duration is watched by someone: after an engine stop it stays up for
        # inspection (and ~/reset). A run with one is a batch run: nobody is there to press Ctrl-C
        self.stay_up_after_stop = self.duration == 0
        self.counts = dict(received=0, rejected=0, clipped=0, timeouts=0, ignored=0, stale=0)
        self.run_rules.counts = self.counts     # the run's rules count the rejected and clipped commands here
        self.fault = None               # (status, message): the run ended by a fault (recording, lockstep_timeout)
        self.last_command_wall = None
        self.timed_out = False
        self._wall_first_period = None  # wall clock at the first control period (figures: periods per wall s)
        self.earlier_runs = dict(runs=0, periods=0, engine_wall=0.0)   # the engines ~/reset replaced (figures)

        out = set(prm["outputs"])
        if self.mode == "lockstep" and "joint_states" not in out:
            # a lockstep controller answers each joint_states message: without it no command comes and
            # the run waits in silence (the watch's warning needs lockstep_warn_after s, if it is set)
            raise StartupError(f"time_mode lockstep needs joint_states in outputs (the controller answers each "
                               f"state with the command that advances the run; outputs={prm['outputs']}): add "
                               "it, e.g. outputs:=[" + ", ".join(["joint_states", *prm["outputs"]]) + "]")
        self.pub_js = self._publisher(JointState, "joint_states") if "joint_states" in out else None
        self.pub_grf = self._publisher(WrenchStamped, "ground_reaction") if "ground_reaction" in out else None
        self.pub_impact = (self._publisher(DiagnosticArray, "impact")
                           if "impact" in out and "impact" in prm["phases"] else None)
        self.pub_clock = self._publisher(Clock, "/clock") if "clock" in out else None
        self.pub_diag = self._publisher(DiagnosticArray, "diagnostics")
        # the robot drawn, at marker_rate of wall time; a scene without "markers" computes nothing for it
        self.pub_markers = self._publisher(MarkerArray, "markers") if "markers" in out else None
        self.markers = MarkerStream(self.sim.model, prm["slope"], prm["marker_rate"]) if "markers" in out else None
        self.sub = self.create_subscription(Float64MultiArray, "hip_torque", self._on_command, COMMAND_QOS,
                                            callback_group=TakenByTheLoop(),
                                            event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False))
        self.control = SimControl(self, COMMAND_QOS)    # ~/pause, ~/step, ~/reset and the push topic
        state_pubs = dict(joint_states=self.pub_js, ground_reaction=self.pub_grf, clock=self.pub_clock)
        # the state messages come labelled with their topics: published by topic, recorded as they come
        self.run_rules.label_states({name: pub.topic_name for name, pub in state_pubs.items() if pub is not None})
        self._state_pubs = {pub.topic_name: pub for pub in state_pubs.values() if pub is not None}
        self.recorder = self.bag_path = None
        if prm["record"]:
            self._open_recorder()
        self.watch = run_watch.RunWatch(self)     # other nodes on our topics, a silent lockstep controller
        self.get_logger().info(
            f"biped_sim: robot={prm['robot']}, time_mode={self.mode}, control_period={self.period:g} s, "
            f"duration={self.duration:g} s, "
            f"outputs={sorted(out)}, phases={sorted(prm['phases'])}, base={prm['base']}, "
            f"method={self.sim.method}" + (" (auto)" if prm["method"] == "auto" else "")
            + f", generated code in {GENERATED_CODE}" + (f" ({WHY_PYTHON})" if WHY_PYTHON else "")
            + (", hybrid loop in C" if compiled_loop.AVAILABLE and self.sim._loop is not None
               else f", hybrid loop in Python ({compiled_loop.WHY_NOT or self._why_python_loop()})")
            + (f", recording to {self.bag_path}" if self.recorder else ""))

    def _why_python_loop(self):
        """Why the hybrid loop is Python's: a described robot's reason (compiled_loop.why_not_described)."""
        return compiled_loop.why_not_described(self.sim.model) or compiled_loop.WHY_NOT_GENERATED

    # the run's state lives in its NodeRun; these names are the node's view of it
    sim = property(lambda self: self.run_rules.sim)
    u = property(lambda self: self.run_rules.u, lambda self, u: setattr(self.run_rules, "u", u))
    finished = property(lambda self: self.run_rules.finished)
    stopped = property(lambda self: self.run_rules.stopped)

    def _publisher(self, msg_type, topic):
        # no default event callbacks: the node does not act on QoS events
        return self.create_publisher(msg_type, topic, STATE_QOS,
                                     event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

    def publishers_by_output(self) -> dict:
        """{output name (a key of TOPIC_TYPES): publisher} of the topics this run publishes."""
        pubs = dict(joint_states=self.pub_js, ground_reaction=self.pub_grf, impact=self.pub_impact,
                    clock=self.pub_clock, diagnostics=self.pub_diag, markers=self.pub_markers)
        return {k: v for k, v in pubs.items() if v is not None}

    # -- recording ------------------------------------------------------------------------------
    def restart_run(self):
        """A new engine at the scene's initial state (~/reset) replaces the current one, whose cost the
        figures keep."""
        self.earlier_runs["runs"] += 1
        self.earlier_runs["periods"] += self.sim.control_periods
        self.earlier_runs["engine_wall"] += self.sim.stats["wall_time"]
        self.run_rules.restart()

    def _open_recorder(self, path=None):
        try:
            from biped_sim.recording.recorder import BagRecorder  # optional: needs mcap
        except ModuleNotFoundError as exc:
            if exc.name != "biped_sim.recording.recorder":
                raise
            self.get_logger().warning("record is true but biped_sim.recording.recorder is not available: "
                                      "this run is not recorded")
            return
        claimed = None
        if path is None:
            when = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
            self.bag_path = claimed = self._claim_bag_dir(f"{self.params['scene']}-{when}")
        else:
            self.bag_path = path
        try:
            self.recorder = GuardedRecorder(BagRecorder(self.bag_path, parameters=dict(self.params)),
                                            self._recording_failed)
        except (OSError, ValueError) as exc:
            if claimed is not None:
                try:
                    os.rmdir(claimed)       # leave no empty bag directory behind
                except OSError:
                    pass
            raise StartupError(f"cannot record to '{self.bag_path}': {exc} (set bag_dir to a writable "
                               "folder, or record:=false)") from None
        for output, pub in self.publishers_by_output().items():
            self.recorder.add_topic(pub.topic_name, TOPIC_TYPES[output], qos=STATE_QOS)
        if self.markers is not None:    # recorded, not published: no tf2_msgs type support here
            self.recorder.add_topic(TF_TOPIC, TF_TYPE, qos=STATE_QOS)
        self.recorder.add_topic(self.sub.topic_name, TOPIC_TYPES["hip_torque"], qos=COMMAND_QOS)
        # the writer process starts now rather than during the run's first periods (on 2 cores it took
        # the CPU from them: about 0.15 s of imports)
        self.recorder.wait_ready()

    def _claim_bag_dir(self, name: str) -> str:
        """``<bag_dir>/<name>``, or ``<name>-2``, ``-3``, ... if taken, created here so that it is this
        node's alone: two nodes started in one second with one ``bag_dir`` (a launch file) chose the
        same name, and the second refused to start ("exists and is not an empty directory"), or both
        wrote into it. A folder that cannot be made is left for the recorder to report."""
        base = os.path.join(self.params["bag_dir"], name)
        for n in range(1, 1000):
            candidate = base if n == 1 else f"{base}-{n}"
            try:
                os.makedirs(self.params["bag_dir"], exist_ok=True)
                os.mkdir(candidate)
                return candidate
            except FileExistsError:
                continue
            except OSError:
                return base
        return base

    def _publish(self, pub, msg, t):
        pub.publish(msg)
        if self.recorder is not None:
            self.recorder.write(pub.topic_name, msg, to_ns(t))

    def _recording_failed(self, exc):
        """The bag cannot be written (disk full, writer gone): say so, end the run (see run_watch)."""
        message = failure_message(self.bag_path, exc, self.sim.t)
        self.get_logger().error(message)
        self.fault = self.fault or ("failed", message)

    def close(self) -> bool:
        """Close the bag; False if that failed (said in the log)."""
        recorder, self.recorder = self.recorder, None
        return recorder is None or recorder.close(self.get_logger(), self.sim.t)

    # -- commands -----------------------------------------------------------------------------
    def _on_command(self, msg):
        self._command(list(msg.data), msg, msg)

    def _command(self, data, msg, recorded):
        """A ``hip_torque`` command's values ``data``: recorded (``recorded``: the message or its CDR),
        checked, and held from now on (in lockstep, after the stale check of ``msg``, then one period)."""
        t = self.sim.t
        self.counts["received"] += 1
        if self.recorder is not None:
            self.recorder.write(self.sub.topic_name, recorded, to_ns(t))
        if self.mode == "lockstep" and self._stale(msg, t):
            return
        u = self._check_command(data, t)
        if u is not None:
            self.u = u
            self.last_command_wall = time.monotonic()
            if self.timed_out:
                self.timed_out = False
                self.get_logger().info(f"hip_torque commands again at t={t:.6f} s")
        if self.mode == "lockstep":
            self._lockstep(t)

    def take_commands(self):
        """Run the command callback for each ``hip_torque`` message received since the last call, in
        order, without waiting (realtime and fast: at each period's start; the newest one holds)."""
        sub = self.sub
        raw = self.mode != "lockstep"     # realtime, fast: the tag is not read, so the CDR is decoded here
        with sub.handle:
            while True:
                taken = sub.handle.take_message(sub.msg_type, raw)
                if taken is None:
                    return
                if not raw:
                    self._on_command(taken[0])
                    continue
                # its CDR read by hand and handed to the bag as it came (rclpy's message and the
                # recorder's encoding of it cost ~10 us a command: issue 35's figures, performance.md)
                values = read_float64_multi_array(taken[0])
                if values is None:
                    self._on_command(deserialize_message(taken[0], sub.msg_type))
                else:
                    self._command(values[0], None, taken[0])

    def _lockstep(self, t):
        """One control period per command, then its state."""
        if self.control.hold_in_lockstep():    # paused: this command steps once on resume
            return
        if self.finished or self.stopped:
            self.counts["ignored"] += 1
            self.get_logger().warning(
                f"lockstep: command ignored, the run has {'ended' if self.finished else 'stopped'} at "
                f"t={t:.6f} s ({self.counts['ignored']} ignored)", throttle_duration_sec=1.0)
            return
        self.watch.commanded(t)
        self.step()
        self.publish_state()

    def _stale(self, msg, t) -> bool:
        """A command tagged as the answer to a state other than the newest: ignored (counted, warned)."""
        why = stale_command(answered_ns(msg), to_ns(t), self.control.before_reset_ns)
        if why is None or self.finished or self.stopped:
            return False
        self.counts["stale"] += 1
        self.get_logger().warning(f"lockstep: hip_torque ignored at t={t:.6f} s: {why} ({self.counts['stale']} "
                                  "stale so far)", throttle_duration_sec=1.0)
        return True

    def _check_command(self, data, t):
        """The torques to use, or None (rejected: counted, throttled warning, last command held)."""
        u, why = self.run_rules.check_command(data)
        if why is None:
            return u
        if u is not None:
            self.get_logger().warning(f"hip_torque {why} at t={t:.6f} s: clipped ({self.counts['clipped']} "
                                      "clipped so far)", throttle_duration_sec=1.0)
            return u
        self.get_logger().warning(
            f"hip_torque rejected at t={t:.6f} s: {why}; holding {self.u} ({self.counts['rejected']} rejected "
            "so far)", throttle_duration_sec=1.0)
        return None

    def check_timeout(self):
        if not self.timeout or self.last_command_wall is None or self.timed_out:
            return
        if time.monotonic() - self.last_command_wall > self.timeout:
            self.timed_out = True
            self.counts["timeouts"] += 1
            self.get_logger().warning(
                f"no hip_torque command for more than command_timeout={self.timeout:g} s (wall) at "
                f"t={self.sim.t:.6f} s: zero torque until the next command")
            self.u = self.run_rules.zero_torque()

    # -- stepping and publishing ----------------------------------------------------------------
    def step(self):
        """Advance one control period with the held torques (after the pushes received since the
        last one); publish its events."""
        if self._wall_first_period is None:
            self._wall_first_period = time.monotonic()
        events, ended = self.run_rules.advance(self.control.take_pushes())
        for ev in events:
            self._publish_event(ev)
        if ended == "stopped":
            self._on_engine_stopped()
        elif ended == "finished":
            self.get_logger().info(f"duration {self.duration:g} s reached: the run ends")

    def _publish_event(self, ev):
        st = event_status(ev)
        msg = diagnostic_array(ev.time, [st])
        if event_output(ev) == "impact":
            if self.pub_impact is not None:
                self._publish(self.pub_impact, msg, ev.time)
            if ev.warnings:
                self.get_logger().warning(st.message)
        else:
            self._publish(self.pub_diag, msg, ev.time)

    def _on_engine_stopped(self):
        sim = self.sim
        then = ("The node stays up for inspection (the last state stays published; ~/reset restarts the run); "
                "stop it with Ctrl-C" if self.stay_up_after_stop else
                f"The run ends here, before its duration {self.duration:g} s (exit code 1)")
        self.get_logger().error(f"the engine {sim.status} at t={sim.t:.9f} s: {sim.message}. {then}")
        self.publish_state()
        self.publish_run_status()

    def publish_run_status(self):
        """A DiagnosticStatus 'biped_sim/run' with the run's status and counters."""
        sim = self.sim
        st = DiagnosticStatus(name="biped_sim/run")
        status, message = self.fault or (sim.status, sim.message)   # a fault is never "running"
        if status == "running":
            st.level = DiagnosticStatus.OK
            st.message = "completed" if self.finished else "running"
        else:
            st.level = DiagnosticStatus.ERROR
            st.message = f"{status}: {message}"
        values = dict(status=status if status != "running" else st.message, time=repr(float(sim.t)),
                      message=message, control_periods=str(sim.control_periods), events=str(len(sim.events)),
                      impacts=str(sim.stats["impacts"]), engine_wall_time=repr(float(sim.stats["wall_time"])))
        values.update({f"commands_{k}": str(v) for k, v in self.counts.items()})
        values.update({k: str(v) for k, v in self.control.counts.items()})    # pushes, ~/step, ~/reset
        self.control.refused_pushes.flush(final=True)     # the end of a burst is said before the status
        st.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        self._publish(self.pub_diag, diagnostic_array(sim.t, [st]), sim.t)

    def publish_state(self):
        """joint_states, ground_reaction (in stance) and /clock at the engine's current time.

        The content of ``joint_state_message``/``wrench_message``/``clock_msg``, serialised once
        (:class:`~biped_sim.recording.cdr.StateSerializer`), published as bytes and handed to the
        recorder as they are."""
        sim = self.sim
        t_ns = to_ns(sim.t)
        state = self.run_rules.state_messages()
        for topic, data in state:
            self._state_pubs[topic].publish(data)
        if self.recorder is not None and state:
            self.recorder.write_messages(t_ns, state)
        if self.markers is not None:   # the last state of a run is always drawn
            begin = time.monotonic()
            msg = self.markers.poll(begin, sim, force=self.finished or self.stopped)
            if msg is not None:   # serialised once for the topic and the bag (1.2 ms a MarkerArray)
                self._publish(self.pub_markers, serialize_message(msg), sim.t)
                if self.recorder is not None:     # the frame a 3D view of the bag follows
                    self.recorder.write(TF_TOPIC, hip_transform(to_ns(sim.t), self.markers.hip), to_ns(sim.t))
                self.watch.markers.drew(time.monotonic() - begin)     # its share of the wall time (run_watch)

    def offer_state_again(self):
        """The newest state's messages published again to the subscribers, not recorded (a lockstep
        controller that subscribed after it was published: :class:`~biped_sim.ros.run_watch.RunWatch`)."""
        for topic, data in self.run_rules.state_messages():
            self._state_pubs[topic].publish(data)

    # -- time modes ---------------------------------------------------------------------------
    def run(self, should_stop, executor):
        """The run in the chosen time mode, until the duration, an engine error or ``should_stop()``;
        after an engine error a run without a duration stays up (for inspection) until ``should_stop()``
        or a ``~/reset``; one with a duration ends there."""
        self._cpu_run0 = time.process_time()
        self.publish_state()
        if self.mode == "lockstep":     # the command callback steps and publishes
            spin = OneTopicSpin(executor, self, self.sub)     # hip_torque first: see one_topic_spin
            while True:
                run_lockstep(self, should_stop, spin)
                self._end_run(should_stop, lambda: executor.spin_once(timeout_sec=0.1))
                if should_stop() or self.finished or self.stopped:
                    return              # else a ~/reset restarted a stopped run
        with spinning_in_background(executor):
            try:
                while True:
                    (run_fast if self.mode == "fast" else run_realtime)(self, should_stop)
                    self._end_run(should_stop, lambda: self.take_commands() or
                                  self.control.between_periods(should_stop) or time.sleep(0.05))
                    if should_stop() or self.finished or self.stopped:
                        return
            finally:
                self.control.close_requests(f"the node is shutting down at t={self.sim.t:.6f} s")

    def _end_run(self, should_stop, wait):
        self._cpu_end = time.process_time()
        self._wall_end = time.monotonic()
        if self.finished:
            self.publish_run_status()
        while not should_stop() and self.stopped and self.stay_up_after_stop:
            wait()

    def log_figures(self):
        """The run's cost: control periods, engine time and this process's CPU time per period, and the
        wall time from the first control period (in lockstep: the first command) to the end of the run
        (``benchmarks/bench_node.py`` and ``bench_record.py`` read this line)."""
        self.watch.check_markers(final=True)     # a run too short for the watch's stretches
        earlier = self.earlier_runs      # the runs before each ~/reset count too
        n = earlier["periods"] + self.sim.control_periods
        k = max(1, n)
        engine = earlier["engine_wall"] + self.sim.stats["wall_time"]
        cpu = getattr(self, "_cpu_end", time.process_time()) - getattr(self, "_cpu_run0", 0.0)
        end = getattr(self, "_wall_end", time.monotonic())
        wall = paused = 0.0
        if self._wall_first_period is not None:
            wall = end - self._wall_first_period
            paused = self.control.paused_between(self._wall_first_period, end)
        running = wall - paused
        runs = (f" in {earlier['runs'] + 1} runs ({earlier['runs']} ~/reset), the last" if earlier["runs"] else "")
        self.get_logger().info(
            f"{n} control periods{runs} to t={self.sim.t:.6f} s: engine {1e3 * engine / k:.3f} ms (wall) and process "
            f"CPU {1e3 * cpu / k:.3f} ms per period; wall {wall:.4f} s from the first control period "
            f"({n / running if running > 0 else 0.0:.1f} periods/s" + (f" over the {running:.4f} s not paused"
                                                                       if paused > 0 else "")
            + f"); commands {self.counts}; pushes and requests {self.control.counts}")

    def flush(self, timeout=5.0):
        """Wait (at most ``timeout`` s in all) until subscribers acknowledged what was published: a
        reliable message still unacknowledged when the node exits is lost, and a subscriber on a
        loaded machine can be seconds behind a lockstep run that ends."""
        deadline = time.monotonic() + timeout
        for pub in self.publishers_by_output().values():
            left = deadline - time.monotonic()
            if left <= 0:
                break
            try:
                pub.wait_for_all_acked(Duration(seconds=left))
            except Exception:  # an unacknowledged message is lost either way: do not fail the shutdown
                pass


def usage() -> str:
    topics = {t: TOPIC_TYPES[t] for t in ("joint_states", "ground_reaction", "impact", "diagnostics", "clock",
                                          "markers")}
    topics["/clock"] = topics.pop("clock")
    return usage_text("sim_node", "biped_sim", "Simulate the planar three-link biped; hip torques in, the state "
                      "out, the run recorded to a bag (record, bag_dir). Stop it with Ctrl-C or SIGTERM.",
                      P.PARAMETERS, {"hip_torque": TOPIC_TYPES["hip_torque"], "push": TOPIC_TYPES["push"]}, topics)


def main(argv=None):
    argv = sys.argv if argv is None else argv
    code = startup.read_command_line("sim_node", argv, usage)
    if code is not None:
        return code
    stop = startup.init("sim_node", argv)
    if stop is None:
        return startup.EXIT_REFUSED
    node = None
    try:
        try:
            node = SimNode(argv=argv)
        except StartupError as exc:
            return startup.refuse("sim_node", exc)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        # everything built so far (modules, rclpy, the node) lives until the end: exempt it from the
        # cyclic collector, whose full passes over it were the long pauses of a 1 kHz loop
        gc.collect()
        gc.freeze()
        node.run(lambda: bool(stop) or node.fault is not None, executor)
        if node.fault:          # said when it happened; the final status says it again
            node.publish_run_status()
        elif stop:
            node.get_logger().info(f"{startup.signal_name(stop[0])}: shutting down at t={node.sim.t:.6f} s")
            node.publish_run_status()
        node.log_figures()
        node.flush()
    finally:
        closed = True
        if node is not None:
            closed = node.close()
            node.destroy_node()
        rclpy.try_shutdown()
    # a run that did not complete by itself: a fault, or an engine stop that ended a run with a duration
    incomplete = node.fault or (node.stopped and not node.stay_up_after_stop)
    return 1 if incomplete or not closed else 0


if __name__ == "__main__":
    sys.exit(main())
