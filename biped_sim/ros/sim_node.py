"""``sim_node``: the rclpy node (name ``biped_sim``) around the hybrid engine; no physics here.

Owns the ROS side of a run: the parameters (declared from ``parameters.PARAMETERS``, checked with
``parameters.validate``; an unknown or ill-typed one stops the start with exit code 2), the topics
(``hip_torque`` in; ``joint_states``, ``ground_reaction``, ``impact``, ``diagnostics`` and ``/clock``
out), the three time modes (realtime, fast, lockstep), the checks on incoming torque commands, the
command timeout, the signals, and the calls to the recorder (``biped_sim.recording.recorder``, optional).
The state comes from ``hybrid.HybridSimulator.advance``, one control period at a time; the
messages are built by the ``*_message`` functions below (also used by the tools and tests).
"""
from __future__ import annotations

import difflib
import gc
import math
import signal
import sys
import threading
import time
from datetime import datetime, timezone

from biped_sim.config import parameters as P
from biped_sim.recording.messages import (IMPACT_KINDS, JOINT_NAMES, diagnostic_array, event_status, foot_frame,
                                          joint_state_message, stamp, wrench_message)

ROS_OWN_PARAMETERS = ("use_sim_time", "start_type_description_service")
QOS_DEPTH = 100


class StartupError(Exception):
    """The node cannot start: the message says why (printed without a traceback, exit code 2)."""


# -- parameters ---------------------------------------------------------------------------------
def allowed_values(p: P.Param) -> str:
    """What a parameter accepts, in words."""
    if p.type is list:
        kind = f"list of {p.item.__name__}" + (f" with {p.length} entries" if p.length else "")
        if p.choices:
            kind += f", each one of {list(p.choices)}"
        return kind
    kind = {float: "double", int: "integer", bool: "bool (true/false)", str: "string"}[p.type]
    if p.choices:
        return f"{kind}, one of {list(p.choices)}"
    if p.low is not None or p.high is not None:
        return f"{kind} in [{p.low}, {p.high}]"
    return kind


def _ros_type(p: P.Param):
    from rclpy.parameter import Parameter
    if p.type is list:
        return Parameter.Type.DOUBLE_ARRAY if p.item is float else Parameter.Type.STRING_ARRAY
    return {float: Parameter.Type.DOUBLE, int: Parameter.Type.INTEGER, bool: Parameter.Type.BOOL,
            str: Parameter.Type.STRING}[p.type]


def descriptor(p: P.Param):
    """rcl_interfaces/ParameterDescriptor of a table entry (type, description, range, choices)."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
    d = ParameterDescriptor(name=p.name, type=_ros_type(p).value,
                            description=f"{p.description} ({allowed_values(p)}; default {p.default!r})",
                            read_only=False)
    if p.choices:
        d.additional_constraints = f"one of {list(p.choices)}"
    if p.type is float and p.low is not None and p.high is not None:
        d.floating_point_range = [FloatingPointRange(from_value=float(p.low), to_value=float(p.high), step=0.0)]
    if p.type is int:
        lo = min(p.choices) if p.choices else p.low
        hi = max(p.choices) if p.choices else p.high
        if lo is not None and hi is not None:
            d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
    return d


def _plain(value):
    """A parameter override's value as plain Python (lists, not array.array)."""
    if isinstance(value, (str, bytes, bool, int, float)) or value is None:
        return value
    try:
        return list(value)
    except TypeError:
        return value


