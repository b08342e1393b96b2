"""The simulator's parameters: one table for the node (ROS parameters), scene files and the CLI.

Owns names, types, defaults, ranges and descriptions of every setting of a run, and their
validation (no ROS import: the node turns this table into ``declare_parameter`` calls, the scene
loader checks a YAML file's ``biped_sim: ros__parameters:`` section against it, and both build the
engine's arguments with :func:`engine_arguments`). Names in CONTRACT_NAMES are used by outside
tests and must not change.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

from biped_sim.engine.integrators import FIXED_STEP_METHODS, METHODS
from biped_sim.engine.model import BipedParameters
from biped_sim.engine.options import PHASES, SCUFF_RULES

CONTRACT_NAMES = ("time_mode", "control_period", "initial_q", "initial_dq", "initial_stance_leg",
                  "rtol", "atol", "duration")
OUTPUTS = ("joint_states", "ground_reaction", "impact", "clock", "markers")
#: the outputs of a run that does not name them: the numbers; a scene adds "markers" to be seen
DEFAULT_OUTPUTS = ("joint_states", "ground_reaction", "impact", "clock")


@dataclass(frozen=True)
class Param:
    name: str
    type: type            # float, int, bool, str, or list (of floats / of str, see item)
    default: object
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple | None = None
    item: type | None = None      # element type of a list
    length: int | None = None     # fixed list length
    coordinates: bool = False     # one entry per coordinate of the robot: its length is the robot's N (5 above)
    file_name: bool = False       # the value becomes part of a file's name: a plain name, never a path

    def check(self, value):
        """The value converted to this parameter's type, or ValueError naming the parameter."""
        where = f"parameter '{self.name}'"
        if self.type is list:
            if not isinstance(value, (list, tuple)):
                raise ValueError(f"{where} must be a list of {self.item.__name__}, got {value!r}")
            if self.length is not None and len(value) != self.length:
                raise ValueError(f"{where} must have {self.length} entries, got {len(value)}: {list(value)!r}")
            out = []
            for v in value:
                if self.item is float:
                    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                        raise ValueError(f"{where} must hold finite numbers, got {list(value)!r}")
                    out.append(float(v))
                else:
                    if not isinstance(v, str) or (self.choices and v not in self.choices):
                        raise ValueError(f"{where}: {v!r} is not one of {list(self.choices)}")
                    out.append(v)
            return out
        if self.type is bool:
            if not isinstance(value, bool):
                raise ValueError(f"{where} must be true or false, got {value!r}")
            return value
        if self.type is str:
            if isinstance(value, bool):     # rcl reads y/n/yes/no/on/off/true/false unquoted as a bool
                raise ValueError(f"{where} must be a string, got {value!r} (unquoted, y, n, yes, no, on, off, "
                                 "true and false are read as true/false: quote the string, e.g. 'n')")
            if not isinstance(value, str):
                raise ValueError(f"{where} must be a string, got {value!r}")
            if self.choices and value not in self.choices:
                raise ValueError(f"{where} must be one of {list(self.choices)}, got {value!r}")
            if self.file_name:
                check_file_name(value, where)
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{where} must be a number, got {value!r}")
        if self.type is int:
            if float(value) != int(value):
                raise ValueError(f"{where} must be an integer, got {value!r}")
            value = int(value)
            if self.choices and value not in self.choices:
                raise ValueError(f"{where} must be one of {list(self.choices)}, got {value!r}")
        else:
            value = float(value)
            if not math.isfinite(value):
                raise ValueError(f"{where} must be finite, got {value!r}")
        if self.low is not None and value < self.low or self.high is not None and value > self.high:
            raise ValueError(f"{where} must be in [{self.low}, {self.high}], got {value!r}")
        return value


#: the longest value of a ``file_name`` parameter (UTF-8 bytes): a bag's file is
#: ``<scene>-<UTC time>-reset<N>_0.mcap``, and a file name has at most 255 bytes (NAME_MAX)
FILE_NAME_MAX_BYTES = 200


def check_file_name(value: str, where: str) -> str:
    """``value`` if it is a plain file name (no folder in it), else ValueError naming ``where``.

    A value that becomes part of a file's name must not choose the folder: ``scene:=../../tmp/x`` or
    ``scene:=/tmp/x`` would put the bag outside ``bag_dir``, the one folder the user chose for it."""
    why = None
    if not value:
        why = "it is empty"
    elif value in (".", ".."):
        why = f"{value!r} names a folder"
    elif "/" in value or "\\" in value:
        why = "it holds a path separator ('/' or '\\')"
    elif any(ord(c) < 32 for c in value):
        why = "it holds a control character"
    elif len(value.encode("utf-8", "surrogatepass")) > FILE_NAME_MAX_BYTES:
        why = f"it is longer than {FILE_NAME_MAX_BYTES} bytes"
    if why:
        raise ValueError(f"{where} must be a plain name, not a path (it becomes part of a file name; "
                         f"the folder is bag_dir): got {value!r}, {why}")
    return value


