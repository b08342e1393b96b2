"""The resets of the hybrid system: what happens to the state when a guard fires.

Each reset is a named function of the state at the event that returns the :class:`Event`; the
simulator then takes the new mode from it (``stance_leg_after``, ``dq_plus``), as Drake's compass
gait takes its new state from ``CollisionDynamics``.

* ``touchdown_reset``: the rigid plastic impact of docs/model.md "Impact" (``impact_map``), then
  relabeling: the foot that landed is the new stance foot; ``double_touchdown_reset``: both feet at
  once, the new stance foot the one that took the larger normal impulse, the rear foot on a tie
  (double support is not modelled);
* ``liftoff_reset``: the stance foot leaves the ground; the velocities are unchanged, flight follows;
* ``slip_event``: the ground force leaves the friction cone; the model has no sliding phase;
  ``friction_cone_stop``: the same for the ground's impulse of an impact or a push;
* ``push_reset``: an impulse on the hip from outside (``push_response``), with the stance foot held
  while the ground can hold it.
"""
from __future__ import annotations

import numpy as np

from biped_sim.engine.dynamics import IMPACT_CONDITION_LIMIT, impact_condition, impact_map_fast, push_response
from biped_sim.engine.guards import foot_states, normal_tangent
from biped_sim.engine.model import as_state_vector
from biped_sim.engine.results import Event

#: the largest push accepted (N s, magnitude): 100 N s would throw the 20 kg reference robot at 5 m/s;
#: a larger one is a typo or a unit error (N instead of N s over a short time), not a disturbance
PUSH_IMPULSE_LIMIT = 100.0

#: two normal impulses of a double touchdown within this relative difference are a tie (the solve
#: computes them to ~1e-15 relative)
TIE_TOL = 1e-9


def touchdown_reset(model, t, q, dq, legs, stance_leg, ground, mu=None) -> Event:
    """The impact of foot ``legs[0]`` (or of both feet, ``legs == [1, 2]``) at the state (q, dq) (arrays)."""
    impact_leg = legs[0] if len(legs) == 1 else (1, 2)
    dq_plus, impulse = impact_map_fast(model, q, dq, impact_leg)
    if len(legs) == 1:
        new, kind = legs[0], "touchdown"
    else:
        n1 = normal_tangent(impulse[0:2], ground)[0]
        n2 = normal_tangent(impulse[2:4], ground)[0]
        if abs(n1 - n2) <= TIE_TOL * max(abs(n1), abs(n2)):
            # a tie (a symmetric landing): which impulse is larger is rounding, so the rear foot, by
            # rule: then the front foot's touchdown is the next event and says that both feet stay
            # down; on the front foot the rear one's sinking would pass for a scuff behind it
            p1x, p2x = model.foot_position(q, 1)[0], model.foot_position(q, 2)[0]
            new = 1 if p1x <= p2x else 2
        else:
            new = 1 if n1 > n2 else 2
        kind = "double_touchdown"
    ql = q.tolist()
    loss = model.energy_fast(ql, dq.tolist()) - model.energy_fast(ql, dq_plus.tolist())
    warnings = impact_warnings(model, q, dq_plus, impulse, legs, stance_leg, ground, mu)
    return Event(t, kind, new, q, dq, dq_plus, impulse, stance_leg, new, loss, warnings)


def double_touchdown_reset(model, t, q, dq, stance_leg, ground, mu=None) -> Event:
    """Both feet land at once (within ``simultaneous_tol``): the plastic impact of both, the run goes
    on in stance on the foot that took the larger normal impulse, the rear foot on a tie (double support
    is not modelled)."""
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


