"""A minimal controller node: one hip_torque command for each joint_states message (rclpy's default QoS).

Run it beside sim_node (any time mode; in lockstep each command advances the run one control period):
    python examples/minimal_controller.py
"""
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray


class MinimalController(Node):
    def __init__(self):
        super().__init__("minimal_controller")
        self.pub = self.create_publisher(Float64MultiArray, "hip_torque", 10)
        self.create_subscription(JointState, "joint_states", self.on_state, 10)

    def on_state(self, msg):
        q, dq = msg.position, msg.velocity   # [x, y, q1, q2, q3] and their rates (docs/model.md)
        kp, kd, target = 5.0, 1.0, 0.3       # hold the legs at +-target from the torso (a toy, not a walk)
        u = [-kp * (q[2] - target) - kd * dq[2], -kp * (q[3] + target) - kd * dq[3]]
        self.pub.publish(Float64MultiArray(data=u))


def main():
    rclpy.init()
    try:
        rclpy.spin(MinimalController())
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass


if __name__ == "__main__":
    main()
