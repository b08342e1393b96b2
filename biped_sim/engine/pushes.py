"""Pushes: an impulse on the hip from outside, applied to a running :class:`HybridSimulator`.

The physics is ``push_response`` (dynamics.py: the impact's KKT system with the push's generalized
impulse J_hip^T P on the right) and ``push_reset`` (resets.py: whether the ground can hold the
foot); this module applies the resulting event to the simulator's state and mode, between two
``advance`` calls, as ``_reset`` does for a guard that fired (docs/engine.md "Pushes").
"""
from __future__ import annotations

import numpy as np

from biped_sim.engine.resets import check_push, friction_cone_stop, liftoff_reset, push_reset
from biped_sim.engine.results import SceneAssumptionError


def apply_push(sim, impulse) -> list:
    """Apply the push ``impulse`` (N s, [x forward, y up]) to ``sim`` now, at ``sim.t``; returns its
    events (``push``, then ``liftoff`` if it lifted the stance foot; or an ``error``: the run stops)."""
    P = check_push(impulse)
    if sim.status != "running":
        return []
    n_events = len(sim.events)
    t, q, leg = sim.t, sim.q.copy(), sim.stance_leg
    flight_allowed = "flight" in sim.opt.phases
    try:
        ev = push_reset(sim.model, t, q, sim.dq.copy(), P, leg, sim.ground, sim.mu, flight_allowed)
    except (np.linalg.LinAlgError, ValueError) as exc:
        sim._fail(f"the push {P.tolist()} N s could not be applied: {exc}")
        return sim.events[n_events:]
    sim.stats["pushes"] += 1
    sim._push_event(ev)
    if ev.kind == "error":
        sim._stop("stopped", ev.message)
        return sim.events[n_events:]
    sim.dq = ev.dq_plus
    sim.push_work -= ev.energy_loss
    if ev.stance_leg_after != leg:      # the foot left the ground: flight from this instant
        lift = liftoff_reset(t, q, ev.dq_plus, leg, flight_allowed)
        try:
            sim.locator.after_reset(lift)
        except SceneAssumptionError as exc:
            sim._fail(str(exc), status="stopped")
            return sim.events[n_events:]
        sim.stance_leg, sim.pin = 0, None
        sim._push_event(lift)
    dq_list = sim.dq.tolist()
    u = sim._torque_at(t, q.tolist(), dq_list)
    F = sim._force_at(t, q.tolist(), dq_list, u)
    sim._record(sim.q, sim.dq, sim.stance_leg, F, u)
    # the next step starts from the pushed state, not from the last step's end (the same time)
    sim.locator.restart(t, sim.feet(q.tolist(), dq_list), F)
    slip = friction_cone_stop(ev, sim.ground, sim.mu, sim.opt)
    if slip is not None:
        sim._stop("stopped", slip)
    elif sim.status == "running":
        sim._check_stance_start(t)   # the new velocities can make the normal force negative at once
    return sim.events[n_events:]