def read_parameters(node) -> dict:
    """Check the node's parameter overrides against the table, declare every parameter, return values."""
    from rclpy.parameter import Parameter
    overrides = dict(getattr(node, "_parameter_overrides", {}) or {})
    own = set(ROS_OWN_PARAMETERS) | set(getattr(node, "_parameters", {}))
    unknown = sorted(n for n in overrides if n not in P.BY_NAME and n not in own and not n.startswith("qos_overrides."))
    if unknown:
        hints = []
        for n in unknown:
            close = difflib.get_close_matches(n, list(P.BY_NAME), n=1)
            hints.append(f"'{n}'" + (f" (did you mean '{close[0]}'?)" if close else ""))
        raise StartupError(f"unknown parameter {', '.join(hints)} for node 'biped_sim'. Allowed parameters: "
                           + "; ".join(f"{p.name} ({allowed_values(p)})" for p in P.PARAMETERS) + ".")
    raw = {n: _plain(overrides[n].value) for n in overrides if n in P.BY_NAME}
    try:
        values = P.validate(raw)
    except ValueError as exc:
        culprit = next((p for p in P.PARAMETERS if f"'{p.name}'" in str(exc)), None)
        extra = f" Allowed values of '{culprit.name}': {allowed_values(culprit)}." if culprit else ""
        raise StartupError(f"{exc}.{extra}") from None
    for p in P.PARAMETERS:
        node.declare_parameter(p.name, _ros_type(p), descriptor(p), ignore_override=True)
    node.set_parameters([Parameter(p.name, _ros_type(p), values[p.name]) for p in P.PARAMETERS])
    return values


