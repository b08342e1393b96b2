"""Scenes: what a run needs, read from ``msg_configs/<name>.yaml`` (ROS 2 parameter YAML).

Owns the scene loader and the walking controller's parameter table. A scene file holds

* ``biped_sim: ros__parameters: {...}``: the simulation node's parameters (names, types and ranges
  from :mod:`biped_sim.config.parameters`); among them ``phases`` (the hybrid phases the run may enter) and
  ``outputs`` (the topics the node publishes and the recorder records), so that the engine and the
  node build only those;
* optionally ``walk_controller: ros__parameters: {...}``: the reference walking controller's
  parameters (:data:`CONTROLLER_PARAMETERS`), read by the ``walk_controller`` node and, headless, by
  :meth:`Scene.controller`. A scene without this section runs with u = 0.

``load_scene("walk")`` finds ``msg_configs`` next to the package (a source checkout or an editable
install), then in ``share/biped_sim/msg_configs`` of an ament index if one is present; a path to a
``.yaml`` file works too. No ROS import here: the CLI uses it headless.
"""
from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import yaml

from biped_sim.config import parameters as P, params_yaml

NODE_SECTION = "biped_sim"
CONTROLLER_SECTION = "walk_controller"

#: Parameters of the ``walk_controller`` node (the scene file's ``walk_controller`` section).
#: The gains and shape constants are those of :class:`biped_sim.control.walking.WalkingController`; the
#: model and slope must match the simulation's (the loader checks it).
CONTROLLER_PARAMETERS = [
    P.Param("law", str, "walking", "the walking law: walking (the three-link robots' reference law, "
            "WalkingController) or rabbit_walking (RABBIT's, RabbitWalkingController: docs/models.md)",
            choices=("walking", "rabbit_walking")),
    P.Param("torso_pitch", float, 0.15, "virtual constraint: absolute torso angle to hold (rad, + leans forward)",
            -1.0, 1.0),
    P.Param("step_angle", float, 0.2, "virtual constraint: stance-leg angle from vertical at touchdown (rad)",
            0.01, 1.0),
    P.Param("clearance", float, 0.5, "virtual constraint: swing-leg bend that lifts the foot at mid-stance (-)",
            0.0, 5.0),
    P.Param("lag", float, -0.04, "virtual constraint: shift of the mid-stance graze (rad; < 0: behind the stance foot)",
            -0.5, 0.5),
    P.Param("stance_knee", float, 0.3, "rabbit_walking: the stance knee's bend (rad, > 0: the knee forward)",
            0.0, 3.0),
    P.Param("swing_knee", float, 1.0, "rabbit_walking: the swing knee's bend at mid-step, which lifts the foot "
            "(rad)", 0.0, 3.0),
    P.Param("impact_blend", float, 0.9, "rabbit_walking: the fraction of a step over which the targets blend "
            "from the post-impact rates into the nominal ones (-)", 0.01, 0.99),
    P.Param("kp", float, 200.0, "output PD gain, proportional (1/s^2)", 0.0, 1e6),
    P.Param("kd", float, 30.0, "output PD gain, derivative (1/s)", 0.0, 1e4),
    P.Param("torque_limit", float, 500.0, "the controller clips its torques to +-this (N m)", 0.0, 1e6),
    P.Param("contact_height_tol", float, 1e-4,
            "stance detection: a foot is on the ground when within this height of it (m)", 1e-9, 0.1),
    P.Param("contact_speed_tol", float, 1e-3,
            "stance detection: ... and slower than this (m/s); the pinned stance foot is at rest", 1e-9, 1.0),
    P.BY_NAME["robot"],
    P.BY_NAME["slope"],
] + [p for p in P.PARAMETERS if p.name.startswith("model.")]
CONTROLLER_BY_NAME = {p.name: p for p in CONTROLLER_PARAMETERS}
_SHARED_WITH_SIM = [p.name for p in CONTROLLER_PARAMETERS
                    if p.name in ("robot", "slope") or p.name.startswith("model.")]