def friction_cone_stop(ev, ground, mu, opt) -> str | None:
    """Why the run stops at the impact or push ``ev`` (its ground impulse applied as a sticking contact),
    or None: with ``mu`` and ``opt.stop_on_slip``, a ground impulse Lambda outside the friction cone,
    |Lambda_t| > mu Lambda_n by more than ``opt.impulse_tol``, is a slip the model does not have, as a
    stance force outside it is (``slip_event``). The one rule of touchdowns, double touchdowns and
    pushes; ``stop_on_slip=False`` keeps the sticking impulse, with the event's warning. (Within the
    tolerance the impulse is zero to rounding and its direction meaningless: a foot landing at rest.)"""
    if mu is None or not opt.stop_on_slip:
        return None
    if ev.kind == "push":
        legs = [ev.leg] if ev.leg and ev.stance_leg_after == ev.leg else []   # held; lifted: no ground impulse
        what = f"the push at t={ev.time:.9g} s"
        keep = "keep the foot pinned"
    else:
        legs = [1, 2] if ev.kind == "double_touchdown" else [ev.leg]
        what = f"the {ev.kind.replace('_', ' ')} at t={ev.time:.9g} s"
        keep = "keep the sticking impact"
    for j, leg in enumerate(legs):
        n, tg = normal_tangent(ev.impulse[2 * j: 2 * j + 2], ground)
        if abs(tg) - mu * n > opt.impulse_tol:
            ratio = f"|Lambda_t|/Lambda_n = {abs(tg) / n:.6g}" if n > 0 else f"Lambda_n = {n:.6g} N s"
            return (f"{what}: the ground's impulse on foot {leg} is outside the friction cone ({ratio} > "
                    f"mu = {mu:g}: |Lambda_t| = {abs(tg):.6g} N s > mu Lambda_n = {mu * n:.6g} N s); the model "
                    f"has no sliding phase (raise mu, or set stop_on_slip=False to {keep} with a warning)")
    return None


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


def check_push(impulse, name="impulse") -> np.ndarray:
    """The push as an array of two finite floats within PUSH_IMPULSE_LIMIT, or a ValueError naming ``name``."""
    P = as_state_vector(impulse, name, 2)
    size = float(np.hypot(P[0], P[1]))
    if size > PUSH_IMPULSE_LIMIT:
        raise ValueError(f"{name} is {size:.6g} N s, above the limit of {PUSH_IMPULSE_LIMIT:g} N s "
                         f"(an impulse, N s, not a force): {P.tolist()}")
    return P


def push_reset(model, t, q, dq, impulse, stance_leg, ground, mu, flight_allowed) -> Event:
    """A push ``impulse`` (N s) on the hip at the state (q, dq) (arrays): the ``push`` Event.

    In stance the foot is held (``push_response``) if the ground's impulse on it pushes (normal
    >= 0). If it would have to pull, the contact is unilateral: the foot leaves the ground with the
    free response (``stance_leg_after`` 0; the simulator follows with a liftoff), or, without a
    flight phase, or if the free response would drive the foot into the ground (a sliding contact,
    not modelled), an ``error`` Event: the run stops. A ground impulse outside the friction cone
    (with ``mu``) is a warning of the event (and a stop: ``friction_cone_stop``)."""
    P = check_push(impulse)
    dq_plus, ground_impulse = push_response(model, q, dq, P, stance_leg)
    after, warnings = stance_leg, []
    if stance_leg:
        n, tg = normal_tangent(ground_impulse, ground)
        if n < 0.0:
            dq_free, ground_impulse = push_response(model, q, dq, P, 0)
            rate = foot_states(model, q.tolist(), dq_free.tolist(), ground.tan)[stance_leg - 1].dheight
            why = None
            if not flight_allowed:
                why = "this scene has no flight phase: add 'flight' to its phases"
            elif rate < 0.0:
                why = (f"without the ground the foot would move into it ({rate:.6g} m/s): a sliding contact, "
                       "which the model does not have")
            if why is not None:
                return Event(t, "error", stance_leg, q, dq, dq.copy(), None, stance_leg, stance_leg, push=P,
                             message=f"the push {P.tolist()} N s at t={t:.9g} s lifts the stance foot (leg "
                                     f"{stance_leg}) off the ground (holding it would need a pull of {-n:.6g} "
                                     f"N s), but {why}")
            dq_plus, after = dq_free, 0
        elif mu is not None and abs(tg) > mu * n:
            warnings.append(f"the ground's impulse on foot {stance_leg} is outside the friction cone "
                            f"(|tangential| {abs(tg):.6g} > mu * normal {mu * n:.6g} N s)")
    loss = model.energy(q, dq) - model.energy(q, dq_plus)
    return Event(t, "push", stance_leg, q, dq, dq_plus, ground_impulse, stance_leg, after, loss, warnings, push=P)
