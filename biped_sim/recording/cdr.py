"""Fast CDR serialisation of the recorder's hot message types (the recorder's ``write`` path).

Owns the bytes only, not the message layout: it serialises the rclpy message objects the node's
functions build (:mod:`biped_sim.recording.messages`), in plain little-endian CDR (XCDR1, encapsulation
``00 01 00 00``) as rmw_fastrtps does. ``rclpy.serialization.serialize_message`` costs 10-60 us a
message here; this costs 2-4 us, which keeps recording within its budget (bench_record). Types
other than the four below, or shapes not seen before, go to rclpy's serialiser; the tests check
that both decode to the same message.

CDR rules used: primitives aligned to their size (relative to the end of the 4-byte encapsulation
header); a string is a uint32 length including the NUL, the bytes, the NUL; a sequence is a uint32
count, then its elements.
"""
from __future__ import annotations

import struct

#: the CDR encapsulation header every serialised message starts with (little-endian plain CDR)
ENCAPSULATION_HEADER = b"\x00\x01\x00\x00"
_II = struct.Struct("<iI")


def _pad(offset, align):
    return (-offset) % align


def _string(buf, off, s):
    b = s.encode() + b"\x00"
    p = _pad(off, 4)
    buf += b"\x00" * p + struct.pack("<I", len(b)) + b
    return off + p + 4 + len(b)


def _joint_state_layout(frame_id, names, n_pos, n_vel, n_eff):
    """(constant bytes after the stamp, struct for the three float sequences) of a JointState shape."""
    buf = bytearray()
    off = 8                                      # after stamp (sec, nanosec)
    off = _string(buf, off, frame_id)
    p = _pad(off, 4)
    buf += b"\x00" * p + struct.pack("<I", len(names))
    off += p + 4
    for name in names:
        off = _string(buf, off, name)
    fmt = "<"
    for n in (n_pos, n_vel, n_eff):
        p = _pad(off, 4)
        fmt += f"{p}xI" if p else "I"
        off += p + 4
        if n:
            p = _pad(off, 8)
            fmt += (f"{p}x" if p else "") + f"{n}d"
            off += p + 8 * n
    return bytes(buf), struct.Struct(fmt)


_js_cache = {}


def joint_state(m):
    h = m.header
    names = m.name
    pos, vel, eff = m.position, m.velocity, m.effort
    key = (h.frame_id, tuple(names), len(pos), len(vel), len(eff))
    lay = _js_cache.get(key)
    if lay is None:
        lay = _js_cache[key] = _joint_state_layout(*key)
    st = h.stamp
    return b"".join((ENCAPSULATION_HEADER, _II.pack(st.sec, st.nanosec), lay[0],
                     lay[1].pack(len(pos), *pos, len(vel), *vel, len(eff), *eff)))


_wrench_cache = {}


def wrench_stamped(m):
    h = m.header
    st = _wrench_cache.get(h.frame_id)
    if st is None:
        fmt, const = wrench_stamped_format(h.frame_id)
        st = _wrench_cache[h.frame_id] = (struct.Struct("<" + fmt), const)
    f, t = m.wrench.force, m.wrench.torque
    s = h.stamp
    return st[0].pack(ENCAPSULATION_HEADER, s.sec, s.nanosec, st[1], f.x, f.y, f.z, t.x, t.y, t.z)


def clock(m):
    c = m.clock
    return ENCAPSULATION_HEADER + _II.pack(c.sec, c.nanosec)


_f64_cache = {}


def float64_multi_array(m):
    dims = m.layout.dim
    if not dims:
        return float64_multi_array_data(m.data, m.layout.data_offset)
    # a labelled layout (a lockstep command's "answers" tag): dims, then data_offset, data
    buf = bytearray(struct.pack("<I", len(dims)))
    off = 4
    for d in dims:
        off = _string(buf, off, d.label)
        p = _pad(off, 4)
        buf += b"\x00" * p + struct.pack("<II", d.size, d.stride)
        off += p + 8
    data = m.data
    n = len(data)
    p = _pad(off, 4)
    buf += b"\x00" * p + struct.pack("<II", m.layout.data_offset, n)
    off += p + 8
    if n:
        buf += b"\x00" * _pad(off, 8) + struct.pack(f"<{n}d", *data)
    return ENCAPSULATION_HEADER + bytes(buf)


