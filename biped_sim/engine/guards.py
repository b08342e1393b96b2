"""The guards (witness functions) of the hybrid system, and how a crossing is located.

(``witnesses.py`` makes each guard one row: its value from here, its direction, its reset.)

A guard is a scalar function of the state that is positive while the current mode holds; the mode
ends where it crosses zero going down (every guard here has that one direction, as Drake's witness
functions ``FootCollision`` and the liftoff witness do):

* ``touchdown_guard``: the swing foot's height above the ground (docs/model.md "Impact"); armed only once
  the foot has been above the ground by more than ``arm_height``, so that the guard, zero right after
  its own reset, cannot fire again at once;
* ``liftoff_guard``: the normal component of the ground force on the stance foot (the KKT force of
  "Stance"); its crossing ends stance (flight follows where the scene has it);
* ``slip_guard``: ``mu F_n - |F_t|``, the margin inside the friction cone (only with ``mu`` given).

The event locator (``locator.py``) brackets a crossing between a step's two ends (or, for touchdown,
a dip inside the step, found with a guarantee by ``grazing.py``) and finds its time on the
integrator's dense output with ``brentq``, to ``event_tol`` seconds.

Feet travel as :class:`FootState` pairs (x, height above the sloped ground, and their rates).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from biped_sim.engine import loop_rules as rules
from biped_sim.engine.compiled import gen
from biped_sim.engine.loop_state import RESULT, new_state
from biped_sim.engine.model import BipedModel


class FootState(NamedTuple):
    """One foot: world x (m), height above the (sloped) ground (m), and their rates (m/s)."""
    x: float
    height: float
    dx: float
    dheight: float


def foot_states(model, q, dq, tan_slope=0.0) -> tuple[FootState, FootState]:
    """(foot 1, foot 2) at the physical state (lists q, dq); heights measured across the slope."""
    ft = [0.0] * 8
    if type(model) is BipedModel or isinstance(model, BipedModel):
        kinematics = gen.foot_kinematics(q, dq, model.k["foot_kinematics"])
    else:       # a described robot's kernel, the same layout
        kinematics = model.k_foot_kinematics(q, dq)
    rules.ev_foot_states(kinematics, 0, tan_slope, ft, 0)
    return FootState._make(ft[:4]), FootState._make(ft[4:])


def foot_xy(model, q, leg):
    """(x, y) of foot ``leg`` (1 or 2) at the configuration q (a list)."""
    point = [0.0, 0.0]
    if type(model) is BipedModel or isinstance(model, BipedModel):
        positions = gen.foot_positions(q, model.k["foot_positions"])
    else:
        positions = model.k_foot_positions(q)
    rules.ev_foot_point(positions, leg, point)
    return point[0], point[1]


def other_foot(model, leg) -> int:
    """The other foot of a biped: foot ``leg``'s mirror image (a described robot's ``contact_mirror``), 3 - leg
    for the three-link biped."""
    mirror = getattr(model, "contact_mirror", None)
    return 3 - leg if mirror is None else mirror[leg - 1] + 1


def foot_height(model, q, leg, tan_slope=0.0) -> float:
    """Height of foot ``leg`` above the ground: the touchdown guard from q alone (root finding)."""
    x, y = foot_xy(model, q, leg)
    return rules.ev_across(tan_slope, x, y)


class Ground(NamedTuple):
    """The ground line through the origin at angle ``slope`` (rad; positive: it falls in +x)."""
    slope: float
    sin: float
    cos: float
    tan: float

    @classmethod
    def of(cls, slope: float) -> "Ground":
        return cls(slope, math.sin(slope), math.cos(slope), math.tan(slope))


def normal_tangent(F, ground: Ground):
    """(normal, tangential) components of a ground force or impulse [Fx, Fy] on the ground line."""
    s, c = ground.sin, ground.cos
    return rules.ev_normal(s, c, F[0], F[1]), rules.ev_tangential(s, c, F[0], F[1])


# -- the guards: positive while the mode holds, an event where they cross zero going down --------
def touchdown_guard(feet, leg) -> float:
    """Swing foot ``leg``'s height above the ground."""
    return feet[leg - 1].height


def liftoff_guard(normal, tangential) -> float:
    """The normal ground force on the stance foot (N)."""
    return normal


def slip_guard(normal, tangential, mu) -> float:
    """The friction-cone margin mu F_n - |F_t| (N): the rule ``loop_rules.ev_slip_margin``."""
    return rules.ev_slip_margin(mu, normal, tangential)


# -- the scuff assumption of touchdown_rule "front" --------------------------------------------------
def swinging_through(foot: FootState) -> bool:
    """A foot moving forward more than it sinks (a crossing at most 45 degrees steep): a leg swinging
    through near the bottom of its arc, not a robot falling onto its foot (which moves backward, or
    down). The rule ``loop_rules.ev_swinging_through``."""
    return rules.ev_swinging_through(foot.dx, foot.dheight)


def starts_scuff(swing: FootState, stance: FootState, opt) -> bool:
    """Whether the swing foot, crossing the ground going down here, passes through it (a scuff) rather
    than touching down: at or behind the stance foot (within ``front_tol`` counts as behind), and under
    ``scuff_rule`` "forward" swinging through (``swinging_through``; a foot that comes down behind
    otherwise is the robot falling back onto it, and lands)."""
    return rules.ev_starts_scuff(opt.scuff_rule == "forward", opt.front_tol, swing.x, swing.dx, swing.dheight,
                                 stance.x)