_defaults = BipedParameters()
#: the coordinates of the three-link robots (BipedModel): q's names, in order
THREE_LINK_COORDINATES = ("base_x", "base_y", "hip_1", "hip_2", "torso_pitch")
PARAMETERS = [
    Param("scene", str, "custom", "name of the scene (used in the bag's name: a plain name, no '/')",
          file_name=True),
    Param("time_mode", str, "realtime", "realtime: sim time follows the wall clock times rate_factor; "
          "fast: as fast as possible; lockstep: one control period per torque command",
          choices=("realtime", "fast", "lockstep")),
    Param("rate_factor", float, 1.0, "realtime mode: simulated seconds per wall-clock second", 1e-3, 1e3),
    Param("control_period", float, 0.001, "torque hold period (s): the engine advances one period per step",
          1e-5, 1.0),
    Param("publish_rate", float, 1000.0, "joint_states/ground_reaction/clock publish rate (Hz, simulated time)",
          0.1, 1e5),
    Param("marker_rate", float, 30.0, "markers publish rate (Hz of wall time, in every time mode; only with "
          "markers in outputs)", 0.1, 1000.0),
    Param("duration", float, 0.0, "simulated time to run (s); 0 = until stopped", 0.0, 1e7),
    Param("initial_q", list, [0.0, 1.0, math.pi, math.pi, 0.0],
          "initial q = [x, y, q1, q2, q3] (m, rad), physical coordinates; one entry per coordinate of the robot "
          "(7 for rabbit: docs/models.md)", item=float, length=5, coordinates=True),
    Param("initial_dq", list, [0.0] * 5, "initial dq (m/s, rad/s)", item=float, length=5, coordinates=True),
    Param("initial_stance_leg", int, 1, "initial stance leg: 1, 2, or 0 (flight)", choices=(0, 1, 2)),
    Param("method", str, "auto", "integrator; auto: dopri5 for control periods up to "
          "5 ms (one step per period reaches the tolerance with 7 evaluations against dop853's 13), "
          "dop853 for longer ones", choices=("auto",) + METHODS),
    Param("rtol", float, 1e-9, "relative tolerance (adaptive methods)", 1e-14, 0.1),
    Param("atol", float, 1e-9, "absolute tolerance (adaptive methods)", 1e-14, 0.1),
    Param("step", float, 1e-4, f"step size (s) of the fixed-step methods ({', '.join(FIXED_STEP_METHODS)})",
          1e-7, 0.1),
    Param("base", str, "floating", "stance method: floating (KKT) or fixed (3-coordinate pinned chain)",
          choices=("floating", "fixed")),
    Param("phases", list, ["stance", "impact", "flight"], "phases this scene needs", item=str,
          choices=tuple(sorted(PHASES))),
    Param("outputs", list, list(DEFAULT_OUTPUTS), "topics to publish (and record)", item=str, choices=OUTPUTS),
    Param("touchdown_rule", str, "front", "front: a swing foot crossing the ground behind the stance foot may pass "
          "through it (a scuff, see scuff_rule); any: every crossing is a touchdown", choices=("front", "any")),
    Param("scuff_rule", str, "forward", "which crossings pass through the ground under touchdown_rule front: "
          "forward: a swing foot moving forward more than it sinks (a foot falling back lands); behind: every "
          "one behind the stance foot", choices=SCUFF_RULES),
    Param("scuff_depth", float, 0.0, "a scuff deeper than this (m) stops the run; 0 = no bound", 0.0, 10.0),
    Param("slope", float, 0.0, "ground slope (rad); positive: the ground falls in +x", -0.5, 0.5),
    Param("mu", float, 0.0, "friction coefficient; 0 = enough friction (slip never checked)", 0.0, 100.0),
    Param("on_slip", str, "stop", "stop the run on slip, or keep the foot pinned and go on",
          choices=("stop", "continue")),
    Param("torque_limit", float, 1000.0, "largest accepted hip torque (N m)", 0.0, 1e9),
    Param("torque_limit_action", str, "reject", "a command beyond the limit is rejected or clipped",
          choices=("reject", "clip")),
    Param("command_timeout", float, 0.5, "no command for this long (wall s): zero torque and a warning; "
          "0 disables (never in lockstep)", 0.0, 3600.0),
    Param("lockstep_warn_after", float, 5.0, "lockstep: no command for this long (wall s): a warning with the "
          "last command's simulated time and age, repeated after 2, 4, ... times as long (at most every 60 s); "
          "the node keeps waiting; 0 = no warning", 0.0, 3600.0),
    Param("lockstep_timeout", float, 0.0, "lockstep: no command for this long (wall s) ends the run (status "
          "stopped on diagnostics, exit code 1); 0 = wait for the controller forever", 0.0, 1e7),
    Param("start_paused", bool, False, "start paused (as Gazebo's -u): the state at t = 0 is published, nothing "
          "advances until ~/pause false (or ~/step); lets a controller connect before the run moves"),
    Param("record", bool, True, "record the run to an MCAP bag"),
    Param("bag_dir", str, "bags", "folder for bags; each run records to <bag_dir>/<scene>-<UTC time>/"),
    Param("robot", str, "three_link", "the robot: a shipped name (three_link, compass_gait, three_link_hip_mass, "
          "rabbit) or a description file (.yaml, .yml, .urdf; a relative path is from the current folder); the "
          "model.* parameters default to a shipped three-link robot's (docs/models.md)"),
] + [
    Param(f"model.{name}", float, float(getattr(_defaults, name)), f"model parameter {name} (SI)",
          0.0 if name in ("g", "I_torso", "I_leg", "l_torso") else 1e-9, 1e9)
    for name in ("m_torso", "I_torso", "l_torso", "m_leg", "I_leg", "l_leg", "g")
] + [
    # 0 stands for "half the link" (a ROS parameter has one type and no None), so that a scene that
    # changes model.l_leg alone keeps a uniform leg, as BipedModel(l_leg=...) does
    Param(f"model.c_{link}", float, 0.0, f"model parameter c_{link} (SI): the {link}'s centre of mass from the "
          f"hip; 0 = half of model.l_{link} (a uniform link)", 0.0, 1e9)
    for link in ("torso", "leg")
]
BY_NAME = {p.name: p for p in PARAMETERS}


