"""Arrays <-> ROS messages: the one conversion used by the node, the recorder, replay and resim.

Owns the message layout of every topic (names relative to the node's namespace):

* ``joint_states`` (``sensor_msgs/msg/JointState``): ``name`` = JOINT_NAMES (the order of q),
  ``position`` = q, ``velocity`` = dq (physical coordinates: leg 1 stays leg 1 across impacts),
  ``effort`` = the applied generalised force B u = [0, 0, u1, u2, 0].
* ``ground_reaction`` (``geometry_msgs/msg/WrenchStamped``): the force of the ground on the stance
  foot (N), ``frame_id`` = ``foot_1`` or ``foot_2``; torque zero (a point foot). Nothing in flight.
* ``impact`` (``trajectory_msgs/msg/JointTrajectory``): one per application of the impact map,
  ``header.stamp`` = the located impact time, ``header.frame_id`` = the foot that touched down
  (``foot_1``/``foot_2``; ``foot_1+foot_2`` for a double touchdown, the new stance foot first),
  ``joint_names`` = JOINT_NAMES, ``points[0]`` = pre-impact (positions q, velocities dq-),
  ``points[1]`` = post-impact (positions q, velocities dq+, effort = the generalised impulse
  J^T Lambda = D (dq+ - dq-) in N s: entries 0 and 1 are the ground's impulse on the foot, x and y).
* ``clock`` (``rosgraph_msgs/msg/Clock``): the simulation time.
* ``hip_torque`` (``std_msgs/msg/Float64MultiArray``, subscribed): [u1, u2] in N m.

Times are integer nanoseconds of simulation time (:func:`to_ns`), so that a stamp, the bag's log
time and the engine's ``t`` agree exactly.
"""
from __future__ import annotations

import math

JOINT_NAMES = ("base_x", "base_y", "hip_1", "hip_2", "torso_pitch")

# topic (relative name) -> ROS type name, as rosbag2 writes it
TOPIC_TYPES = {
    "joint_states": "sensor_msgs/msg/JointState",
    "ground_reaction": "geometry_msgs/msg/WrenchStamped",
    "impact": "trajectory_msgs/msg/JointTrajectory",
    "clock": "rosgraph_msgs/msg/Clock",
    "hip_torque": "std_msgs/msg/Float64MultiArray",
}


def to_ns(t: float) -> int:
    """Simulation time (s) -> integer nanoseconds (rounded)."""
    return int(round(float(t) * 1e9))


def message_class(type_name: str):
    """``"pkg/msg/Name"`` -> the rclpy message class."""
    import importlib
    pkg, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def _time(ns: int):
    from builtin_interfaces.msg import Time
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def stamp_ns(stamp) -> int:
    """``builtin_interfaces/Time`` (any decoded form with sec/nanosec) -> ns."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def joint_state_msg(t, q, dq, u):
    from sensor_msgs.msg import JointState
    m = JointState()
    m.header.stamp = _time(to_ns(t))
    m.name = list(JOINT_NAMES)
    m.position = [float(v) for v in q]
    m.velocity = [float(v) for v in dq]
    m.effort = [0.0, 0.0, float(u[0]), float(u[1]), 0.0]
    return m


def wrench_msg(t, F, leg):
    from geometry_msgs.msg import WrenchStamped
    m = WrenchStamped()
    m.header.stamp = _time(to_ns(t))
    m.header.frame_id = f"foot_{int(leg)}"
    m.wrench.force.x = float(F[0])
    m.wrench.force.y = float(F[1])
    return m


def impact_msg(event, model):
    """An engine ``Event`` of kind touchdown/double_touchdown -> JointTrajectory (see above)."""
    import numpy as np
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
    m = JointTrajectory()
    m.header.stamp = _time(to_ns(event.time))
    leg = int(event.leg)
    m.header.frame_id = f"foot_{leg}" if event.kind == "touchdown" else f"foot_{leg}+foot_{3 - leg}"
    m.joint_names = list(JOINT_NAMES)
    q = [float(v) for v in event.q]
    dqm = np.asarray(event.dq_minus, float)
    dqp = np.asarray(event.dq_plus, float)
    impulse = (model.mass_matrix(np.asarray(q)) @ (dqp - dqm)).tolist()
    m.points = [JointTrajectoryPoint(positions=q, velocities=dqm.tolist()),
                JointTrajectoryPoint(positions=q, velocities=dqp.tolist(), effort=impulse)]
    return m


def clock_msg(t):
    from rosgraph_msgs.msg import Clock
    return Clock(clock=_time(to_ns(t)))


def torque_msg(u):
    from std_msgs.msg import Float64MultiArray
    return Float64MultiArray(data=[float(u[0]), float(u[1])])


# -- the other way: decoded messages (rclpy, rosbags or mcap_ros2 objects) -> plain values --------
def joint_state_values(m):
    """(t_ns, q, dq, u) of a JointState."""
    return stamp_ns(m.header.stamp), list(m.position), list(m.velocity), [m.effort[2], m.effort[3]]


def wrench_values(m):
    """(t_ns, [Fx, Fy], leg) of a WrenchStamped."""
    leg = int(m.header.frame_id.split("_")[1].split("+")[0]) if m.header.frame_id else 0
    return stamp_ns(m.header.stamp), [m.wrench.force.x, m.wrench.force.y], leg


def impact_values(m):
    """dict(t_ns, leg, double, q, dq_minus, dq_plus, impulse) of an impact message."""
    fid = m.header.frame_id
    pre, post = m.points[0], m.points[1]
    return dict(t_ns=stamp_ns(m.header.stamp), leg=int(fid.split("+")[0].split("_")[1]), double="+" in fid,
                q=list(post.positions), dq_minus=list(pre.velocities), dq_plus=list(post.velocities),
                impulse=list(post.effort))


def clock_ns(m) -> int:
    return stamp_ns(m.clock)


def torque_values(m):
    d = list(m.data)
    return d if len(d) == 2 and all(math.isfinite(v) for v in d) else None
