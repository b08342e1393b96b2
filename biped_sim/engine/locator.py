"""The one event locator: the earliest guard crossing inside each accepted step, and the scuffs.

Under ``touchdown_rule="front"`` a swing foot that goes below the ground behind the stance foot
(straight legs without knees graze the ground near mid-stance) is not a touchdown: that is the
modelling assumption of the compass-gait literature (Drake's ``FootCollision`` guard too). Here it is
explicit and bounded (``guards.starts_scuff``, ``guards.passes_through``): under ``scuff_rule``
"forward" (the default) a foot passes through the ground while it moves forward, as a swinging leg
does, and one that comes down behind the stance foot without moving forward lands (the robot falls
back onto it); under "behind" every crossing behind the stance foot passes through. Each excursion is
a *scuff*, tracked from the down-crossing until the foot is above the ground again, reported as an
Event (kind ``scuff``: when, which foot, deepest dip); a scuff that stops passing through while under
the ground (it stops moving forward; under "behind": it reaches the front of the stance foot), or one
deeper than ``scuff_depth`` (no bound by default), stops the run (``SceneAssumptionError``: status
"stopped"). A down-crossing within ``front_tol`` of the stance foot's x counts as behind, so that
roundoff cannot decide it.
"""
from __future__ import annotations

import math

import numpy as np

from biped_sim.engine import guards as G, loop_rules as rules
from biped_sim.engine.grazing import chain_fields, dip_bracket
from biped_sim.engine.loop_state import (
    ARMED,
    DEEPEST_SCUFF,
    DEEPEST_TRIAL,
    FEET,
    FEET_END,
    FEET_END_T,
    FORCE_END,
    FORCE_END_T,
    N_LATCHED,
    RESULT,
    SCUFF,
    SCUFF_TRIAL,
    SCUFFING,
    SCUFFS,
    T_OLD,
    new_state,
    put,
)
from biped_sim.engine.model import BipedModel
from biped_sim.engine.results import Event, SceneAssumptionError
from biped_sim.engine.witnesses import triggered, witness, witnesses

_tuple_new = tuple.__new__     # a FootState from the state's four floats, without namedtuple's Python __new__


