"""What the node's messages say of a robot: its joint names and the layout of its torques (docs/node.md).

Owns :func:`joint_layout`, the one place that gives, for a robot (a shipped name or a description file,
the scene's ``robot``), the names ``joint_states`` carries (``q``'s coordinates, in order), the actuated
joints (a ``hip_torque`` command has one entry per actuator, in this order) and where each actuator's
torque goes in ``effort`` (``effort = B u``: B has a unit column per actuator, on its joint's
coordinate). The sim node, the recorder's ``StateSerializer``, ``NodeRun``'s command check and the
walk_controller's lookup of joints read it. A shipped robot's names come from its generated module
(an import, no YAML read at start); a description file's from the file.
"""
from __future__ import annotations

import functools
import importlib
from dataclasses import dataclass


@dataclass(frozen=True)
class JointLayout:
    """``coordinates``: q's names, as ``joint_states`` lists them; ``actuated``: the joints with a motor, in
    the order of u (and of a command's entries); ``effort_slots``: for each coordinate, 0 if it has no
    motor, else 1 + the index of its motor in u (so ``effort = itemgetter(*effort_slots)((0.0, *u))``)."""
    robot: str
    coordinates: tuple[str, ...]
    actuated: tuple[str, ...]

    @property
    def effort_slots(self) -> tuple[int, ...]:
        return tuple(self.actuated.index(c) + 1 if c in self.actuated else 0 for c in self.coordinates)

    def effort(self, u) -> list:
        """``B u`` as ``joint_states``' effort: each actuator's torque on its joint's coordinate, 0 elsewhere."""
        return self.effort_function()(u)

    def effort_function(self):
        """:meth:`effort` as a function written out for this layout (``lambda u: [0.0, 0.0, float(u[0]),
        float(u[1]), 0.0]`` for the three-link biped): the node calls it every period, and a list display
        costs about a third of a loop over the slots."""
        return _effort_function(self.effort_slots)

    def command_functions(self):
        """(largest |u_i|, [float(u_i)]) of a command, as two functions written out for this robot's number of
        actuators: the node checks every command, and a loop over its values costs about half as much again
        as the check itself (``NodeRun.check_command``)."""
        return _command_functions(len(self.actuated))

    def command_line(self) -> str:
        """What a command holds, in words: "2, one per actuated joint (hip_1, hip_2)"."""
        return f"{len(self.actuated)}, one per actuated joint ({', '.join(self.actuated)})"


@functools.lru_cache(maxsize=None)
def joint_layout(robot: str = "three_link") -> JointLayout:
    """The :class:`JointLayout` of a robot: a shipped name or a description file (ValueError, one line,
    for neither)."""
    from biped_sim.config import models
    if robot in models.SHIPPED:
        module = importlib.import_module(f"biped_sim.engine._gen.models.{robot}")
        return JointLayout(robot, tuple(module.COORDINATES), tuple(module.ACTUATED))
    desc = models.load_description(robot)
    return JointLayout(robot, desc.coordinates, desc.actuated)


@functools.lru_cache(maxsize=None)
def _effort_function(slots: tuple[int, ...]):
    items = ", ".join("0.0" if k == 0 else f"float(u[{int(k) - 1}])" for k in slots)
    return eval(f"lambda u: [{items}]")  # noqa: S307 -- built from integers only


@functools.lru_cache(maxsize=None)
def _command_functions(n: int):
    if n == 0:
        return (lambda u: 0.0), (lambda u: [])
    items = [f"u[{i}]" for i in range(n)]
    largest = f"abs({items[0]})" if n == 1 else "max(" + ", ".join(f"abs({v})" for v in items) + ")"
    floats = "[" + ", ".join(f"float({v})" for v in items) + "]"
    return eval(f"lambda u: {largest}"), eval(f"lambda u: {floats}")  # noqa: S307 -- from integers only
