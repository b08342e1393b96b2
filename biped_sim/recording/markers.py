"""The robot drawn as ``visualization_msgs/msg/MarkerArray`` (the ``markers`` topic), for RViz and Foxglove.

Owns the marker message (built here, so that the node, ``simulate --record`` and a bag tool make the
same one) and what the animation shares with it: the arrow scale of the ground force, the colours,
the impact flash. The points come from :mod:`biped_sim.engine.drawing` (a three-link ``BipedModel``'s
``stick_figure``; any other chain from its description's links), so that a five-link robot with knees
draws each leg as a polyline hip - knee - foot.

Axes: ``frame_id`` ``world``; the model's sagittal plane (x forward, y up) is drawn as the x-z plane
(x forward, z up, y = 0), as RViz and Foxglove expect a vertical z. Every marker is in namespace
``biped_sim`` with a fixed id (below); a part that is absent (the force arrow in flight, the flash
between impacts) is sent with action DELETE, so each array holds the same nine ids.

Also owns the frame that moves with the robot, ``hip`` (origin at the hip, axes parallel to
``world``'s): a bag records the transform world -> hip on ``/tf`` with each MarkerArray, at its stamp
(:func:`hip_transform`), and the Foxglove layout's 3D panel follows that frame.
"""
from __future__ import annotations

import math

from biped_sim.engine.results import IMPACT_KINDS

#: ground force arrow: this many newtons per metre of arrow (the weight of the default robot,
#: 196 N, is a 0.49 m arrow)
NEWTONS_PER_METRE = 400.0
#: the impact flash lasts this long (s of the stream's clock: wall time in the node, simulated time
#: in a headless recording and in the animation)
FLASH_DURATION = 0.25
#: half the length of the drawn ground line, centred under the hip (m)
GROUND_HALF_LENGTH = 3.0
FRAME_ID = "world"
NAMESPACE = "biped_sim"
#: the frame that moves with the robot (origin at the hip); a 3D view follows it
FOLLOW_FRAME = "hip"
TF_TOPIC = "/tf"
TF_TYPE = "tf2_msgs/msg/TFMessage"

# marker ids
LEG_1, LEG_2, TORSO, HIP, FOOT_1, FOOT_2, FORCE, GROUND, FLASH = range(1, 10)

# colours (r, g, b, a): leg 1 blue, leg 2 orange, torso green as in `biped-sim inspect`; the stance
# foot red, a swing foot grey
LEG_COLOURS = {1: (0.12, 0.47, 0.71, 1.0), 2: (1.0, 0.50, 0.05, 1.0)}
TORSO_COLOUR = (0.17, 0.63, 0.17, 1.0)
HIP_COLOUR = (0.1, 0.1, 0.1, 1.0)
STANCE_FOOT_COLOUR = (0.84, 0.15, 0.16, 1.0)
SWING_FOOT_COLOUR = (0.5, 0.5, 0.5, 1.0)
FORCE_COLOUR = (0.58, 0.40, 0.74, 1.0)
GROUND_COLOUR = (0.3, 0.3, 0.3, 1.0)
FLASH_COLOUR = (1.0, 0.85, 0.0, 0.7)


def ground_y(x: float, slope: float) -> float:
    """The ground line's y at x: height above the ground is y + tan(slope) x (engine/guards.py)."""
    return -math.tan(slope) * x


def force_arrow_end(foot, force):
    """The arrow's tip: the foot plus the force times 1 / NEWTONS_PER_METRE (x, y in the plane)."""
    return (foot[0] + force[0] / NEWTONS_PER_METRE, foot[1] + force[1] / NEWTONS_PER_METRE)


def _point(xy):
    from geometry_msgs.msg import Point
    return Point(x=float(xy[0]), y=0.0, z=float(xy[1]))


def _marker(header, mid, kind, colour, scale, points=(), position=None):
    from std_msgs.msg import ColorRGBA
    from visualization_msgs.msg import Marker
    m = Marker(header=header, ns=NAMESPACE, id=mid, type=kind, action=Marker.ADD)
    m.pose.orientation.w = 1.0
    if position is not None:
        p = _point(position)
        m.pose.position.x, m.pose.position.z = p.x, p.z
    m.scale.x, m.scale.y, m.scale.z = scale
    m.color = ColorRGBA(r=colour[0], g=colour[1], b=colour[2], a=colour[3])
    m.points = [_point(p) for p in points]
    return m


def _deleted(header, mid, kind):
    from visualization_msgs.msg import Marker
    return Marker(header=header, ns=NAMESPACE, id=mid, type=kind, action=Marker.DELETE)


def leg_marker_id(leg: int) -> int:
    """The id of leg ``leg``'s lines (foot ``leg``'s links): LEG_1, LEG_2, then 10, 12, ... for a robot with
    more contact points."""
    return {1: LEG_1, 2: LEG_2}.get(leg, 10 + 2 * (leg - 3))


def foot_marker_id(leg: int) -> int:
    return {1: FOOT_1, 2: FOOT_2}.get(leg, 11 + 2 * (leg - 3))


def _lines_marker(header, mid, colour, width, lines):
    from visualization_msgs.msg import Marker
    return _marker(header, mid, Marker.LINE_STRIP if lines.strip else Marker.LINE_LIST, colour, (width, 0, 0),
                   lines.points)