class EventLocator:
    """Finds the earliest guard crossing inside each accepted step, on the step's dense output.

    Owns the guards' discrete state: which feet are ``armed`` (a foot's touchdown guard counts only
    once it has been higher than ``arm_height``) and which guards are ``latched`` (a guard that just
    fired and was not reset, a slip with ``stop_on_slip=False``, stays off until it is positive at a
    step's end). The caller hands in, per step, the stepper ``st`` (``t_old``, ``t``, ``y_old``,
    ``dense_at``), ``to_phys(y) -> (q, dq, work)``, the state and feet at the step's end, and
    ``force_at(t, q, dq) -> [Fx, Fy]`` for the stance guards.

    The armed feet, the scuffs followed, and the feet and force kept of the last step's end are fields of the
    hybrid state ``S`` (loop_state.py: the simulator's, which the compiled loop reads and writes too).
    """

    def __init__(self, model, ground, opt, mu, feet, stance_leg, impacts, S=None, t0=0.0):
        self.model, self.ground, self.opt, self.mu = model, ground, opt, mu
        self.S = new_state() if S is None else S
        self.impacts = impacts   # the run's ImpactHistory: a crossing in the Zeno limit is an impact
        self._chains = chain_fields(model)     # the feet's chains, the dip bound's (grazing.py)
        self._fixed_chains = not isinstance(model, BipedModel)    # a described robot's fixed base: both chains
        # at the start no reset has just happened, so a free foot above the ground, however little,
        # is armed at once: its crossing is found (a foot on it arms when it rises above arm_height)
        for leg in (1, 2):
            self.S[ARMED + leg - 1] = float(leg != stance_leg and feet[leg - 1].height > 0.0)
            self.S[SCUFFING + leg - 1] = 0.0
        self.latched: set = set()       # (how many: the state's n_latched, which the compiled loop reads)
        self.S[N_LATCHED] = 0.0
        self.scuffs = 0          # touchdowns behind the stance foot ignored under touchdown_rule "front"
        self.deepest_scuff = 0.0  # m, the deepest dip of any scuff so far
        self.scuff_events: list = []    # finished scuffs, for the simulator to report
        leg = G.start_scuffing(feet, stance_leg, opt)
        if leg:
            # a start the start check accepted because the foot's crossing would be a scuff: a scuff under way
            rules.ev_scuff_under_way(self.S, leg, t0, -feet[leg - 1].height)
        self._feet_end = self._force_end = (None, None)   # (t, value) at the last step's end
        # the state the scuffs are followed on (loop_rules.ev_track_scuff): the scuff options
        self._scuff_state = new_state(front_tol=opt.front_tol, scuff_depth=opt.scuff_depth,
                                      forward_rule=float(opt.scuff_rule == "forward"))

    @property
    def armed(self):
        """[foot 1, foot 2]: whether a foot's touchdown counts (it has been higher than arm_height)."""
        return [self.S[ARMED] != 0.0, self.S[ARMED + 1] != 0.0]

    def _set_armed(self, leg, value):
        self.S[ARMED + leg - 1] = float(value)

    @property
    def active_scuffs(self):
        """{leg: [t_start, deepest, t_deepest]} of the feet in a scuff (under the ground, passing through)."""
        S = self.S
        return {leg: list(S[SCUFF + 3 * (leg - 1):SCUFF + 3 * leg]) for leg in (1, 2) if S[SCUFFING + leg - 1]}

    def scuffing_legs(self):
        """The feet in a scuff, as a tuple (what an invariant's check asks, every step)."""
        S = self.S
        return (1,) * (S[SCUFFING] != 0.0) + (2,) * (S[SCUFFING + 1] != 0.0)

    scuffs = property(lambda self: int(self.S[SCUFFS]), lambda self, v: self.S.__setitem__(SCUFFS, v),
                      doc="touchdowns behind the stance foot ignored under touchdown_rule 'front'")
    deepest_scuff = property(lambda self: self.S[DEEPEST_SCUFF], lambda self, v: self.S.__setitem__(DEEPEST_SCUFF, v),
                             doc="the deepest dip of any scuff so far (m)")

    @property
    def _feet_end(self):
        # (t, (foot 1, foot 2)) kept of the last step's end, or (None, None)
        S = self.S
        t = S[FEET_END_T]
        if t != t:
            return None, None
        return t, (_tuple_new(G.FootState, S[FEET_END:FEET_END + 4]),
                   _tuple_new(G.FootState, S[FEET_END + 4:FEET_END + 8]))

    @_feet_end.setter
    def _feet_end(self, value):
        t, feet = value
        if t is None:
            rules.ev_forget_feet_end(self.S)
        else:
            rules.ev_keep_feet_end(self.S, t, [*feet[0], *feet[1]], 0)

    @property
    def _force_end(self):
        # (t, [Fx, Fy]) kept of the last step's end, or (None, None)
        S = self.S
        t = S[FORCE_END_T]
        return (None, None) if t != t else (t, [S[FORCE_END], S[FORCE_END + 1]])

    @_force_end.setter
    def _force_end(self, value):
        t, F = value
        if t is None:
            rules.ev_forget_force_end(self.S)
        else:
            rules.ev_keep_force_end(self.S, t, F[0], F[1])

    def latch(self, guard):
        """Hold ``guard`` off until it is positive at a step's end (a guard that fired and was not reset)."""
        self.latched.add(guard)
        self.S[N_LATCHED] = len(self.latched)

    def python_only(self):
        """Whether the locator holds what only the Python loop follows: a latched guard, or two scuffs."""
        return bool(self.latched) or len(self.active_scuffs) > 1

    def witnesses(self, stance_leg):
        """The witnesses of the mode (:func:`~biped_sim.engine.witnesses.witnesses`) with the feet armed now."""
        return witnesses(stance_leg, self.armed, self.opt.phases, self.mu)

    def after_reset(self, event):
        """Disarm the feet the reset put on the ground (or that just left it); forget the feet and force
        kept of the last step's end: the reset changed the state they were computed from."""
        self._feet_end = self._force_end = (None, None)
        for leg in self.active_scuffs:
            # a liftoff with the other foot still under the ground in a scuff: no mode of the model has
            # a free foot below the ground
            raise SceneAssumptionError(
                f"the stance foot (leg {event.stance_leg_before}) {event.kind} at t={event.time:.9g} s while foot "
                f"{leg} is still below the ground, passing through it (a scuff since "
                f"t={self.active_scuffs[leg][0]:.9g} s): the model has no contact there")
        for leg in (1, 2):
            if rules.ev_disarmed_by_reset(leg, event.kind == "double_touchdown", event.stance_leg_before or 0,
                                          event.stance_leg_after or 0):
                self._set_armed(leg, False)

    def restart(self, t, feet, F):
        """The state changed at ``t`` without a step (a push): the next step starts from it, whose feet
        and stance force (under the torque held until then) are these, not the last step end's."""
        self._feet_end, self._force_end = (t, feet), (t, F)

    def locate(self, st, to_phys, stance_leg, q1, dq1, feet1, force_at, F_end=None):
        """((time, witness, legs) of the earliest crossing, or None; the force at the step's end).

        ``F_end``: the stance force at the step's end if the caller has it (the stepper's last
        evaluation), else it is computed here."""
        rows = self.witnesses(stance_leg)
        t_old, t = st.t_old, st.t       # (read once: a stepper's fields are the state's, behind properties)
        if not rows and not self._resting_feet(stance_leg):
            self._arm(feet1, stance_leg)
            # the step's end is the next step's start: what is kept of the step before is no longer its state
            self._feet_end, self._force_end = (t, feet1), (None, None)
            return None, None
        # the step's start is the last step's end: its feet and force are known (the projection
        # since moved the state by the drift only, ~1e-14)
        S = self.S
        q0 = dq0 = None
        if rules.ev_feet_kept_at(S, t_old):
            feet0 = (_tuple_new(G.FootState, S[FEET_END:FEET_END + 4]),
                     _tuple_new(G.FootState, S[FEET_END + 4:FEET_END + 8]))
        else:
            q0, dq0, _ = to_phys(st.y_old)
            feet0 = G.foot_states(self.model, q0, dq0, self.ground.tan)
        rules.ev_keep_feet_end(S, t, [*feet1[0], *feet1[1]], 0)
        F0 = F1 = None
        if stance_leg:
            if rules.ev_force_kept_at(S, t_old):
                F0 = [S[FORCE_END], S[FORCE_END + 1]]
            else:
                if q0 is None:
                    q0, dq0, _ = to_phys(st.y_old)
                F0 = force_at(t_old, q0, dq0)
            F1 = F_end if F_end is not None else force_at(t, q1, dq1)
            rules.ev_keep_force_end(S, t, F1[0], F1[1])
        if q0 is None and any(w.kind.reads == "state" for w in rows):
            q0, dq0, _ = to_phys(st.y_old)
        roots = []
        for guard in rows:
            g1 = guard.value(self, t, q1, dq1, force_at, feet1, F1)
            if guard in self.latched:
                if g1 > 0:
                    self.latched.discard(guard)
                    self.S[N_LATCHED] = len(self.latched)
                continue
            g0 = guard.value(self, t_old, q0, dq0, force_at, feet0, F0)
            guard_at = self._on_dense_output(st, to_phys, guard, force_at)
            bracket = None
            if triggered(g0, g1, guard.direction):
                bracket = (t_old, t)
            elif guard.name == "touchdown" and g0 > 0 and g1 > 0:
                # both ends above the ground: a dip in between is found with its guarantee
                bracket = dip_bracket(st, to_phys, guard_at, guard.leg, stance_leg, self.opt.base == "fixed",
                                      self._chains, self.ground.tan, g0, g1, self.opt.graze_tol,
                                      fixed_chains=self._fixed_chains)
            if bracket is None:
                continue
            t_root = self._crossing(st, guard, guard_at, bracket)
            if not self._is_scuff(st, to_phys, guard, stance_leg, t_root):
                roots.append((t_root, guard))
        for leg in self._resting_feet(stance_leg):
            # a free foot on the ground that is not armed (it just lifted off, or started there at rest)
            # and that the dynamics push into it, deeper than ground_tol at the step's end or inside the step:
            # a touchdown from where it rests, not a crossing
            guard = witness("touchdown", leg)
            guard_at = self._on_dense_output(st, to_phys, guard, force_at)
            if rules.ev_violated(feet1[leg - 1].height, self.opt.ground_tol):
                t_below = t
            else:
                t_below = self._resting_foot_dips(st, to_phys, guard_at, leg, stance_leg, feet0[leg - 1].height,
                                                  feet1[leg - 1].height)
                if t_below is None:
                    continue
            t_root = self._crossing(st, guard, guard_at, landing_bracket(guard_at, t_old, t_below))
            if not self._is_scuff(st, to_phys, guard, stance_leg, t_root):
                roots.append((t_root, guard))
        t_end = min(roots)[0] if roots else t
        if self.S[SCUFFING] or self.S[SCUFFING + 1]:
            self._track_scuffs(st, to_phys, stance_leg, t_end)
        if not roots:
            self._arm(feet1, stance_leg)
            return None, F1
        roots.sort()
        t_first, guard = roots[0]
        legs = [guard.leg]
        if guard.name == "touchdown" and not stance_leg:
            legs += [g.leg for t, g in roots[1:] if g.name == "touchdown" and t - t_first <= self.opt.simultaneous_tol]
            other = G.other_foot(self.model, guard.leg)
            if len(legs) == 1 and self.armed[other - 1]:
                # the other foot may be within the tolerance without having crossed yet
                fo = self._feet_at(st, to_phys, t_first)[other - 1]
                if fo.dheight < 0 and fo.height <= -fo.dheight * self.opt.simultaneous_tol:
                    legs.append(other)
        return (t_first, guard, sorted(set(legs))), F1

    def _crossing(self, st, guard, guard_at, bracket):
        """The guard's crossing in the bracket (``guards.locate_crossing``); a touchdown's by the compiled
        loop's stepper where it has one (the same algorithm on the same values)."""
        crossing = getattr(st, "height_crossing", None) if guard.name == "touchdown" else None
        t_root = crossing(guard.leg, *bracket) if crossing is not None else None
        return t_root if t_root is not None else G.locate_crossing(guard_at, *bracket, self.opt.event_tol)

    def _on_dense_output(self, st, to_phys, guard, force_at):
        """The guard as a function of time along the last step's dense output (for root finding)."""
        def guard_at(t):
            q, dq, _ = to_phys(st.dense_at(t))
            return guard.value(self, t, q, dq, force_at)
        return guard_at

    def _is_scuff(self, st, to_phys, guard, stance_leg, t_root):
        """Under touchdown_rule "front", a crossing that passes through the ground (``guards.starts_scuff``)
        is a scuff: start following it."""
        if guard.name != "touchdown" or not stance_leg or self.opt.touchdown_rule != "front":
            return False
        fr = self._feet_at(st, to_phys, t_root)
        if not G.starts_scuff(fr[guard.leg - 1], fr[stance_leg - 1], self.opt) or self.impacts.accumulating(t_root):
            return False
        S, leg = self.S, guard.leg
        S[SCUFFING + leg - 1] = 1.0
        self.scuffs = rules.ev_start_scuff(S, SCUFF + 3 * (leg - 1), t_root, self.scuffs)
        return True

    def _resting_feet(self, stance_leg):
        """The free feet whose touchdown no witness watches: not armed (on the ground: it just lifted off, or
        started there at rest) and not in a scuff; with an impact phase."""
        if "impact" not in self.opt.phases:
            return []
        S = self.S
        return [leg for leg in (1, 2) if leg != stance_leg and not S[ARMED + leg - 1] and not S[SCUFFING + leg - 1]]

    def _resting_foot_dips(self, st, to_phys, height_at, leg, stance_leg, h0, h1):
        """A time in the last step where the resting foot ``leg`` (heights h0, h1 at the step's ends, not below
        -ground_tol) is deeper than ground_tol under the ground, or None: the dip search of its height plus
        ground_tol (the rule ``loop_rules.ev_resting_foot_dips``, which _core.c's quiet step applies)."""
        tol = self.opt.ground_tol
        if not rules.ev_may_sink_in_step(h0, h1, tol):
            return None
        bracket = dip_bracket(st, to_phys, lambda t: height_at(t) + tol, leg, stance_leg, self.opt.base == "fixed",
                              self._chains, self.ground.tan, h0 + tol, h1 + tol, self.opt.graze_tol,
                              fixed_chains=self._fixed_chains)
        return None if bracket is None else bracket[1]

    def _track_scuffs(self, st, to_phys, stance_leg, t_end):
        """Follow each scuffing foot over the step up to ``t_end`` (the rule ``loop_rules.ev_track_scuff``):
        its deepest dip (on 9 points of the dense output), the end of the scuff when it is above the ground
        again, and the two ways a scuff leaves the model (it stops passing through under the ground; deeper
        than scuff_depth), which stop the run here."""
        S = self._scuff_state
        for leg, scuff in list(self.active_scuffs.items()):
            S[T_OLD] = st.t_old
            S[SCUFF_TRIAL:SCUFF_TRIAL + 3] = scuff
            S[DEEPEST_TRIAL] = self.deepest_scuff
            outcome = rules.ev_track_scuff(S, _feet_into_state, (self, st, to_phys), leg, stance_leg, t_end)
            scuff[:] = S[SCUFF_TRIAL:SCUFF_TRIAL + 3]
            put(self.S, SCUFF + 3 * (leg - 1), scuff)
            if outcome == -1:
                t, depth, foot = S[RESULT], S[RESULT + 1], G.FootState(*S[FEET + 4 * (leg - 1):FEET + 4 * leg])
                raise SceneAssumptionError(scuff_left_model(leg, scuff[0], depth, t, foot, self.opt.scuff_rule))
            self.deepest_scuff = S[DEEPEST_TRIAL]
            if outcome == -2:
                raise SceneAssumptionError(
                    f"foot {leg} went {scuff[1]:.3g} m below the ground behind the stance foot (leg {stance_leg}) "
                    f"at t={scuff[2]:.9g} s, deeper than scuff_depth={self.opt.scuff_depth:g} m: the robot is "
                    "falling onto that foot, which the model (touchdown_rule='front') does not let touch down "
                    "(a larger scuff_depth, or inf, lets deeper scuffs pass)")
            if outcome == 1:     # the foot is above the ground at t_end
                self.S[SCUFFING + leg - 1] = 0.0
                self.scuff_events.append(self._scuff_event(st, to_phys, leg, stance_leg, scuff, t_end))

    def _scuff_event(self, st, to_phys, leg, stance_leg, scuff, t_up):
        t_deep = scuff[2]
        q, dq, _ = to_phys(st.dense_at(t_deep)) if rules.ev_within_step(st.t_old, st.t, t_deep) else (None, None, None)
        return scuff_event(leg, stance_leg, scuff, t_up, q, dq, self.opt.scuff_depth, self.opt.scuff_rule,
                           self.model.n)

    def _feet_at(self, st, to_phys, t):
        q, dq, _ = to_phys(st.dense_at(t))
        return G.foot_states(self.model, q, dq, self.ground.tan)

    def _arm(self, feet, stance_leg):
        S = self.S
        for leg in (1, 2):
            if not S[ARMED + leg - 1] and rules.ev_arms(leg != stance_leg, feet[leg - 1].height, self.opt.arm_height):
                S[ARMED + leg - 1] = 1.0


