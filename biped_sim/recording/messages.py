"""Arrays <-> ROS messages for the recorder, ``simulate --record``, replay, resim and inspect.

There is ONE conversion from the engine's arrays to messages, the ``*_message`` functions here
(the node publishes with them, the recorder and the tools reuse them), and the way back, from a
decoded message (rclpy, ``rosbags`` or ``mcap_ros2`` objects alike) to plain values. The ROS message
packages are imported inside the functions, so that reading a bag needs no rclpy.

Topics (names relative to the node's namespace) and their types:

* ``joint_states`` (``sensor_msgs/msg/JointState``): q, dq, effort = B u ([0, 0, u1, u2, 0] for the
  three-link biped; names and layout from the robot, :mod:`biped_sim.config.joints`);
  ``frame_id`` names the stance foot (``foot_1``/``foot_2``/``flight``).
* ``ground_reaction`` (``geometry_msgs/msg/WrenchStamped``): the ground's force on the stance foot.
* ``impact`` (``diagnostic_msgs/msg/DiagnosticArray``): one status per impact, stamped with the
  located impact time; keys kind, time, foot, q, dq_minus, dq_plus, impulse, energy_loss, ...
* ``diagnostics`` (``diagnostic_msgs/msg/DiagnosticArray``): other events and the run's status.
* ``/clock`` (``rosgraph_msgs/msg/Clock``), ``hip_torque`` (``std_msgs/msg/Float64MultiArray``, in).
* ``markers`` (``visualization_msgs/msg/MarkerArray``): the robot drawn, built by
  :mod:`biped_sim.recording.markers`.

Times are integer nanoseconds of simulation time: :func:`to_ns` rounds as the node's ``stamp`` does.
"""
from __future__ import annotations

import math

#: the three-link biped's joint_states names (``config.joints.joint_layout("three_link").coordinates``, which
#: a test checks); a run's names are its robot's layout (``NodeRun.layout``)
JOINT_NAMES = ("base_x", "base_y", "hip_1", "hip_2", "torso_pitch")
#: the columns of the three-link biped's ``effort`` that hold u1 and u2 (its hips'): a reader of a bag takes
#: its robot's (:mod:`biped_sim.recording.bag_robot`)
THREE_LINK_SLOTS = (2, 3)
IMPACT_KINDS = ("touchdown", "double_touchdown")

# topic (relative name) -> ROS type name, as rosbag2 writes it
TOPIC_TYPES = {
    "joint_states": "sensor_msgs/msg/JointState",
    "ground_reaction": "geometry_msgs/msg/WrenchStamped",
    "impact": "diagnostic_msgs/msg/DiagnosticArray",
    "diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "clock": "rosgraph_msgs/msg/Clock",
    "hip_torque": "std_msgs/msg/Float64MultiArray",
    "markers": "visualization_msgs/msg/MarkerArray",
    "push": "geometry_msgs/msg/Vector3Stamped",
}


def to_ns(t: float) -> int:
    """Simulation time (s) -> integer nanoseconds, rounded (the node's ``stamp``)."""
    return int(round(t * 1e9))


def message_class(type_name: str):
    """``"pkg/msg/Name"`` -> the rclpy message class."""
    import importlib
    pkg, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