def validate(values: dict, table=None, owner: str = "") -> dict:
    """All parameters of ``table`` (default: the simulator's), defaults filled in, after checking
    ``values``; a ValueError names the culprit and the allowed names. ``owner`` prefixes the message
    (e.g. "walk_controller ")."""
    table = PARAMETERS if table is None else table
    by_name = {p.name: p for p in table}
    unknown = sorted(set(values) - set(by_name))
    if unknown:
        raise ValueError(f"unknown {owner}parameter(s) {unknown}; allowed: {', '.join(by_name)}")
    out = {p.name: p.default for p in table}
    coordinates = None      # the robot's coordinates, looked up for the first parameter of one entry each
    for name, value in values.items():
        param = by_name[name]
        if param.coordinates and "robot" in by_name:
            coordinates = coordinates or _robot_coordinates(values, by_name["robot"])
            if isinstance(value, (list, tuple)) and len(value) != len(coordinates):
                robot = values.get("robot", by_name["robot"].default)
                raise ValueError(f"parameter '{name}' must have {len(coordinates)} entries, one for each coordinate "
                                 f"of robot {robot!r} ({', '.join(coordinates)}), got {len(value)}: {list(value)!r}")
            param = replace(param, length=len(coordinates))
        out[name] = param.check(value)
    if "robot" in by_name:
        _robot_defaults(values, out, table)
    return out


def _robot_coordinates(values: dict, robot_param) -> tuple:
    """The coordinates of the robot ``values`` names (three_link's when none): q's names, in order."""
    from biped_sim.config import models
    robot = robot_param.check(values["robot"]) if "robot" in values else robot_param.default
    if robot in models.THREE_LINK_PARAMETERS:
        return THREE_LINK_COORDINATES
    try:
        return models.load_description(robot).coordinates
    except ValueError as exc:
        raise ValueError(f"parameter 'robot': {exc}") from None


def _robot_defaults(values: dict, out: dict, table) -> None:
    """Check ``robot`` (a shipped name or an existing description file) and give the ``model.*``
    parameters that ``values`` does not set the values of a shipped three-link robot
    (``config.models.THREE_LINK_PARAMETERS``): ``robot: compass_gait`` alone is the compass gait. A described
    robot (not a three-link one) takes no ``model.*`` parameter (its numbers are its description's) and needs
    its initial state given (the defaults are the three-link's 5 coordinates)."""
    from biped_sim.config import models
    try:
        models.description_path(out["robot"])
    except ValueError as exc:
        raise ValueError(f"parameter 'robot': {exc}") from None
    robot = out["robot"]
    if robot not in models.THREE_LINK_PARAMETERS:
        given = sorted(n for n in values if n.startswith("model."))
        if given:
            raise ValueError(f"parameter {given[0]!r} sets a number of the three-link biped; robot {robot!r} takes "
                             "its numbers from its description (edit the description instead)")
        names = _robot_coordinates(values, next(p for p in table if p.name == "robot"))
        for p in table:
            if p.coordinates and p.name not in values and len(p.default) != len(names):
                raise ValueError(f"parameter {p.name!r} must be given for robot {robot!r}: {len(names)} entries, "
                                 f"one for each of its coordinates ({', '.join(names)}); the default is the "
                                 "three-link biped's 5")
    robot_parameters = models.THREE_LINK_PARAMETERS.get(robot, {})
    for name, value in robot_parameters.items():
        key = f"model.{name}"
        if key in out and key not in values:
            out[key] = float(value)