def landing_bracket(height_at, t_old, t, n=16):
    """Where a free foot that rested on the ground at the step's start and is under it at its end lands:
    a touchdown needs the foot moving down, so where it rose above the ground inside the step (it lifted
    off and comes back) the bracket ends at the last down-crossing of ``height_at`` seen on n + 1 even
    points and on points closing in on the start geometrically (a hop shorter than the step's 1/n); else
    the step's start (the dynamics push the resting foot in from there)."""
    dt = t - t_old
    ts = sorted(set(np.linspace(t_old, t, n + 1).tolist() + [t_old + dt * 0.5 ** k for k in range(1, 53)]))
    ts = [tk for tk in ts if t_old < tk < t] + [t]
    above = [k for k, tk in enumerate(ts[:-1]) if height_at(tk) > 0.0]
    return (ts[above[-1]], ts[above[-1] + 1]) if above else (t_old, t)


def _feet_into_state(S, ctx, t):
    """The feet on the dense output at t into S[FEET], as the rules call feet_at(S, ctx, t): ctx is (the
    locator, the stepper, to_phys)."""
    locator, st, to_phys = ctx
    foot1, foot2 = locator._feet_at(st, to_phys, t)
    S[FEET:FEET + 8] = [*foot1, *foot2]


def scuff_left_model(leg, t_start, depth, t, foot, scuff_rule) -> str:
    """The message of a scuff that stops passing through the ground while the foot (a FootState) is under it."""
    if scuff_rule == "forward":
        return (f"foot {leg} went below the ground behind the stance foot at t={t_start:.9g} s swinging forward (a "
                f"scuff) and at t={t:.9g} s, {depth:.3g} m below the ground, no longer swings through (it moves at "
                f"{foot.dx:.3g} m/s forward, {foot.dheight:.3g} m/s up): the robot is falling onto that foot, which "
                "cannot touch down under the ground (scuff_rule='forward': a foot passes through the ground only while "
                "it moves forward more than it sinks; scuff_rule='behind' lets every foot behind the stance foot pass, "
                "touchdown_rule='any' makes every crossing a touchdown)")
    return (f"foot {leg} went below the ground behind the stance foot at t={t_start:.9g} s and is {depth:.3g} m below "
            f"it in front of the stance foot at t={t:.9g} s: a touchdown there cannot be placed (scuff_rule='behind': "
            "a foot passes through the ground only behind the stance foot; scuff_rule='forward' lets a foot moving "
            "forward pass, touchdown_rule='any' makes every crossing a touchdown)")


def scuff_event(leg, stance_leg, scuff, t_up, q, dq, scuff_depth, scuff_rule, n=5) -> Event:
    """The Event of a scuff of foot ``leg`` that ended at ``t_up`` (``scuff``: [t_start, deepest,
    t_deepest]; q, dq: the state at t_deepest, or None when it is not inside the last step; n coordinates)."""
    t_start, depth, t_deep = scuff
    q = np.array(q) if q is not None else np.full(n, np.nan)
    dq = np.array(dq) if dq is not None else np.full(n, np.nan)
    return Event(t_start, "scuff", leg, q, dq, dq.copy(), None, stance_leg, stance_leg,
                 message=f"foot {leg} scuffed the ground behind the stance foot from t={t_start:.9g} s to "
                         f"t={t_up:.9g} s, {depth:.3g} m deep at t={t_deep:.9g} s (the assumption of "
                         f"touchdown_rule='front', scuff_rule='{scuff_rule}'"
                         + (f"; bounded by scuff_depth={scuff_depth:g} m)" if math.isfinite(scuff_depth) else ")"))
