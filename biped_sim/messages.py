"""Arrays <-> ROS messages for the recorder, ``simulate --record``, replay, resim and inspect.

There is ONE conversion from the engine's arrays to messages: the ``*_message`` functions of
:mod:`biped_sim.node` (the node publishes with them). This module only forwards to them (imported
lazily, so that it works whichever module is loaded first) and adds the way back, from a decoded
message (rclpy, ``rosbags`` or ``mcap_ros2`` objects alike) to plain values.

Topics (names relative to the node's namespace) and their types:

* ``joint_states`` (``sensor_msgs/msg/JointState``): q, dq, effort = B u = [0, 0, u1, u2, 0];
  ``frame_id`` names the stance foot (``foot_1``/``foot_2``/``flight``).
* ``ground_reaction`` (``geometry_msgs/msg/WrenchStamped``): the ground's force on the stance foot.
* ``impact`` (``diagnostic_msgs/msg/DiagnosticArray``): one status per impact, stamped with the
  located impact time; keys kind, time, foot, q, dq_minus, dq_plus, impulse, energy_loss, ...
* ``diagnostics`` (``diagnostic_msgs/msg/DiagnosticArray``): other events and the run's status.
* ``/clock`` (``rosgraph_msgs/msg/Clock``), ``hip_torque`` (``std_msgs/msg/Float64MultiArray``, in).

Times are integer nanoseconds of simulation time: :func:`to_ns` rounds as the node's ``stamp`` does.
"""
from __future__ import annotations

import ast
import math

JOINT_NAMES = ("base_x", "base_y", "hip_1", "hip_2", "torso_pitch")
IMPACT_KINDS = ("touchdown", "double_touchdown")

# topic (relative name) -> ROS type name, as rosbag2 writes it
TOPIC_TYPES = {
    "joint_states": "sensor_msgs/msg/JointState",
    "ground_reaction": "geometry_msgs/msg/WrenchStamped",
    "impact": "diagnostic_msgs/msg/DiagnosticArray",
    "diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "clock": "rosgraph_msgs/msg/Clock",
    "hip_torque": "std_msgs/msg/Float64MultiArray",
}


def to_ns(t: float) -> int:
    """Simulation time (s) -> integer nanoseconds, rounded (the node's ``stamp``)."""
    return int(round(t * 1e9))


def message_class(type_name: str):
    """``"pkg/msg/Name"`` -> the rclpy message class."""
    import importlib
    pkg, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


# -- arrays -> messages: the node's functions ------------------------------------------------------
_NODE = None


def _node():
    global _NODE
    if _NODE is None:
        from . import node
        _NODE = node
    return _NODE


def joint_state_msg(t, q, dq, u, stance_leg):
    return _node().joint_state_message(t, q, dq, u, stance_leg)


def wrench_msg(t, force, stance_leg):
    return _node().wrench_message(t, force, stance_leg)


def impact_msg(event):
    """The ``impact`` (or, for other kinds, ``diagnostics``) message of an engine Event."""
    n = _node()
    return n.diagnostic_array(event.time, [n.event_status(event)])


def foot_frame(stance_leg):
    return _node().foot_frame(stance_leg)


def clock_msg(t):
    from rosgraph_msgs.msg import Clock
    return Clock(clock=_node().stamp(t))


def torque_msg(u):
    from std_msgs.msg import Float64MultiArray
    return Float64MultiArray(data=[float(u[0]), float(u[1])])


# -- messages -> plain values (any decoded form) ---------------------------------------------------
def stamp_ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def joint_state_values(m):
    """(t_ns, q, dq, u, stance_leg) of a JointState."""
    fid = m.header.frame_id
    leg = int(fid.split("_")[1]) if fid.startswith("foot_") else 0
    eff = list(m.effort)
    u = [eff[2], eff[3]] if len(eff) >= 4 else [0.0, 0.0]
    return stamp_ns(m.header.stamp), list(m.position), list(m.velocity), u, leg


def wrench_values(m):
    """(t_ns, [Fx, Fy], stance_leg) of a WrenchStamped."""
    fid = m.header.frame_id
    leg = int(fid.split("_")[1]) if fid.startswith("foot_") else 0
    return stamp_ns(m.header.stamp), [m.wrench.force.x, m.wrench.force.y], leg


def _value(text):
    if text in ("", "[]"):
        return [] if text == "[]" else ""
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def event_values(m):
    """Events of a DiagnosticArray (``impact``/``diagnostics``): list of dicts, values parsed."""
    out = []
    for st in m.status:
        d = {kv.key: _value(kv.value) for kv in st.values}
        lvl = st.level
        d["name"], d["message"], d["level"] = st.name, st.message, lvl[0] if isinstance(lvl, (bytes, bytearray)) else int(lvl)
        d["t_ns"] = stamp_ns(m.header.stamp)
        out.append(d)
    return out


def clock_ns(m) -> int:
    return stamp_ns(m.clock)


def torque_values(m):
    """The two torques of a command, or None if it is not two finite numbers."""
    d = [float(v) for v in m.data]
    return d if len(d) == 2 and all(math.isfinite(v) for v in d) else None