def float64_multi_array_data(data, data_offset=0):
    """The CDR of ``std_msgs/Float64MultiArray(data=data)`` (empty layout) without building the message:
    ``simulate --record`` records its commands with it (the node records the messages it receives)."""
    n = len(data)
    s = _f64_cache.get(n)
    if s is None:
        # layout.dim count (0), layout.data_offset, data count, (pad to 8), data
        s = _f64_cache[n] = struct.Struct(f"<III4x{n}d" if n else "<III")
    return ENCAPSULATION_HEADER + s.pack(0, data_offset, n, *data)


# -- the same layouts as struct formats, for packing a whole period's state in one call -------------
def joint_state_format(frame_id, names, n):
    """(format without byte order, constant) of a JointState with ``n`` positions, velocities and
    efforts; its values are (ENCAPSULATION_HEADER, sec, nanosec, constant, n, *position, n, *velocity, n, *effort)."""
    const, st = _joint_state_layout(frame_id, tuple(names), n, n, n)
    return f"4siI{len(const)}s" + st.format.lstrip("<"), const


def wrench_stamped_format(frame_id):
    """(format, constant) of a WrenchStamped: values (ENCAPSULATION_HEADER, sec, nanosec, constant, fx, fy,
    fz, tx, ty, tz)."""
    buf = bytearray()
    off = _string(buf, 8, frame_id)
    p = _pad(off, 8)
    return f"4siI{len(buf)}s" + (f"{p}x6d" if p else "6d"), bytes(buf)


CLOCK_FORMAT = "4siI"          # values (ENCAPSULATION_HEADER, sec, nanosec)
_CLOCK = struct.Struct("<" + CLOCK_FORMAT)


def _three_link_effort(u):
    return [0.0, 0.0, float(u[0]), float(u[1]), 0.0]


class StateSerializer:
    """The CDR of the node's state messages from plain values, without building rclpy messages: the
    bytes of ``serialize_message`` of :func:`~biped_sim.recording.messages.joint_state_message`,
    ``wrench_message`` and ``clock_msg`` (tested), in one ``struct`` call each. ``sim_node`` publishes
    these bytes and records the same bytes: filling rosidl messages (their setters check every value)
    and letting rclpy convert and serialise them cost about 35 us a period more (bench_node)."""

    def __init__(self, names, labels=None, effort=None):
        self.names = tuple(names)
        # u -> joint_states' effort (B u), from the robot's joint layout (config.joints); default the
        # three-link biped's [0, 0, u1, u2, 0]
        self._effort = effort or _three_link_effort
        self._joint_state, self._wrench = {}, {}      # (struct, constant) per frame id (and size)
        # what ``period`` names each message by: the output name, or e.g. its topic (``labels``), so that
        # the node hands the list to the recorder as it is
        self._labels = tuple((labels or {}).get(name, name) for name in ("joint_states", "ground_reaction", "clock"))

    def joint_state(self, sec: int, nanosec: int, frame_id: str, position, velocity, effort) -> bytes:
        """sensor_msgs/JointState(header(stamp, frame_id), the names, position, velocity, effort)."""
        n = len(position)
        plan = self._joint_state.get((frame_id, n))
        if plan is None:
            fmt, const = joint_state_format(frame_id, self.names, n)
            plan = self._joint_state[(frame_id, n)] = (struct.Struct("<" + fmt).pack, const)
        return plan[0](ENCAPSULATION_HEADER, sec, nanosec, plan[1], n, *position, n, *velocity, n, *effort)

    def wrench_stamped(self, sec: int, nanosec: int, frame_id: str, force) -> bytes:
        """geometry_msgs/WrenchStamped(header(stamp, frame_id), force (fx, fy, 0), zero torque)."""
        plan = self._wrench.get(frame_id)
        if plan is None:
            fmt, const = wrench_stamped_format(frame_id)
            plan = self._wrench[frame_id] = (struct.Struct("<" + fmt).pack, const)
        return plan[0](ENCAPSULATION_HEADER, sec, nanosec, plan[1], force[0], force[1], 0.0, 0.0, 0.0, 0.0)

    @staticmethod
    def clock(sec: int, nanosec: int) -> bytes:
        """rosgraph_msgs/Clock(clock=stamp)."""
        return _CLOCK.pack(ENCAPSULATION_HEADER, sec, nanosec)

    def period(self, t_ns: int, frame_id: str, position, velocity, u, force, joint_states=True,
               ground_reaction=True, clock=True) -> list:
        """The state messages of one period as ``sim_node`` publishes them: [(label, CDR bytes)] of
        joint_states (effort B u: [0, 0, u1, u2, 0] for the three-link biped), ground_reaction (unless
        ``force`` is None: in flight) and clock, those asked for, stamped ``t_ns``; a label is the output name unless
        ``labels`` named it otherwise."""
        sec, nanosec = divmod(t_ns, 1_000_000_000)
        out = []
        labels = self._labels
        if joint_states:
            out.append((labels[0], self.joint_state(sec, nanosec, frame_id, position, velocity, self._effort(u))))
        if ground_reaction and force is not None:
            out.append((labels[1], self.wrench_stamped(sec, nanosec, frame_id, force)))
        if clock:
            out.append((labels[2], self.clock(sec, nanosec)))
        return out


