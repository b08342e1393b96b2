"""A user's controller, given to any tool: an object, a class or factory, or ``"MODULE:ATTR"``.

Owns what ``--controller MODULE:ATTR`` (simulate, sweep, gait, basin, animate --scene) and the
``controller=`` argument of :func:`biped_sim.sweep` and :meth:`Scene.simulate` accept, and the check
that a controller can be called as the engine calls it, before a run starts:

* a **controller**: anything callable as ``controller(t, q, dq, stance_leg) -> [u1, u2]`` (a function, an
  instance with ``__call__``);
* a **class** (or a **factory** function): called to make the controller, with the keyword arguments a
  sweep's ``controller.NAME`` grid names give, and ``model=`` (the scene's
  :class:`~biped_sim.engine.model.BipedModel`) when it takes a parameter named ``model``;
* ``"MODULE:ATTR"``: either of the above, imported from MODULE (found on the Python path or in the
  current folder), as ``python -m`` finds a module.

A function is a factory when it takes a parameter named ``model``, or when it can be called with no
argument and not with the four of a controller; otherwise it is the controller itself (and a function
of the wrong arguments is refused as one, saying so).
"""
from __future__ import annotations

import importlib
import inspect
import os
import sys
from pathlib import Path

from biped_sim.engine.controller_check import call_signature, check_controller, qualified_name, takes_controller_call

#: the prefix of a sweep's grid names that reach the controller's constructor (``controller.kp``)
CONTROLLER_PREFIX = "controller."


def is_factory(spec) -> bool:
    """A class, or a function that takes ``model``, or one callable with no argument but not as a controller."""
    if inspect.isclass(spec):
        return True
    if not (inspect.isfunction(spec) or inspect.ismethod(spec)):
        return False
    sig = call_signature(spec)
    if sig is None:
        return False
    if "model" in sig.parameters:
        return True
    try:        # callable with keywords alone (its arguments' defaults), and not as a controller
        sig.bind()
    except TypeError:
        return False
    return not takes_controller_call(spec)


def import_spec(text: str):
    """The object ``"MODULE:ATTR"`` names (ATTR may be dotted). MODULE is found on the Python path or
    in the current folder. ValueError says what is wrong with the text or the import."""
    module_name, sep, attr = str(text).partition(":")
    if not sep or not module_name or not attr:
        raise ValueError(f"controller {text!r}: expected MODULE:ATTR (e.g. my_controllers:HZDController, "
                         "a class, a factory or a controller in my_controllers.py)")
    try:
        module = _import(module_name)
    except ImportError as exc:
        raise ValueError(f"controller {text!r}: cannot import {module_name!r}: {exc} (run from the folder "
                         "that holds it, or add that folder to PYTHONPATH)") from None
    except Exception as exc:    # the module's own code failed: a mistake in it, not in this program
        import traceback
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        raise ValueError(f"controller {text!r}: importing {module_name!r} raised {type(exc).__name__}: {exc} "
                         f"({frame.filename}:{frame.lineno})") from exc
    obj = module
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            names = [n for n in dir(module) if not n.startswith("_")]
            raise ValueError(f"controller {text!r}: module {module_name!r} ({getattr(module, '__file__', '?')}) "
                             f"has no {attr!r}; it has: {', '.join(names) or 'nothing public'}") from None
    return obj


def _import(module_name):
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        here = os.getcwd()
        if exc.name != module_name.split(".")[0] or here in sys.path:
            raise
        # the current folder, as `python -m` and `python script.py` put it first (a console script's
        # path starts with its own bin/ folder instead)
        sys.path.insert(0, here)
        return importlib.import_module(module_name)


def portable(spec):
    """``spec`` as a sweep sends it to its workers: a ``"MODULE:ATTR"`` text is checked here (imported)
    and sent with the folder its module came from, so that a worker started elsewhere imports it too."""
    if isinstance(spec, str):
        obj = import_spec(spec)
        name = spec.partition(":")[0]
        module = sys.modules[name]
        folder = None
        if getattr(module, "__file__", None):
            # the folder the top-level package is found in: examples.hzd_bezier in <repo>/examples/ -> <repo>
            path = Path(module.__file__).resolve()
            levels = name.count(".") + (path.name == "__init__.py")
            folder = str(path.parents[levels])
        return ImportedController(spec, folder, obj)
    return spec


class ImportedController:
    """A ``"MODULE:ATTR"`` controller and the folder its module was found in (pickled as those two)."""

    def __init__(self, text, folder, obj=None):
        self.text, self.folder, self._obj = text, folder, obj

    def resolve(self):
        if self._obj is None:
            if self.folder and self.folder not in sys.path:
                sys.path.append(self.folder)
            self._obj = import_spec(self.text)
        return self._obj

    def __reduce__(self):
        return ImportedController, (self.text, self.folder)

    def __repr__(self):
        return self.text