_GAINS = ("torso_pitch", "step_angle", "clearance", "lag", "kp", "kd", "torque_limit")
#: each law's parameters of the table (the rest of the table belongs to the other law)
LAW_GAINS = {"walking": _GAINS,
             "rabbit_walking": ("torso_pitch", "step_angle", "stance_knee", "swing_knee", "impact_blend", "kp", "kd",
                                "torque_limit")}


def validate_controller(values: dict, table: list | None = None) -> dict:
    """All controller parameters (defaults filled in) after checking ``values``; ValueError names the culprit.
    The parameters of the law the section does not run are refused; those of its law that ``values`` leaves
    out take the law's own defaults (``RabbitWalkingController``'s for rabbit_walking). ``table``: the
    parameters' table, default :data:`CONTROLLER_PARAMETERS` (the ``walk_controller`` node adds its own)."""
    out = P.validate(values, CONTROLLER_PARAMETERS if table is None else table, owner="walk_controller ")
    law = out["law"]
    others = [k for k in values if k not in LAW_GAINS[law] and any(k in g for g in LAW_GAINS.values())]
    if others:
        raise ValueError(f"walk_controller parameter(s) {', '.join(others)} belong to another law than this "
                         f"section's (law: {law}); {law}'s parameters: {', '.join(LAW_GAINS[law])}")
    if law == "rabbit_walking":
        import inspect

        from biped_sim.control.rabbit_walking import RabbitWalkingController
        defaults = inspect.signature(RabbitWalkingController).parameters
        for name in LAW_GAINS[law]:
            if name not in values:
                out[name] = float(defaults[name].default)
    return out


def make_controller(cparams: dict):
    """The walking controller of checked controller parameters: a :class:`WalkingController` on the
    robot's ``BipedModel``, or for the law rabbit_walking a :class:`RabbitWalkingController` on the robot's
    ``GeneratedModel``."""
    law = cparams["law"]
    if law == "rabbit_walking":
        from biped_sim.config.models import load_model
        from biped_sim.control.rabbit_walking import RabbitWalkingController
        return RabbitWalkingController(load_model(cparams["robot"]), **{k: cparams[k] for k in LAW_GAINS[law]})
    from biped_sim.control.walking import WalkingController
    model = P.three_link_model(cparams, "the reference walking controller (walk_controller)")
    return WalkingController(model, **{k: cparams[k] for k in _GAINS})


def scene_dirs() -> list[Path]:
    """Where scene files are looked up, in order."""
    dirs = [Path(__file__).resolve().parents[2] / "msg_configs"]
    try:  # an installed ROS 2 package; optional
        from ament_index_python.packages import get_package_share_directory
        dirs.append(Path(get_package_share_directory("biped_sim")) / "msg_configs")
    except Exception:
        pass
    return dirs


def available_scenes() -> list[str]:
    names = set()
    for d in scene_dirs():
        if d.is_dir():
            names.update(p.stem for p in d.glob("*.yaml"))
    return sorted(names)


def scene_path(name_or_path) -> Path:
    text = str(name_or_path)
    p = Path(text)
    if text.endswith((".yaml", ".yml")) or p.parent != Path("."):
        if p.is_dir():
            raise ValueError(f"scene file {text!r} is a folder: give a .yaml file, e.g. {text.rstrip('/')}/walk.yaml")
        if not p.is_file():
            raise ValueError(f"scene file {text!r} does not exist: check the path ({Path.cwd()} is the current "
                             f"folder), or give a scene by name: {', '.join(available_scenes()) or 'none'}")
        return p
    for d in scene_dirs():
        cand = d / f"{text}.yaml"
        if cand.is_file():
            return cand
    raise ValueError(f"unknown scene {text!r}; available: {', '.join(available_scenes()) or 'none'} "
                     f"(looked in {', '.join(str(d) for d in scene_dirs())}), or give a path to a .yaml file")


#: ``Scene.simulate(controller=...)``'s default: the controller of the scene's file
SCENE_CONTROLLER = type("SceneController", (), {"__repr__": lambda self: "the scene's controller"})()


