"""Robots by name or file: ``load_model("compass_gait")``, ``load_model("my_robot.urdf")`` (docs/models.md).

Owns the shipped robot descriptions (``biped_sim/config/robots/<name>.yaml`` and ``.urdf``), the reading
of a description file (the compact YAML form or a planar URDF), and where a description's generated
dynamics come from: a shipped model's module is generated at build time (``make generate``:
``biped_sim/engine/_gen/models/<name>.py``); a user's is generated on first use with sympy (the optional
extra ``biped_sim[models]``) and cached under ``$XDG_CACHE_HOME/biped_sim/models`` (default
``~/.cache/biped_sim/models``), keyed by a hash of the description.
"""
from __future__ import annotations

import importlib
import importlib.util
import os
import sys
import time
from pathlib import Path

import yaml

from biped_sim.engine.description import (
    DescriptionError,
    RobotDescription,
    description_from_dict,
    description_from_urdf,
)

ROBOTS_DIR = Path(__file__).resolve().parent / "robots"
SHIPPED = ("three_link", "compass_gait", "three_link_hip_mass", "rabbit")

#: the shipped robots today's three-link engine runs, as ``BipedModel`` keyword arguments: the torso
#: carries the hip mass. compass_gait: a 10 kg torso with its centre at the hip (c_torso = 0, so its angle
#: never acts on the legs; its inertia only keeps D positive definite), point-mass legs (I_leg = 0).
#: three_link_hip_mass: the hip mass (15 kg) and the torso's point mass (10 kg, 0.5 m up) as one body of
#: 25 kg, centre 0.2 m up, inertia 1.5 kg m^2 about it; point-mass legs. The YAML files say the same.
THREE_LINK_PARAMETERS = {
    "three_link": {},
    "compass_gait": dict(m_torso=10.0, I_torso=1.0, l_torso=0.0, c_torso=0.0,
                         m_leg=5.0, I_leg=0.0, l_leg=1.0, c_leg=0.5, g=9.81),
    "three_link_hip_mass": dict(m_torso=25.0, I_torso=1.5, l_torso=0.5, c_torso=0.2,
                                m_leg=5.0, I_leg=0.0, l_leg=1.0, c_leg=0.5, g=9.81),
}


def _fail_line(text):
    raise ValueError(text)


def description_path(name_or_path) -> Path:
    text = str(name_or_path)
    if text in SHIPPED:
        return ROBOTS_DIR / f"{text}.yaml"
    p = Path(text)
    if p.suffix.lower() in (".yaml", ".yml", ".urdf") or p.parent != Path("."):
        if p.is_dir():
            _fail_line(f"robot description {text!r} is a folder: give a .yaml or .urdf file in it, or a shipped "
                       f"model: {', '.join(SHIPPED)}")
        if not p.is_file():
            _fail_line(f"robot description {text!r} does not exist: give a .yaml or .urdf file, or a shipped "
                       f"model: {', '.join(SHIPPED)}")
        if p.suffix.lower() not in (".yaml", ".yml", ".urdf"):
            # read as YAML it would fail with a parser's message about the wrong format
            _fail_line(f"robot description {text!r}: a description is a .yaml, .yml or .urdf file, not "
                       f"{p.suffix or 'a file without a suffix'}")
        return p
    _fail_line(f"unknown model {text!r}; shipped: {', '.join(SHIPPED)}, or give a path to a .yaml or .urdf file")


def load_description(name_or_path) -> RobotDescription:
    """The :class:`RobotDescription` of a shipped name or a description file (.yaml, .yml, .urdf)."""
    p = description_path(name_or_path)
    if p.suffix.lower() == ".urdf":
        return description_from_urdf(str(p))
    try:
        data = yaml.safe_load(p.read_text())
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark else ""
        raise DescriptionError(f"robot description {p}: not valid YAML{where}: "
                               f"{getattr(e, 'problem', None) or e}") from None
    return description_from_dict(data, str(p))


def cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "biped_sim" / "models"


