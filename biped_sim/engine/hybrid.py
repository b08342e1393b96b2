"""The hybrid simulation: integrate a mode, locate its guards, apply the reset, and keep the run.

Owns the hybrid system of docs/model.md "Phases" (stance on leg 1 or 2, impact with relabeling, flight)
and its bookkeeping. The pieces it puts together each live in their own module: the continuous
dynamics of a mode (``modes.py``, on ``dynamics.py``), the steppers (``integrators.py``), the
guards (``guards.py``) and the event locator with its scuffs (``locator.py``, ``grazing.py``), the
resets (``resets.py``), the invariants checked after every step and reset (``invariants.py``), the
options (``options.py``) and what a run returns (``results.py``).

State, as in Drake's compass gait:
  * continuous: ``q = [x, y, q1, q2, q3]`` and ``dq`` in *physical* coordinates (leg 1 stays leg 1
    across impacts), plus the work done by the hip motors (a quadrature, for the energy balance);
    with ``base="fixed"`` the integrated state is the chain ``(q1, q2, q3)`` and its rates, and
    the hip follows from the pinned foot;
  * discrete: the stance foot's pin ``c`` (where it touched down);
  * abstract: ``stance_leg`` (1, 2, or 0 in flight).

Constraint drift (floating base): after each accepted step the state is projected back onto the
constraint manifold (``modes.project_onto_pin``) and the drift seen *before* the projection is
reported; ``project_constraints=False`` turns this off, to measure the raw drift.
"""
from __future__ import annotations

import math
import numbers
import time

import numpy as np

from biped_sim.engine import compiled_loop, guards as G, loop_rules as rules
from biped_sim.engine.compiled import IMPLEMENTATION as GENERATED_CODE, gen
from biped_sim.engine.controller_check import check_controller
from biped_sim.engine.dynamics import stance_fixed_fast, stance_floating_fast
from biped_sim.engine.integrators import StepFailure, _count, _entry, make_stepper, prepare as prepare_stepper
from biped_sim.engine.invariants import ImpactHistory, check_impact, check_sample
from biped_sim.engine.locator import EventLocator, scuff_event
from biped_sim.engine.loop_state import (
    CONTROL_PERIODS,
    E0,
    ENERGY_LOST,
    INITIAL_SAMPLE_PENDING,
    MODE_BEGUN,
    MODE_EVENTS,
    N_RECORDS,
    PIN,
    PUSH_WORK,
    RUNNING,
    SIM_DQ,
    SIM_H,
    SIM_Q,
    SIM_STATE_UNMADE,
    SIM_T,
    SIM_U,
    SIM_WORK,
    STANCE_HOLDS,
    STANCE_LEG,
    STANCE_LIFTS_OFF,
    T_NEXT,
    Outcome,
    Record,
    put,
)
from biped_sim.engine.model import BipedModel, as_state_vector, short_repr
from biped_sim.engine.modes import (
    bind_controller,
    checked_command,
    count_word,
    finite_floats,
    floating_to_phys,
    mode_functions,
    project_onto_pin,
    two_finite_floats,
)
from biped_sim.engine.options import Options, check_number, check_run_arguments
from biped_sim.engine.pushes import apply_push
from biped_sim.engine.resets import friction_cone_stop
from biped_sim.engine.results import (
    IMPACT_KINDS,
    ControllerError,
    Event,
    Samples,
    SceneAssumptionError,
    SimulationError,
    SimulationResult,
)
from biped_sim.engine.torque_hook import reference_law
from biped_sim.engine.witnesses import ResetContext, witness


def held_torque(u, m=2):
    """u as m finite floats (the three-link's two: [u1, u2]), or ValueError (plain float checks: the node's every
    period)."""
    checked = two_finite_floats(u) if m == 2 else finite_floats(u, m)
    if checked is None:
        one = "" if m == 2 else ", one an actuator"
        raise ValueError(f"u must be {count_word(m)} finite torques{one} (real numbers, N m: not bools, complex "
                         f"numbers or strings), got {short_repr(u)}")
    return checked



def period_index(t, period, k):
    """The index of the control period under way at t (loop_rules.ev_period_index), k the periods begun so far;
    a ValueError where it would pass 2^53."""
    j = rules.ev_period_index(t, period, k)
    if j < 0:
        raise ValueError(f"period={period!r} s is too short for a run at t={t!r} s: more than 2**53 control "
                         "periods would end before it")
    return j


