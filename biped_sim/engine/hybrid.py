"""The hybrid simulation: phases, guards, resets, and the run's figures.

Owns the hybrid system of MODEL.md "Phases" (stance on leg 1 or 2, impact with relabeling,
flight) and its bookkeeping. The continuous dynamics come from ``dynamics.py``; integration from
``integrators.py``.

State, as in Drake's compass gait:
  * continuous: ``q = [x, y, q1, q2, q3]`` and ``dq`` in *physical* coordinates (leg 1 stays leg 1
    across impacts), plus the work done by the hip motors (a quadrature, for the energy balance);
    with ``base="fixed"`` the integrated state is the chain ``(q1, q2, q3)`` and its rates, and
    the hip follows from the pinned foot;
  * discrete: the stance foot's pin ``c`` (where it touched down);
  * abstract: ``stance_leg`` (1, 2, or 0 in flight).

Guards (witness functions), each located by root finding on the integrator's dense output:
  * ``touchdown``: height of the swing foot above the ground reaches zero moving down. With the
    default ``touchdown_rule="front"`` only a crossing in front of the stance foot (larger x, the
    walking direction) counts: the down-crossing behind it when straight legs scuff the ground near
    mid-stance is ignored (counted in ``stats["scuffs_ignored"]``). ``"any"`` takes every crossing.
    A foot's guard is armed only once the foot has been above the ground by more than
    ``arm_height``, so a guard that is zero right after a reset cannot fire again.
    Because a foot can dip below the ground and come back within one step, each step's
    end-point heights and vertical velocities are checked with a cubic Hermite bound too.
  * ``liftoff``: the normal ground force reaches zero (to flight; a scene without the flight phase
    stops here with a message).
  * ``slip``: |F_t| > mu F_n (only with ``mu`` given; ``stop_on_slip`` says whether it stops).
  * in flight, ``touchdown`` of either foot, or of both within ``simultaneous_tol`` seconds
    (a ``double_touchdown``: the plastic impact of both feet; the run continues in stance on the
    foot that took the larger normal impulse -- double support is not modelled).
Resets: touchdown applies ``impact_map`` (the new stance leg is the foot that landed: in the notes'
stance/swing labels this is the relabeling R); liftoff changes only the mode.

Constraint drift (floating base): after each accepted step the state is projected back onto the
constraint manifold -- the hip is placed so that the stance foot is at its pin and the base velocity
is set to -A dq_r so that J dq = 0 -- and the drift seen *before* the projection is reported.
``project_constraints=False`` turns this off, to measure the raw drift.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from biped_sim.engine.compiled import IMPLEMENTATION as GENERATED_CODE, gen
from biped_sim.engine.dynamics import (flight_fast, impact_map, stance_fixed_accel_fast, stance_fixed_fast,
                       stance_floating_fast)
from biped_sim.engine.integrators import (ADAPTIVE_METHODS, FIXED_STEP_METHODS, METHODS, StepFailure,
                          make_stepper)
from biped_sim.engine.model import BipedModel, as_state_vector

PHASES = frozenset({"stance", "impact", "flight"})
EVENT_KINDS = ("touchdown", "double_touchdown", "liftoff", "slip", "error", "zeno")


@dataclass
class Event:
    """One discrete event. ``q``, ``dq_minus`` and ``dq_plus`` are physical coordinates.

    kind: ``touchdown`` (the impact map was applied to foot ``leg``), ``double_touchdown`` (both
    feet at once; ``leg`` is the new stance foot, ``impulse`` has 4 entries, foot 1 first),
    ``liftoff`` (foot ``leg`` leaves the ground; flight follows), ``slip`` (foot ``leg`` would slip),
    ``error`` (the run stopped: ``message`` says why), ``zeno`` (impacts accumulate; the run stopped).
    ``impulse`` is the ground's impulse on the foot (N s), for touchdowns only.
    ``warnings`` lists violated contact assumptions of an impact (the old stance foot does not leave
    the ground, the impulse is outside the friction cone).
    """
    time: float
    kind: str
    leg: int
    q: np.ndarray
    dq_minus: np.ndarray
    dq_plus: np.ndarray
    impulse: np.ndarray | None = None
    stance_leg_before: int = 0
    stance_leg_after: int = 0
    energy_loss: float = 0.0
    warnings: list = field(default_factory=list)
    message: str = ""


@dataclass
class SimulationResult:
    """Samples at every accepted step (and twice at each impact: before and after)."""
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    stance_leg: np.ndarray
    grf: np.ndarray
    u: np.ndarray
    events: list
    stats: dict
    status: str = "completed"     # "completed", "stopped" (a scene's assumption left), "failed"
    message: str = ""

    @property
    def impacts(self):
        return [e for e in self.events if e.kind in ("touchdown", "double_touchdown")]


class SimulationError(RuntimeError):
    pass


class SceneAssumptionError(SimulationError):
    """The physics left the scene's declared phases: the run stops (status "stopped")."""


