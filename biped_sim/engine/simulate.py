"""The one-call API: ``simulate`` a run from a state, and ``stance_state`` to build a consistent one."""
from __future__ import annotations

import math

import numpy as np

from biped_sim.engine.controller_check import check_controller
from biped_sim.engine.hybrid import HybridSimulator
from biped_sim.engine.model import BipedModel, as_state_vector, check_leg
from biped_sim.engine.options import check_number
from biped_sim.engine.resets import check_push
from biped_sim.engine.results import SimulationResult


def stance_state(model: BipedModel, joints, joint_rates, stance_leg=1, foot=(0.0, 0.0)):
    """A consistent stance state: the base placed so that the stance foot is at ``foot`` and at rest.

    ``joints`` and ``joint_rates`` are q[2:] and dq[2:]: ``(q1, q2, q3)`` and ``(dq1, dq2, dq3)`` for the
    three-link biped, the n - 2 joint coordinates of a described robot (``GeneratedModel``, its
    ``coordinates[2:]``), whose stance foot is contact ``stance_leg``; returns physical (q, dq).
    """
    if not isinstance(model, BipedModel) and hasattr(model, "contact_position"):
        names = f"q[2:] of {model.name}: {', '.join(model.coordinates[2:])}"
        qs = as_state_vector(joints, f"joints ({names})", model.n - 2)
        dqs = as_state_vector(joint_rates, f"joint_rates (dq[2:] of {model.name})", model.n - 2)
    else:
        qs = as_state_vector(joints, "joints", 3)
        dqs = as_state_vector(joint_rates, "joint_rates", 3)
    c = as_state_vector(foot, "foot", 2)
    base, dbase = model.base_hung_from(check_leg(stance_leg) - 1, c.tolist(), qs.tolist(), dqs.tolist())
    return np.concatenate([base, qs]), np.concatenate([dbase, dqs])


#: what ``simulate`` does when the controller fails: "fail" (the run ends "failed", its result returned) or
#: "raise" (the controller's exception raised once the run is closed, the result on it as ``exc.result``)
ON_CONTROLLER_ERROR = ("fail", "raise")


def simulate(model, q0, dq0, t_final, controller=None, stance_leg=1, rtol=1e-9, atol=1e-9,
             method="dop853", control_period=None, mu=None, pushes=(), on_controller_error="fail",
             **options) -> SimulationResult:
    """Simulate the hybrid biped from (q0, dq0) to ``t_final`` seconds.

    ``controller(t, q, dq, stance_leg) -> u`` (u[0] on hip 1, u[1] on hip 2, physical legs) is called
    at every right-hand-side evaluation, or once per ``control_period`` and held (zero-order hold,
    as the node does; the torque is held through an impact inside the period). ``mu=None`` means
    enough friction. ``options`` are the fields of :class:`Options` (``base``, ``phases``,
    ``touchdown_rule``, ``stop_on_slip``, ``project_constraints``, ``step`` for fixed-step methods,
    ``slope``, ...). ``pushes = [(t, impulse), ...]``: impulses (N s, [x forward, y up]) on the hip
    (``HybridSimulator.push``), each applied at its time t, or with a ``control_period`` at the start
    of the first period that starts at or after t, as the node applies its ``push`` topic. A run
    that leaves the scene's assumptions or whose integration fails ends with
    ``result.status`` "stopped" or "failed", a final event, and ``result.message``; bad arguments
    raise ``ValueError``. A controller that raises, or returns anything but two finite real numbers, ends
    the run "failed" and is ``result.controller_error`` (the controller's exception, with its traceback);
    ``on_controller_error="raise"`` raises it once the run is closed, with the result as its ``result``.
    """
    if on_controller_error not in ON_CONTROLLER_ERROR:
        raise ValueError(f"on_controller_error must be one of {', '.join(map(repr, ON_CONTROLLER_ERROR))}, got "
                         f"{on_controller_error!r}")
    check_number("t_final", t_final, 0.0, math.inf, "s")
    why = None if isinstance(model, BipedModel) else getattr(model, "engine_refusal", None)
    if why is not None:
        raise ValueError(why)   # a described robot the engine cannot run (docs/models.md)
    if control_period is not None:
        check_number("control_period", control_period, 0.0, math.inf, "s", open_low=True)
        if controller is None:
            raise ValueError("control_period needs a controller to hold once per period: give "
                             "controller=..., or leave control_period out for u = 0")
    if controller is not None:
        check_controller(controller)
    pushes = _checked_pushes(pushes, t_final)
    sim = HybridSimulator(model, q0, dq0, stance_leg, rtol, atol, method, mu, **options)
    if controller is None or control_period is None:
        for t_push, impulse in pushes:
            sim.advance(t_push, controller=controller)
            sim.push(impulse)
        sim.advance(t_final, controller=controller)
    else:
        due = 0
        while sim.status == "running" and sim.t < t_final:
            due = _push_due(sim, pushes, due, 1e-9 * control_period)
            sim.advance_periods(control_period, controller, t_final, pushes[due][0] if due < len(pushes) else math.inf)
        _push_due(sim, pushes, due, 1e-9 * control_period)
    result = sim.result()
    error = result.controller_error
    if error is not None and on_controller_error == "raise":
        try:
            error.result = result
        except AttributeError:     # (an exception type that takes no attributes: the result is lost to it)
            pass
        raise error
    return result


def _checked_pushes(pushes, t_final):
    """``pushes`` as a list of (time, impulse array) sorted by time, or a ValueError naming the entry."""
    try:
        entries = list(pushes)
    except TypeError:
        raise ValueError(f"pushes must be a list of (t, impulse) pairs, got {pushes!r}") from None
    out = []
    for i, entry in enumerate(entries):
        if not (isinstance(entry, (tuple, list)) and len(entry) == 2):
            raise ValueError(f"pushes[{i}] must be a pair (t, impulse), got {entry!r}")
        check_number(f"pushes[{i}] time", entry[0], 0.0, t_final, "s, within the run")
        out.append((float(entry[0]), check_push(entry[1], f"pushes[{i}] impulse")))
    return sorted(out, key=lambda p: p[0])


def _push_due(sim, pushes, i, tol):
    """Apply the pushes from index i whose time has come (at or before sim.t, within tol); the next index."""
    while i < len(pushes) and pushes[i][0] <= sim.t + tol and sim.status == "running":
        sim.push(pushes[i][1])
        i += 1
    return i
