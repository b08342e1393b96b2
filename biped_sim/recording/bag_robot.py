"""The robot a bag recorded: its coordinates, its actuators, where their torques are in ``effort``, its model.

Owns :func:`bag_robot`, which every reader of a bag (``load_run``, ``inspect``, ``animate``) asks what the
rows of its ``joint_states`` are. The robot is the run's ``robot`` parameter as the bag's ``biped_sim``
record carries it (a shipped name or a description file); a bag of a version that recorded no ``robot`` is
the three-link biped's. Its layout (:func:`biped_sim.config.joints.joint_layout`) names the actuated joints;
the recorded ``joint_states`` names say which column of q, dq and ``effort`` each coordinate is, so u is
read from ``effort`` at the actuated joints' columns (``effort = B u``). A bag whose robot cannot be loaded
(a description file that is gone) is read by the names it recorded: q and dq whole, the torques left in
``effort`` (u has no columns), and :attr:`BagRobot.problem` says so in one line.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from biped_sim.recording.messages import JOINT_NAMES

THREE_LINK = "three_link"
#: the three-link biped's actuated joints (``joint_layout("three_link").actuated``)
THREE_LINK_ACTUATED = ("hip_1", "hip_2")


@dataclass
class BagRobot:
    """``robot``: the recorded robot (its name or description file; None for a bag of another program);
    ``coordinates``: q's names, in the order of the recorded rows; ``actuators``: u's names (the actuated
    joints, in the order of a command's entries; empty when the robot is not known); ``slots``: the column of
    ``effort`` (and of q) that holds each actuator's torque; ``problem``: '' or, in one line, why the robot
    could not be loaded and what is read without it (``unloaded``: its first part, why). :meth:`model` gives
    the model to draw it with (loaded once, on first use)."""
    robot: str | None
    coordinates: tuple
    actuators: tuple
    slots: tuple
    params: dict | None = None
    problem: str = ""
    unloaded: str = ""
    _model: object = field(default=None, repr=False)

    @property
    def n(self) -> int:
        return len(self.coordinates)

    @property
    def three_link(self) -> bool:
        """Whether the run is of a three-link robot (:func:`is_three_link`)."""
        return is_three_link(self.robot, self.coordinates, self.actuators)

    def model(self):
        """The robot's model: a ``BipedModel`` of the run's ``model.*`` parameters for a three-link robot, a
        ``GeneratedModel`` for any other description; ValueError, one line, when it cannot be loaded."""
        if self._model is None:
            if self.problem:
                raise ValueError(f"{self.unloaded or self.problem}: its links cannot be drawn")
            if self.robot is None and not self.three_link:
                raise ValueError(f"the bag does not say which robot it recorded (no biped_sim record) and its "
                                 f"joint_states names ({', '.join(self.coordinates) or 'none'}) are not the "
                                 "three-link biped's: its robot cannot be drawn")
            self._model = run_model(self.params, self.robot or THREE_LINK)
        return self._model


def is_three_link(robot, coordinates, actuators) -> bool:
    """Whether a run is of a three-link robot the engine runs as a ``BipedModel`` (``three_link``,
    ``compass_gait``, whose base angle is ``hip_pitch``, ``three_link_hip_mass``; or another program's bag
    with the three-link's names), its rows those of docs/model.md: the summary and the data frame keep its
    names (u1, u2; x, y, q1, q2, q3)."""
    from biped_sim.config.models import THREE_LINK_PARAMETERS
    known = coordinates == JOINT_NAMES if robot is None else robot in THREE_LINK_PARAMETERS
    return (known and len(coordinates) == 5 and tuple(coordinates[2:4]) == THREE_LINK_ACTUATED
            and tuple(actuators) == THREE_LINK_ACTUATED)


def run_model(params: dict | None, robot: str = THREE_LINK):
    """The model of a run's parameters: a ``BipedModel`` of the ``model.*`` values for a shipped three-link
    robot (the defaults without parameters), else the description's ``GeneratedModel``."""
    from biped_sim.config import models
    if robot in models.THREE_LINK_PARAMETERS:
        from biped_sim.config.parameters import model_arguments
        from biped_sim.engine.model import BipedModel
        return BipedModel(**model_arguments(params)) if params else BipedModel()
    return models.load_model(robot)


def bag_robot(params: dict | None, names) -> BagRobot:
    """The :class:`BagRobot` of a bag's parameters record (None: not recorded by biped_sim) and the names its
    ``joint_states`` carry (empty or None: no message, or none named; the robot's layout names them)."""
    from biped_sim.config.joints import joint_layout
    names = tuple(names or ())
    robot = None if params is None else str(params.get("robot", THREE_LINK))
    if robot is None:
        # another program's bag: the three-link biped's names are read as today; any other names as they are
        coordinates = names or JOINT_NAMES
        if coordinates == JOINT_NAMES:
            return BagRobot(None, JOINT_NAMES, THREE_LINK_ACTUATED, (2, 3), params)
        return BagRobot(None, coordinates, (), (), params)
    try:
        layout = joint_layout(robot)
    except (ValueError, OSError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        unloaded = f"the bag's robot {robot!r} cannot be loaded ({reason})"
        read = (f"its joint angles are read by the names joint_states recorded ({', '.join(names)}), its motor "
                "torques are left in effort" if names else "no joint_states to read")
        return BagRobot(robot, names, (), (), params, f"{unloaded}: {read}", unloaded)
    coordinates = names or layout.coordinates
    missing = [a for a in layout.actuated if a not in coordinates]
    if missing:
        return BagRobot(robot, coordinates, (), (), params,
                        f"the bag's robot {robot!r} has actuated joints {', '.join(missing)} that its joint_states "
                        f"do not name ({', '.join(coordinates)}): the description changed since the recording? "
                        "its motor torques are left in effort")
    return BagRobot(robot, coordinates, layout.actuated, tuple(coordinates.index(a) for a in layout.actuated),
                    params)
