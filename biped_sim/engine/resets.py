"""The resets of the hybrid system: what happens to the state when a guard fires.

Each reset is a named function of the state at the event that returns the :class:`Event`; the
simulator then takes the new mode from it (``stance_leg_after``, ``dq_plus``), as Drake's compass
gait takes its new state from ``CollisionDynamics``.

* ``touchdown_reset``: the rigid plastic impact of docs/model.md "Impact" (``impact_map``), then
  relabeling: the foot that landed is the new stance foot; ``double_touchdown_reset``: both feet at
  once, the new stance foot the one that took the larger normal impulse (double support is not
  modelled);
* ``liftoff_reset``: the stance foot leaves the ground; the velocities are unchanged, flight follows;
* ``slip_event``: the ground force leaves the friction cone; the model has no sliding phase.
"""
from __future__ import annotations

from biped_sim.engine.dynamics import IMPACT_CONDITION_LIMIT, impact_condition, impact_map
from biped_sim.engine.guards import foot_states, normal_tangent
from biped_sim.engine.results import Event


def touchdown_reset(model, t, q, dq, legs, stance_leg, ground, mu=None) -> Event:
    """The impact of foot ``legs[0]`` (or of both feet, ``legs == [1, 2]``) at the state (q, dq) (arrays)."""
    impact_leg = legs[0] if len(legs) == 1 else (1, 2)
    dq_plus, impulse = impact_map(model, q, dq, impact_leg)
    if len(legs) == 1:
        new, kind = legs[0], "touchdown"
    else:
        n1 = normal_tangent(impulse[0:2], ground)[0]
        n2 = normal_tangent(impulse[2:4], ground)[0]
        new, kind = (1 if n1 >= n2 else 2), "double_touchdown"
    loss = model.energy(q, dq) - model.energy(q, dq_plus)
    warnings = impact_warnings(model, q, dq_plus, impulse, legs, stance_leg, ground, mu)
    return Event(t, kind, new, q, dq, dq_plus, impulse, stance_leg, new, loss, warnings)


def double_touchdown_reset(model, t, q, dq, stance_leg, ground, mu=None) -> Event:
    """Both feet land at once (within ``simultaneous_tol``): the plastic impact of both, the run goes
    on in stance on the foot that took the larger normal impulse (double support is not modelled)."""
    return touchdown_reset(model, t, q, dq, [1, 2], stance_leg, ground, mu)


def impact_warnings(model, q, dq_plus, impulse, legs, old, ground, mu) -> list[str]:
    """The contact assumptions an impact violates: the old stance foot must leave the ground, and each
    impulse must push (and lie inside the friction cone, with ``mu``)."""
    warnings = []
    feet = foot_states(model, q.tolist(), dq_plus.tolist(), ground.tan)
    if len(legs) == 2 and impact_condition(model, q, (1, 2)) > IMPACT_CONDITION_LIMIT:
        gap = abs(feet[0].x - feet[1].x)
        warnings.append(f"the feet land {gap:.3g} m apart, nearly at one point: the post-impact velocity is "
                        "determined, the split of the impulse between them is not (the smallest impulses are "
                        "reported)")
    if old and old not in legs and feet[old - 1].dheight < 0:
        warnings.append(f"the old stance foot (leg {old}) does not leave the ground after the impact "
                        f"(vertical velocity {feet[old - 1].dheight:.6g} m/s)")
    for j, leg in enumerate(legs):
        n, tg = normal_tangent(impulse[2 * j: 2 * j + 2], ground)
        if n < 0:
            warnings.append(f"the impulse on foot {leg} pulls it into the ground (normal {n:.6g} N s)")
        elif mu is not None and abs(tg) > mu * n:
            warnings.append(f"the impulse on foot {leg} is outside the friction cone "
                            f"(|tangential| {abs(tg):.6g} > mu * normal {mu * n:.6g} N s)")
    return warnings


def liftoff_reset(t, q, dq, stance_leg, flight_allowed) -> Event:
    """The stance foot leaves the ground (its normal force reached zero). Without a flight phase in
    the scene this is an ``error`` event: the run stops."""
    ev = Event(t, "liftoff", stance_leg, q, dq, dq.copy(), None, stance_leg, 0)
    if not flight_allowed:
        ev.kind = "error"
        ev.stance_leg_after = stance_leg
        ev.message = (f"the stance foot (leg {stance_leg}) would lift off at t={t:.9g} s (normal force "
                      "reaches zero), but this scene has no flight phase: add 'flight' to its phases")
    return ev


def slip_event(t, q, dq, stance_leg, F, ground, mu) -> Event:
    """The ground force F on the stance foot leaves the friction cone (|F_t| > mu F_n)."""
    n, tg = normal_tangent(F, ground)
    return Event(t, "slip", stance_leg, q, dq, dq.copy(), None, stance_leg, stance_leg,
                 message=f"the stance foot (leg {stance_leg}) would slip at t={t:.9g} s: |F_t| = {abs(tg):.6g} N "
                         f"> mu F_n = {mu * n:.6g} N (mu = {mu:g})")
