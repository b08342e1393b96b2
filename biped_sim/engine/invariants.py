"""The invariants of a correct run, checked after every accepted step and every reset.

A run that ends "completed" has all of these true at every sample (docs/engine.md, "What a correct
run is"); a violated one is a bug or an edge the model does not cover, and the run stops with
status "failed" (``InvariantViolation``), saying which invariant, when and by how much:

* the state is finite;
* every foot is at or above the ground (``ground_tol``); the one stated exception is a scuff of
  ``touchdown_rule="front"`` (a foot passing through the ground, ``scuff_rule``; ``locator.py``);
* in stance, the ground pushes (normal force >= -``force_tol``) and, with a friction coefficient and
  ``stop_on_slip``, the force is inside the friction cone;
* an impact pushes (every normal impulse >= -``impulse_tol``) and leaves every foot that stays on the ground at rest
  or moving up: the old stance foot must leave the ground (an impact after which it does not is the
  limit of impacts that accumulate: a ``zeno`` stop where the last gaps shrank, else a violation).

Scene assumptions that are not invariants (no impact or flight phase where one is needed) stop the
run with status "stopped" (``SceneAssumptionError``) instead.
"""
from __future__ import annotations

from biped_sim.engine import loop_rules as rules
from biped_sim.engine.guards import normal_tangent, starts_scuff
from biped_sim.engine.loop_state import new_state
from biped_sim.engine.results import SceneAssumptionError, SimulationError


class InvariantViolation(SimulationError):
    """An invariant of a correct run does not hold: the run ends "failed"."""


def check_sample(t, q, dq, feet, stance_leg, F, ground, mu, opt, scuffing, last_impact):
    """The invariants of an accepted sample (lists q, dq; ``scuffing``: the legs under the ground
    in a scuff)."""
    if not rules.ev_finite_state(q, dq, len(q)):
        raise InvariantViolation(f"invariant 'finite state' violated at t={t:.9g} s: q={q}, dq={dq}")
    for leg in (1, 2):
        f = feet[leg - 1]
        if leg == stance_leg or leg in scuffing or not rules.ev_violated(f.height, opt.ground_tol):
            continue
        if "impact" not in opt.phases:
            # no touchdown guard is built: the scene, not the run, is at fault; where a crossing would be a
            # scuff of touchdown_rule "front", it is one, bounded the same way
            scuff = stance_leg and opt.touchdown_rule == "front" and starts_scuff(f, feet[stance_leg - 1], opt)
            if scuff and -f.height <= opt.scuff_depth:
                continue
            raise SceneAssumptionError(
                f"foot {leg} touches the ground at t={t:.9g} s (it is {-f.height:.3g} m below at the end of the "
                "step" + (f", passing through it: deeper than scuff_depth={opt.scuff_depth:g} m" if scuff else "")
                + "), but this scene has no impact phase: add 'impact' to its phases")
        why = ""
        if last_impact is not None and last_impact.kind == "double_touchdown":
            why = (f" after the double touchdown at t={last_impact.time:.9g} s: double support is not modelled "
                   f"(the run continued on foot {last_impact.leg} only)")
        raise InvariantViolation(
            f"invariant 'feet at or above the ground' violated: foot {leg} is {-f.height:.3g} m below the ground "
            f"at t={t:.9g} s (tolerance ground_tol={opt.ground_tol:g} m){why}")
    if stance_leg:
        n, tg = normal_tangent(F, ground)
        if rules.ev_violated(n, opt.force_tol):
            raise InvariantViolation(
                f"invariant 'the ground pushes' violated: the normal force on the stance foot (leg {stance_leg}) "
                f"is {n:.6g} N at t={t:.9g} s (a liftoff was not found)")
        if mu is not None and opt.stop_on_slip and rules.ev_violated(rules.ev_slip_margin(mu, n, tg), opt.force_tol):
            raise InvariantViolation(
                f"invariant 'inside the friction cone' violated at t={t:.9g} s: |F_t| = {abs(tg):.6g} N > "
                f"mu F_n = {mu * n:.6g} N (a slip was not found)")