def recorded_given(recorded: dict) -> dict:
    """The parameters to check again from a run's recorded (checked) ones: all of them for a three-link
    robot; for a described robot all but the ``model.*`` entries, which a check fills with the three-link
    defaults and which a described robot refuses when given."""
    from biped_sim.config import models
    if recorded.get("robot", "three_link") in models.THREE_LINK_PARAMETERS:
        return dict(recorded)
    return {n: v for n, v in recorded.items() if not n.startswith("model.")}


#: control periods up to this use dopri5 under method "auto". Measured (python -m benchmarks.bench
#: --only engine, last table): at 1 ms dopri5 and dop853 reach the same error over a walk, dopri5
#: with 7 evaluations a period instead of 13; at 5 ms dopri5's error is 4.9e-9 against dop853's
#: 2e-11. Bags store "auto", and resim resolves it with this bound: changing it changes which
#: method re-simulates the bags recorded between the old and the new bound.
AUTO_DOPRI5_MAX_PERIOD = 0.005


def resolve_method(params: dict) -> str:
    """The integrator a run uses: ``method``, with "auto" resolved from ``control_period``."""
    if params["method"] != "auto":
        return params["method"]
    return "dopri5" if params["control_period"] <= AUTO_DOPRI5_MAX_PERIOD else "dop853"


def method_label(params: dict) -> str:
    """``method`` as a report shows it: "auto (dopri5)" names what "auto" ran."""
    m = params.get("method", "?")
    return f"auto ({resolve_method(params)})" if m == "auto" and "control_period" in params else str(m)


def model_arguments(params: dict) -> dict:
    """``BipedModel`` keyword arguments from the ``model.*`` values of ``params``; a ``model.c_*`` of 0
    is left out (the model's default: half the link's length)."""
    return {n.split(".", 1)[1]: v for n, v in params.items()
            if n.startswith("model.") and not (n.startswith("model.c_") and v == 0.0)}


def robot_model(params: dict):
    """The engine's model of checked parameters: a ``BipedModel`` of the ``model.*`` values for a shipped
    three-link robot, a described robot's ``GeneratedModel`` (``config.models.load_model``) otherwise;
    ValueError, one line, for a robot the engine cannot run (its ``engine_refusal``)."""
    from biped_sim.config import models
    from biped_sim.engine.model import BipedModel
    robot = params.get("robot", "three_link")
    if robot not in models.THREE_LINK_PARAMETERS:
        model = models.load_model(robot)
        if model.engine_refusal is not None:
            raise ValueError(model.engine_refusal)
        return model
    return BipedModel(**model_arguments(params))


#: three_link_model's advice for a controller (the reference walking controller: the three-link robots only)
OWN_CONTROLLER = ("give it a controller of its own (Scene.simulate(controller=...), --controller MODULE:ATTR), "
                  "or none")


def three_link_model(params: dict, who: str, advice: str = OWN_CONTROLLER):
    """``robot_model`` for what runs the three-link biped only (``who``: the reference walking controller, the
    step-to-step map), or ValueError, one line, naming the robot and what to do instead (``advice``)."""
    from biped_sim.config import models
    from biped_sim.engine.model import BipedModel
    model = robot_model(params)
    if not isinstance(model, BipedModel):
        raise ValueError(f"{who} runs the three-link robots ({', '.join(models.THREE_LINK_PARAMETERS)}); robot "
                         f"{params.get('robot')!r} has {model.n} coordinates and {model.m} motors: {advice}")
    return model


def engine_arguments(params: dict) -> dict:
    """Keyword arguments of ``HybridSimulator`` / ``simulate`` (and the model's) from checked values."""
    model = robot_model(params)
    phases = frozenset(params["phases"])
    kwargs = dict(model=model, q0=params["initial_q"], dq0=params["initial_dq"],
                  stance_leg=params["initial_stance_leg"], rtol=params["rtol"], atol=params["atol"],
                  method=resolve_method(params), mu=params["mu"] or None, base=params["base"], phases=phases,
                  touchdown_rule=params["touchdown_rule"], scuff_rule=params["scuff_rule"],
                  scuff_depth=params["scuff_depth"] or math.inf, slope=params["slope"],
                  stop_on_slip=params["on_slip"] == "stop",
                  compute_grf=bool({"ground_reaction", "markers"} & set(params["outputs"])))
    if params["method"] in FIXED_STEP_METHODS:
        kwargs["step"] = params["step"]
    return kwargs