# -- the node -------------------------------------------------------------------------------------
def _make_node_class():
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
    from geometry_msgs.msg import WrenchStamped
    from rcl_interfaces.msg import SetParametersResult
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from diagnostic_msgs.msg import DiagnosticArray

    from biped_sim.engine.compiled import IMPLEMENTATION as GENERATED_CODE, WHY_PYTHON
    from biped_sim.engine.hybrid import HybridSimulator

    class SimNode(Node):
        """The node; ``run(should_stop)`` drives it in the chosen time mode."""

        def __init__(self, context=None):
            super().__init__("biped_sim", context=context, allow_undeclared_parameters=False,
                             automatically_declare_parameters_from_overrides=False)
            self.params = prm = read_parameters(self)
            self.add_on_set_parameters_callback(self._on_set_parameters)
            try:
                # the node publishes as it goes: the engine keeps only the last sample
                self.sim = HybridSimulator(**P.engine_arguments(prm), keep_samples=False)
            except ValueError as exc:
                raise StartupError(f"cannot start the engine with these parameters: {exc}") from None
            self.mode = prm["time_mode"]
            self.period = prm["control_period"]
            self.duration = prm["duration"]
            self.limit = prm["torque_limit"]
            self.clip = prm["torque_limit_action"] == "clip"
            self.timeout = 0.0 if self.mode == "lockstep" else prm["command_timeout"]
            self.u = [0.0, 0.0]
            self.k = 0                      # control periods done
            self.finished = False           # duration reached
            self.stopped = False            # the engine stopped (error): stay up for inspection
            self.counts = dict(received=0, rejected=0, clipped=0, timeouts=0, ignored=0)
            self.last_command_wall = None
            self.timed_out = False
            self.lag_warnings = 0
            # reliable, and transient_local so that a subscriber that asks for it (a lockstep controller
            # that starts after the node) still gets the last QOS_DEPTH messages, e.g. the state at t = 0
            qos = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self.qos = qos
            out = set(prm["outputs"])
            from rclpy.event_handler import PublisherEventCallbacks

            def publisher(msg_type, topic):
                return self.create_publisher(msg_type, topic, qos,
                                             event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))
            self.pub_js = publisher(JointState, "joint_states") if "joint_states" in out else None
            self.pub_grf = publisher(WrenchStamped, "ground_reaction") if "ground_reaction" in out else None
            self.pub_impact = (publisher(DiagnosticArray, "impact")
                               if "impact" in out and "impact" in prm["phases"] else None)
            self.pub_clock = publisher(Clock, "/clock") if "clock" in out else None
            self.pub_diag = publisher(DiagnosticArray, "diagnostics")
            self.sub = self.create_subscription(Float64MultiArray, "hip_torque", self._on_command,
                                                QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE))
            self._js_msg = self._grf_msg = None
            self._clock_msg = Clock()
            self.recorder = None
            self.bag_path = None
            self._open_recorder()
            self.get_logger().info(
                f"biped_sim: time_mode={self.mode}, control_period={self.period:g} s, duration={self.duration:g} s, "
                f"outputs={sorted(out)}, phases={sorted(prm['phases'])}, base={prm['base']}, "
                f"method={self.sim.method}" + (" (auto)" if prm["method"] == "auto" else "")
                + f", generated code in {GENERATED_CODE}" + (f" ({WHY_PYTHON})" if WHY_PYTHON else "")
                + (f", recording to {self.bag_path}" if self.recorder else ""))

        # -- recording ------------------------------------------------------------------------
        def _open_recorder(self):
            if not self.params["record"]:
                return
            try:
                from biped_sim.recording.recorder import BagRecorder
            except ModuleNotFoundError as exc:
                if exc.name != "biped_sim.recording.recorder":
                    raise
                self.get_logger().warning("record is true but biped_sim.recording.recorder is not available: "
                                          "this run is not recorded")
                return
            when = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
            import os
            self.bag_path = os.path.join(self.params["bag_dir"], f"{self.params['scene']}-{when}")
            try:
                self.recorder = BagRecorder(self.bag_path, parameters=dict(self.params))
            except (OSError, ValueError) as exc:
                raise StartupError(f"cannot record to '{self.bag_path}': {exc} (set bag_dir to a writable "
                                   "folder, or record:=false)") from None
            types = {"joint_states": "sensor_msgs/msg/JointState", "ground_reaction": "geometry_msgs/msg/WrenchStamped",
                     "impact": "diagnostic_msgs/msg/DiagnosticArray", "clock": "rosgraph_msgs/msg/Clock",
                     "diagnostics": "diagnostic_msgs/msg/DiagnosticArray"}
            for key, pub in self._publishers_by_output().items():
                self.recorder.add_topic(pub.topic_name, types[key], qos=self.qos)
            self.recorder.add_topic(self.sub.topic_name, "std_msgs/msg/Float64MultiArray",
                                    qos=QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE))

        def _publishers_by_output(self):
            pubs = dict(joint_states=self.pub_js, ground_reaction=self.pub_grf, impact=self.pub_impact,
                        clock=self.pub_clock, diagnostics=self.pub_diag)
            return {k: v for k, v in pubs.items() if v is not None}

        def _publish(self, pub, msg, t):
            pub.publish(msg)
            if self.recorder is not None:
                self.recorder.write(pub.topic_name, msg, int(round(t * 1e9)))

        def close(self):
            if self.recorder is not None:
                try:
                    self.recorder.close()
                except Exception as exc:  # report, but finish the shutdown
                    self.get_logger().error(f"closing the bag {self.bag_path} failed: {exc}")
                self.recorder = None

        def _on_set_parameters(self, params):
            return SetParametersResult(successful=False, reason="biped_sim reads its parameters at start: "
                                       "restart the node to change them")

        # -- commands -------------------------------------------------------------------------
        def _on_command(self, msg):
            t = self.sim.t
            self.counts["received"] += 1
            if self.recorder is not None:
                self.recorder.write(self.sub.topic_name, msg, int(round(t * 1e9)))
            u = self._check_command(list(msg.data), t)
            if u is not None:
                self.u = u
                self.last_command_wall = time.monotonic()
                if self.timed_out:
                    self.timed_out = False
                    self.get_logger().info(f"hip_torque commands again at t={t:.6f} s")
            if self.mode == "lockstep":
                if self.finished or self.stopped:
                    self.counts["ignored"] += 1
                    self.get_logger().warning(
                        f"lockstep: command ignored, the run has {'ended' if self.finished else 'stopped'} at "
                        f"t={self.sim.t:.6f} s ({self.counts['ignored']} ignored)", throttle_duration_sec=1.0)
                    return
                self.step()
                self.publish_state()

        def _check_command(self, data, t):
            """The torques to use, or None (rejected: counted, throttled warning, last command held)."""
            why = None
            if len(data) != 2:
                why = f"{len(data)} values instead of 2 (hip 1, hip 2)"
            elif not all(math.isfinite(v) for v in data):
                why = f"not finite: {data}"
            elif max(abs(data[0]), abs(data[1])) > self.limit:
                if self.clip:
                    self.counts["clipped"] += 1
                    self.get_logger().warning(
                        f"hip_torque {data} beyond torque_limit {self.limit:g} N m at t={t:.6f} s: clipped "
                        f"({self.counts['clipped']} clipped so far)", throttle_duration_sec=1.0)
                    return [max(-self.limit, min(self.limit, v)) for v in data]
                why = f"{data} beyond torque_limit {self.limit:g} N m"
            if why is None:
                return [float(data[0]), float(data[1])]
            self.counts["rejected"] += 1
            self.get_logger().warning(
                f"hip_torque rejected at t={t:.6f} s: {why}; holding {self.u} ({self.counts['rejected']} rejected "
                "so far)", throttle_duration_sec=1.0)
            return None

        def _check_timeout(self):
            if not self.timeout or self.last_command_wall is None or self.timed_out:
                return
            if time.monotonic() - self.last_command_wall > self.timeout:
                self.timed_out = True
                self.counts["timeouts"] += 1
                self.get_logger().warning(
                    f"no hip_torque command for more than command_timeout={self.timeout:g} s (wall) at "
                    f"t={self.sim.t:.6f} s: zero torque until the next command")
                self.u = [0.0, 0.0]

        # -- stepping and publishing ------------------------------------------------------------
        def step(self):
            """Advance one control period with the held torques; publish its events."""
            sim = self.sim
            events = sim.advance_period(self.period, u=self.u, t_final=self.duration)
            self.k = sim.control_periods
            for ev in events:
                self._publish_event(ev)
            if sim.status != "running" and not self.stopped:
                self._on_engine_stopped()
            elif self.duration > 0 and sim.t >= self.duration and not self.finished:
                self.finished = True
                self.get_logger().info(f"duration {self.duration:g} s reached: the run ends")

        def _publish_event(self, ev):
            st = event_status(ev)
            msg = diagnostic_array(ev.time, [st])
            if ev.kind in IMPACT_KINDS:
                if self.pub_impact is not None:
                    self._publish(self.pub_impact, msg, ev.time)
                if ev.warnings:
                    self.get_logger().warning(st.message)
            else:
                self._publish(self.pub_diag, msg, ev.time)

        def _on_engine_stopped(self):
            self.stopped = True
            sim = self.sim
            self.get_logger().error(f"the engine {sim.status} at t={sim.t:.9f} s: {sim.message}. The node stays "
                                    "up for inspection (the last state stays published); stop it with Ctrl-C")
            self.publish_state()
            self.publish_run_status()

        def publish_run_status(self):
            """A DiagnosticStatus 'biped_sim/run' with the run's status and counters."""
            sim = self.sim
            st = DiagnosticStatus()
            st.name = "biped_sim/run"
            if sim.status == "running":
                st.level = DiagnosticStatus.OK
                st.message = "completed" if self.finished else "running"
            else:
                st.level = DiagnosticStatus.ERROR
                st.message = f"{sim.status}: {sim.message}"
            values = dict(status=sim.status if sim.status != "running" else st.message, time=repr(float(sim.t)),
                          message=sim.message, control_periods=str(self.k), events=str(len(sim.events)),
                          impacts=str(sim.stats["impacts"]), engine_wall_time=repr(float(sim.stats["wall_time"])))
            values.update({f"commands_{k}": str(v) for k, v in self.counts.items()})
            st.values = [KeyValue(key=k, value=v) for k, v in values.items()]
            self._publish(self.pub_diag, diagnostic_array(sim.t, [st]), sim.t)

        def publish_state(self):
            """joint_states, ground_reaction (in stance) and /clock at the engine's current time.

            The same content as ``joint_state_message``/``wrench_message``, but into messages made
            once and refilled (building rosidl messages costs more than publishing them)."""
            sim = self.sim
            t = sim.t
            st = stamp(t)
            frame = foot_frame(sim.stance_leg)
            state = []
            q, dq = sim.q.tolist(), sim.dq.tolist()
            effort = [0.0, 0.0, float(self.u[0]), float(self.u[1]), 0.0]
            if self.pub_js is not None:
                m = self._js_msg
                if m is None:
                    m = self._js_msg = joint_state_message(t, sim.q, sim.dq, self.u, sim.stance_leg)
                else:
                    m.header.stamp = st
                    m.header.frame_id = frame
                    m.position = q
                    m.velocity = dq
                    m.effort = effort
                state.append((self.pub_js, m))
            if self.pub_grf is not None and sim.stance_leg:
                m = self._grf_msg
                force = sim.ground_force
                if m is None:
                    m = self._grf_msg = wrench_message(t, force, sim.stance_leg)
                else:
                    m.header.stamp = st
                    m.header.frame_id = frame
                    m.wrench.force.x = float(force[0])
                    m.wrench.force.y = float(force[1])
                state.append((self.pub_grf, m))
            if self.pub_clock is not None:
                self._clock_msg.clock = st
                state.append((self.pub_clock, self._clock_msg))
            for pub, m in state:
                pub.publish(m)
            if self.recorder is not None and state:   # the same messages, packed in one call
                self.recorder.write_state(
                    int(round(t * 1e9)), tuple(p.topic_name if p is not None else None
                                               for p in (self.pub_js, self.pub_grf, self.pub_clock)),
                    frame, JOINT_NAMES, q, dq, effort,
                    sim.ground_force if sim.stance_leg and self.pub_grf is not None else None)

        # -- time modes -------------------------------------------------------------------------
        def run(self, should_stop, executor):
            self._cpu_run0 = time.process_time()
            self.publish_state()
            if self.mode == "lockstep":     # the command callback steps and publishes
                while not should_stop() and not self.finished:
                    executor.spin_once(timeout_sec=0.1)
                self._cpu_end = time.process_time()
                if self.finished:
                    self.publish_run_status()
                while not should_stop() and self.stopped:   # after an error: stay up for inspection
                    executor.spin_once(timeout_sec=0.1)
                return
            # realtime and fast: commands are taken by the executor in a second thread (the callback
            # only stores them), so that waiting for them costs the simulation loop nothing
            done = threading.Event()

            def spin():
                while not done.is_set():
                    executor.spin_once(timeout_sec=0.05)
            spinner = threading.Thread(target=spin, name="biped_sim-commands", daemon=True)
            spinner.start()
            try:
                if self.mode == "fast":
                    self._run_fast(should_stop)
                else:
                    self._run_realtime(should_stop)
                self._cpu_end = time.process_time()
                if self.finished:
                    self.publish_run_status()
                while not should_stop() and self.stopped:   # after an error: stay up for inspection
                    time.sleep(0.05)
            finally:
                done.set()
                spinner.join(timeout=2.0)

        def _run_fast(self, should_stop):
            pub_period = 1.0 / self.params["publish_rate"]
            next_pub = pub_period
            while not (self.stopped or self.finished or should_stop()):
                self._check_timeout()
                self.step()
                if self.sim.t >= next_pub - 1e-12 or self.finished or self.stopped:
                    self.publish_state()
                    next_pub = (math.floor(self.sim.t / pub_period + 1e-9) + 1) * pub_period

        def _run_realtime(self, should_stop):
            pub_period = 1.0 / self.params["publish_rate"]
            next_pub = pub_period
            rate = self.params["rate_factor"]
            wall0 = time.monotonic()
            lag_report = wall0
            self.publish_walls = walls = []          # wall times of the state publications (figures)
            self._cpu0, self._k0 = time.process_time(), self.k
            while not (self.stopped or self.finished or should_stop()):
                self._check_timeout()
                self.step()                  # compute ahead: the state at the end of this period
                deadline = wall0 + self.sim.t / rate
                now = time.monotonic()
                if now > deadline + max(self.period / rate, 0.005) and now - lag_report > 2.0:
                    lag_report = now
                    self.lag_warnings += 1
                    self.get_logger().warning(
                        f"realtime: cannot keep up: simulated time {self.sim.t:.3f} s is "
                        f"{(now - deadline) * rate:.3f} s behind the wall clock x rate_factor {rate:g} "
                        f"(achieved real-time factor {self.sim.t / (now - wall0):.3g}); lower publish_rate or "
                        "rate_factor, raise control_period, or use time_mode fast")
                left = deadline - time.monotonic()
                if left > 2e-4:              # sleep overshoots by ~0.1 ms: wake early, spin the rest
                    time.sleep(left - 1.5e-4)
                while time.monotonic() < deadline:
                    pass
                if self.sim.t >= next_pub - 1e-12 or self.finished or self.stopped:
                    if len(walls) < 1_000_000:
                        walls.append(time.monotonic())
                    self.publish_state()
                    next_pub = (math.floor(self.sim.t / pub_period + 1e-9) + 1) * pub_period
            self._report_realtime(walls, pub_period / rate, wall0)

        def _report_realtime(self, walls, period, wall0):
            """Log the achieved publish rate and the period jitter (wall clock) of a realtime run."""
            if len(walls) < 3:
                return
            d = sorted(abs((b - a) - period) for a, b in zip(walls, walls[1:]))
            pick = lambda q: d[min(len(d) - 1, int(q * (len(d) - 1)))]  # noqa: E731
            self.realtime_figures = dict(rate=(len(walls) - 1) / (walls[-1] - walls[0]), jitter_p50=pick(0.5),
                                         jitter_p99=pick(0.99), rtf=self.sim.t / (time.monotonic() - wall0),
                                         cpu=(time.process_time() - self._cpu0) / max(1, self.k - self._k0))
            f = self.realtime_figures
            self.get_logger().info(
                f"realtime figures: {len(walls)} states published at {f['rate']:.1f} Hz (wall; target "
                f"{1 / period:.1f} Hz), period jitter p50 {f['jitter_p50'] * 1e6:.0f} us, p99 {f['jitter_p99'] * 1e6:.0f} us, "
                f"real-time factor {f['rtf']:.3f}; CPU time of this process {f['cpu'] * 1e3:.3f} ms per control period")

        def log_figures(self):
            """The run's cost: control periods, engine time and this process's CPU time per period."""
            k = max(1, self.k)
            cpu = getattr(self, "_cpu_end", time.process_time()) - getattr(self, "_cpu_run0", 0.0)
            self.get_logger().info(
                f"{self.k} control periods to t={self.sim.t:.6f} s: engine {1e3 * self.sim.stats['wall_time'] / k:.3f} ms "
                f"(wall) and process CPU {1e3 * cpu / k:.3f} ms per period; commands {self.counts}")

        def flush(self, timeout=5.0):
            """Wait (at most ``timeout`` s in all) until subscribers acknowledged what was published: a
            reliable message still unacknowledged when the node exits is lost, and a subscriber on a
            loaded machine can be seconds behind a lockstep run that ends."""
            from rclpy.duration import Duration
            deadline = time.monotonic() + timeout
            for pub in self._publishers_by_output().values():
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                try:
                    pub.wait_for_all_acked(Duration(seconds=left))
                except Exception:
                    pass

    return SimNode


def main(argv=None):
    args = sys.argv if argv is None else argv
    try:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions
    except ImportError as exc:
        print(f"sim_node: error: rclpy is not available ({exc}); install the ROS 2 Jazzy Python packages",
              file=sys.stderr)
        return 2
    stop = []

    def on_signal(signum, _frame):
        stop.append(signum)
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # a bad --ros-args or params file
        print(f"sim_node: error: cannot read the ROS arguments: {exc}", file=sys.stderr)
        return 2
    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    node = None
    code = 0
    try:
        try:
            node = _make_node_class()()
        except StartupError as exc:
            print(f"sim_node: error: {exc}", file=sys.stderr)
            return 2
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        # everything built so far (modules, rclpy, the node) lives until the end: exempt it from the
        # cyclic collector, whose full passes over it were the long pauses of a 1 kHz loop
        gc.collect()
        gc.freeze()
        node.run(lambda: bool(stop), executor)
        if stop:
            node.get_logger().info(f"{signal.Signals(stop[0]).name}: shutting down at t={node.sim.t:.6f} s")
            node.publish_run_status()
        node.log_figures()
        node.flush()
    finally:
        if node is not None:
            node.close()
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