def check_impact(event, feet_after, ground, recent_gaps, impulse_tol, rest_tol):
    """The invariants of an impact (``feet_after``: at the state after it). Returns the message of a
    Zeno stop, or None; raises InvariantViolation otherwise. The old stance foot must leave the
    ground faster than ``rest_tol`` (m/s): at rest on it, both feet are on the ground."""
    landing = [1, 2] if event.kind == "double_touchdown" else [event.leg]
    for j, leg in enumerate(landing):
        n = normal_tangent(event.impulse[2 * j: 2 * j + 2], ground)[0]
        if rules.ev_violated(n, impulse_tol):
            raise InvariantViolation(
                f"invariant 'an impact pushes' violated at t={event.time:.9g} s: the ground's impulse on foot {leg} "
                f"pulls it ({n:.6g} N s normal): a plastic impact there is not physical")
    old = event.stance_leg_before
    if old and old not in landing and rules.ev_stays_down(feet_after[old - 1].dheight, rest_tol):
        v = feet_after[old - 1].dheight
        if len(recent_gaps) >= 3 and all(b < a for a, b in zip(recent_gaps, recent_gaps[1:])):
            return (f"the impacts accumulate (Zeno behaviour): the gaps between the last impacts shrink "
                    f"({', '.join(f'{g:.3g}' for g in recent_gaps[-4:])} s) and after the impact at "
                    f"t={event.time:.9g} s the old stance foot (leg {old}) no longer leaves the ground ({v:.3g} m/s): "
                    "both feet stay on the ground (double support, the Zeno limit), which the model does not cover")
        raise InvariantViolation(
            f"invariant 'the old stance foot leaves the ground' violated at the impact of t={event.time:.9g} s: "
            f"foot {old} {'moves into the ground' if v < 0 else 'stays on the ground'} ({v:.3g} m/s) after it, so "
            "both feet stay in contact: double support is not modelled")
    return None


class ImpactHistory:
    """The times of the last impacts: ``zeno_count`` impacts in a row closer than ``zeno_interval``
    are a Zeno stop (``record`` returns its message), and the gaps feed ``check_impact``.

    The times are kept here (up to ``zeno_count`` + 1 of them: no fixed field holds that many); what the
    compiled loop checks a touchdown against, the last impact and the last four, is the hybrid state's
    (``last_impact``, ``n_impacts``, ``recent_impacts``, ``n_recent``), which ``record`` writes and a
    touchdown the loop applies writes itself."""

    def __init__(self, zeno_count, zeno_interval, S=None):
        self.count, self.interval = zeno_count, zeno_interval
        self.times: list[float] = []
        self.S = new_state() if S is None else S

    def record(self, t, in_state=True):
        """Record an impact at t (``in_state`` False: one the compiled loop applied, which the state holds
        already); the message of a Zeno stop, or None."""
        self.times.append(t)
        if in_state:
            rules.ev_count_impact(self.S, t)
        if len(self.times) > max(self.count + 1, 5):
            del self.times[0]
        last = self.times[-(self.count + 1):]
        # (each gap's later impact has one before it at least)
        if len(last) == self.count + 1 and all(rules.ev_impacts_close(1, a, b, self.interval)
                                               for a, b in zip(last, last[1:])):
            return (f"{self.count} impacts in a row less than {self.interval:g} s apart ending at t={t:.9g} s: "
                    "the impacts accumulate (Zeno behaviour); the run stops")
        return None

    def gaps(self):
        return [b - a for a, b in zip(self.times, self.times[1:])]

    def accumulating(self, t):
        """Whether a crossing at t continues a run of impacts that accumulate: the last three gaps shrink,
        the last to at most half the first (a walk's steps settle far more slowly), and t comes sooner
        than the last gap. That is the Zeno limit, where a foot comes back to the ground at vanishing
        speed: such a crossing is an impact (whose check says Zeno), never a scuff: the rule
        ``loop_rules.ev_accumulating``, which _core.c's quiet step calls too."""
        recent = self.times[-4:]
        return rules.ev_accumulating(recent, len(recent), t)
