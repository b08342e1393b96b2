"""Control of a running simulation: ``~/pause``, ``~/step``, ``~/reset`` (std_srvs, the semantics of
ROS ``simulation_interfaces``) and the ``push`` topic of ``sim_node``.

Owns the requests and when they apply; the node keeps the physics (``HybridSimulator.push``) and
the publishing. The callbacks run in the executor. In ``realtime`` and ``fast`` the engine loop runs
in the main thread and the executor in a second one (``time_modes.spinning_in_background``): a
callback only queues its request under a lock, the loop applies it between two control periods
(``between_periods``), and a ``~/step`` or ``~/reset`` callback answers once the loop has done it.
In ``lockstep`` the callbacks run in the loop's thread and apply at once. docs/node.md "Controlling
the simulation" says what each does in each time mode.
"""
from __future__ import annotations

import math
import threading
import time
from collections import deque

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3Stamped
from std_srvs.srv import SetBool, Trigger

from biped_sim.engine.resets import check_push
from biped_sim.recording.messages import TOPIC_TYPES, diagnostic_array, to_ns
from biped_sim.ros.run_watch import WarningBurst
from biped_sim.ros.startup import StartupError

#: a ~/step or ~/reset callback waits this long (wall s) for the loop to do it, then answers failure
REQUEST_TIMEOUT = 10.0


class _Request:
    def __init__(self, kind):
        self.kind, self.done, self.success, self.message = kind, threading.Event(), False, ""
        self.old_recorder = None