def passes_through(swing: FootState, stance: FootState, opt) -> bool:
    """Whether a swing foot under the ground still passes through it, as a scuff under way: under
    ``scuff_rule`` "forward" while it swings through (wherever it is), under "behind" while it is behind
    the stance foot."""
    return rules.ev_passes_through(opt.scuff_rule == "forward", opt.front_tol, swing.x, swing.dx, swing.dheight,
                                   stance.x)


# -- locating a crossing -----------------------------------------------------------------------
def _guard(S, guard_at, t):
    """A Python function of t as the rules call a guard: g(S, ctx, t), ctx the function."""
    return guard_at(t)


def locate_crossing(guard_at, ta, tb, event_tol) -> float:
    """The time in [ta, tb] where ``guard_at`` (positive at ta, <= 0 at tb) crosses zero, to
    ``event_tol`` seconds (an end of the bracket where the guard is already zero there): the rule
    ``loop_rules.ev_locate_crossing`` (scipy's brentq, the same iterates), which the compiled loop runs
    compiled. Where brentq gives up (no sign change, a NaN, no convergence) scipy's raises its error."""
    S = new_state(event_tol=event_tol)
    if rules.ev_locate_crossing(S, _guard, guard_at, ta, tb) == 0:
        return float(S[RESULT])
    from scipy.optimize import brentq  # here: its import (~0.4 s) is paid by a run whose root finder gives up
    return brentq(guard_at, ta, tb, xtol=event_tol, rtol=4 * np.finfo(float).eps, maxiter=200)


# -- the ground as a constraint on states ----------------------------------------------------------
def prepare_event_location():
    """Import the root finder now (``locate_crossing`` imports it where it is used, a slow import): a
    realtime run must not stall at its first event for it."""
    import scipy.optimize  # noqa: F401


def start_scuffing(feet, stance_leg, opt):
    """The free foot of a stance start that lies deeper than ``ground_tol`` under the ground where its crossing would
    be a scuff (``touchdown_rule`` "front" with an impact phase, ``starts_scuff``), else 0: the start check lets it
    lie down to ``scuff_depth``, and the run follows it from its first instant as a scuff under way
    (``loop_rules.ev_scuff_under_way``), by the rules of any scuff."""
    if not stance_leg or "impact" not in opt.phases:
        return 0
    leg = 3 - stance_leg
    swing = feet[leg - 1]
    if not rules.ev_violated(swing.height, opt.ground_tol) or not _passes_at_start(swing, feet[stance_leg - 1], opt):
        return 0
    return leg


def _passes_at_start(swing: FootState, stance: FootState, opt) -> bool:
    # the start check's allowance: a swing foot whose crossing would be a scuff
    return opt.touchdown_rule == "front" and starts_scuff(swing, stance, opt)


def check_initial_contact(feet, stance_leg, opt):
    """A ValueError unless the initial state agrees with its mode: in stance, the stance foot on the
    ground within ``contact_tol`` and at rest, and the swing foot not below it; in flight, both feet
    not below it; and no free foot on the ground moving into it (that is an impact still to apply, not
    a state to start from). "Not below" is the invariant's own bound, ``ground_tol``, with the run's
    one allowance: a swing foot whose crossing would be a scuff (``touchdown_rule`` "front", ``starts_scuff``) may be
    up to ``scuff_depth`` below (with an impact phase the run follows it as a scuff: ``start_scuffing``). A start
    the check of every sample would reject is refused here, before it can end "completed" with its first sample
    wrong."""
    tol = opt.contact_tol
    if stance_leg:
        f = feet[stance_leg - 1]
        if abs(f.height) > tol:
            raise ValueError(f"initial state: the stance foot (leg {stance_leg}) is {f.height:.6g} m "
                             f"above the ground (tolerance {tol:g} m); place the hip so that the foot is on "
                             "the ground (biped_sim.stance_state does this)")
        if math.hypot(f.dx, f.dheight) > tol:
            raise ValueError(f"initial state: the stance foot (leg {stance_leg}) moves at "
                             f"({f.dx:.6g}, {f.dheight:.6g}) m/s; it must be at rest (J dq = 0; "
                             "biped_sim.stance_state gives a consistent dq)")
        swing = feet[2 - stance_leg]
        scuff = _passes_at_start(swing, f, opt)
        if swing.height < -(opt.scuff_depth if scuff else opt.ground_tol):
            raise ValueError(
                f"initial state: the swing foot (leg {3 - stance_leg}) is {-swing.height:.6g} m below the ground "
                + (f"passing through it (scuff_depth {opt.scuff_depth:g} m)" if scuff else
                   f"(ground_tol {opt.ground_tol:g} m; it passes through only behind the stance foot" + (
                       " moving forward, scuff_rule 'forward')" if opt.scuff_rule == "forward" else
                       ", scuff_rule 'behind')")) + "; raise the hip or the foot")
    else:
        for leg in (1, 2):
            if rules.ev_violated(feet[leg - 1].height, opt.ground_tol):
                raise ValueError(f"initial state in flight: foot {leg} is {-feet[leg - 1].height:.6g} m below the "
                                 f"ground (ground_tol {opt.ground_tol:g} m); raise the hip")
    for leg in (1, 2):
        f = feet[leg - 1]
        if leg != stance_leg and f.height <= 0.0 and f.dheight < -tol:
            raise ValueError(
                f"initial state: the contact of foot {leg} is ambiguous: it is on the ground ({f.height:.3g} m) and "
                f"moving into it at {f.dheight:.3g} m/s, an impact that has not been applied; start from the state "
                "after the impact (biped_sim.impact_map), or with the foot above the ground")