@dataclass
class Scene:
    """A loaded scene: checked node parameters and (optionally) controller parameters."""
    name: str
    path: Path
    params: dict                              # all sim-node parameters, defaults filled in
    controller_params: dict | None = None     # None: no controller (u = 0)
    given: dict = field(default_factory=dict)  # the node parameters the file sets

    @property
    def robot(self) -> str:
        """The robot the scene names (parameter ``robot``): a shipped name or a description file."""
        return self.params["robot"]

    @property
    def phases(self) -> frozenset:
        return frozenset(self.params["phases"])

    @property
    def outputs(self) -> tuple:
        return tuple(self.params["outputs"])

    @property
    def duration(self) -> float:
        return self.params["duration"]

    def engine_arguments(self) -> dict:
        """Keyword arguments of ``HybridSimulator`` (``model``, ``q0``, ``dq0``, ... , options)."""
        return P.engine_arguments(self.params)

    def controller(self):
        """A fresh walking controller with the scene's parameters (``make_controller``: the law its section
        names), or None (u = 0)."""
        return None if self.controller_params is None else make_controller(self.controller_params)

    def simulate_kwargs(self, hold=True, controller=SCENE_CONTROLLER, controller_args=None) -> dict:
        """Keyword arguments of :func:`biped_sim.engine.simulate.simulate`, ``t_final`` and ``controller`` included.

        ``hold=True`` holds each torque over ``control_period`` as the node does (the node in lockstep
        with the walk_controller gives this same run); ``hold=False``: continuous feedback.
        ``controller``: the scene's (default), None (u = 0), or a controller, a class or factory, or
        ``"MODULE:ATTR"`` (:mod:`biped_sim.config.controllers`), made with ``controller_args`` and the
        scene's model.
        """
        kw = self.engine_arguments()
        kw["t_final"] = self.duration
        if controller is SCENE_CONTROLLER:
            if controller_args:
                raise ValueError("controller arguments need a controller=... (a class or factory) to make")
            kw["controller"] = self.controller()
        elif controller is None:
            kw["controller"] = None
        else:
            from biped_sim.config.controllers import make_controller as make_users
            kw["controller"] = make_users(controller, kw["model"], **(controller_args or {}))
        if kw["controller"] is not None and hold:
            kw["control_period"] = self.params["control_period"]
        return kw

    def simulate(self, hold=True, controller=SCENE_CONTROLLER, controller_args=None, **overrides):
        """The scene's run (:meth:`simulate_kwargs`), with ``overrides`` of
        :func:`~biped_sim.engine.simulate.simulate`'s arguments."""
        from biped_sim.engine.simulate import simulate
        kw = self.simulate_kwargs(hold, controller, controller_args)
        kw.update(overrides)
        return simulate(**kw)


def yaml_error_line(exc: yaml.YAMLError) -> str:
    """PyYAML's error (five lines: what it was parsing, a copy of the line with a caret, the problem,
    another copy) as one line: the problem, where, and what it was parsing since where."""
    mark = getattr(exc, "problem_mark", None)
    problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
    line = f"not valid YAML at line {mark.line + 1}, column {mark.column + 1}: {problem}" if mark else \
        f"not valid YAML: {problem}"
    context, start = getattr(exc, "context", None), getattr(exc, "context_mark", None)
    if context:
        since = f" started at line {start.line + 1}, column {start.column + 1}" if start else ""
        line += f" ({context}{since})"
    return line + "; fix the file there (msg_configs/walk.yaml shows the form)"