# -- arrays -> messages: the one conversion (the node publishes these) ---------------------------
def stamp(t):
    """builtin_interfaces/Time of a simulated time in seconds (rounded to the nanosecond)."""
    from builtin_interfaces.msg import Time
    ns = int(round(t * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def foot_frame(stance_leg):
    return f"foot_{stance_leg}" if stance_leg else "flight"


def joint_state_message(t, q, dq, u, stance_leg, layout=None):
    """sensor_msgs/JointState; effort = B u ([0, 0, u1, u2, 0] for the three-link biped); frame_id names the
    stance foot. ``layout``: the robot's :class:`~biped_sim.config.joints.JointLayout` (default the
    three-link biped's)."""
    from sensor_msgs.msg import JointState
    msg = JointState()
    msg.header.stamp = stamp(t)
    msg.header.frame_id = foot_frame(stance_leg)
    msg.name = list(JOINT_NAMES if layout is None else layout.coordinates)
    msg.position = [float(v) for v in q]
    msg.velocity = [float(v) for v in dq]
    msg.effort = [0.0, 0.0, float(u[0]), float(u[1]), 0.0] if layout is None else layout.effort(u)
    return msg


def wrench_message(t, force, stance_leg):
    """geometry_msgs/WrenchStamped: the ground's force on the stance foot (world axes, N)."""
    from geometry_msgs.msg import WrenchStamped
    msg = WrenchStamped()
    msg.header.stamp = stamp(t)
    msg.header.frame_id = foot_frame(stance_leg)
    msg.wrench.force.x = float(force[0])
    msg.wrench.force.y = float(force[1])
    return msg


def _floats(values):
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def _state(values):
    """A state's value: ``[]`` when it is unknown (a scuff whose deepest point was not inside the last
    step carries an all-NaN state): a reader gets no ``nan`` strings to take for numbers."""
    return _floats(values) if values is not None and all(math.isfinite(float(v)) for v in values) else "[]"


def event_status(event, prefix="biped_sim"):
    """diagnostic_msgs/DiagnosticStatus of an engine Event (docs/node.md lists every key)."""
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
    st = DiagnosticStatus()
    if event.kind in IMPACT_KINDS:
        st.level = DiagnosticStatus.WARN if event.warnings else DiagnosticStatus.OK
        st.name = f"{prefix}/impact"
        st.message = (f"{event.kind}: foot {event.leg} touched down at t={event.time:.9f} s"
                      + ("; " + "; ".join(event.warnings) if event.warnings else ""))
    elif event.kind == "push":
        st.level = DiagnosticStatus.WARN if event.warnings else DiagnosticStatus.OK
        st.name = f"{prefix}/push"
        st.message = (f"push: {_floats(event.push)} N s on the hip at t={event.time:.9f} s"
                      + ("; the stance foot lifted off" if event.stance_leg_before and not event.stance_leg_after
                         else "") + ("; " + "; ".join(event.warnings) if event.warnings else ""))
    elif event.kind in ("error", "zeno") or event.message and event.kind not in ("liftoff", "scuff"):
        st.level = DiagnosticStatus.ERROR
        st.name = f"{prefix}/{event.kind}"
        st.message = event.message or event.kind
    else:
        st.level = DiagnosticStatus.OK
        st.name = f"{prefix}/{event.kind}"
        st.message = event.message or f"{event.kind} of foot {event.leg} at t={event.time:.9f} s"
    st.hardware_id = f"foot_{event.leg}" if event.leg else ""
    kv = [("kind", event.kind), ("time", repr(float(event.time))), ("foot", str(event.leg)),
          ("stance_leg_before", str(event.stance_leg_before)), ("stance_leg_after", str(event.stance_leg_after)),
          ("q", _state(event.q)), ("dq_minus", _state(event.dq_minus)), ("dq_plus", _state(event.dq_plus)),
          ("impulse", _floats(event.impulse) if event.impulse is not None else "[]"),
          ("energy_loss", repr(float(event.energy_loss))), ("warnings", "; ".join(event.warnings))]
    if event.push is not None:
        kv.append(("push", _floats(event.push)))
    st.values = [KeyValue(key=k, value=v) for k, v in kv]
    return st


def diagnostic_array(t, statuses):
    from diagnostic_msgs.msg import DiagnosticArray
    msg = DiagnosticArray()
    msg.header.stamp = stamp(t)
    msg.status = list(statuses)
    return msg


def status_values(status):
    """{key: value} of a DiagnosticStatus (strings)."""
    return {kv.key: kv.value for kv in status.values}


def impact_msg(event):
    """The ``impact`` (or, for other kinds, ``diagnostics``) message of an engine Event."""
    return diagnostic_array(event.time, [event_status(event)])


def clock_msg(t):
    from rosgraph_msgs.msg import Clock
    return Clock(clock=stamp(t))


#: the label of a command's ``layout.dim[0]`` that says which state it answers: "answers 1.234000000"
#: (the state's stamp, seconds and nanoseconds), so that a lockstep node can tell a stale command
ANSWERS = "answers "


def answers_label(t_ns: int) -> str:
    """The tag of a command that answers the state stamped ``t_ns``: ``answers <sec>.<nanosec>``."""
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    return f"{ANSWERS}{sec}.{nsec:09d}"


def torque_msg(u, answers_ns: int | None = None):
    """A ``hip_torque`` command: one torque per actuated joint (``[u1, u2]`` for the three-link biped);
    tagged with the state it answers if ``answers_ns`` is given."""
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension
    msg = Float64MultiArray(data=[float(v) for v in u])
    if answers_ns is not None:
        msg.layout.dim = [MultiArrayDimension(label=answers_label(answers_ns), size=len(msg.data),
                                              stride=len(msg.data))]
    return msg


# -- messages -> plain values (any decoded form) ---------------------------------------------------
def stamp_ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def torques_of_effort(effort, slots=THREE_LINK_SLOTS) -> list:
    """u of a JointState's ``effort`` (``B u``): the values at ``slots``, the actuated joints' columns (the
    three-link biped's hips by default); zeros for an effort too short to hold them (none recorded)."""
    if slots and len(effort) > max(slots):
        return [effort[i] for i in slots]
    return [0.0] * len(slots)


def joint_state_values(m, slots=THREE_LINK_SLOTS):
    """(t_ns, q, dq, u, stance_leg) of a JointState; u is ``effort`` at ``slots`` (:func:`torques_of_effort`)."""
    fid = m.header.frame_id
    leg = int(fid.split("_")[1]) if fid.startswith("foot_") else 0
    return stamp_ns(m.header.stamp), list(m.position), list(m.velocity), torques_of_effort(list(m.effort), slots), leg


def _leg_of_frame(frame_id) -> int:
    return int(frame_id.split("_")[1]) if frame_id.startswith("foot_") else 0


def joint_state_fields_cdr(type_name, data):
    """(t_ns, q, dq, effort, stance_leg) of a JointState's CDR bytes, read without building the message
    (``cdr.read_joint_state``; rclpy's deserialiser for a form that reader does not take)."""
    from biped_sim.recording.cdr import read_joint_state
    fields = read_joint_state(data)
    if fields is None:
        from biped_sim.recording.bagio import decode
        m = decode(type_name, data)
        return (stamp_ns(m.header.stamp), list(m.position), list(m.velocity), list(m.effort),
                _leg_of_frame(m.header.frame_id))
    t_ns, frame_id, position, velocity, effort = fields
    return t_ns, position, velocity, effort, _leg_of_frame(frame_id)


def joint_state_values_cdr(type_name, data, slots=THREE_LINK_SLOTS):
    """:func:`joint_state_values` of a JointState's CDR bytes (:func:`joint_state_fields_cdr`)."""
    t_ns, position, velocity, effort, leg = joint_state_fields_cdr(type_name, data)
    return t_ns, position, velocity, torques_of_effort(effort, slots), leg


def joint_state_names_cdr(type_name, data) -> list:
    """The names of a JointState's CDR bytes: q's coordinates, in order (``cdr.read_joint_state_names``)."""
    from biped_sim.recording.cdr import read_joint_state_names
    names = read_joint_state_names(data)
    if names is None:
        from biped_sim.recording.bagio import decode
        names = list(decode(type_name, data).name)
    return names


def wrench_values_cdr(type_name, data):
    """:func:`wrench_values` of a WrenchStamped's CDR bytes (``cdr.read_wrench_stamped``)."""
    from biped_sim.recording.cdr import read_wrench_stamped
    fields = read_wrench_stamped(data)
    if fields is None:
        from biped_sim.recording.bagio import decode
        return wrench_values(decode(type_name, data))
    t_ns, frame_id, wrench = fields
    return t_ns, [wrench[0], wrench[1]], _leg_of_frame(frame_id)


def wrench_values(m):
    """(t_ns, [Fx, Fy], stance_leg) of a WrenchStamped."""
    fid = m.header.frame_id
    leg = int(fid.split("_")[1]) if fid.startswith("foot_") else 0
    return stamp_ns(m.header.stamp), [m.wrench.force.x, m.wrench.force.y], leg


def typed_value(text: str):
    """A DiagnosticStatus value (a string by its message type) as what it says: an int (``"2"``), a
    float (``"0.4715595367472371"``, as written by ``repr``), a list of floats (``"[0.1, 2.0]"``,
    ``"[]"``), else the string itself (kinds, messages, warnings)."""
    text = text.strip()
    if text.startswith("[") and text.endswith("]"):
        inner = text[1:-1].strip()
        try:
            return [float(v) for v in inner.split(",")] if inner else []
        except ValueError:
            return text
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def event_values(m):
    """Events of a DiagnosticArray (``impact``/``diagnostics``): list of dicts, values parsed."""
    out = []
    for st in m.status:
        d = {kv.key: typed_value(kv.value) for kv in st.values}
        lvl = st.level
        d["name"], d["message"] = st.name, st.message
        d["level"] = lvl[0] if isinstance(lvl, (bytes, bytearray)) else int(lvl)
        d["t_ns"] = stamp_ns(m.header.stamp)
        out.append(d)
    return out


def event_values_cdr(type_name, data):
    """:func:`event_values` of a DiagnosticArray's CDR bytes, read without building the message
    (``cdr.read_diagnostic_array``; rclpy's deserialiser for a form that reader does not take)."""
    from biped_sim.recording.cdr import read_diagnostic_array
    fields = read_diagnostic_array(data)
    if fields is None:
        from biped_sim.recording.bagio import decode
        return event_values(decode(type_name, data))
    t_ns, statuses = fields
    out = []
    for level, name, message, _hardware_id, values in statuses:
        d = {key: typed_value(value) for key, value in values}
        d["name"], d["message"], d["level"], d["t_ns"] = name, message, level, t_ns
        out.append(d)
    return out


def clock_ns(m) -> int:
    return stamp_ns(m.clock)


def answered_ns(m) -> int | None:
    """The stamp (ns) of the state a command answers (its ``answers`` tag), or None if untagged."""
    dims = m.layout.dim
    label = dims[0].label if len(dims) else ""
    if not label.startswith(ANSWERS):
        return None
    sec, _, nsec = label[len(ANSWERS):].partition(".")
    try:
        return int(sec) * 1_000_000_000 + int(nsec.ljust(9, "0")[:9])
    except ValueError:
        return None


def torque_values(m, count=2):
    """The torques of a command (one per actuator: ``count``, two for the three-link biped), or None if it is
    not ``count`` finite numbers."""
    d = [float(v) for v in m.data]
    return d if len(d) == count and all(math.isfinite(v) for v in d) else None