def marker_array(t, figure, stance_leg, force, slope=0.0, flash_at=None):
    """The MarkerArray of one state at simulated time ``t`` (the header stamp).

    ``figure``: the robot drawn (:meth:`biped_sim.engine.drawing.RobotDrawing.figure`, any chain), or a
    three-link ``BipedModel.stick_figure(q)``; ``stance_leg`` 1, 2 or 0 (flight); ``force`` the
    ground's force on the stance foot [Fx, Fy] (N; ignored in flight); ``slope`` the ground's angle
    (rad); ``flash_at``: the (x, y) of a touchdown to flash, or None.
    """
    from builtin_interfaces.msg import Duration
    from std_msgs.msg import Header
    from visualization_msgs.msg import Marker, MarkerArray

    from biped_sim.engine.drawing import Figure, from_stick_figure
    from biped_sim.recording.messages import stamp
    if not isinstance(figure, Figure):
        figure = from_stick_figure(figure)
    header = Header(stamp=stamp(t), frame_id=FRAME_ID)
    hip, feet = figure.hip, figure.feet
    out = [_lines_marker(header, leg_marker_id(k), LEG_COLOURS[2 - k % 2], 0.04, lines)
           for k, lines in enumerate(figure.legs, start=1)]
    out[2:2] = [_lines_marker(header, TORSO, TORSO_COLOUR, 0.05, figure.body),
                _marker(header, HIP, Marker.SPHERE, HIP_COLOUR, (0.09, 0.09, 0.09), position=hip)]
    for leg, point in enumerate(feet, start=1):
        stance = leg == stance_leg
        d = 0.08 if stance else 0.06
        out.append(_marker(header, foot_marker_id(leg), Marker.SPHERE,
                           STANCE_FOOT_COLOUR if stance else SWING_FOOT_COLOUR, (d, d, d), position=point))
    if 1 <= stance_leg <= len(feet):
        foot = feet[stance_leg - 1]
        out.append(_marker(header, FORCE, Marker.ARROW, FORCE_COLOUR, (0.02, 0.05, 0.06),
                           (foot, force_arrow_end(foot, force))))
    else:
        out.append(_deleted(header, FORCE, Marker.ARROW))
    x0, x1 = hip[0] - GROUND_HALF_LENGTH, hip[0] + GROUND_HALF_LENGTH
    out.append(_marker(header, GROUND, Marker.LINE_STRIP, GROUND_COLOUR, (0.02, 0, 0),
                       ((x0, ground_y(x0, slope)), (x1, ground_y(x1, slope)))))
    if flash_at is not None:
        m = _marker(header, FLASH, Marker.SPHERE, FLASH_COLOUR, (0.25, 0.25, 0.25), position=flash_at)
        m.lifetime = Duration(sec=0, nanosec=int(FLASH_DURATION * 1e9))
        out.append(m)
    else:
        out.append(_deleted(header, FLASH, Marker.SPHERE))
    return MarkerArray(markers=out)


def hip_transform(t_ns: int, hip) -> bytes:
    """The CDR of the ``/tf`` message at stamp ``t_ns``: the transform world -> hip, the hip's (x, y)
    in the plane drawn as (x, 0, y), no rotation (the view turns with nothing but follows the walk)."""
    from biped_sim.recording.cdr import tf_message
    sec, nanosec = divmod(int(t_ns), 1_000_000_000)
    return tf_message(sec, nanosec, [(FRAME_ID, FOLLOW_FRAME, (float(hip[0]), 0.0, float(hip[1])),
                                      (0.0, 0.0, 0.0, 1.0))])


class MarkerStream:
    """When to send the next MarkerArray and what it shows, for a simulator advancing period by period.

    ``poll(now, sim)`` returns the array of the simulator's current state once ``1 / rate`` has
    passed on the caller's clock ``now`` (the node: wall time; a headless recording: simulated time),
    else None; nothing is computed in between but the look for new touchdowns, each of which
    flashes for FLASH_DURATION on that clock (at least one array).
    """

    def __init__(self, model, slope: float, rate: float):
        from biped_sim.engine.drawing import RobotDrawing
        self.model, self.slope, self.interval = model, float(slope), 1.0 / float(rate)
        self.drawing = RobotDrawing(model)      # any chain: its description's links (drawing.py)
        self.restart()

    def restart(self):
        """A new run (the node's ~/reset): its first state is drawn at once, its events counted from 0."""
        self.next_due = -math.inf
        self.hip = None         # the hip (x, y) of the last array made
        self.n_events = 0
        self.flash_at, self.flash_until = None, -math.inf

    def poll(self, now: float, sim, force: bool = False):
        """The MarkerArray of ``sim``'s state (``t``, ``q``, ``stance_leg``, ``ground_force``,
        ``events``) if one is due at ``now`` (or ``force``), else None."""
        events = sim.events
        if len(events) > self.n_events:
            touchdowns = [e for e in events[self.n_events:] if e.kind in IMPACT_KINDS]
            self.n_events = len(events)
            if touchdowns:
                last = touchdowns[-1]
                self.flash_at = tuple(self.drawing.foot(last.q, last.leg))
                self.flash_until = now + FLASH_DURATION
                self.next_due = min(self.next_due, now)     # show it now
        if now < self.next_due and not force:
            return None
        self.next_due = now + self.interval
        flash = self.flash_at if now <= self.flash_until else None
        if flash is None:
            self.flash_at = None
        leg = sim.stance_leg
        figure = self.drawing.figure(sim.q)
        self.hip = figure.hip       # the /tf of this array (hip_transform)
        return marker_array(sim.t, figure, leg, sim.ground_force if leg else (0.0, 0.0), self.slope, flash)