def load_scene(name_or_path, overrides=None) -> Scene:
    """Read, check and return a scene (a name in msg_configs/ or a path to a YAML file).

    ``overrides`` maps parameter names to values that replace the file's (see
    :func:`apply_overrides` for the names); the result is checked exactly as if the file said them.
    """
    path = scene_path(name_or_path)
    try:        # as the node reads it (rcl's rules, not YAML 1.1's): see params_yaml
        doc = params_yaml.load(path.read_text(), f"scene {path}")
    except yaml.YAMLError as exc:
        raise ValueError(f"scene {path}: {yaml_error_line(exc)}") from None
    if not isinstance(doc, dict):
        raise ValueError(f"scene {path}: expected a mapping with a '{NODE_SECTION}' section")
    unknown = sorted(set(doc) - {NODE_SECTION, CONTROLLER_SECTION})
    if unknown:
        raise ValueError(f"scene {path}: unknown section(s) {unknown}; allowed: {NODE_SECTION}, {CONTROLLER_SECTION}")
    given = _section(doc, NODE_SECTION, path)
    cgiven = _section(doc, CONTROLLER_SECTION, path) if CONTROLLER_SECTION in doc else None
    if overrides:
        given, cgiven = apply_overrides(given, cgiven, overrides, path)
    try:
        params = P.validate(given)
    except ValueError as exc:
        raise ValueError(f"scene {path}, section {NODE_SECTION}: {exc}") from None
    for key in ("phases", "outputs"):
        if key not in given:
            raise ValueError(f"scene {path}: section {NODE_SECTION} must declare '{key}' (allowed values: "
                             f"{list(P.BY_NAME[key].choices)})")
    cparams = None
    if cgiven is not None:
        try:
            cparams = validate_controller(cgiven)
        except ValueError as exc:
            raise ValueError(f"scene {path}, section {CONTROLLER_SECTION}: {exc}") from None
        for name in _SHARED_WITH_SIM:
            if (cparams[name] != params[name] if isinstance(params[name], str) else
                    not math.isclose(cparams[name], params[name], rel_tol=1e-12, abs_tol=1e-15)):
                raise ValueError(f"scene {path}: {CONTROLLER_SECTION} parameter '{name}' = {cparams[name]!r} "
                                 f"differs from the simulation's {params[name]!r}; set it to the same value "
                                 "in both sections")
    name = params["scene"] if given.get("scene") else path.stem
    return Scene(name=name, path=path, params=params, controller_params=cparams, given=given)


#: node parameters that only the node reads (its clock, topics, timeouts, bag): a headless run (a
#: sweep, Scene.simulate) accepts them and ignores them, so an error message does not offer them
NODE_ONLY = frozenset({"scene", "time_mode", "rate_factor", "publish_rate", "marker_rate", "command_timeout",
                       "lockstep_warn_after", "lockstep_timeout", "start_paused", "record", "bag_dir"})

_OVERRIDE_NAME = re.compile(r"(?:(?P<section>biped_sim|walk_controller)\.)?(?P<name>[A-Za-z_][\w.]*?)"
                            r"(?:\[(?P<index>\d+)\])?")