@dataclass
class Options:
    base: str = "floating"
    phases: frozenset = PHASES
    touchdown_rule: str = "front"
    stop_on_slip: bool = True
    project_constraints: bool = True
    step: float | None = None          # fixed-step methods: the step size (s)
    max_step: float = np.inf
    slope: float = 0.0                 # ground angle (rad), positive: the ground falls in +x
    arm_height: float = 1e-9           # m above the ground that arms a foot's touchdown guard
    event_tol: float = 1e-13           # s, root-finding tolerance on event times
    simultaneous_tol: float = 1e-9     # s, two touchdowns closer than this are one double touchdown
    contact_tol: float = 1e-6          # m and m/s, initial-state check of the stance foot
    max_events: int = 100_000
    zeno_interval: float = 1e-6        # s; this many impacts in a row closer than it stop the run
    zeno_count: int = 20
    max_speed: float = 1e4             # a velocity entry above this is a diverging state
    max_penetration: float = 0.05      # m; a free foot this deep below the ground: the robot fell
                                       # or a touchdown was missed (checked when impacts are modelled)
    compute_grf: bool = True
    keep_samples: bool = True          # False: keep only the last sample (a long-running node)

    def check(self):
        if self.base not in ("floating", "fixed"):
            raise ValueError(f"base must be 'floating' or 'fixed', got {self.base!r}")
        unknown = set(self.phases) - PHASES
        if unknown or "stance" not in self.phases and "flight" not in self.phases:
            raise ValueError(f"phases must be a subset of {sorted(PHASES)} with stance or flight, "
                             f"got {sorted(self.phases)}")
        if self.base == "fixed" and "flight" in self.phases:
            raise ValueError("the fixed-base method has no flight phase: use base='floating' or drop 'flight'")
        if self.touchdown_rule not in ("front", "any"):
            raise ValueError(f"touchdown_rule must be 'front' or 'any', got {self.touchdown_rule!r}")


def stance_state(model: BipedModel, joints, joint_rates, stance_leg=1, foot=(0.0, 0.0)):
    """A consistent stance state: the hip placed so that the stance foot is at ``foot`` and at rest.

    ``joints = (q1, q2, q3)`` and ``joint_rates = (dq1, dq2, dq3)``; returns physical (q, dq).
    """
    qs = as_state_vector(joints, "joints", 3)
    dqs = as_state_vector(joint_rates, "joint_rates", 3)
    l = model.parameters.l_leg
    i = 0 if stance_leg == 1 else 1
    th, dth = qs[i] + qs[2], dqs[i] + dqs[2]
    hip = np.array(foot, float) - l * np.array([math.sin(th), math.cos(th)])
    dhip = -l * np.array([math.cos(th), -math.sin(th)]) * dth
    return np.concatenate([hip, qs]), np.concatenate([dhip, dqs])