def make_controller(spec, model=None, **arguments):
    """The controller ``spec`` gives (see the module's docstring), made with ``arguments`` (a sweep's
    ``controller.NAME`` values) and ``model`` where its factory takes one; checked callable as the engine
    calls it. ValueError names the problem."""
    if isinstance(spec, str):
        spec = import_spec(spec)
    if isinstance(spec, ImportedController):
        spec = spec.resolve()
    if is_factory(spec):
        sig = call_signature(spec)
        kwargs = dict(arguments)
        if sig is not None and "model" in sig.parameters and model is not None:
            kwargs.setdefault("model", model)
        if sig is not None:
            unknown = [k for k in arguments if k not in sig.parameters] \
                if not any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()) else []
            if unknown:
                raise ValueError(f"controller {qualified_name(spec)} takes no argument {unknown[0]!r}; its parameters: "
                                 f"{', '.join(n for n in sig.parameters if n != 'self') or 'none'}")
            try:
                sig.bind(**kwargs)
            except TypeError as exc:
                raise ValueError(f"controller {qualified_name(spec)}{sig}: {exc}") from None
        controller = spec(**kwargs)
    else:
        if arguments:
            raise ValueError(f"controller {qualified_name(spec)} is a controller, not a class or factory: it takes no "
                             f"arguments ({', '.join(CONTROLLER_PREFIX + k for k in arguments)}); give its class")
        controller = spec
    what = f"controller made by {qualified_name(spec)}" if controller is not spec else "controller"
    return check_controller(controller, what)


def controller_arguments(point: dict) -> tuple[dict, dict]:
    """A sweep point split into (scene overrides, controller arguments) by the ``controller.`` prefix."""
    scene, ctrl = {}, {}
    for name, value in point.items():
        if isinstance(name, str) and name.startswith(CONTROLLER_PREFIX):
            ctrl[name[len(CONTROLLER_PREFIX):]] = value
        else:
            scene[name] = value
    return scene, ctrl


#: the help of ``--controller`` on the commands that take one
CLI_HELP = ("MODULE:ATTR: your controller (a class, a factory or a controller(t, q, dq, stance_leg) -> u), "
            "imported from MODULE on the Python path or in the current folder (docs/controllers.md); "
            "'walk': the reference walking controller (the scene's, with its parameters); 'none': u = 0")


def cli_controller(text):
    """``--controller``'s value: None (not given: the scene's), "walk", "none" or a checked
    ``"MODULE:ATTR"`` (imported now, so that a typo is one line before any run)."""
    if text is None or text in ("walk", "none"):
        return text
    import_spec(text)
    return text


def run_without_scene(choice, q0=None, dq0=None):
    """(model, controller, q0, dq0) of ``biped-sim simulate`` without ``--scene`` (headless or recorded):
    the reference model, the controller ``--controller`` chose, and the start ``--q0``/``--dq0`` give, else
    the controller's ``initial_state()``, else the reference gait's. ValueError for one of q0, dq0 alone."""
    from biped_sim.control.walking import WalkingController
    from biped_sim.engine.model import BipedModel
    if (q0 is None) != (dq0 is None):
        raise ValueError("give both --q0 and --dq0, or neither")
    model = BipedModel()
    controller = chosen_controller(choice, model=model)
    if q0 is None:
        q0, dq0 = getattr(controller, "initial_state", WalkingController(model).initial_state)()
    return model, controller, q0, dq0


def no_torque(t, q, dq, stance_leg):
    """u = 0: ``--controller none`` where a tool calls a controller itself (gait, basin: a passive gait)."""
    return [0.0, 0.0]


def _no_torque_jacobian(t, q, dq, stance_leg):
    """d u / d(q, dq) of u = 0: zero (so that the exact step Jacobian says 'law derivative: exact')."""
    import numpy as np
    return np.zeros((2, 10))


no_torque.jacobian = _no_torque_jacobian


def cli_law(text):
    """``--controller`` where a tool takes a controller to call itself (gait, basin): None for the scene's
    (not given, or "walk"), :func:`no_torque` for "none", else the checked ``"MODULE:ATTR"``."""
    text = cli_controller(text)
    return {None: None, "walk": None, "none": no_torque}.get(text, text)


def chosen_controller(choice, scene=None, model=None):
    """The controller ``--controller`` chose: with a ``scene``, the scene's (not given, or "walk");
    without, the reference walking controller on ``model`` (not given, or "walk"); None for "none";
    else yours (MODULE:ATTR) made on the scene's model or ``model``."""
    if choice == "none":
        return None
    if scene is not None:
        if choice in (None, "walk"):
            if choice == "walk" and scene.controller_params is None:
                raise ValueError(f"--controller walk: scene {scene.name} has no walk_controller section to take "
                                 "the walking controller's parameters from; leave --controller out (u = 0) or "
                                 "give MODULE:ATTR")
            return scene.controller()
        return make_controller(choice, scene.engine_arguments()["model"])
    if choice in (None, "walk"):
        from biped_sim.control.walking import WalkingController
        return WalkingController(model)
    return make_controller(choice, model)
