"""``walk_controller``: the reference walking controller as a separate rclpy node (name ``walk_controller``).

Owns the ROS side of :class:`biped_sim.control.walking.WalkingController` (virtual constraints for the torso
angle and the swing leg, enforced by input-output linearisation). Subscribes ``joint_states``
(``sensor_msgs/JointState``: base_x, base_y, hip_1, hip_2, torso_pitch in physical coordinates,
matched by name), publishes ``hip_torque`` (``std_msgs/Float64MultiArray``: [hip of leg 1, hip of
leg 2], N m): one command per joint-state message, answered exactly once and in order, so that in the
sim node's ``lockstep`` mode each command advances one control period (a message seen twice -- same
stamp and state -- is not answered again). Each command is tagged with the stamp of the state it
answers (``layout.dim[0].label`` = ``answers <sec>.<nanosec>``, :func:`biped_sim.recording.messages.torque_msg`),
so that a lockstep node ignores an answer to an old state; of the states received before the
command publisher matched (a controller started late gets the node's whole transient-local
history) only the newest is answered.

Parameters: :data:`biped_sim.config.scenes.CONTROLLER_PARAMETERS` (the scene file's ``walk_controller``
section; ``--ros-args --params-file msg_configs/walk.yaml``) plus ``stance_source``:

* The controller must know the stance leg. ``auto`` (default) takes it from the joint-state
  message's ``header.frame_id`` when the sim node names the stance foot there (``foot_1``,
  ``foot_2``, ``flight``): it is the engine's own discrete state, in the same message as the
  positions, so it can never be out of step with them. Otherwise (another publisher), it is derived
  from the state: the stance foot is the one *on the ground and at rest* (height within
  ``contact_height_tol``, speed below ``contact_speed_tol``; the pinned foot has exactly zero
  velocity, and right after an impact the new stance foot is at rest while the old one lifts off);
  neither -> flight. "The lower foot" is not used: near mid-stance the swing foot grazes the ground
  behind the stance foot and can be the lower one. Subscribing to ``ground_reaction`` is not used
  either: it is an optional output of a scene, and a second topic is not synchronised with
  ``joint_states``.
* ``state`` always derives it from the state; ``frame_id`` requires the frame id.

Headless, the same controller runs in-process (``Scene.controller()`` as the ``simulate`` callback):
``simulate(..., control_period=...)`` with it gives the run the node gives in lockstep.
"""
from __future__ import annotations

import math
import sys

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from biped_sim.config.joints import joint_layout
from biped_sim.config.parameters import Param, robot_model, three_link_model
from biped_sim.config.scenes import CONTROLLER_PARAMETERS, LAW_GAINS, make_controller, validate_controller
from biped_sim.recording.messages import TOPIC_TYPES, stamp_ns, torque_msg
from biped_sim.ros import params_files, startup
from biped_sim.ros.one_topic_spin import OneTopicSpin
from biped_sim.ros.parameters import declare_from_table, usage_text, value_less_override_message
from biped_sim.ros.startup import StartupError

STANCE_SOURCES = ("auto", "state", "frame_id")
PARAMETERS = CONTROLLER_PARAMETERS + [Param(
    "stance_source", str, "auto", "where the stance leg comes from: auto (the joint_states frame_id if it "
    "names a foot, else the state), state (the foot on the ground and at rest), frame_id",
    choices=STANCE_SOURCES), Param(
    "controller", str, "walk", "the law that answers: walk (the reference walking controller, with the "
    "parameters above) or MODULE:ATTR, your controller (a class or factory made on the model of the "
    "model.* parameters, or a controller; docs/controllers.md)")]


def validate_parameters(values: dict, table: list = PARAMETERS) -> dict:
    """The node's parameters, checked as a scene's walk_controller section is (``validate_controller``: the
    parameters of its law, that law's defaults for those left out), so that the node and ``Scene.controller()``
    build the same controller from the same section."""
    return validate_controller(values, table)


QOS_DEPTH = 100
COMMAND_QOS = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
# transient_local: the state at t = 0 that a lockstep sim node published before we started
STATE_QOS = QoSProfile(depth=QOS_DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)


def stance_from_state(model, q, dq, slope=0.0, height_tol=1e-4, speed_tol=1e-3) -> int:
    """1 or 2: the foot on the ground and at rest (the slower if both), 0: neither (flight)."""
    best, best_speed = 0, math.inf
    t = math.tan(slope)
    for leg in (1, 2):
        p = model.foot_position(q, leg)
        v = model.foot_velocity(q, dq, leg)
        height = p[1] + t * p[0]
        speed = math.hypot(v[0], v[1])
        if abs(height) <= height_tol and speed <= speed_tol and speed < best_speed:
            best, best_speed = leg, speed
    return best


def stance_from_frame(frame_id: str):
    """The stance leg named by a joint-state frame id, or None if it names none."""
    return {"foot_1": 1, "foot_2": 2, "flight": 0}.get(frame_id)