class HybridSimulator:
    """Integrates the hybrid dynamics forward from a state, one ``advance(t_end, u)`` at a time.

    ``advance`` holds the torque ``u`` (physical: u[0] on hip 1, u[1] on hip 2) constant over the
    interval unless a ``controller(t, q, dq, stance_leg) -> u`` is given, which is then called at
    every right-hand-side evaluation. ``simulate`` drives it; the ROS node calls ``advance`` once per
    control period.
    """

    def __init__(self, model: BipedModel, q0, dq0, stance_leg=1, rtol=1e-9, atol=1e-9,
                 method="dop853", mu=None, t0=0.0, **options):
        self.model = model
        self.opt = Options(**options)
        self.opt.check()
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
        if method in FIXED_STEP_METHODS and not self.opt.step:
            raise ValueError(f"method {method!r} is fixed-step: give step=<seconds>")
        for name, v in (("rtol", rtol), ("atol", atol)):
            if method in ADAPTIVE_METHODS and not (isinstance(v, (int, float)) and 0 < v < 1):
                raise ValueError(f"{name} must be a number in (0, 1), got {v!r}")
        if mu is not None and not (isinstance(mu, (int, float)) and mu >= 0 and math.isfinite(mu)):
            raise ValueError(f"mu must be None or a finite number >= 0, got {mu!r}")
        self.method, self.rtol, self.atol, self.mu = method, rtol, atol, mu
        q0 = as_state_vector(q0, "q0")
        dq0 = as_state_vector(dq0, "dq0")
        if stance_leg not in (0, 1, 2):
            raise ValueError(f"stance_leg must be 1, 2 or 0 (flight), got {stance_leg!r}")
        if stance_leg == 0 and "flight" not in self.opt.phases:
            raise ValueError("stance_leg=0 starts in flight, but the phases do not include 'flight'")
        if stance_leg != 0 and "stance" not in self.opt.phases:
            raise ValueError("the phases do not include 'stance': start in flight with stance_leg=0")
        self.p = model.p
        self._sin_s, self._cos_s = math.sin(self.opt.slope), math.cos(self.opt.slope)
        self._tan_s = math.tan(self.opt.slope)
        self._check_initial_state(q0, dq0, stance_leg)
        self.t = self.t0 = float(t0)
        self.stance_leg = stance_leg
        self.q, self.dq = q0.copy(), dq0.copy()
        self.work = 0.0
        self.energy_lost = 0.0
        self.E0 = model.energy(q0, dq0)
        self._last_start_F_t = None
        self.events: list[Event] = []
        feet = self._feet(q0.tolist(), dq0.tolist())
        self.armed = [feet[1] > self.opt.arm_height, feet[5] > self.opt.arm_height]  # (issue 5) foot 2 height is feet[5]
        self.pin = None
        if stance_leg:
            fx, fy = self._foot_xy(q0.tolist(), stance_leg)
            self.pin = [fx, fy]
            self.armed[stance_leg - 1] = False
        self.status, self.message = "running", ""
        self._u = [0.0, 0.0]
        self._controller = None
        self._h = None
        self._stepper = None
        self._last_F = [0.0, 0.0]
        self._recent_impacts: list[float] = []
        # a guard that just fired starts at ~0 after its reset: it stays latched (off) until it has
        # been positive at a step's end, so it cannot fire again at the same instant
        self._latched: set = set()
        self.stats = dict(steps=0, rejected_steps=0, rhs_evaluations=0, events=0, impacts=0,
                          max_constraint_drift_position=0.0, max_constraint_drift_velocity=0.0,
                          max_energy_balance_residual=0.0, scuffs_ignored=0, wall_time=0.0)
        self._nfev_base = 0
        self._rejected_base = 0
        self._F_end = None
        self._feet_end, self._feet_end_t = None, None
        self._samples = []
        self._record(self.q, self.dq, self.stance_leg, self._force_at(self.t, self.q.tolist(), self.dq.tolist()))

    # -- geometry helpers ----------------------------------------------------------------------
    def _feet(self, q, dq):
        """Per foot: (x, height above the ground, vx, vertical velocity) -> list of 8 values."""
        p1x, p1y, p2x, p2y, v1x, v1y, v2x, v2y = gen.foot_kinematics(q, dq, self.model.k["foot_kinematics"])
        t = self._tan_s
        return [p1x, p1y + t * p1x, v1x, v1y + t * v1x, p2x, p2y + t * p2x, v2x, v2y + t * v2x]

    def _foot_xy(self, q, leg):
        p = gen.foot_positions(q, self.model.k["foot_positions"])
        return p[2 * leg - 2], p[2 * leg - 1]

    def _normal_tangent(self, F):
        """(normal, tangential) components of a ground force or impulse on a slope."""
        s, c = self._sin_s, self._cos_s
        return F[0] * s + F[1] * c, F[0] * c - F[1] * s

    def _check_initial_state(self, q, dq, stance_leg):
        tol = self.opt.contact_tol
        f = self._feet(q.tolist(), dq.tolist())
        if stance_leg:
            i = 4 * (stance_leg - 1)
            if abs(f[i + 1]) > tol:
                raise ValueError(f"initial state: the stance foot (leg {stance_leg}) is {f[i + 1]:.6g} m "
                                 f"above the ground (tolerance {tol:g} m); place the hip so that the foot is on "
                                 "the ground (biped_sim.engine.hybrid.stance_state does this)")
            if math.hypot(f[i + 2], f[i + 3]) > tol:
                raise ValueError(f"initial state: the stance foot (leg {stance_leg}) moves at "
                                 f"({f[i + 2]:.6g}, {f[i + 3]:.6g}) m/s; it must be at rest (J dq = 0; "
                                 "biped_sim.engine.hybrid.stance_state gives a consistent dq)")
            other = 4 * (2 - stance_leg)
            if f[other + 1] < -tol:
                raise ValueError(f"initial state: the swing foot (leg {3 - stance_leg}) is {-f[other + 1]:.6g} m "
                                 "below the ground")
        else:
            for leg in (1, 2):
                if f[4 * (leg - 1) + 1] < -tol:
                    raise ValueError(f"initial state in flight: foot {leg} is below the ground")

    # -- continuous dynamics of the current mode -------------------------------------------------
    def _mode_functions(self):
        """(rhs, to_physical, from_physical) of the current mode, for the integrator's state y."""
        model, leg = self.model, self.stance_leg
        ctrl = self._controller_function()
        u_hold = self._u
        sim = self

        if leg and self.opt.base == "fixed":
            c = self.pin

            l_leg = model.parameters.l_leg
            i = leg - 1

            def to_phys(y):
                # the hip hangs from the pin: hip = c - l (sin th, cos th), th = q_stance + q3
                yl = y if type(y) is list else y.tolist()
                th, w = yl[i] + yl[2], yl[3 + i] + yl[5]
                sn, cs = math.sin(th), math.cos(th)
                return ([c[0] - l_leg * sn, c[1] - l_leg * cs] + yl[0:3],
                        [-l_leg * cs * w, l_leg * sn * w] + yl[3:6], yl[6])

            def from_phys(q, dq, w):   # lists
                return q[2:] + dq[2:] + [w]

            def rhs(t, y):
                qs, dqs = y[0:3], y[3:6]
                if ctrl is None:
                    u = u_hold
                else:
                    q, dq, _ = to_phys(y)
                    u = ctrl(t, q, dq)
                dds = stance_fixed_accel_fast(model, qs, dqs, u, leg)   # no force: guards ask for it
                return dqs + dds + [u[0] * dqs[0] + u[1] * dqs[1]]
            return rhs, to_phys, from_phys

        def to_phys(y):
            yl = y if type(y) is list else y.tolist()
            return yl[0:5], yl[5:10], yl[10]

        def from_phys(q, dq, w):   # lists
            return q + dq + [w]

        # the right-hand sides take and return lists (integrators.py): y = [q, dq, work of the motors]
        if leg:   # the generated closed form itself, one per stance leg
            k_stance = model.k_stance
            stance = gen.stance_floating_1 if leg == 1 else gen.stance_floating_2

            def rhs(t, y):
                q, dq = y[0:5], y[5:10]
                u = u_hold if ctrl is None else ctrl(t, q, dq)
                ddq, F = stance(q, dq, u, k_stance)
                sim._last_F = F
                return dq + ddq + [u[0] * dq[2] + u[1] * dq[3]]
        else:
            def rhs(t, y):
                q, dq = y[0:5], y[5:10]
                u = u_hold if ctrl is None else ctrl(t, q, dq)
                ddq = flight_fast(model, q, dq, u)
                return dq + ddq + [u[0] * dq[2] + u[1] * dq[3]]
        return rhs, to_phys, from_phys

    def _call_controller(self, t, q, dq, controller=None):
        """u = controller(t, q, dq, stance_leg) as a list of two finite floats (lists q, dq)."""
        ctrl = controller or self._controller
        # a controller that sets ``accepts_lists = True`` takes q, dq as lists (no array round trip)
        if getattr(ctrl, "accepts_lists", False):
            return _torques(ctrl(t, q, dq, self.stance_leg), t)
        return _torques(ctrl(t, np.array(q), np.array(dq), self.stance_leg), t)

    def _controller_function(self):
        """``_call_controller`` with the controller and stance leg of this mode bound (or None)."""
        ctrl, leg = self._controller, self.stance_leg
        if ctrl is None:
            return None
        if not getattr(ctrl, "accepts_lists", False):
            return lambda t, q, dq: _torques(ctrl(t, np.array(q), np.array(dq), leg), t)

        def call(t, q, dq):   # at every right-hand-side evaluation: one check, the message only on failure
            u = ctrl(t, q, dq, leg)
            v = _two_finite_floats(u)
            return v if v is not None else _torques(u, t)
        return call

    def _force_at(self, t, q, dq):
        """Ground force on the stance foot at a physical state (zeros in flight)."""
        if not self.stance_leg:
            return [0.0, 0.0]
        u = self._u if self._controller is None else self._call_controller(t, q, dq)
        if self.opt.base == "fixed":
            return stance_fixed_fast(self.model, q[2:], dq[2:], u, self.stance_leg)[1]
        return stance_floating_fast(self.model, q, dq, u, self.stance_leg)[1]

    # -- guards -------------------------------------------------------------------------------
    def _guards(self):
        """Names of the guards active in the current mode: list of (kind, leg)."""
        g = []
        if self.stance_leg:
            swing = 3 - self.stance_leg
            if "impact" in self.opt.phases and self.armed[swing - 1]:
                g.append(("touchdown", swing))
            g.append(("liftoff", self.stance_leg))
            if self.mu is not None:
                g.append(("slip", self.stance_leg))
        elif "impact" in self.opt.phases:
            for leg in (1, 2):
                if self.armed[leg - 1]:
                    g.append(("touchdown", leg))
        return g

    def _guard_value(self, kind, leg, t, q, dq, feet=None, F=None):
        if kind == "touchdown":
            if feet is None:   # the height only (root finding evaluates this many times)
                x, y = self._foot_xy(q, leg)
                return y + self._tan_s * x
            return feet[4 * (leg - 1) + 1]
        F = F if F is not None else self._force_at(t, q, dq)
        n, tg = self._normal_tangent(F)
        if kind == "liftoff":
            return n
        return self.mu * n - abs(tg)

    # -- main loop ----------------------------------------------------------------------------
    def advance(self, t_end, u=None, controller=None):
        """Integrate to ``t_end`` (or until the run stops); returns the events of this interval."""
        if self.status != "running":
            return []
        if u is not None:   # (plain float checks: the node calls this every control period)
            self._u = _two_finite_floats(u)
            if self._u is None:
                raise ValueError(f"u must be two finite torques, got {u!r}")
        self._controller = controller
        n_events = len(self.events)
        wall0 = time.perf_counter()
        try:
            self._integrate(float(t_end))
        except SceneAssumptionError as exc:
            self._fail(str(exc), status="stopped")
        except (StepFailure, SimulationError, np.linalg.LinAlgError, FloatingPointError, OverflowError,
                ValueError) as exc:
            self._fail(f"{type(exc).__name__}: {exc}" if isinstance(exc, np.linalg.LinAlgError) else str(exc))
        finally:
            self.stats["wall_time"] += time.perf_counter() - wall0
            if self._stepper is not None:
                self.stats["rhs_evaluations"] = self._nfev_base + self._stepper.nfev
        return self.events[n_events:]

    def _new_stepper(self, t_bound):
        if self._stepper is not None:
            self._nfev_base += self._stepper.nfev
            self._rejected_base += self._stepper.nrejected
        rhs, to_phys, from_phys = self._mode_functions()
        y0 = from_phys(self.q.tolist(), self.dq.tolist(), self.work)
        self._to_phys = to_phys
        self._stepper = make_stepper(self.method, rhs, self.t, y0, t_bound, self.rtol, self.atol,
                                     step=self.opt.step, n_positions=(len(y0) - 1) // 2, h0=self._h,
                                     max_step=self.opt.max_step)

    def _integrate(self, t_end):
        self._new_stepper(t_end)
        st = self._stepper
        while self.t < t_end and self.status == "running":
            st.step()
            self.stats["steps"] += 1
            self._h = getattr(st, "h_abs", None) or getattr(st, "h", None)
            q, dq, w = self._to_phys(st.y)
            if max(map(abs, dq)) > self.opt.max_speed:
                raise SimulationError(f"diverging state at t={st.t:.9g} s: a velocity exceeds "
                                      f"{self.opt.max_speed:g} (dq={np.round(dq, 3).tolist()})")
            feet = self._feet(q, dq)   # the end state's feet, shared by the checks below
            event = self._detect(st, q, dq, feet)
            if event is None:
                # (issue 5) checked only when no guard crossed in this step: a long free-flight step
                # can pass the ground by more than max_penetration before its touchdown is located
                self._check_ground(st.t, feet)
            if event is not None:
                t_ev, kind, legs = event
                y_ev = st.dense_at(t_ev)
                qe, dqe, we = self._to_phys(y_ev)
                self._accept(t_ev, qe, dqe, we)
                self._apply_event(kind, legs, t_ev, qe, dqe)
                if self.status != "running":
                    break
                self._new_stepper(t_end)
                st = self._stepper
                continue
            q, dq = self._project(q, dq, feet)
            self._accept(st.t, q, dq, w, self._F_end)
            if self.opt.project_constraints and self.stance_leg and self.opt.base == "floating":
                st.replace_y(q + dq + [w])  # continue from the projected state
        self.stats["rejected_steps"] = self._rejected_base + st.nrejected

    @property
    def last_impact(self):
        """The last touchdown event, or None."""
        return next((e for e in reversed(self.events) if e.kind in ("touchdown", "double_touchdown")), None)

    def _check_ground(self, t, f):
        if "impact" not in self.opt.phases:
            # no touchdown guard is built; a swing foot that reaches the ground where a touchdown
            # would count leaves the scene's assumptions: say so instead of walking through the ground
            for leg in (1, 2):
                if leg != self.stance_leg and f[4 * (leg - 1) + 1] < 0.0 and (
                        not self.stance_leg or self.opt.touchdown_rule == "any"
                        or f[4 * (leg - 1)] > f[4 * (self.stance_leg - 1)]):
                    raise SceneAssumptionError(
                        f"foot {leg} touches the ground at t={t:.9g} s (it is {-f[4 * (leg - 1) + 1]:.3g} m below "
                        f"at the end of the step), but this scene has no impact phase: add 'impact' to its phases")
            return
        for leg in (1, 2):
            if leg != self.stance_leg and f[4 * (leg - 1) + 1] < -self.opt.max_penetration:
                last = self.last_impact
                if last is not None and last.kind == "double_touchdown":
                    raise SimulationError(
                        f"foot {leg} goes {-f[4 * (leg - 1) + 1]:.3g} m into the ground at t={t:.9g} s after the "
                        f"double touchdown at t={last.time:.9g} s: double support is not modelled (the run "
                        f"continued on foot {last.leg} only)")
                if last is not None and last.warnings and leg == last.stance_leg_before:
                    raise SimulationError(
                        f"foot {leg} goes {-f[4 * (leg - 1) + 1]:.3g} m into the ground at t={t:.9g} s: at the "
                        f"impact of t={last.time:.9g} s {'; '.join(last.warnings)}, so the feet stay in "
                        f"contact (impacts accumulating, Zeno-like, or double support), which the model "
                        f"does not cover")
                raise SimulationError(
                    f"foot {leg} is {-f[4 * (leg - 1) + 1]:.3g} m below the ground at t={t:.9g} s: the robot fell "
                    f"or the foot passed the ground where no touchdown counts (touchdown_rule="
                    f"{self.opt.touchdown_rule!r}, phases={sorted(self.opt.phases)})")

    def _project(self, q, dq, f):
        """Measure the stance constraint drift and (by default) remove it; ``f`` is _feet(q, dq)."""
        if not self.stance_leg or self.opt.base == "fixed":
            return q, dq
        leg = self.stance_leg
        i = 4 * (leg - 1)
        fx = f[i]
        fy = f[i + 1] - self._tan_s * fx        # f holds the height above the (sloped) ground
        self.stats["max_constraint_drift_position"] = max(self.stats["max_constraint_drift_position"],
                                                          math.hypot(fx - self.pin[0], fy - self.pin[1]))
        self.stats["max_constraint_drift_velocity"] = max(self.stats["max_constraint_drift_velocity"],
                                                          math.hypot(f[i + 2], f[i + 3]))
        if not self.opt.project_constraints:
            return q, dq
        q = list(q)
        dq = list(dq)
        q[0] += self.pin[0] - fx
        q[1] += self.pin[1] - fy
        dq[0] -= f[i + 2]                 # J = [I2 | A]: subtracting J dq from dq_base makes J dq = 0
        dq[1] -= f[i + 3] - self._tan_s * f[i + 2]
        return q, dq

    def _accept(self, t, q, dq, w, F=None):
        """The state (q, dq: lists) at t becomes the current one, and a sample."""
        self.t = float(t)
        self.q, self.dq, self.work = np.array(q), np.array(dq), float(w)
        if F is None:
            F = self._force_at(self.t, list(q), list(dq)) if (self.opt.compute_grf and self.stance_leg) else [0.0, 0.0]
        self._record(self.q, self.dq, self.stance_leg, F, (q, dq))

    def _record(self, q, dq, leg, F, lists=None):
        """A sample of the arrays q, dq (``lists``: the same as lists, if at hand) and the energy balance."""
        T, V = gen.energy(*(lists or (q.tolist(), dq.tolist())), self.model.k["energy"])
        E = T + V
        residual = E - self.E0 - self.work + self.energy_lost
        self.stats["max_energy_balance_residual"] = max(self.stats["max_energy_balance_residual"], abs(residual))
        if not self.opt.keep_samples:
            self._samples.clear()
        self._samples.append((self.t, q, dq, leg, F, list(self._u), residual))

    def _detect(self, st, q1, dq1, feet1):
        """Earliest guard crossing inside the last step: (time, kind, legs) or None.
        ``feet1`` is _feet(q1, dq1), the step's end."""
        guards = self._guards()
        self._F_end = None
        if not guards:
            self._update_arming(feet1)
            return None
        # the step's start is the last step's end: its feet and force are known (the projection
        # since moved the state by the drift only, ~1e-14)
        q0 = dq0 = None
        if self._feet_end_t == st.t_old:
            feet0 = self._feet_end
        else:
            q0, dq0, _ = self._to_phys(st.y_old)
            feet0 = self._feet(q0, dq0)
        self._feet_end, self._feet_end_t = feet1, st.t
        F0 = F1 = None
        if self.stance_leg:
            if self._last_start_F_t == st.t_old:
                F0 = self._last_start_F
            else:
                if q0 is None:
                    q0, dq0, _ = self._to_phys(st.y_old)
                F0 = self._force_at(st.t_old, q0, dq0)
            # our steppers evaluate the right-hand side last at the step's end (FSAL): reuse its force
            # (the fixed-base right-hand side computes no force)
            F1 = (list(self._last_F) if st.last_eval_at_end and self.opt.base == "floating"
                  else self._force_at(st.t, q1, dq1))
            self._last_start_F, self._last_start_F_t = F1, st.t
        self._F_end = F1
        h = st.t - st.t_old
        roots = []
        for kind, leg in guards:
            g1 = self._guard_value(kind, leg, st.t, q1, dq1, feet1, F1)
            if (kind, leg) in self._latched:
                if g1 > 0:
                    self._latched.discard((kind, leg))
                continue
            g0 = self._guard_value(kind, leg, st.t_old, q0, dq0, feet0, F0)
            bracket = None
            if g0 > 0 and g1 <= 0:
                bracket = (st.t_old, st.t)
            elif kind == "touchdown" and g0 > 0 and g1 > 0:
                i = 4 * (leg - 1) + 3
                if _hermite_min(g0, feet0[i] * h, g1, feet1[i] * h) <= 0:
                    bracket = self._sample_bracket(st, kind, leg)
            if bracket is None:
                continue
            t_root = self._root(st, kind, leg, *bracket)
            if kind == "touchdown" and self.stance_leg and self.opt.touchdown_rule == "front":
                qr, dqr, _ = self._to_phys(st.dense_at(t_root))
                fr = self._feet(qr, dqr)
                if fr[4 * (leg - 1)] <= fr[4 * (self.stance_leg - 1)]:
                    self.stats["scuffs_ignored"] += 1
                    continue
            roots.append((t_root, kind, leg))
        if not roots:
            self._update_arming(feet1)
            return None
        roots.sort()
        t_first, kind, leg = roots[0]
        legs = [leg]
        if kind == "touchdown" and not self.stance_leg:
            legs += [r[2] for r in roots[1:] if r[1] == "touchdown" and r[0] - t_first <= self.opt.simultaneous_tol]
            if len(legs) == 1:  # the other foot may be within the tolerance without having crossed yet
                other = 3 - leg
                if self.armed[other - 1]:
                    qe, dqe, _ = self._to_phys(st.dense_at(t_first))
                    fe = self._feet(qe, dqe)
                    ht, vt = fe[4 * (other - 1) + 1], fe[4 * (other - 1) + 3]
                    if vt < 0 and ht <= -vt * self.opt.simultaneous_tol:
                        legs.append(other)
        return t_first, kind, sorted(set(legs))

    def _update_arming(self, f):
        for leg in (1, 2):
            if not self.armed[leg - 1] and leg != self.stance_leg and f[4 * (leg - 1) + 1] > self.opt.arm_height:
                self.armed[leg - 1] = True

    def _sample_bracket(self, st, kind, leg, n=8):
        ts = np.linspace(st.t_old, st.t, n + 1).tolist()
        prev = None
        for t in ts:
            q, dq, _ = self._to_phys(st.dense_at(t))
            g = self._guard_value(kind, leg, t, q, dq)
            if prev is not None and prev[1] > 0 and g <= 0:
                return prev[0], t
            prev = (t, g)
        return None

    def _root(self, st, kind, leg, ta, tb):
        def g(t):
            q, dq, _ = self._to_phys(st.dense_at(t))
            return self._guard_value(kind, leg, t, q, dq)
        ga, gb = g(ta), g(tb)
        if gb == 0.0:
            return tb
        if ga <= 0:
            return ta
        # the event time is the last time the guard is still positive or the first it is not;
        # take the root's right end so that the reset happens at or just after the crossing
        return brentq(g, ta, tb, xtol=self.opt.event_tol, rtol=4 * np.finfo(float).eps, maxiter=200)

    # -- resets -------------------------------------------------------------------------------
    def _apply_event(self, kind, legs, t, q, dq):
        model, old = self.model, self.stance_leg
        qa, dqa = np.array(q), np.array(dq)
        if kind == "touchdown":
            impact_leg = legs[0] if len(legs) == 1 else (1, 2)
            dq_plus, impulse = impact_map(model, qa, dqa, impact_leg)
            if len(legs) == 1:
                new, ev_kind = legs[0], "touchdown"
            else:
                n1 = self._normal_tangent(impulse[0:2])[0]
                n2 = self._normal_tangent(impulse[2:4])[0]
                new, ev_kind = (1 if n1 >= n2 else 2), "double_touchdown"
            loss = model.energy(qa, dqa) - model.energy(qa, dq_plus)
            warnings = self._impact_warnings(qa, dq_plus, impulse, legs, old)
            ev = Event(t, ev_kind, new, qa, dqa, dq_plus, impulse, old, new, loss, warnings)
            self.energy_lost += loss
            self.stance_leg = new
            self.pin = list(self._foot_xy(list(q), new))
            self.armed = [False, False] if len(legs) == 2 else self.armed
            self.armed[new - 1] = False
            if old:
                self.armed[old - 1] = False
            self.dq = dq_plus
            self._record(self.q, self.dq, self.stance_leg, self._force_at(t, list(q), dq_plus.tolist()))
            self.stats["impacts"] += 1
            self._push_event(ev)
            self._check_zeno(t)
            return
        if kind == "liftoff":
            ev = Event(t, "liftoff", old, qa, dqa, dqa.copy(), None, old, 0)
            if "flight" not in self.opt.phases:
                ev.kind = "error"
                ev.stance_leg_after = old
                ev.message = (f"the stance foot (leg {old}) would lift off at t={t:.9g} s (normal force "
                              "reaches zero), but this scene has no flight phase: add 'flight' to its phases")
                self._push_event(ev)
                self._stop("stopped", ev.message)
                return
            self.stance_leg = 0
            self.pin = None
            self.armed[old - 1] = False
            self._push_event(ev)
            return
        if kind == "slip":
            F = self._force_at(t, list(q), list(dq))
            n, tg = self._normal_tangent(F)
            ev = Event(t, "slip", old, qa, dqa, dqa.copy(), None, old, old,
                       message=f"the stance foot (leg {old}) would slip at t={t:.9g} s: |F_t| = {abs(tg):.6g} N "
                               f"> mu F_n = {self.mu * n:.6g} N (mu = {self.mu:g})")
            self._push_event(ev)
            self._latched.add(("slip", old))
            if self.opt.stop_on_slip:
                self._stop("stopped", ev.message + "; the model has no sliding phase (raise mu, or "
                           "set stop_on_slip=False to keep the foot pinned)")

    def _impact_warnings(self, q, dq_plus, impulse, legs, old):
        warnings = []
        f = self._feet(q.tolist(), dq_plus.tolist())
        if old and old not in legs and f[4 * (old - 1) + 3] < 0:
            warnings.append(f"the old stance foot (leg {old}) does not leave the ground after the impact "
                            f"(vertical velocity {f[4 * (old - 1) + 3]:.6g} m/s)")
        for j, leg in enumerate(legs):
            n, tg = self._normal_tangent(impulse[2 * j: 2 * j + 2])
            if n < 0:
                warnings.append(f"the impulse on foot {leg} pulls it into the ground (normal {n:.6g} N s)")
            elif self.mu is not None and abs(tg) > self.mu * n:
                warnings.append(f"the impulse on foot {leg} is outside the friction cone "
                                f"(|tangential| {abs(tg):.6g} > mu * normal {self.mu * n:.6g} N s)")
        return warnings

    def _push_event(self, ev):
        self.events.append(ev)
        self.stats["events"] = len(self.events)
        if len(self.events) >= self.opt.max_events:
            self._stop("stopped", f"stopped after {len(self.events)} events (max_events)")
        recent = self.events[-50:]
        if len(recent) == 50 and recent[-1].time - recent[0].time < 1e-9:
            self._stop("stopped", f"event loop: 50 events within 1e-9 s ending at t={ev.time:.9g} s "
                                  f"(last: {ev.kind} of leg {ev.leg}); the run stops instead of hanging")

    def _check_zeno(self, t):
        r = self._recent_impacts
        r.append(t)
        if len(r) > self.opt.zeno_count + 1:
            del r[0]
        if len(r) == self.opt.zeno_count + 1 and all(b - a < self.opt.zeno_interval for a, b in zip(r, r[1:])):
            msg = (f"{self.opt.zeno_count} impacts in a row less than {self.opt.zeno_interval:g} s apart "
                   f"ending at t={t:.9g} s: the impacts accumulate (Zeno behaviour); the run stops")
            self.events.append(Event(t, "zeno", self.stance_leg, self.q.copy(), self.dq.copy(), self.dq.copy(),
                                     message=msg))
            self._stop("stopped", msg)

    def _stop(self, status, message):
        self.status, self.message = status, message

    def _fail(self, message, status="failed"):
        msg = f"integration stopped at t={self.t:.9g} s: {message}"
        self.events.append(Event(self.t, "error", self.stance_leg, self.q.copy(), self.dq.copy(), self.dq.copy(),
                                 message=msg))
        self.stats["events"] = len(self.events)
        self._stop(status, msg)

    @property
    def ground_force(self):
        """Ground force on the stance foot at the last accepted sample, [Fx, Fy] (N); zeros in flight."""
        return list(self._samples[-1][4])

    # -- results ------------------------------------------------------------------------------
    def result(self) -> SimulationResult:
        s = self._samples
        t = np.array([x[0] for x in s])
        stats = dict(self.stats)
        stats["simulated_time"] = self.t - self.t0
        stats["real_time_factor"] = stats["simulated_time"] / stats["wall_time"] if stats["wall_time"] > 0 else math.inf
        stats["energy_balance_residual"] = float(s[-1][6]) if s else 0.0
        stats["energy_lost_at_impacts"] = self.energy_lost
        stats["motor_work"] = self.work
        stats["method"] = self.method
        stats["generated_code"] = GENERATED_CODE   # "C" (the compiled twin) or "Python": same results
        return SimulationResult(
            t=t, q=np.array([x[1] for x in s]), dq=np.array([x[2] for x in s]),
            stance_leg=np.array([x[3] for x in s], dtype=int), grf=np.array([x[4] for x in s]),
            u=np.array([x[5] for x in s]), events=list(self.events), stats=stats,
            status="completed" if self.status == "running" else self.status, message=self.message)