class SimControl:
    """The services and the push subscription of one :class:`~biped_sim.ros.sim_node.SimNode`."""

    def __init__(self, node, qos):
        self.node = node
        self.qos = qos
        self.lockstep = node.mode == "lockstep"
        self.cond = threading.Condition()
        self.paused = bool(node.params["start_paused"])
        self.pauses = [[time.monotonic(), None]] if self.paused else []   # [begin, end] (wall), the figures
        self.pushes = []                  # impulses to apply at the start of the next control period
        self.requests = deque()           # step and reset requests for the loop thread
        self.closed = None                # why the loop takes no more requests (the node is ending)
        self.lockstep_command_held = False   # lockstep: a command came while paused
        self.resets = 0
        self.before_reset_ns = None       # the latest state a run before a ~/reset reached (stale answers)
        self.first_bag = None
        self.recording_off = None         # why the last ~/reset could not open its bag (recording wanted)
        # in the run's final status and the closing summary (a refusal is otherwise only a log line)
        self.counts = dict(pushes_received=0, pushes_refused=0, steps=0, resets=0, requests_refused=0)
        # a publisher of bad pushes can send hundreds a second: one line, then a summary per interval
        self.refused_pushes = WarningBurst(node.get_logger().warning, "pushes refused")
        node.create_service(SetBool, "~/pause", self._on_pause)
        node.create_service(Trigger, "~/step", self._on_step)
        node.create_service(Trigger, "~/reset", self._on_reset)
        self.sub_push = node.create_subscription(Vector3Stamped, "push", self._on_push, qos)

    # -- the push topic -----------------------------------------------------------------------
    def _on_push(self, msg):
        node = self.node
        t = node.sim.t
        self.counts["pushes_received"] += 1
        rec = node.recorder
        if rec is not None:
            rec.add_topic(self.sub_push.topic_name, TOPIC_TYPES["push"], qos=self.qos)
            rec.write(self.sub_push.topic_name, msg, to_ns(t))
        v = msg.vector
        try:
            if not (math.isfinite(v.z) and v.z == 0.0):
                raise ValueError(f"vector.z must be 0 (the model is planar: x forward, y up), got {v.z!r}")
            impulse = check_push([v.x, v.y], "the push (vector.x, vector.y)")
        except ValueError as exc:
            self.counts["pushes_refused"] += 1
            self.refused_pushes.add(f"push refused at t={t:.6f} s: {exc}; the run goes on")
            return
        with self.cond:
            self.pushes.append(impulse)

    def take_pushes(self) -> list:
        """The pushes received since the last control period (the node applies them now, in order)."""
        with self.cond:
            pushes, self.pushes = self.pushes, []
        return pushes

    # -- ~/pause ------------------------------------------------------------------------------
    def _on_pause(self, request, response):
        node = self.node
        with self.cond:
            was, self.paused = self.paused, bool(request.data)
            self.cond.notify_all()
        if self.paused and not was:
            self.pauses.append([time.monotonic(), None])
        elif was and not self.paused:
            self.pauses[-1][1] = time.monotonic()
        state = "paused" if self.paused else "running"
        response.success = True
        response.message = (f"{'already ' if was == self.paused else ''}{state} at t={node.sim.t:.6f} s"
                            + (f" (the run has {'ended' if node.finished else 'stopped'})"
                               if node.finished or node.stopped else ""))
        node.get_logger().info(f"~/pause: {response.message}")
        if self.lockstep and not self.paused and self.lockstep_command_held:
            self.lockstep_command_held = False     # the period the held command asked for
            node._lockstep(node.sim.t)
        return response

    def paused_between(self, begin: float, end: float) -> float:
        """Wall seconds the run was paused between the wall times ``begin`` and ``end``."""
        return sum(max(0.0, min(end, b if b is not None else end) - max(begin, a)) for a, b in self.pauses)

    def hold_in_lockstep(self) -> bool:
        """Lockstep: True if paused (the command is held, not stepped: it steps once on resume)."""
        if self.paused:
            self.lockstep_command_held = True
        return self.paused

    # -- ~/step -------------------------------------------------------------------------------
    def _on_step(self, request, response):
        node = self.node
        why = None
        if self.lockstep:
            why = ("refused in lockstep: the node advances one control period per hip_torque command "
                   "(pause holds the commands)")
        elif not self.paused:
            why = "refused: the simulation is running; pause it first (~/pause true)"
        elif node.finished or node.stopped:
            why = (f"refused: the run has {'ended' if node.finished else 'stopped'} at t={node.sim.t:.6f} s"
                   + ("" if node.finished else "; ~/reset restarts it"))
        if why is not None:
            self.counts["requests_refused"] += 1
            response.success, response.message = False, why
            return response
        return self._through_loop(_Request("step"), response)

    # -- ~/reset ------------------------------------------------------------------------------
    def _on_reset(self, request, response):
        node = self.node
        if node.finished:
            self.counts["requests_refused"] += 1
            response.success = False
            response.message = f"refused: the run has ended at t={node.sim.t:.6f} s (duration); restart the node"
            return response
        req = _Request("reset")
        if self.lockstep:
            self.serve(req)
        else:
            self._through_loop(req, response)
        if req.old_recorder is not None:
            # closed here, in the executor: no other callback (a command, a push) is writing to it now
            try:
                req.old_recorder.close()
            except OSError as exc:
                node.get_logger().error(f"closing the bag before the reset failed: {exc}")
        response.success, response.message = req.success, req.message
        return response

    def _through_loop(self, req, response):
        with self.cond:
            if self.closed is None:
                self.requests.append(req)
                self.cond.notify_all()
            else:
                self._refuse(req, self.closed)
        if not req.done.wait(REQUEST_TIMEOUT):
            req.message = f"the simulation loop did not take the {req.kind} within {REQUEST_TIMEOUT:g} s"
        response.success, response.message = req.success, req.message
        return response

    def _refuse(self, req, why):
        self.counts["requests_refused"] += 1
        req.success, req.message = False, f"refused: {why}; the {req.kind} was not done"
        req.done.set()

    def close_requests(self, why: str):
        """The loop has ended: refuse the step and reset requests it will not take (and any later one)
        at once. Their callbacks waited REQUEST_TIMEOUT s for it, the caller got no answer, and the
        node's end waited on the executor thread they held."""
        with self.cond:
            self.closed = why
            while self.requests:
                self._refuse(self.requests.popleft(), why)

    # -- the loop's side ------------------------------------------------------------------------
    def between_periods(self, should_stop) -> bool:
        """Called by the realtime and fast loops before each control period (and while the run is
        stopped): applies the step and reset requests, and waits here while paused. True when the
        loop's clocks must start again from the simulated time (it paused, stepped or reset)."""
        restart = False
        while True:
            if restart:     # the commands received while paused: the last one holds, as in a period
                self.node.take_commands()
            with self.cond:
                req = self.requests.popleft() if self.requests else None
                if req is None:
                    if not self.paused or should_stop():
                        if restart and self.node.last_command_wall is not None:
                            self.node.last_command_wall = time.monotonic()   # a pause is not a silent controller
                        return restart
                    restart = True
                    self.cond.wait(0.1)
                    continue
            self.serve(req)
            restart = True

    def serve(self, req):
        """Do a step or reset request (in the loop's thread) and answer it."""
        node = self.node
        try:
            if req.kind == "step":
                t0 = node.sim.t
                self.counts["steps"] += 1
                node.take_commands()
                node.step()
                node.publish_state()
                sim = node.sim
                req.success = sim.status == "running"
                if req.success:
                    req.message = (f"stepped one control period from t={t0:.6f} s to t={sim.t:.6f} s"
                                   + (f"; the run has reached its duration {node.duration:g} s" if node.finished
                                      else ""))
                else:   # the step did not complete: say where it ended, not that it stepped
                    req.message = (f"the step from t={t0:.6f} s did not complete: the engine {sim.status} at "
                                   f"t={sim.t:.9f} s: {sim.message}"
                                   + ("; ~/reset restarts the run" if node.stay_up_after_stop else
                                      "; the run ends here (duration set)"))
            else:
                self._reset(req)
        finally:
            req.done.set()

    def _reset(self, req):
        node = self.node
        t_old = node.sim.t
        # a run that has not advanced is at the scene's initial state: the reset republishes the very
        # state the controller may have answered already (start_paused, or a second reset in one
        # pause), and a lockstep controller does not answer a state twice: its held answer stands
        untouched = node.sim.control_periods == 0 and t_old == 0.0 and node.sim.status == "running"
        keep_held = self.lockstep and untouched
        self.resets += 1
        self.before_reset_ns = max(self.before_reset_ns or 0, to_ns(t_old))
        self.counts["resets"] = self.resets
        old_bag = node.bag_path if node.recorder is not None else None
        new_recorder, new_bag, not_recorded = self._next_recorder()
        self._publish_marker(t_old, dict(time=repr(float(t_old)), resets=str(self.resets),
                                         next_bag=new_bag or ""),
                             f"reset at t={t_old:.6f} s: the simulation restarts at t = 0"
                             + (f"; recording goes on in {new_bag}" if new_bag else "")
                             + (f"; the run after the reset is NOT recorded: {not_recorded}" if not_recorded else ""))
        if old_bag is not None or new_bag is not None:
            req.old_recorder, node.recorder = node.recorder, new_recorder
            node.bag_path = new_bag if new_bag is not None else node.bag_path
        node.restart_run()
        if node.markers is not None:      # the new run's events count from 0; its first state drawn at once
            node.markers.restart()
        if not keep_held:
            node.u = node.run_rules.zero_torque()
            self.lockstep_command_held = False
        node.timed_out = False
        node.last_command_wall = None
        self.take_pushes()                # a push aimed at the old run does not hit the new one
        self._publish_marker(0.0, dict(time="0.0", resets=str(self.resets), previous_time=repr(float(t_old)),
                                       previous_bag=old_bag or ""),
                             f"restarted at t = 0 from the scene's initial state (reset {self.resets}, "
                             f"from t={t_old:.6f} s)")
        node.publish_state()
        req.success = True
        req.message = (f"reset to t = 0 at the scene's initial state (from t={t_old:.6f} s; reset {self.resets})"
                       + (f"; recording to {new_bag}" if new_bag else "")
                       + (f"; recording is OFF: {not_recorded}" if not_recorded else ""))
        node.get_logger().info(f"~/reset: {req.message}")

    def _next_recorder(self):
        """(recorder, path, None) of the bag after a reset, or (None, None, why not) when it cannot be
        created (a full disk), or (None, None, None) for a run not recorded (record false). A reset after
        one that could not record tries again: recording comes back with the space."""
        node = self.node
        if node.recorder is None and self.recording_off is None:
            return None, None, None
        self.first_bag = self.first_bag or node.bag_path
        path = f"{self.first_bag}-reset{self.resets}"
        old_recorder, old_path = node.recorder, node.bag_path
        node.recorder = None
        try:
            node._open_recorder(path)
            self.recording_off = None
            return node.recorder, path, None
        except StartupError as exc:   # the run goes on, unrecorded, and the answer says so
            self.recording_off = (f"{exc}; the next ~/reset tries again (free some space, or set bag_dir "
                                  "before starting the node)")
            node.get_logger().error(f"~/reset: the run after the reset is NOT recorded: {self.recording_off}")
            return None, None, self.recording_off
        finally:
            node.recorder, node.bag_path = old_recorder, old_path     # the old bag gets the reset marker

    def _publish_marker(self, t, values, message):
        st = DiagnosticStatus(level=DiagnosticStatus.OK, name="biped_sim/reset", message=message)
        st.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        self.node._publish(self.node.pub_diag, diagnostic_array(t, [st]), t)
