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

from biped_sim.engine import loop_rules as rules
from biped_sim.engine.dynamics import IMPACT_CONDITION_LIMIT, impact_condition, impact_map_fast, push_response
from biped_sim.engine.guards import foot_states, normal_tangent
from biped_sim.engine.loop_kernels import register
from biped_sim.engine.loop_state import (
    DQ_MINUS,
    DQ_PLUS,
    FEET_AFTER,
    IMPACT_OLD_FOOT_SINKS,
    IMPACT_OUTSIDE_CONE,
    IMPACT_PULLS,
    IMPULSE,
    Q_IMPACT,
    new_state,
)
from biped_sim.engine.model import BipedModel, as_state_vector
from biped_sim.engine.results import Event

#: the largest push accepted (N s, magnitude): 100 N s would throw the 20 kg reference robot at 5 m/s;
#: a larger one is a typo or a unit error (N instead of N s over a short time), not a disturbance
PUSH_IMPULSE_LIMIT = 100.0

#: two normal impulses of a double touchdown within this relative difference are a tie (the solve
#: computes them to ~1e-15 relative)
TIE_TOL = 1e-9


def touchdown_state(model, ground, mu=None) -> list:
    """A state (``loop_state``) with what the impact's rule ``loop_rules.ev_impact`` reads: the model's kernels
    (the three-link's closed-form constants, or a generated model's registered kernels), its coordinates N, the
    ground, the friction coefficient (0 without one)."""
    common = dict(n_q=model.n, tan_s=ground.tan, sin_s=ground.sin, cos_s=ground.cos, mu=0.0 if mu is None else mu)
    if isinstance(model, BipedModel):
        return new_state(k_impact=model.k["impact_map_1"], k_energy=model.k["energy"],
                         k_feet=model.k["foot_kinematics"], **common)
    return new_state(model_kernels=register(model), **common)


def touchdown_reset(model, t, q, dq, legs, stance_leg, ground, mu=None) -> Event:
    """The impact of foot ``legs[0]`` (or of both feet, ``legs == [1, 2]``) at the state (q, dq) (arrays)."""
    if len(legs) == 1:
        # one foot: the rule the compiled loop runs (loop_rules.ev_impact), on a state of its own
        S = touchdown_state(model, ground, mu)
        n = len(q)
        S[Q_IMPACT:Q_IMPACT + n] = q.tolist()
        S[DQ_MINUS:DQ_MINUS + n] = dq.tolist()
        checks = rules.ev_impact(S, legs[0], stance_leg, mu is not None)
        dq_plus, impulse = np.array(S[DQ_PLUS:DQ_PLUS + n]), np.array(S[IMPULSE:IMPULSE + 2])
        loss = rules.ev_impact_loss(S)
        dheight = S[FEET_AFTER + 4 * (stance_leg - 1) + 3] if stance_leg else 0.0
        warnings = impact_warnings([checks & ~IMPACT_OLD_FOOT_SINKS], checks & IMPACT_OLD_FOOT_SINKS, dheight,
                                   impulse, legs, stance_leg, ground, mu)
        return Event(t, "touchdown", legs[0], q, dq, dq_plus, impulse, stance_leg, legs[0], loss, warnings)
    # both feet (Python only: the compiled loop runs one foot's touchdown)
    dq_plus, impulse = impact_map_fast(model, q, dq, (1, 2))
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
    ql = q.tolist()
    loss = model.energy_fast(ql, dq.tolist()) - model.energy_fast(ql, dq_plus.tolist())
    warnings = []
    if impact_condition(model, q, (1, 2)) > IMPACT_CONDITION_LIMIT:
        feet = foot_states(model, ql, dq_plus.tolist(), ground.tan)
        warnings.append(f"the feet land {abs(feet[0].x - feet[1].x):.3g} m apart, nearly at one point: the "
                        "post-impact velocity is determined, the split of the impulse between them is not (the "
                        "smallest impulses are reported)")
    checks = [rules.ev_impulse_checks(mu is not None, 0.0 if mu is None else mu,
                                      *normal_tangent(impulse[2 * j: 2 * j + 2], ground)) for j in range(2)]
    warnings += impact_warnings(checks, 0, 0.0, impulse, [1, 2], stance_leg, ground, mu)
    return Event(t, "double_touchdown", new, q, dq, dq_plus, impulse, stance_leg, new, loss, warnings)


def double_touchdown_reset(model, t, q, dq, stance_leg, ground, mu=None) -> Event:
    """Both feet land at once (within ``simultaneous_tol``): the plastic impact of both, the run goes
    on in stance on the foot that took the larger normal impulse, the rear foot on a tie (double support
    is not modelled)."""
    return touchdown_reset(model, t, q, dq, [1, 2], stance_leg, ground, mu)


def impact_warnings(impulse_checks, old_foot_sinks, dheight, impulse, legs, old, ground, mu) -> list[str]:
    """The messages of the contact assumptions an impact violates (the bits of ``loop_rules.ev_impact``'s
    checks): the old stance foot must leave the ground (``old_foot_sinks``; ``dheight`` its rate across the
    ground after the impact), and each landing foot's impulse must push, inside the friction cone with ``mu``
    (``impulse_checks``, the bits of each, in the order of ``legs``)."""
    warnings = []
    if old_foot_sinks:
        warnings.append(f"the old stance foot (leg {old}) does not leave the ground after the impact "
                        f"(vertical velocity {dheight:.6g} m/s)")
    for j, (leg, checks) in enumerate(zip(legs, impulse_checks)):
        if not checks:
            continue
        n, tg = normal_tangent(impulse[2 * j: 2 * j + 2], ground)
        if checks & IMPACT_PULLS:
            warnings.append(f"the impulse on foot {leg} pulls it into the ground (normal {n:.6g} N s)")
        elif checks & IMPACT_OUTSIDE_CONE:
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
        if rules.ev_outside_cone(mu, n, tg, opt.impulse_tol):
            if n > 0:
                why = (f"|Lambda_t|/Lambda_n = {abs(tg) / n:.6g} > mu = {mu:g}: |Lambda_t| = {abs(tg):.6g} N s > "
                       f"mu Lambda_n = {mu * n:.6g} N s")
            else:       # (no ratio to give: the cone's apex is behind it)
                why = f"its normal part pulls: Lambda_n = {n:.6g} N s, |Lambda_t| = {abs(tg):.6g} N s, mu = {mu:g}"
            return (f"{what}: the ground's impulse on foot {leg} is outside the friction cone ({why}); the model "
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
        elif rules.ev_impulse_checks(mu is not None, 0.0 if mu is None else mu, n, tg) & IMPACT_OUTSIDE_CONE:
            warnings.append(f"the ground's impulse on foot {stance_leg} is outside the friction cone "
                            f"(|tangential| {abs(tg):.6g} > mu * normal {mu * n:.6g} N s)")
    loss = model.energy(q, dq) - model.energy(q, dq_plus)
    return Event(t, "push", stance_leg, q, dq, dq_plus, ground_impulse, stance_leg, after, loss, warnings, push=P)