class WalkControllerNode(Node):
    """One hip_torque command per joint_states message, from the reference walking controller."""

    def __init__(self, context=None, argv=None):
        try:
            super().__init__("walk_controller", context=context,
                             automatically_declare_parameters_from_overrides=True)
        except ValueError as exc:
            raise StartupError(value_less_override_message(exc) or exc) from None
        params_files.check_applies(self, sys.argv if argv is None else argv)
        self.values = v = declare_from_table(self, PARAMETERS, validate_parameters)
        try:
            self.model = robot_model(v)       # the robot the engine runs (a refusal names it and says why)
            if v["controller"] == "walk" and v["law"] == "walking":   # (the three-link robots' law)
                three_link_model(v, "the reference walking controller (walk_controller)")
        except ValueError as exc:
            raise StartupError(str(exc)) from None
        self.layout = joint_layout(v["robot"])     # the joints looked up in joint_states, by name
        if v["controller"] == "walk":
            self.ctrl = make_controller(v)
        else:
            from biped_sim.config.controllers import make_controller as make_users
            try:
                self.ctrl = make_users(v["controller"], self.model)
            except ValueError as exc:
                raise StartupError(f"parameter controller: {exc}") from None
        self.source = v["stance_source"]
        self.answered = 0
        self.duplicates = 0
        self.older = 0              # states left unanswered: a newer one was waiting too
        self.failures = 0
        self._last = None
        self._pending = []          # states received before the hip_torque subscriber matched
        self.pub = self.create_publisher(Float64MultiArray, "hip_torque", COMMAND_QOS)
        self.sub = self.create_subscription(JointState, "joint_states", self._on_state, STATE_QOS)
        self.timer = self.create_timer(0.01, self._flush_pending)
        # the robot first: the sim node's names the same joints for every three-link robot, so a controller
        # started for another robot than the sim's runs without a word
        self.get_logger().info(
            f"walk_controller: robot={v['robot']!r}, "
            + (", ".join(f"{k}={v[k]!r}" for k in LAW_GAINS[v["law"]][:-1] + ("slope", "stance_source"))
               if v["controller"] == "walk" else
               f"controller={v['controller']!r}, slope={v['slope']!r}, stance_source={v['stance_source']!r}"))

    def _matched(self):
        """Every hip_torque subscriber known to the graph (the sim node's among them) is matched."""
        n = self.pub.get_subscription_count()
        return n > 0 and n >= self.count_subscribers(self.pub.topic_name)

    def _flush_pending(self):
        if self._pending and self._matched():
            # answer the newest only (the last to arrive: a publisher's history comes in order, and
            # after a reset of the node its time goes back): the older ones (the node's history, for
            # a controller started after the node) are states a lockstep node has gone past
            newest = self._pending[-1]
            self.older += len(self._pending) - 1
            self._pending = []
            self._answer(newest)

    def _on_state(self, msg):
        if self._pending or not self._matched():
            self._pending.append(msg)      # a command sent now could be lost: answer once matched
            return
        self._answer(msg)

    def _answer(self, msg):
        key = (msg.header.stamp.sec, msg.header.stamp.nanosec, tuple(msg.position), tuple(msg.velocity))
        if key == self._last:
            self.duplicates += 1
            return
        self._last = key
        try:
            idx = [list(msg.name).index(n) for n in self.layout.coordinates]
            # lists of floats, as the engine calls a controller (headless and node runs get the same bits)
            q = [msg.position[i] for i in idx]
            dq = [msg.velocity[i] for i in idx]
        except (ValueError, IndexError):
            self.get_logger().error(f"joint_states without the joints {list(self.layout.coordinates)} (got names "
                                    f"{list(msg.name)}): not answered", throttle_duration_sec=1.0)
            return
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        try:
            leg = self.stance_leg(msg.header.frame_id, q, dq)
            u = self.ctrl(t, q, dq, leg)
            if not np.all(np.isfinite(u)):
                raise FloatingPointError(f"torques {u}")
        except Exception as exc:   # noqa: BLE001 -- any law's failure: said, and the run gets zero torque
            self.failures += 1
            self.get_logger().error(f"control law failed at t={t:.6f} s ({exc}): sending zero torque",
                                    throttle_duration_sec=1.0)
            u = [0.0] * len(self.layout.actuated)
        self.pub.publish(torque_msg(u, answers_ns=stamp_ns(msg.header.stamp)))
        self.answered += 1

    def stance_leg(self, frame_id, q, dq) -> int:
        if self.source != "state":
            leg = stance_from_frame(frame_id)
            if leg is not None:
                return leg
            if self.source == "frame_id":
                raise ValueError(f"joint_states frame_id {frame_id!r} names no stance foot")
        v = self.values
        return stance_from_state(self.model, q, dq, v["slope"], v["contact_height_tol"],
                                 v["contact_speed_tol"])


def usage() -> str:
    return usage_text("walk_controller", "walk_controller", "The reference walking controller: one hip torque "
                      "command per joint_states message (so that it drives a lockstep sim_node). Stop it with "
                      "Ctrl-C or SIGTERM.", PARAMETERS, {"joint_states": TOPIC_TYPES["joint_states"]},
                      {"hip_torque": TOPIC_TYPES["hip_torque"]})


def main(argv=None):
    argv = sys.argv if argv is None else argv
    code = startup.read_command_line("walk_controller", argv, usage)
    if code is not None:
        return code
    stop = startup.init("walk_controller", argv)
    if stop is None:
        return startup.EXIT_REFUSED
    node = None
    try:
        try:
            node = WalkControllerNode(argv=argv)
        except StartupError as exc:
            return startup.refuse("walk_controller", exc)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        spin = OneTopicSpin(executor, node, node.sub)     # joint_states first: see one_topic_spin
        while not stop:
            spin.spin_once(0.1)
        node.get_logger().info(f"{startup.signal_name(stop[0])}: shutting down after {node.answered} commands "
                               f"({node.duplicates} duplicate states skipped, {node.older} older states left for "
                               f"a newer one, {node.failures} failures)")
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
