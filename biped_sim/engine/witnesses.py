"""The witnesses of the hybrid system: each guard as one row.

A :class:`Witness` is everything the loop needs of a guard, in one object: its name (the event it
makes), the foot it watches, its direction (when a change of its value between a step's two ends is
an event: :func:`triggered`), its value (a scalar of the state, positive while the mode holds:
``guards.py``'s guard functions), its reset (the Event it makes, and why the run stops there, if it
does: ``resets.py``) and the invariants of ``invariants.py`` it protects (its crossing found, they
hold). :func:`witnesses` gives the rows of a mode, in the order the locator looks at them. The
event locator and the simulator know witnesses, their values and their resets, not feet: a new
guard is a new row in :data:`KINDS` (and, where the compiled loop should decide it too, its line in
``_core.c``'s quiet step).
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from biped_sim.engine import guards as G, loop_rules as rules
from biped_sim.engine.resets import double_touchdown_reset, liftoff_reset, slip_event, touchdown_reset

#: the one direction of this model's witnesses (Drake's ``kPositiveThenNonPositive``): an event where
#: the value is positive at a step's start and zero or negative at its end
POSITIVE_THEN_NON_POSITIVE = "positive then non-positive"


def triggered(w0, w1, direction=POSITIVE_THEN_NON_POSITIVE) -> bool:
    """Whether a witness whose value is ``w0`` at a step's start and ``w1`` at its end fired in the step:
    the rule ``loop_rules.ev_triggered``, which the compiled loop runs compiled."""
    if direction != POSITIVE_THEN_NON_POSITIVE:
        raise ValueError(f"a witness's direction must be {POSITIVE_THEN_NON_POSITIVE!r}, got {direction!r}")
    return rules.ev_triggered(w0, w1)


class ResetContext(NamedTuple):
    """What a reset reads of the run: the model, the ground, the friction coefficient (or None), the
    options, and ``force_at(t, q, dq) -> [Fx, Fy]`` (the stance force under the torque applied at t)."""
    model: object
    ground: G.Ground
    mu: float | None
    opt: object
    force_at: Callable


# -- the values: positive while the mode holds -----------------------------------------------------
# value(ctx, leg, t, q, dq, force_at, feet=None, F=None): ctx the locator (model, ground, mu); feet and F
# the state's feet and stance force where the caller has them, else computed here from q, dq (lists). At a
# step's start the locator passes the feet and force it kept of the last step's end, and q, dq only to a
# witness that reads the state (WitnessKind.reads)
def _height(ctx, leg, t, q, dq, force_at, feet=None, F=None):
    if feet is None:   # the height only (root finding evaluates this many times)
        return G.foot_height(ctx.model, q, leg, ctx.ground.tan)
    return G.touchdown_guard(feet, leg)


def _normal_force(ctx, leg, t, q, dq, force_at, feet=None, F=None):
    return G.liftoff_guard(*G.normal_tangent(F if F is not None else force_at(t, q, dq), ctx.ground))


def _cone_margin(ctx, leg, t, q, dq, force_at, feet=None, F=None):
    n, tg = G.normal_tangent(F if F is not None else force_at(t, q, dq), ctx.ground)
    return G.slip_guard(n, tg, ctx.mu)


# -- the resets: (the Event, why the run stops there or None) ----------------------------------------
# reset(ctx, t, q, dq, legs, stance_leg): ctx a ResetContext, q and dq lists, legs the feet it fires for
def _touch_down(ctx, t, q, dq, legs, stance_leg):
    qa, dqa = _arrays(q, dq)
    if len(legs) == 2:
        return double_touchdown_reset(ctx.model, t, qa, dqa, stance_leg, ctx.ground, ctx.mu), None
    return touchdown_reset(ctx.model, t, qa, dqa, legs, stance_leg, ctx.ground, ctx.mu), None


def _lift_off(ctx, t, q, dq, legs, stance_leg):
    ev = liftoff_reset(t, *_arrays(q, dq), stance_leg, "flight" in ctx.opt.phases)
    return ev, ev.message if ev.kind == "error" else None


def _slip(ctx, t, q, dq, legs, stance_leg):
    ev = slip_event(t, *_arrays(q, dq), stance_leg, ctx.force_at(t, list(q), list(dq)), ctx.ground, ctx.mu)
    stop = None
    if ctx.opt.stop_on_slip:
        stop = (ev.message + "; the model has no sliding phase (raise mu, or set stop_on_slip=False to keep the "
                "foot pinned)")
    return ev, stop


def _arrays(q, dq):
    return np.array(q), np.array(dq)


# -- the feet each watches in a mode: legs(stance_leg, armed, phases, mu) ----------------------------------
def _armed_free_feet(stance_leg, armed, phases, mu):
    """In stance the swing foot, in flight both feet: where armed, and with an impact phase."""
    if "impact" not in phases:
        return ()
    return tuple(leg for leg in (1, 2) if leg != stance_leg and armed[leg - 1])


def _stance_foot(stance_leg, armed, phases, mu):
    return (stance_leg,) if stance_leg else ()


def _stance_foot_with_friction(stance_leg, armed, phases, mu):
    return (stance_leg,) if stance_leg and mu is not None else ()


class WitnessKind(NamedTuple):
    """One guard of the model: name (the kind of the event its reset makes), direction, value, reset,
    the invariants it protects, ``legs(stance_leg, armed, phases, mu)`` (the feet it watches in a mode),
    ``latches`` (after its reset the mode goes on with the witness still at or below zero: it stays off
    until it is positive again at a step's end), ``reads`` (what its value reads where the locator has it
    kept: "feet", "force", or "state") and ``compiled`` (``_core.c``'s quiet step decides it too;
    a mode with a witness it does not know runs in the Python loop)."""
    name: str
    direction: str
    value: Callable
    reset: Callable
    invariants: tuple
    legs: Callable
    latches: bool = False
    reads: str = "state"
    compiled: bool = False


#: the guards of the model (docs/model.md; guards.py has their values), in the order the locator looks at them
KINDS = {
    "touchdown": WitnessKind("touchdown", POSITIVE_THEN_NON_POSITIVE, _height, _touch_down,
                             ("feet at or above the ground",), _armed_free_feet, reads="feet", compiled=True),
    "liftoff": WitnessKind("liftoff", POSITIVE_THEN_NON_POSITIVE, _normal_force, _lift_off, ("the ground pushes",),
                           _stance_foot, reads="force", compiled=True),
    "slip": WitnessKind("slip", POSITIVE_THEN_NON_POSITIVE, _cone_margin, _slip, ("inside the friction cone",),
                        _stance_foot_with_friction, latches=True, reads="force", compiled=True),
}


class Witness(NamedTuple):
    """A row: a guard (:class:`WitnessKind`) watching foot ``leg``."""
    kind: WitnessKind
    leg: int

    @property
    def name(self):
        return self.kind.name

    @property
    def direction(self):
        return self.kind.direction

    def value(self, ctx, t, q, dq, force_at, feet=None, F=None):
        return self.kind.value(ctx, self.leg, t, q, dq, force_at, feet, F)

    def reset(self, ctx, t, q, dq, legs, stance_leg):
        return self.kind.reset(ctx, t, q, dq, legs, stance_leg)


def witness(name, leg) -> Witness:
    """The row of guard ``name`` on foot ``leg``."""
    return Witness(KINDS[name], leg)


def witnesses(stance_leg, armed, phases, mu) -> list[Witness]:
    """The witnesses of a mode, in :data:`KINDS`' order: in stance the armed swing foot's touchdown, the
    stance foot's liftoff and, with a friction coefficient, its slip; in flight each armed foot's
    touchdown."""
    return [Witness(kind, leg) for kind in KINDS.values() for leg in kind.legs(stance_leg, armed, phases, mu)]


def all_compiled() -> bool:
    """Whether the compiled loop decides every witness of the model (else the Python loop runs)."""
    return all(kind.compiled for kind in KINDS.values())