def _import_file(name, path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def dynamics_module(desc: RobotDescription):
    """The generated module of ``desc``: the shipped one when it matches, else the cached one, else generated
    now (needs sympy; one ValueError line without it)."""
    from biped_sim.config import codegen
    try:
        module = importlib.import_module(f"biped_sim.engine._gen.models.{desc.name}")
        if module.DIGEST == desc.digest() and module.GENERATOR_VERSION == codegen.GENERATOR_VERSION:
            return module
    except ImportError:
        pass
    path = cache_dir() / f"{desc.name}-{desc.digest()}-g{codegen.GENERATOR_VERSION}.py"
    _generate_once(desc, path, "its dynamics are generated on first use", "the dynamics",
                   "on its first use (a few seconds", codegen.generate_source)
    return _import_file(f"biped_sim_model_{desc.name}_{desc.digest()}", path)


def parameters_module(desc: RobotDescription):
    """The generated module of ``desc``'s derivatives by its model parameters
    (``codegen.generate_parameter_source``): the shipped one when it matches, else the cached one, else generated
    now (needs sympy). Asked for by a run Jacobian by model parameters only, not on a model's load."""
    from biped_sim.config import codegen

    def current(module):
        return (module.DIGEST == desc.digest() and module.GENERATOR_VERSION == codegen.GENERATOR_VERSION
                and module.PARAMETER_GENERATOR_VERSION == codegen.PARAMETER_GENERATOR_VERSION)
    try:
        module = importlib.import_module(f"biped_sim.engine._gen.models.{desc.name}_parameters")
        if current(module):
            return module
    except ImportError:
        pass
    path = cache_dir() / (f"{desc.name}-{desc.digest()}-g{codegen.GENERATOR_VERSION}"
                          f"-p{codegen.PARAMETER_GENERATOR_VERSION}_parameters.py")
    _generate_once(desc, path, "its derivatives by model parameters are generated on first request",
                   "the derivatives by model parameters", "on their first request (seconds",
                   codegen.generate_parameter_source)
    return _import_file(f"biped_sim_parameters_{desc.name}_{desc.digest()}", path)



def _generate_once(desc: RobotDescription, path, needs: str, what: str, when: str, generate) -> None:
    """Write ``generate(desc)`` (sympy) to the cache file ``path`` unless it is there, saying so on stderr before
    and after (a first use takes seconds, about 6 s for a robot of RABBIT's size: a node's start would look hung);
    one ValueError line without sympy (``needs``: what is generated when)."""
    from biped_sim.config import codegen
    if path.is_file():
        return
    if codegen._sympy() is None:
        _fail_line(f"robot description {desc.source or desc.name}: {needs} with sympy, which is not installed: "
                   "pip install 'biped_sim[models]' (or sympy)")
    said = f"robot {desc.name!r} ({desc.source or desc.name})"
    _say(f"biped_sim: generating {what} of {said} with sympy {when}; cached in {path.parent})")
    start = time.perf_counter()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text(generate(desc))
    os.replace(tmp, path)          # another process may generate the same file: the last rename wins
    _say(f"biped_sim: generated {what} of {said} in {time.perf_counter() - start:.1f} s: {path.name}")

def _say(line: str) -> None:
    """One line on stderr, at once (a node's log, a CLI's terminal)."""
    print(line, file=sys.stderr, flush=True)


def generated_model(name_or_path):
    """The :class:`~biped_sim.engine.generated_model.GeneratedModel` of any description (shipped ones too)."""
    from biped_sim.engine.generated_model import GeneratedModel
    desc = load_description(name_or_path)
    model = GeneratedModel(desc, dynamics_module(desc), parameters=lambda: parameters_module(desc))
    q = [0.0, 1.0] + [0.3 + 0.1 * i for i in range(desc.n - 2)]
    model.check_positive_definite(q)
    return model


def load_model(name_or_path):
    """The model of a shipped name or a description file, accepted wherever a model is today.

    ``three_link``: ``BipedModel()``. ``compass_gait``, ``three_link_hip_mass``: a ``BipedModel`` with their
    parameters (:data:`THREE_LINK_PARAMETERS`). ``rabbit`` and a user's description: a
    :class:`~biped_sim.engine.generated_model.GeneratedModel`. The engine runs both (a GeneratedModel in its
    Python loop).
    """
    if isinstance(name_or_path, str) and name_or_path in THREE_LINK_PARAMETERS:
        from biped_sim.engine.model import BipedModel
        return BipedModel(**THREE_LINK_PARAMETERS[name_or_path])
    return generated_model(name_or_path)