class HybridSimulator:
    """Integrates the hybrid dynamics forward from a state, one ``advance(t_end, u)`` at a time.

    ``advance`` holds the torque ``u`` (physical: u[0] on hip 1, u[1] on hip 2) constant over the
    interval unless a ``controller(t, q, dq, stance_leg) -> u`` is given, which is then called at
    every right-hand-side evaluation. ``advance_period`` advances one control period with the torque
    held (the node, the recorder, resim and ``simulate(control_period=...)`` all use it).
    ``on_step(t_start, t_end, interpolant)``, if given, sees each accepted step's dense output
    before the constraint projection (the work-precision study keeps them).
    """

    def __init__(self, model: BipedModel, q0, dq0, stance_leg=1, rtol=1e-9, atol=1e-9,
                 method="dop853", mu=None, t0=0.0, on_step=None, **options):
        why = None if isinstance(model, BipedModel) else model.engine_refusal
        if why is not None:
            raise ValueError(why)
        self.model = model
        # the sizes: N coordinates and M actuators (the three-link biped's 5 and 2, a described robot's own)
        self.n, self._m = model.n, model.B.shape[1]
        self.p = model.p if isinstance(model, BipedModel) else None     # (the three-link's parameters)
        # the hybrid state, the simulator's for its life: the fields below that the compiled loop reads and
        # writes are properties over it (loop_state.py: sim_t, e0, control_periods, ...)
        self.S, self._loop = compiled_loop.run_state(model)
        self.opt = Options(**options)
        self.opt.check()
        stance_leg = check_run_arguments(self.opt, method, rtol, atol, mu, stance_leg)
        check_number("t0", t0, -math.inf, math.inf, "s")
        self.method, self.rtol, self.atol, self.mu = method, rtol, atol, mu
        # the stepper's imports, paid here and not inside its first step; the root finder (scipy.optimize,
        # ~0.4 s) is imported by the first event located in Python, or by a realtime caller up front
        # (sim_node: prepare_event_location), so that a short batch run does not pay for it
        prepare_stepper(method)
        q0 = as_state_vector(q0, "q0", self.n)
        dq0 = as_state_vector(dq0, "dq0", self.n)
        self.ground = G.Ground.of(self.opt.slope)
        feet = self.feet(q0.tolist(), dq0.tolist())
        G.check_initial_contact(feet, stance_leg, self.opt)
        self.t = self.t0 = float(t0)
        self.stance_leg = stance_leg
        self.q, self.dq = q0.copy(), dq0.copy()
        self.work = 0.0
        self.energy_lost = 0.0
        self.push_work = 0.0                # kinetic energy added by pushes (J)
        self.E0 = model.energy(q0, dq0)
        self.events: list[Event] = []
        self.impacts = ImpactHistory(self.opt.zeno_count, self.opt.zeno_interval, self.S)
        self.locator = EventLocator(model, self.ground, self.opt, mu, feet, stance_leg, self.impacts, self.S,
                                    self.t0)
        self.pin = list(G.foot_xy(model, q0.tolist(), stance_leg)) if stance_leg else None
        self.status, self.message = "running", ""    # (_stop changes it, and the state's running flag)
        self.S[RUNNING] = 1.0
        self.controller_error = None        # what ended the run in the controller (SimulationResult's)
        self._signatures_checked = {}       # id -> the controllers whose signature was checked (held: no id reused)
        self.control_periods = 0            # advance_period calls so far
        self.on_step = on_step
        self._u = [0.0] * self._m
        self._controller = None
        self._h = None
        self._stepper = None
        self._compiled = None               # the compiled loop's stepper, built at its first mode
        self._last_F, self._last_u = [0.0, 0.0], [0.0] * self._m   # the last right-hand-side evaluation's
        self._initial_sample_pending = True
        self._periods_outcome = None        # how the compiled loop's last periods() ended
        self._stats = dict(steps=0, compiled_loop_steps=0, rejected_steps=0, rhs_evaluations=0, events=0, impacts=0,
                          max_constraint_drift_position=0.0, max_constraint_drift_velocity=0.0,
                          max_energy_balance_residual=0.0, pushes=0, scuffs_ignored=0, deepest_scuff=0.0, wall_time=0.0)
        self._nfev_base = 0
        self._rejected_base = 0
        self._samples = Samples(keep=self.opt.keep_samples, S=self.S, n=self.n, m=self._m)
        self._record(self.q, self.dq, self.stance_leg, self._force_at(self.t, self.q.tolist(), self.dq.tolist()),
                     self.u)

    def __reduce_ex__(self, protocol):
        # the one place that says why a simulator is not pickled: its state is the compiled loop's memory
        # (a C Loop, with the law it was begun with and the records it keeps) and its mode's right-hand side
        # is a closure; a run is remade from what made it
        raise TypeError("a HybridSimulator cannot be pickled or copied: it holds the compiled loop's memory and "
                        "its mode's functions; pickle what makes it (the model, q0, dq0, the options) or its "
                        "result()")

    def feet(self, q, dq):
        """(foot 1, foot 2) as :class:`~biped_sim.engine.guards.FootState` at a physical state (lists)."""
        return G.foot_states(self.model, q, dq, self.ground.tan)

    def active_guards(self):
        """The guards of the current mode as (name, leg) pairs (:func:`~biped_sim.engine.witnesses.witnesses`)."""
        return [(w.name, w.leg) for w in self.locator.witnesses(self.stance_leg)]

    @property
    def integrated_size(self):
        """How many values the integrator carries in the current mode (None before the first
        ``advance``): q, dq and the motors' work, 11 with the floating base, 7 for the fixed base's
        three-coordinate chain."""
        return None if self._stepper is None else len(self._stepper.y)

    @property
    def q(self):
        """The coordinates now, ``[x, y, q1, q2, q3]`` (physical, leg 1 stays leg 1): a new array each time
        the state changes."""
        if self.S[SIM_STATE_UNMADE]:
            self._state_from_loop()
        return self._q

    @q.setter
    def q(self, value):
        S = self.S
        if S[SIM_STATE_UNMADE]:
            self._state_from_loop()
        self._q = value
        S[MODE_BEGUN] = 0.0     # (the compiled loop begins its mode again from it)

    @property
    def dq(self):
        """The rates now (as ``q``)."""
        if self.S[SIM_STATE_UNMADE]:
            self._state_from_loop()
        return self._dq

    @dq.setter
    def dq(self, value):
        S = self.S
        if S[SIM_STATE_UNMADE]:
            self._state_from_loop()
        self._dq = value
        S[MODE_BEGUN] = 0.0

    def state_lists(self):
        """``(q.tolist(), dq.tolist())``, what a message takes, without making the arrays where a quiet
        period left them unmade (the node publishes the state every period)."""
        S = self.S
        if S[SIM_STATE_UNMADE]:
            return list(S[SIM_Q:SIM_Q + self.n]), list(S[SIM_DQ:SIM_DQ + self.n])
        return self._q.tolist(), self._dq.tolist()

    def _state_from_loop(self):
        # a run of the compiled loop leaves q and dq in the state (sim_q, sim_dq) to be made when read: the
        # node's engine period makes no arrays nobody reads
        S = self.S
        self._q, self._dq = np.array(S[SIM_Q:SIM_Q + self.n]), np.array(S[SIM_DQ:SIM_DQ + self.n])
        S[SIM_STATE_UNMADE] = 0.0

    # -- the fields of the state (loop_state.py) the compiled loop reads and writes
    @property
    def t(self):
        """The time now (s): the last accepted state's."""
        return self.S[SIM_T]

    @t.setter
    def t(self, value):
        S = self.S
        S[SIM_T] = value
        S[MODE_BEGUN] = 0.0

    stance_leg = _count(STANCE_LEG, "The stance foot: 1 or 2, 0 in flight.")

    @property
    def pin(self):
        """Where the stance foot is pinned, [x, y] (m); None in flight."""
        S = self.S
        if not S[STANCE_LEG]:
            return None
        pin = S[PIN:PIN + 2]
        return pin if type(pin) is list else pin.tolist()

    @pin.setter
    def pin(self, value):
        if value is not None:       # (in flight the state's pin is not read)
            S = self.S
            S[PIN], S[PIN + 1] = value

    work = _entry(SIM_WORK, "The hip motors' work so far (J).")
    E0 = _entry(E0, "The energy at the run's start (J).")
    push_work = _entry(PUSH_WORK, "The kinetic energy pushes added (J).")
    energy_lost = _entry(ENERGY_LOST, "The energy the impacts took out (J).")
    control_periods = _count(CONTROL_PERIODS, "The control periods begun so far (``advance_period``).")

    @property
    def _initial_sample_pending(self):
        # the t0 sample, redone under the first advance's torque
        return bool(self.S[INITIAL_SAMPLE_PENDING])

    @_initial_sample_pending.setter
    def _initial_sample_pending(self, value):
        self.S[INITIAL_SAMPLE_PENDING] = float(value)

    @property
    def _u(self):
        # the torque held now, [u1, u2] (a described robot's: one an actuator)
        S = self.S
        if self._m != 2:
            return list(S[SIM_U:SIM_U + self._m])
        return [S[SIM_U], S[SIM_U + 1]]

    @_u.setter
    def _u(self, value):
        S = self.S
        if self._m != 2:
            put(S, SIM_U, value)
            return
        S[SIM_U], S[SIM_U + 1] = value

    @property
    def _h(self):
        # the step size the next stepper starts with, None for the initial one
        h = self.S[SIM_H]
        return None if h != h else h

    @_h.setter
    def _h(self, value):
        self.S[SIM_H] = math.nan if value is None else value

    @property
    def u(self):
        """The torque held now, [u1, u2] (N m; a described robot's M, one an actuator): the last ``advance`` or
        ``advance_period``'s."""
        return list(self._u)

    # -- controller and ground force -----------------------------------------------------------
    def _call_controller(self, t, q, dq, controller=None):
        """u = controller(t, q, dq, stance_leg) as a list of two finite floats (lists q, dq: the controller
        gets copies, its own)."""
        return checked_command(controller or self._controller, self._m)(t, list(q), list(dq), self.stance_leg)

    def _check_signature(self, controller):
        """A ValueError before anything runs for a controller that cannot be called as controller(t, q, dq,
        stance_leg) (``controller_check``); each controller object is checked once."""
        if id(controller) in self._signatures_checked:
            return
        check_controller(controller)
        if len(self._signatures_checked) >= 16:     # (a new controller every call: bounded)
            self._signatures_checked.clear()
        self._signatures_checked[id(controller)] = controller

    def _torque_at(self, t, q, dq):
        """The torque applied at a physical state (lists): the held one, or the controller's."""
        if self._controller is None:
            S = self.S
            return [S[SIM_U], S[SIM_U + 1]] if self._m == 2 else list(S[SIM_U:SIM_U + self._m])
        return self._call_controller(t, q, dq)

    def _force_at(self, t, q, dq, u=None):
        """Ground force on the stance foot at a physical state under torque u (by default the one
        applied there); zeros in flight."""
        if not self.stance_leg:
            return [0.0, 0.0]
        if u is None:
            u = self._torque_at(t, q, dq)
        if self.p is None:      # a described robot: the KKT solve's force (its fixed base's state is consistent)
            return self.model.k_stance(q, dq, u, self.stance_leg - 1)[1]
        if self.opt.base == "fixed":
            return stance_fixed_fast(self.model, q[2:], dq[2:], u, self.stance_leg)[1]
        return stance_floating_fast(self.model, q, dq, u, self.stance_leg)[1]

    # -- main loop ----------------------------------------------------------------------------
    def advance(self, t_end, u=None, controller=None, _periods=None):
        """Integrate to ``t_end`` (or until the run stops); returns the events of this interval.
        (``_periods``: ``advance_periods``' control periods run by the compiled loop.)"""
        if not (type(t_end) is float or isinstance(t_end, numbers.Real) and not isinstance(t_end, bool)) \
                or not math.isfinite(t_end):
            raise ValueError(f"t_end must be a finite number of seconds, got {t_end!r}")
        if controller is not None:
            self._check_signature(controller)
        if self.status != "running":
            return []
        return self._advance(float(t_end), u, controller, _periods)

    def _advance(self, t_end, u, controller, periods=None, held=None):
        """``advance``'s run (``periods``: advance_periods' in C; ``held``: a Loop.period's result to finish)."""
        if u is not None:   # (refused: the torque held stays)
            self._u = held_torque(u, self._m)
        self._controller = controller
        n_events = len(self.events)
        wall0 = time.perf_counter()
        try:
            if self._initial_sample_pending:
                self._initial_sample_pending = False
                self._redo_initial_sample()
                self._check_stance_start(self.t)
            elif controller is None and held is None and periods is None:
                self._check_torque_change()
            if held is not None:
                self._integrate(t_end, self._compiled.finish_held(held, t_end))
            elif periods is None:
                self._integrate(t_end)
            else:
                self._integrate_periods(*periods)
        except SceneAssumptionError as exc:
            self._fail(str(exc), status="stopped")
        except (StepFailure, SimulationError, np.linalg.LinAlgError, FloatingPointError, OverflowError,
                ValueError) as exc:
            self._fail(f"{type(exc).__name__}: {exc}" if isinstance(exc, np.linalg.LinAlgError) else str(exc),
                       error=exc)
        finally:
            self._stats["wall_time"] += time.perf_counter() - wall0
        return self.events[n_events:]

    def advance_period(self, period, u=None, controller=None, t_final=0.0):
        """Advance one control period with the torque held (zero-order hold, through any impact
        inside the period): ``u``, or ``controller(t, q, dq, stance_leg)`` evaluated once at the
        period's start. Period k ends at (k + 1) ``period``, or at ``t_final`` (> 0) where that comes
        first or within 1e-9 of a period. Returns the events of the period."""
        if controller is not None:
            self._check_signature(controller)
        st = self._compiled
        if controller is None and st is not None and self._stepper is st:
            # the node's period in one C call while the loop holds the state (Loop.period, _core.c: these
            # lines' twin); None when it cannot, having changed nothing
            outcome = st.loop.period(period, u, t_final, self._samples._data)
            if outcome != Outcome.DECLINED:
                if outcome == Outcome.DONE and not self.S[N_RECORDS]:
                    return []
                return self._advance(self.S[T_NEXT], None, None, held=outcome)
        if self.status != "running":
            return []
        check_number("period", period, 0.0, math.inf, "s", open_low=True)   # (refused: no period begun)
        check_number("t_final", t_final, 0.0, math.inf, "s; 0 for none", allow_inf=True)
        if controller is None and u is not None:
            u = held_torque(u, self._m)
        k = period_index(self.t, period, self.control_periods)
        t_next = rules.ev_period_end(k, period, t_final)
        self.control_periods = k + 1
        if controller is not None:
            # a compiled law on the compiled loop: its torque computed in C, the same bits
            try:
                u = self._compiled.command(controller) if self._compiled is not None else None
            except ControllerError as exc:      # the law failed: the run ends "failed", as in Loop.periods
                self._fail(str(exc), error=exc)
                return self.events[-1:]
            if u is None:
                u = self.command(controller)
            if u is None:
                return self.events[-1:]
        if not math.isfinite(t_next):
            raise ValueError(f"period must be a finite number of seconds, got {period!r}")
        if u is not None:       # checked above, or by the controller's call
            self._u = u
        return self._advance(float(t_next), None, None)

    def advance_periods(self, period, controller, t_final, t_stop=math.inf):
        """``advance_period(period, controller=controller, t_final=t_final)`` repeated until ``t_final``, or
        until a period starts at or after ``t_stop`` (within 1e-9 period: a push due then). The same run;
        on the compiled loop a compiled law's periods run in C, their commands computed there."""
        check_number("period", period, 0.0, math.inf, "s", open_low=True)
        self._check_signature(controller)
        law = None      # the periods' law on the compiled loop, found once: a compiled law or the controller
        S = self.S
        while self.status == "running" and rules.ev_next_period_runs(S[SIM_T], t_final, t_stop, period):
            st = self._compiled
            if st is None or self._stepper is not st or self._initial_sample_pending or not st.can_run_periods():
                self.advance_period(period, controller=controller, t_final=t_final)
                continue
            if law is None:
                law = reference_law(controller, self.model) or controller
            self._periods_outcome = None
            self.advance(t_final, _periods=(period, law, t_final, t_stop))
            if self._periods_outcome is not None and self._periods_outcome[0] == Outcome.TORQUE_CHANGE \
                    and self.status == "running":
                # the stance guards refuse the next period's command at its start: its events are the Python
                # code's (_check_torque_change), under that command (the controller is not called again)
                self.advance_period(period, u=self._periods_outcome[1], t_final=t_final)

    def _integrate_periods(self, period, law, t_final, t_stop):
        outcome, t_next, refused = self._compiled.periods(period, law, t_final, t_stop)
        self._periods_outcome = outcome, refused
        if outcome not in (Outcome.DONE, Outcome.TORQUE_CHANGE):    # the rest of the period in
            self._integrate(t_next, outcome)                                   # progress, as any

    def push(self, impulse):
        """A push: the impulse (N s, [x forward, y up]) on the hip, applied now, between two
        ``advance`` calls (so at the start of the next control period), as a velocity jump with
        the stance foot held (:mod:`biped_sim.engine.pushes`). Returns its events. A bad impulse
        (not two finite numbers, above ``PUSH_IMPULSE_LIMIT``) raises ValueError."""
        n_events = len(self.events)
        try:
            return apply_push(self, impulse)
        except ControllerError as exc:     # (the sample after the push calls a continuous controller)
            self._fail(str(exc), error=exc)
            return self.events[n_events:]

    def command(self, controller):
        """``controller(t, q, dq, stance_leg)`` at the current state as two finite floats, or None
        when it fails (raises, or returns anything else): the run then ends "failed", saying why."""
        self._check_signature(controller)
        q, dq = self.state_lists()
        try:
            return checked_command(controller, self._m)(self.t, q, dq, self.stance_leg)
        except ControllerError as exc:
            self._fail(str(exc), error=exc)
            return None

    def _new_stepper(self, t_bound):
        law = compiled_loop.covers(self, self._controller)
        if law is not None and self._stepper is not None and self._stepper is self._compiled:
            self._compiled.start(t_bound, law, False)   # the same C stepper: its counters go on
            return
        if self._stepper is not None:
            self._nfev_base += self._stepper.nfev
            self._rejected_base += self._stepper.nrejected
        if law is not None:     # the mode stepped by the compiled loop (compiled_loop.py)
            if self._compiled is None:
                self._compiled = compiled_loop.CompiledStepper(self)
            self._compiled.start(t_bound, law, True)
            self._stepper, self._to_phys = self._compiled, floating_to_phys
            return
        S = self.S
        rhs, to_phys, from_phys = mode_functions(
            self.model, self.stance_leg, self.opt.base, self.pin, self._u,
            bind_controller(self._controller, self.stance_leg, self._m), self._keep_evaluation)
        y0 = from_phys(self.q.tolist(), self.dq.tolist(), S[SIM_WORK])
        self._to_phys = to_phys
        # a Python stepper's fields are the simulator's state's where it is a list (pure Python); beside the
        # compiled loop's memory (a memoryview, slower to index and slice) it keeps a list of its own
        self._stepper = make_stepper(self.method, rhs, S[SIM_T], y0, t_bound, self.rtol, self.atol,
                                     step=self.opt.step, n_positions=(len(y0) - 1) // 2, h0=self._h,
                                     max_step=self.opt.max_step, S=S if type(S) is list else None)

    def _keep_evaluation(self, F, u):
        if F is not None:
            self._last_F = F
        self._last_u = u

    def _redo_initial_sample(self):
        """The t0 sample under the torque applied at t0 (known only now: the held torque or the
        controller of this first advance), and the ground force under it."""
        q, dq = self.q.tolist(), self.dq.tolist()
        u = self._torque_at(self.t, q, dq)
        F = self._force_at(self.t, q, dq, u)
        self._samples.pop()
        self._record(self.q, self.dq, self.stance_leg, F, u, (q, dq))

    def _integrate(self, t_end, outcome=None):
        """To t_end; ``outcome``: the compiled loop's, of a step it took and handed back (continue from it)."""
        st = self._stepper
        if outcome is None and self._controller is None and st is not None and st is self._compiled:
            outcome = st.held_period(t_end)    # the node's period: one C call while nothing happens
        if outcome is None:
            self._new_stepper(t_end)
            st = self._stepper
        S = self.S      # (its fields read directly on this hot path: sim_t, sim_h)
        while S[SIM_T] < t_end and self.status == "running":
            if st is self._compiled:    # its quiet steps in C; a step it hands back is handled below
                if outcome is None:
                    outcome = st.run(t_end)
                if outcome == Outcome.DONE:
                    break
                if outcome == Outcome.PYTHON_STEPS:
                    st.step()
                outcome = None          # (the Python code handles this step)
            else:
                st.step()
            self._stats["steps"] += 1
            h = getattr(st, "h_abs", None) or getattr(st, "h", None)
            S[SIM_H] = math.nan if h is None else h     # (the _h property's write)
            q, dq, w = self._to_phys(st.y)
            if rules.ev_diverging(dq, len(dq), self.opt.max_speed):
                raise SimulationError(f"diverging state at t={st.t:.9g} s: a velocity exceeds "
                                      f"{self.opt.max_speed:g} (dq={np.round(dq, 3).tolist()})")
            feet = self.feet(q, dq)   # the end state's feet, shared by the checks below
            # our steppers evaluate the right-hand side last at the step's end (FSAL): reuse its
            # torque and stance force (the fixed-base right-hand side computes no force)
            at_end = st.last_eval_at_end
            u_end = list(self._last_u) if at_end else None
            leg = self.stance_leg       # (the state's: read once, a quiet step does not change it)
            fsal = leg and at_end and self.opt.base == "floating"
            event, F_end = self.locator.locate(st, self._to_phys, leg, q, dq, feet, self._force_at,
                                               list(self._last_F) if fsal else None)
            while self.locator.scuff_events:
                self._push_event(self.locator.scuff_events.pop(0))
            if event is None:
                q, dq = self._project(q, dq, feet)
                self._accept(st.t, q, dq, w, F_end, u_end)
                if self.opt.check_invariants:
                    check_sample(self.t, q, dq, feet, leg, self._samples.last_force(), self.ground, self.mu,
                                 self.opt, self.locator.scuffing_legs(), self.last_impact)
                if self.opt.project_constraints and leg and self.opt.base == "floating":
                    st.replace_y(q + dq + [w])  # continue from the projected state
                continue
            t_ev, fired, legs = event
            qe, dqe, we = self._to_phys(st.dense_at(t_ev))
            self._accept(t_ev, qe, dqe, we)
            self._reset(fired, legs, t_ev, qe, dqe)
            if self.status != "running":
                break
            self._new_stepper(t_end)
            st = self._stepper

    @property
    def last_impact(self):
        """The last touchdown event, or None."""
        return next((e for e in reversed(self.events) if e.kind in IMPACT_KINDS), None)

    def _project(self, q, dq, feet):
        """Measure the stance constraint drift and (by default) remove it; ``feet`` at (q, dq)."""
        leg = self.stance_leg
        if not leg or self.opt.base == "fixed":
            return q, dq
        q, dq, drift, rate = project_onto_pin(q, dq, feet[leg - 1], self.pin, self.ground.tan,
                                              self.opt.project_constraints)
        s = self._stats
        s["max_constraint_drift_position"] = rules.ev_running_max(s["max_constraint_drift_position"], drift)
        s["max_constraint_drift_velocity"] = rules.ev_running_max(s["max_constraint_drift_velocity"], rate)
        return q, dq

    def _accept(self, t, q, dq, w, F=None, u=None):
        """The state (q, dq: lists) at t becomes the current one, and a sample (with the torque u
        applied there and the ground force F under it, computed here where not given)."""
        st = self._stepper
        if self.on_step is not None and st is not None and t > st.t_old:
            self.on_step(st.t_old, float(t), st.dense_output())
        # (the t, q, dq and work properties' writes, on the state's fields directly: this runs every step)
        S, t = self.S, float(t)
        S[SIM_T], S[SIM_WORK], S[MODE_BEGUN], S[SIM_STATE_UNMADE] = t, float(w), 0.0, 0.0
        self._q, self._dq = np.array(q), np.array(dq)
        if u is None:
            u = self._torque_at(t, list(q), list(dq))
        if F is None:
            grf = self.opt.compute_grf and self.stance_leg
            F = self._force_at(t, list(q), list(dq), u) if grf else [0.0, 0.0]
        self._record(self._q, self._dq, self.stance_leg, F, u, (q, dq))

    def _record(self, q, dq, leg, F, u, lists=None):
        """A sample of the arrays q, dq (``lists``: the same as lists, if at hand), the torque u applied
        there, and the energy balance."""
        if self.p is None:      # a described robot's kernel
            T, V = self.model.k_energy(*(lists or (q.tolist(), dq.tolist())))
        else:
            T, V = gen.energy(*(lists or (q.tolist(), dq.tolist())), self.model.k["energy"])
        S = self.S
        residual = rules.ev_energy_residual(T + V, S[E0], S[SIM_WORK], S[PUSH_WORK], S[ENERGY_LOST])
        self._stats["max_energy_balance_residual"] = rules.ev_running_max(self._stats["max_energy_balance_residual"],
                                                                           abs(residual))
        self._samples.append(S[SIM_T], q, dq, leg, F, u, residual)

    # -- resets -------------------------------------------------------------------------------
    def _reset(self, fired, legs, t, q, dq):
        """Apply the reset of the witness that fired (for the feet ``legs``) at the state (q, dq: lists) at t,
        take the new mode from its event."""
        self._samples.keep_last()       # the sample at the event, before its reset
        self.S[MODE_BEGUN] = 0.0        # the compiled loop begins its mode again after any reset Python applies
        old = self.stance_leg
        ev, stop = fired.reset(ResetContext(self.model, self.ground, self.mu, self.opt, self._force_at), t, q, dq,
                               legs, old)
        if ev.kind in IMPACT_KINDS:
            self._take_impact(ev, t, q)
            return
        if ev.stance_leg_after != ev.stance_leg_before:    # the foot left the ground: flight
            self.stance_leg = ev.stance_leg_after
            self.pin = None
            self.locator.after_reset(ev)
        self._push_event(ev)
        if fired.kind.latches:
            self.locator.latch(fired)   # off until it is positive again: it must not fire at once
        if stop is not None:
            self._stop("stopped", stop)

    def _take_impact(self, ev, t, q):
        """The new stance of an impact's Event at the state (q, dq+), its sample, and the checks of the
        impact: a Zeno stop, its invariants, an impulse outside the friction cone, the new stance's start."""
        self.energy_lost = rules.ev_energy_lost_after(self.energy_lost, ev.energy_loss)
        self.stance_leg = ev.stance_leg_after
        self.pin = list(G.foot_xy(self.model, list(q), ev.stance_leg_after))
        self.locator.after_reset(ev)
        self.dq = ev.dq_plus
        u = self._torque_at(t, list(q), ev.dq_plus.tolist())
        self._record(self.q, self.dq, self.stance_leg, self._force_at(t, list(q), ev.dq_plus.tolist(), u), u)
        self._stats["impacts"] += 1
        self._push_event(ev)
        zeno = self.impacts.record(t)
        if zeno is None and self.status == "running" and self.opt.check_invariants:
            zeno = check_impact(ev, self.feet(list(q), ev.dq_plus.tolist()), self.ground, self.impacts.gaps(),
                                self.opt.impulse_tol, self.opt.contact_tol)
        if zeno is not None:
            self.events.append(Event(t, "zeno", self.stance_leg, self.q.copy(), self.dq.copy(), self.dq.copy(),
                                     message=zeno))
            self._stop("stopped", zeno)
        elif self.status == "running" and (slip := friction_cone_stop(ev, self.ground, self.mu, self.opt)):
            self._stop("stopped", slip)    # the impulse slips: as a push's, or a stance force's (slip)
        if self.status == "running":
            self._check_stance_start(t)

    def _check_torque_change(self):
        """The held torque may change at this instant (``advance(u=...)``, a control period's start): the
        stance guards at the state now under the torque from now on. (The compiled loop hands such a
        period back before it changes anything: ``Loop.period``, ``Loop.periods``.)"""
        if self.stance_leg:
            q, dq = self.state_lists()
            t = self.S[SIM_T]
            self._check_stance_start(t, self._force_at(t, q, dq))

    def _check_stance_start(self, t, F=None):
        """A stance that starts with the ground pulling on the foot (normal force < 0), or with the
        force outside the friction cone, ends at that instant: the liftoff and slip guards are
        already past zero there, so no crossing inside a step would ever find them. The same holds
        where the torque changes in stance: ``F`` is the force at t under the new torque (the last
        sample, at t, keeps the old torque and its force, the stance's last); by default it is the
        last sample's, taken at t under the torque from now on. A latched slip guard stays off, as in
        the locator."""
        if not self.stance_leg:
            return
        t0, q, dq, leg, F_sample, u, residual = self._samples.last()
        n, tg = G.normal_tangent(F_sample if F is None else F, self.ground)
        slip = witness("slip", leg)
        start = rules.ev_stance_start(self.mu is not None and slip not in self.locator.latched,
                                      0.0 if self.mu is None else self.mu, n, tg)
        if start == STANCE_HOLDS:
            return
        guard = witness("liftoff", leg) if start == STANCE_LIFTS_OFF else slip
        q, dq = q.tolist(), dq.tolist()
        if F is not None:
            # the next step starts here under the new torque, not from the last step's end under the old one
            self.locator.restart(t, self.feet(q, dq), F)
        self._reset(guard, [leg], t, q, dq)
        if guard.name == "liftoff" and self.stance_leg == 0 and F is None:
            self._samples.set_last_in_flight()   # in flight from this very instant: so is the sample just taken

    def _loop_records(self, records):
        """The Events of what the compiled loop applied (``compiled_loop.take_records``, in order): its touchdowns
        (the energy lost and the impact history are the state's already) and the scuffs that ended."""
        for record in records:
            if record[0] == Record.TOUCHDOWN:
                _, t_ev, old, new, q, dq_minus, dq_plus, impulse, loss, _, _ = record   # (the new stance leg and pin
                # are the state's already)
                self._stats["impacts"] += 1
                self._add_event(Event(t_ev, "touchdown", new, np.array(q), np.array(dq_minus), np.array(dq_plus),
                                      np.array(impulse), old, new, loss, []), applied_in_loop=True)
                # (no Zeno stop: the loop hands back an impact that could make one)
                self.impacts.record(t_ev, in_state=False)
            else:
                _, leg, stance_leg, scuff, t_up, q, dq = record
                self._add_event(scuff_event(leg, stance_leg, scuff, t_up, q, dq, self.opt.scuff_depth,
                                            self.opt.scuff_rule))

    def _push_event(self, ev):
        self._samples.keep_last()       # the sample after the event's reset
        self._add_event(ev)

    def _add_event(self, ev, applied_in_loop=False):
        """Keep the Event; count a change of mode (the state's mode_events and the ring of the last 49 times)
        and stop the run at max_events or an event loop. ``applied_in_loop``: a touchdown the compiled loop
        applied, which it counted itself (it hands back one that would stop the run)."""
        self.events.append(ev)
        self._stats["events"] = len(self.events)
        if ev.kind == "scuff" or applied_in_loop:    # a scuff is a report, not a change of mode
            return
        S = self.S
        t_first = rules.ev_ring_oldest(S)      # the event 49 before this one
        rules.ev_count_mode_event(S, ev.time)
        m = int(S[MODE_EVENTS])                # this one's count
        if rules.ev_over_budget(m, self.opt.max_events):
            self._stop("stopped", f"stopped after {m} events (max_events)")
        if rules.ev_event_loop(m, t_first, ev.time):
            self._stop("stopped", f"event loop: 50 events within 1e-9 s ending at t={ev.time:.9g} s "
                                  f"(last: {ev.kind} of leg {ev.leg}); the run stops instead of hanging")

    def _stop(self, status, message):
        self.status, self.message = status, message
        self.S[RUNNING] = float(status == "running")

    def _fail(self, message, status="failed", error=None):
        """The run ends (``status``) with an error event; ``error``: the exception that ended it (a
        ControllerError keeps the controller's own exception, or itself for a bad return, as the result's
        ``controller_error``)."""
        if isinstance(error, ControllerError):
            self.controller_error = error.__cause__ if error.__cause__ is not None else error
        msg = f"integration stopped at t={self.t:.9g} s: {message}"
        self.events.append(Event(self.t, "error", self.stance_leg, self.q.copy(), self.dq.copy(), self.dq.copy(),
                                 message=msg))
        self._stats["events"] = len(self.events)
        self._stop(status, msg)

    # -- results ------------------------------------------------------------------------------
    @property
    def ground_force(self):
        """Ground force on the stance foot at the last accepted sample, [Fx, Fy] (N); zeros in flight."""
        return self._samples.last_force()

    @property
    def stats(self) -> dict:
        """The run's statistics so far (the compiled loop's and the stepper's counters brought in when read)."""
        s = self._stats
        if self._compiled is not None:     # the compiled loop's since the last read
            steps, drift, rate, residual, wall_time = compiled_loop.take_stats(self.S)
            s["steps"] += steps
            s["compiled_loop_steps"] += steps
            s["wall_time"] += wall_time     # (of the periods run whole in C: Loop.period)
            for key, v in (("max_constraint_drift_position", drift), ("max_constraint_drift_velocity", rate),
                           ("max_energy_balance_residual", residual)):
                s[key] = rules.ev_running_max(s[key], v)
        if self._stepper is not None:
            s["rhs_evaluations"] = self._nfev_base + self._stepper.nfev
            s["rejected_steps"] = self._rejected_base + self._stepper.nrejected
        return s

    def result(self) -> SimulationResult:
        s = self._samples
        stats = dict(self.stats)
        stats["scuffs_ignored"] = self.locator.scuffs
        stats["deepest_scuff"] = self.locator.deepest_scuff      # m
        stats["simulated_time"] = self.t - self.t0
        stats["real_time_factor"] = stats["simulated_time"] / stats["wall_time"] if stats["wall_time"] > 0 else math.inf
        stats["energy_balance_residual"] = s.last()[6] if len(s) else 0.0
        stats["energy_lost_at_impacts"] = self.energy_lost
        stats["motor_work"] = self.work
        stats["push_work"] = self.push_work
        stats["method"] = self.method
        stats["generated_code"] = GENERATED_CODE   # "C" (the compiled twin) or "Python": same results
        return SimulationResult.from_samples(s, list(self.events), stats,
                                             "completed" if self.status == "running" else self.status,
                                             self.message, self.opt, model=self.model,
                                             controller_error=self.controller_error)
