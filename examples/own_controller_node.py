"""A controller node of your own for any robot: a PD law that holds the actuated joints where they start.

The robot is whatever ``sim_node`` runs (its ``robot`` parameter: a shipped name or your URDF); this node
knows nothing of it but the names of its actuated joints, in the order of the command
(``-p joints:="[hip_1, hip_2, knee_1, knee_2]"``). Each ``joint_states`` message is answered with one
command on ``hip_torque``, one torque per actuated joint::

    u_i = -kp (q_i - q_i(0)) - kd dq_i

where ``q_i(0)`` is joint i's angle in the first state received (a posture hold, not a walking law). In
lockstep each command advances the run one control period. From the repository's root, beside
``sim_node --ros-args --params-file my_robot_scene.yaml``::

    python examples/own_controller_node.py --ros-args -p joints:="[hip_1, hip_2, knee_1, knee_2]" -p kp:=200.0

The same law runs headless and in a sweep as :class:`PosturePD` (the same arithmetic, so a lockstep run
through the node is the headless run bit for bit)::

    biped-sim simulate --scene my_robot_scene.yaml --controller examples.own_controller_node:PosturePD
    biped-sim sweep my_robot_scene.yaml --controller examples.own_controller_node:PosturePD \\
        --set controller.kp=100,200,400

rclpy is imported by :func:`main` only, so a sweep's workers import the law without ROS.
"""
from __future__ import annotations


def posture_torques(kp, kd, targets, positions, velocities):
    """``-kp (q_i - q_i(0)) - kd dq_i`` for each actuated joint (the law of both the node and PosturePD)."""
    return [-kp * (q - q0) - kd * dq for q, q0, dq in zip(positions, targets, velocities)]


class PosturePD:
    """The law as a headless controller ``(t, q, dq, stance_leg) -> u``: holds the actuated coordinates of
    ``model`` (``GeneratedModel.actuated_indices``; the hips, q[2] and q[3], of a three-link BipedModel) at
    their angles of the first call."""

    def __init__(self, model=None, kp=200.0, kd=20.0):
        self.kp, self.kd = float(kp), float(kd)
        self.indices = tuple(getattr(model, "actuated_indices", (2, 3)))
        self.targets = None

    def __call__(self, t, q, dq, stance_leg):
        positions = [q[i] for i in self.indices]
        if self.targets is None:
            self.targets = positions
        return posture_torques(self.kp, self.kd, self.targets, positions, [dq[i] for i in self.indices])


def main(args=None):
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    class OwnController(Node):
        def __init__(self):
            super().__init__("own_controller")
            self.joints = list(self.declare_parameter("joints", ["hip_1", "hip_2"]).value)
            self.kp = float(self.declare_parameter("kp", 200.0).value)
            self.kd = float(self.declare_parameter("kd", 20.0).value)
            self.indices = self.targets = None
            self.pub = self.create_publisher(Float64MultiArray, "hip_torque", 10)
            # transient_local: the node's state at t = 0 reaches a controller that starts after it, which a
            # lockstep run waits on
            qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self.create_subscription(JointState, "joint_states", self.on_state, qos)
            self.get_logger().info(f"own_controller: joints {self.joints}, kp={self.kp}, kd={self.kd}")

        def on_state(self, msg):
            if self.indices is None:
                missing = [j for j in self.joints if j not in msg.name]
                if missing:
                    self.get_logger().error(f"joint_states has no joint(s) {missing}; it names {list(msg.name)}")
                    raise SystemExit(2)
                self.indices = [list(msg.name).index(j) for j in self.joints]
            positions = [msg.position[i] for i in self.indices]
            if self.targets is None:
                self.targets = positions
            u = posture_torques(self.kp, self.kd, self.targets, positions, [msg.velocity[i] for i in self.indices])
            self.pub.publish(Float64MultiArray(data=u))

    rclpy.init(args=args)
    node = OwnController()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, SystemExit, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    main()
