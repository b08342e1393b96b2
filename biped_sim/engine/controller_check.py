"""The check that a controller can be called as the engine calls it, made before a run starts (a
wrong signature found at the first call was a run ended "failed" mid-way). Standard library only:
the command line imports it to check ``--controller`` without loading the engine."""
from __future__ import annotations

import inspect

#: what a controller is called with (the engine's call)
CONTROLLER_ARGUMENTS = ("t", "q", "dq", "stance_leg")


def call_signature(fn):
    try:
        return inspect.signature(fn)
    except (TypeError, ValueError):     # a builtin without one: its call decides
        return None


def takes_controller_call(fn) -> bool:
    """Whether ``fn(t, q, dq, stance_leg)`` binds (four positional arguments)."""
    sig = call_signature(fn)
    if sig is None:
        return True
    try:
        sig.bind(*CONTROLLER_ARGUMENTS)
    except TypeError:
        return False
    return True


def check_controller(controller, what="controller"):
    """A ValueError, before the run, for a controller the engine could not call as
    ``controller(t, q, dq, stance_leg)``; returns it."""
    if not callable(controller):
        raise ValueError(f"{what} must be callable as controller(t, q, dq, stance_leg) -> [u1, u2], got "
                         f"{type(controller).__name__} {controller!r}")
    if not takes_controller_call(controller):
        target = controller if inspect.isfunction(controller) or inspect.ismethod(controller) else \
            type(controller).__call__
        raise ValueError(f"{what} {qualified_name(controller)} cannot be called as controller(t, q, dq, "
                         f"stance_leg): its signature is {qualified_name(target)}{call_signature(controller)}; give "
                         "it those four parameters")
    return controller


def qualified_name(obj) -> str:
    mod = getattr(obj, "__module__", None) or type(obj).__module__
    return f"{mod}.{getattr(obj, '__qualname__', type(obj).__qualname__)}"