def tf_message(sec: int, nanosec: int, transforms) -> bytes:
    """The CDR of a ``tf2_msgs/msg/TFMessage``: ``transforms`` a list of (parent frame, child frame,
    translation (x, y, z), rotation quaternion (x, y, z, w)), each stamped (sec, nanosec). Written here
    from values: tf2_msgs has no Python package outside a ROS install (not on PyPI)."""
    buf = bytearray(struct.pack("<I", len(transforms)))
    off = 4
    for parent, child, translation, rotation in transforms:
        p = _pad(off, 4)
        buf += b"\x00" * p + _II.pack(sec, nanosec)
        off = _string(buf, off + p + 8, parent)
        off = _string(buf, off, child)
        p = _pad(off, 8)
        buf += b"\x00" * p + struct.pack("<7d", *translation, *rotation)
        off += p + 56
    return ENCAPSULATION_HEADER + bytes(buf)


# -- reading: the fields of the state messages from their CDR, without rclpy (inspect, load_run) ----
_U32 = struct.Struct("<I")
_WRENCH_VALUES = struct.Struct("<6d")


def _read_string(b, off):
    """(offset after it, the string) of a CDR string at ``off`` (aligned to 4 first)."""
    off += _pad(off, 4)
    (n,) = _U32.unpack_from(b, off)
    return off + 4 + n, bytes(b[off + 4:off + 3 + n]).decode()


def read_joint_state(data):
    """(t_ns, frame_id, position, velocity, effort) of the CDR of a ``sensor_msgs/JointState``; None
    where it is not little-endian plain CDR (a reader then takes rclpy's deserialiser)."""
    if data[:2] != ENCAPSULATION_HEADER[:2]:
        return None
    b = memoryview(data)[4:]            # offsets count from the end of the encapsulation header
    sec, nanosec = _II.unpack_from(b, 0)
    off, frame_id = _read_string(b, 8)
    off += _pad(off, 4)
    (n_names,) = _U32.unpack_from(b, off)
    off += 4
    for _ in range(n_names):
        off += _pad(off, 4)
        off += 4 + _U32.unpack_from(b, off)[0]
    seqs = []
    for _ in range(3):                 # position, velocity, effort
        off += _pad(off, 4)
        (n,) = _U32.unpack_from(b, off)
        off += 4
        if n:
            off += _pad(off, 8)
            seqs.append(list(struct.unpack_from(f"<{n}d", b, off)))
            off += 8 * n
        else:
            seqs.append([])
    return sec * 1_000_000_000 + nanosec, frame_id, *seqs


def read_joint_state_names(data):
    """The names of the CDR of a ``sensor_msgs/JointState`` (q's coordinates, in order); None where it is not
    little-endian plain CDR."""
    if data[:2] != ENCAPSULATION_HEADER[:2]:
        return None
    b = memoryview(data)[4:]
    off, _frame_id = _read_string(b, 8)
    off += _pad(off, 4)
    (n_names,) = _U32.unpack_from(b, off)
    off += 4
    names = []
    for _ in range(n_names):
        off, name = _read_string(b, off)
        names.append(name)
    return names