def override_targets(key, has_controller: bool) -> list[tuple[str, str, int | None]]:
    """Where an override name lands: [(section, parameter, list index or None), ...].

    Names are those of the scene file: a node parameter (``duration``, ``initial_q``), a controller
    parameter (``kp``), an element of a list (``initial_dq[2]``), or a section-qualified name
    (``walk_controller.kp``, ``biped_sim.slope``). A bare name that is in both sections goes to both
    where the loader requires them to be equal (``slope``, ``model.*``); a name in both that may
    differ (``torque_limit``) must be qualified. ValueError names the problem and the allowed names.
    """
    m = _OVERRIDE_NAME.fullmatch(key) if isinstance(key, str) else None
    if m is None:
        raise ValueError(f"override {key!r} is not a parameter name (NAME, NAME[i], {NODE_SECTION}.NAME or "
                         f"{CONTROLLER_SECTION}.NAME)")
    section, name, index = m["section"], m["name"], m["index"]
    tables = {NODE_SECTION: P.BY_NAME, CONTROLLER_SECTION: CONTROLLER_BY_NAME}
    if section is not None:
        sections = [section] if name in tables[section] else []
    else:
        sections = [s for s in (NODE_SECTION, CONTROLLER_SECTION) if name in tables[s]]
    if not sections:
        where = f"in section {section}" if section else "in this scene's sections"
        lists = [p.name for p in P.PARAMETERS if p.type is list and p.item is float]
        node_names = [n for n in P.BY_NAME if n not in NODE_ONLY]
        close = difflib.get_close_matches(name, node_names + list(CONTROLLER_BY_NAME), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ValueError(f"unknown override {key!r}: no parameter {name!r} {where}{hint}; allowed: "
                         f"{', '.join(node_names)} ({NODE_SECTION}); {', '.join(CONTROLLER_BY_NAME)} "
                         f"({CONTROLLER_SECTION}); an element of a list as {lists[0]}[i] ({', '.join(lists)}); "
                         f"a name of both sections as {NODE_SECTION}.NAME or {CONTROLLER_SECTION}.NAME")
    if len(sections) == 2 and name not in _SHARED_WITH_SIM:
        raise ValueError(f"override {key!r}: '{name}' is a parameter of both sections, with different meanings; "
                         f"write {NODE_SECTION}.{name} or {CONTROLLER_SECTION}.{name}")
    if CONTROLLER_SECTION in sections and not has_controller:
        if sections == [CONTROLLER_SECTION]:
            raise ValueError(f"override {key!r}: this scene has no {CONTROLLER_SECTION} section (it runs with "
                             "u = 0), so it has no controller parameter to set")
        sections = [NODE_SECTION]
    param = tables[sections[0]][name]
    if index is not None:
        if param.type is not list:
            raise ValueError(f"override {key!r}: '{name}' is not a list; write {name} = value")
        if param.length is not None and not param.coordinates and int(index) >= param.length:
            raise ValueError(f"override {key!r}: '{name}' has {param.length} entries (indices 0 to "
                             f"{param.length - 1})")
    return [(s, name, None if index is None else int(index)) for s in sections]


def apply_overrides(given: dict, cgiven: dict | None, overrides: dict, path) -> tuple[dict, dict | None]:
    """The node and controller sections of a scene file with ``overrides`` put in (see
    :func:`override_targets`); each overridden value is checked here, by the check the loader
    applies to the file, so that a ValueError names the override."""
    if not isinstance(overrides, dict):
        raise ValueError(f"overrides must be a mapping of parameter names to values, got {overrides!r}")
    sections = {NODE_SECTION: dict(given), CONTROLLER_SECTION: None if cgiven is None else dict(cgiven)}
    tables = {NODE_SECTION: P.BY_NAME, CONTROLLER_SECTION: CONTROLLER_BY_NAME}
    seen = {}
    for key, value in overrides.items():
        try:
            targets = override_targets(key, cgiven is not None)
        except ValueError as exc:
            raise ValueError(f"scene {path}: {exc}") from None
        for section, name, index in targets:
            for (s, n, i), earlier in seen.items():   # the same entry twice, or a list and one of its entries
                if (s, n) == (section, name) and (i is None or index is None or i == index):
                    raise ValueError(f"scene {path}: overrides {earlier!r} and {key!r} both set "
                                     f"{section}.{name}; give one")
            seen[(section, name, index)] = key
            param, values = tables[section][name], sections[section]
            if index is None:
                new = value
            else:
                new = list(values.get(name, param.default))
                if index >= len(new):
                    raise ValueError(f"scene {path}, override {key!r}: '{name}' has {len(new)} entries (indices 0 "
                                     f"to {len(new) - 1})")
                new[index] = value
            try:    # (a list of one entry per coordinate: its length the robot's, which the loader checks)
                (replace(param, length=None) if param.coordinates else param).check(new)
            except ValueError as exc:
                raise ValueError(f"scene {path}, override {key!r}: {exc}") from None
            values[name] = new
    return sections[NODE_SECTION], sections[CONTROLLER_SECTION]


def _section(doc, key, path) -> dict:
    sec = doc.get(key)
    if not isinstance(sec, dict) or set(sec) != {"ros__parameters"} or not isinstance(sec["ros__parameters"], dict):
        raise ValueError(f"scene {path}: section '{key}' must hold exactly 'ros__parameters: {{...}}'")
    return _flatten(sec["ros__parameters"])


def _flatten(d, prefix="") -> dict:
    """ROS 2 parameter YAML allows nested maps for dotted names (model: {g: 9.81} -> model.g)."""
    out = {}
    for k, v in d.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, name + "."))
        else:
            out[name] = v
    return out