def _two_finite_floats(u):
    """[u0, u1] as Python floats if u is two finite numbers, else None (runs at every evaluation)."""
    try:
        u0, u1 = u
        u0, u1 = float(u0), float(u1)
    except (TypeError, IndexError, ValueError):
        return None
    return [u0, u1] if math.isfinite(u0 + u1) else None   # nan + x, inf - inf: nan; inf + x: inf


def _torques(u, t):
    """The two torques a controller returned, as finite floats, or a SimulationError."""
    out = _two_finite_floats(u)
    if out is None:
        raise SimulationError(f"the controller returned {u!r} at t={t:.9g} s: it must return two finite torques")
    return out


def _hermite_min(g0, d0, g1, d1):
    """Lower bound check of the cubic Hermite through (0, g0, d0) and (1, g1, d1) on [0, 1]."""
    # p(s) = g0 + d0 s + (3(g1-g0) - 2 d0 - d1) s^2 + (2(g0-g1) + d0 + d1) s^3
    a, b, c = 3 * (2 * (g0 - g1) + d0 + d1), 2 * (3 * (g1 - g0) - 2 * d0 - d1), d0
    cands = [0.0, 1.0]
    if abs(a) > 1e-300:
        disc = b * b - 4 * a * c
        if disc >= 0:
            r = math.sqrt(disc)
            cands += [(-b + r) / (2 * a), (-b - r) / (2 * a)]
    elif abs(b) > 1e-300:
        cands.append(-c / b)
    best = min(g0, g1)
    for s in cands:
        if 0.0 < s < 1.0:
            best = min(best, g0 + s * (d0 + s * ((3 * (g1 - g0) - 2 * d0 - d1) + s * (2 * (g0 - g1) + d0 + d1))))
    return best