def read_float64_multi_array(data):
    """(data, [dim labels]) of the CDR of a ``std_msgs/Float64MultiArray`` (a ``hip_torque`` command);
    None where it is not little-endian plain CDR (the caller then takes rclpy's deserialiser)."""
    if data[:2] != ENCAPSULATION_HEADER[:2]:
        return None
    b = memoryview(data)[4:]
    (n_dims,) = _U32.unpack_from(b, 0)
    off, labels = 4, []
    for _ in range(n_dims):             # label, size, stride
        off, label = _read_string(b, off)
        labels.append(label)
        off += _pad(off, 4) + 8
    off += _pad(off, 4) + 4             # data_offset
    (n,) = _U32.unpack_from(b, off)
    off += 4
    values = list(struct.unpack_from(f"<{n}d", b, off + _pad(off, 8))) if n else []
    return values, labels


def read_wrench_stamped(data):
    """(t_ns, frame_id, (fx, fy, fz, tx, ty, tz)) of the CDR of a ``geometry_msgs/WrenchStamped``; None
    where it is not little-endian plain CDR."""
    if data[:2] != ENCAPSULATION_HEADER[:2]:
        return None
    b = memoryview(data)[4:]
    sec, nanosec = _II.unpack_from(b, 0)
    off, frame_id = _read_string(b, 8)
    return sec * 1_000_000_000 + nanosec, frame_id, _WRENCH_VALUES.unpack_from(b, off + _pad(off, 8))


def read_diagnostic_array(data):
    """(t_ns, [(level, name, message, hardware_id, [(key, value)])]) of the CDR of a
    ``diagnostic_msgs/DiagnosticArray``; None where it is not little-endian plain CDR."""
    if data[:2] != ENCAPSULATION_HEADER[:2]:
        return None
    b = memoryview(data)[4:]
    sec, nanosec = _II.unpack_from(b, 0)
    off, _frame_id = _read_string(b, 8)
    off += _pad(off, 4)
    (n_status,) = _U32.unpack_from(b, off)
    off += 4
    statuses = []
    for _ in range(n_status):
        level = b[off]
        off, name = _read_string(b, off + 1)
        off, message = _read_string(b, off)
        off, hardware_id = _read_string(b, off)
        off += _pad(off, 4)
        (n_values,) = _U32.unpack_from(b, off)
        off += 4
        values = []
        for _ in range(n_values):
            off, key = _read_string(b, off)
            off, value = _read_string(b, off)
            values.append((key, value))
        statuses.append((level, name, message, hardware_id, values))
    return sec * 1_000_000_000 + nanosec, statuses


#: types without an rclpy message class here, whose CDR this module writes from values (tf_message):
#: the recorder takes their bytes only
BYTES_ONLY = {"tf2_msgs/msg/TFMessage"}

#: encoders that return None for shapes they do not handle (then rclpy serialises)
MAY_DECLINE = {"std_msgs/msg/Float64MultiArray"}

ENCODERS = {
    "sensor_msgs/msg/JointState": joint_state,
    "geometry_msgs/msg/WrenchStamped": wrench_stamped,
    "rosgraph_msgs/msg/Clock": clock,
    "std_msgs/msg/Float64MultiArray": float64_multi_array,
}


def serializer(type_name):
    """A function msg -> CDR bytes for ``type_name`` (the fast one if there is one, else rclpy's)."""
    if type_name in BYTES_ONLY:
        def refuse(msg):
            raise TypeError(f"{type_name} is recorded from its CDR bytes only (no Python message class here), "
                            f"got {type(msg).__name__}")
        return refuse
    from rclpy.serialization import serialize_message
    fast = ENCODERS.get(type_name)
    if fast is None:
        return serialize_message
    if type_name not in MAY_DECLINE:
        return fast

    def ser(msg):
        out = fast(msg)
        return serialize_message(msg) if out is None else out
    return ser