def simulate(model, q0, dq0, t_final, controller=None, stance_leg=1, rtol=1e-9, atol=1e-9,
             method="dop853", control_period=None, mu=None, **options) -> SimulationResult:
    """Simulate the hybrid biped from (q0, dq0) to ``t_final`` seconds.

    ``controller(t, q, dq, stance_leg) -> u`` (u[0] on hip 1, u[1] on hip 2, physical legs) is called
    at every right-hand-side evaluation, or once per ``control_period`` and held (zero-order hold,
    as the node does; the torque is held through an impact inside the period). ``mu=None`` means
    enough friction. ``options`` are the fields of :class:`Options` (``base``, ``phases``,
    ``touchdown_rule``, ``stop_on_slip``, ``project_constraints``, ``step`` for fixed-step methods,
    ``slope``, ...). A run that leaves the scene's assumptions or whose integration fails ends with
    ``result.status`` "stopped" or "failed", a final event, and ``result.message``; bad arguments
    raise ``ValueError``.
    """
    if not (isinstance(t_final, (int, float)) and math.isfinite(t_final) and t_final >= 0):
        raise ValueError(f"t_final must be a finite number >= 0, got {t_final!r}")
    if control_period is not None and not (isinstance(control_period, (int, float)) and control_period > 0):
        raise ValueError(f"control_period must be None or a positive number of seconds, got {control_period!r}")
    if controller is not None and not callable(controller):
        raise ValueError("controller must be callable as controller(t, q, dq, stance_leg) -> u")
    sim = HybridSimulator(model, q0, dq0, stance_leg, rtol, atol, method, mu, **options)
    if controller is None:
        sim.advance(t_final)
    elif control_period is None:
        sim.advance(t_final, controller=controller)
    else:
        k = 0
        while sim.status == "running" and sim.t < t_final:
            t_next = min((k + 1) * control_period, t_final)
            if t_next <= sim.t:
                k += 1
                continue
            try:
                u = sim._call_controller(sim.t, sim.q.tolist(), sim.dq.tolist(), controller)
            except SimulationError as exc:
                sim._fail(str(exc))
                break
            sim.advance(t_next, u=u)
            k += 1
    return sim.result()
