"""The stability suite behind ``biped-sim stability``: stiff and extreme cases.

Owns the suite's cases and their verdicts. Every case runs the engine (``hybrid.simulate``) and
checks that the outcome is either a result that keeps its invariants (finite numbers, bounded
constraint drift, the energy balance within tolerance, the expected events) or a clear error that
names the cause (``ValueError`` or ``status`` "failed"/"stopped" with a message) -- never a silent
NaN, a hang or an endless event loop. Each case returns one :class:`Verdict` with its figures.

``run_suite(quick, broken)``: ``broken`` names a deliberately wrong setting (see ``BREAKS``) that
must make one case FAIL, so the checks are shown to be able to fail.

The engine has rigid contact only (no compliant ground), constraint stabilisation by projection
after every step (no Baumgarte terms), and a mass matrix that is positive definite everywhere; the
only singular configurations are those of the contact Jacobians (two feet at one point).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from biped_sim.analysis.edge_cases import edge_verdicts
from biped_sim.analysis.verify import result_violations
from biped_sim.control.walking import WalkingController
from biped_sim.engine.hybrid import HybridSimulator
from biped_sim.engine.model import BipedModel
from biped_sim.engine.simulate import simulate as _simulate, stance_state

#: deliberately broken settings, each with the case it must make FAIL
BREAKS = {
    "projection": ("constraint_drift", "no projection and rtol = atol = 1e-2: the raw drift exceeds its bound"),
    "event_tol": ("grazing_touchdown", "event_tol = 1e-3 s: the touchdown time is off by far more than 1e-9 s"),
    "zeno": ("near_zeno", "zeno_count = 10**6 and check_invariants = False: neither the Zeno cap nor the check "
                          "of the Zeno limit (the old stance foot no longer leaves the ground) fires"),
}


@dataclass
class Verdict:
    group: str
    name: str
    ok: bool | None        # None: not applicable (SKIP)
    figures: str
    seconds: float = 0.0

    @property
    def word(self):
        return "SKIP" if self.ok is None else ("PASS" if self.ok else "FAIL")

    def line(self):
        return f"{self.word}  {self.group:9s} {self.name:26s} {self.figures}  [{self.seconds:.2f} s]"


class HipPD:
    """High-gain hip PD: u_i = -kp (q_i - target_i) - kd dq_i on the relative hip angles q1, q2."""

    def __init__(self, kp, kd, target):
        self.kp, self.kd = float(kp), float(kd)
        self.target = np.asarray(target, float)

    def __call__(self, t, q, dq, stance_leg):
        return -self.kp * (np.asarray(q)[2:4] - self.target) - self.kd * np.asarray(dq)[2:4]


class ConstantTorque:
    def __init__(self, u):
        self.u = np.asarray(u, float)

    def __call__(self, t, q, dq, stance_leg):
        return self.u


#: every result a case produced, judged by run_suite: a row passes only if each keeps the invariants
_RUNS: list = []


def simulate(*a, **k):
    _RUNS.append(_simulate(*a, **k))
    return _RUNS[-1]


def _finite(r):
    return bool(np.isfinite(r.q).all() and np.isfinite(r.dq).all() and np.isfinite(r.grf).all())


def _energy_scale(model, r):
    """A scale (J) for the energy-balance check: the largest |T| + |V| seen, at least m g l."""
    p = model.parameters
    m = p.m_torso + 2 * p.m_leg
    scale = m * max(p.g, 1.0) * p.l_leg
    for i in range(0, len(r.t), max(1, len(r.t) // 50)):
        scale = max(scale, abs(model.kinetic_energy(r.q[i], r.dq[i])) + abs(model.potential_energy(r.q[i])))
    return scale + abs(r.stats["motor_work"]) + abs(r.stats["energy_lost_at_impacts"])


def _clear(r):
    """A run that ended early says why."""
    return r.status == "completed" or bool(r.message)


def _invariants(model, r, drift_tol=1e-6, energy_rtol=1e-7):
    """(ok, figures) of the common invariants of a run that did not fail."""
    fin = _finite(r)
    drift = r.stats["max_constraint_drift_position"]
    eb = r.stats["max_energy_balance_residual"]
    scale = _energy_scale(model, r)
    ok = fin and drift <= drift_tol and eb <= energy_rtol * scale and _clear(r)
    return ok, f"finite={fin} drift={drift:.2g} m energy-balance={eb:.2g} J (scale {scale:.3g} J)"


def _timed(fn, *a, **k):
    t0 = time.perf_counter()
    out = fn(*a, **k)
    return out, time.perf_counter() - t0


# -- stiff --------------------------------------------------------------------------------------
def case_stiff_pd(quick, broken):
    """Stance on leg 1 (swing foot ignores the ground), hip PD holding a posture 0.01 rad away from
    the start: explicit dop853 and rk4 against implicit radau and bdf, gains up to 1e6."""
    m = BipedModel()
    out = []
    q0, dq0 = stance_state(m, [math.pi - 0.2, math.pi + 0.3, 0.2], [0.0, 0.0, 0.0])
    T = 0.2
    for kp in ((1e2, 1e6) if quick else (1e2, 1e4, 1e6)):
        kd = 0.02 * kp + 20.0            # overdamped at high gain: a fast eigenvalue ~ kd / I
        ctrl = HipPD(kp, kd, q0[2:4] + [0.0, 0.01])
        runs = {}
        t0 = time.perf_counter()
        methods = [("dop853", {}), ("radau", {}), ("bdf", {}), ("rk4", dict(step=1e-3))]
        for meth, kw in methods:
            r, w = _timed(simulate, m, q0, dq0, T, controller=ctrl, method=meth, rtol=1e-8, atol=1e-8,
                          phases=frozenset({"stance"}), scuff_rule="behind", scuff_depth=0.05, **kw)
            runs[meth] = (r, w)
        done = {k: v for k, v in runs.items() if v[0].status == "completed"}
        ends = [np.concatenate([v[0].q[-1], v[0].dq[-1]]) for v in done.values()]
        spread = max((float(np.max(np.abs(e - ends[0]))) for e in ends), default=math.inf)
        ok = ("radau" in done and "bdf" in done and spread <= 1e-4
              and all(_finite(v[0]) or v[0].status == "failed" for v in runs.values())
              and all(_clear(v[0]) for v in runs.values()))
        for k, (r, _wall) in runs.items():
            if k in done:
                ok = ok and _invariants(m, r, drift_tol=1e-6, energy_rtol=1e-5)[0]
        figs = "; ".join(f"{k} {r.stats['steps']} steps {r.stats['rhs_evaluations']} rhs {w:.2f} s"
                         + ("" if r.status == "completed" else f" {r.status.upper()}: {r.message[:60]}")
                         for k, (r, w) in runs.items())
        out.append(Verdict("stiff", f"hip_pd kp={kp:.0e} kd={kd:.0e}", ok,
                           f"{figs}; final-state spread {spread:.1g}", time.perf_counter() - t0))
    return out


def case_constraint_drift(quick, broken):
    """The stance constraint without projection (raw drift of the floating-base DAE) on a walk."""
    m = BipedModel()
    c = WalkingController(m)
    tol = 1e-2 if broken == "projection" else 1e-9
    t0 = time.perf_counter()
    raw = simulate(m, *c.initial_state(), 5.0, controller=c, rtol=tol, atol=tol, project_constraints=False)
    proj = simulate(m, *c.initial_state(), 5.0, controller=c)
    bound = 1e-8
    d_raw, d_proj = raw.stats["max_constraint_drift_position"], proj.stats["max_constraint_drift_position"]
    ok = (raw.status == proj.status == "completed" and _finite(raw) and d_raw <= bound and d_proj <= bound
          and len(raw.impacts) == len(proj.impacts) == 10)
    return [Verdict("stiff", "constraint_drift", ok,
                    f"walk 5 s, 10 impacts: raw drift (no projection, tol {tol:g}) {d_raw:.2g} m, "
                    f"|J dq| {raw.stats['max_constraint_drift_velocity']:.2g} m/s; with projection "
                    f"(per step, before projecting) {d_proj:.2g} m; bound {bound:g} m",
                    time.perf_counter() - t0)]


def case_compliant_ground(quick, broken):
    return [Verdict("stiff", "compliant_ground", None,
                    "not applicable: the engine has rigid contact only (no compliant ground model)")]


# -- extreme parameters --------------------------------------------------------------------------
def case_mass_ratios(quick, broken):
    out = []
    ratios = (1e-4, 1.0, 1e4) if quick else (1e-4, 1e-2, 1.0, 1e2, 1e4)
    for kind in ("mass+inertia", "inertia"):
        t0 = time.perf_counter()
        figs, ok = [], True
        for rr in ratios:
            kw = dict(I_leg=1.0 * rr) if kind == "inertia" else dict(m_leg=10.0 * rr, I_leg=1.0 * rr)
            m = BipedModel(**kw)
            q0, dq0 = stance_state(m, [math.pi - 0.2, math.pi + 0.3, 0.2], [0.6, 0.0, 0.0])
            r = simulate(m, q0, dq0, 0.5)
            good, _ = _invariants(m, r, drift_tol=1e-6, energy_rtol=1e-7)
            clear_end = r.status in ("completed", "stopped") or (r.status == "failed" and bool(r.message))
            good = good if r.status != "failed" else (clear_end and _finite(r))
            ok = ok and good
            figs.append(f"{rr:.0e}: {r.status} {r.stats['steps']} steps {len(r.impacts)} imp "
                        f"eb {r.stats['max_energy_balance_residual'] / _energy_scale(m, r):.1g}"
                        + (f" ({r.message[:50]})" if r.status != "completed" else ""))
        out.append(Verdict("extreme", f"leg/torso {kind} ratio", ok, "; ".join(figs), time.perf_counter() - t0))
    return out


def case_large_torque(quick, broken):
    m = BipedModel()
    q0 = np.array([0.0, 50.0, math.pi - 0.3, math.pi + 0.3, 0.0])
    out = []
    for u, T in ((1e4, 0.02), (1e7, 1.0)):
        t0 = time.perf_counter()
        r = simulate(m, q0, np.zeros(5), T, controller=ConstantTorque([u, -u]), stance_leg=0)
        if r.status == "completed":
            ok, figs = _invariants(m, r, energy_rtol=1e-8)
        else:
            ok, figs = (_clear(r) and "diverging" in r.message), f"{r.status}: {r.message[:110]}"
        out.append(Verdict("extreme", f"torque {u:.0e} N m, {T:g} s", ok,
                           f"flight, {r.stats['steps']} steps, max |dq| {np.max(np.abs(r.dq)):.3g}; {figs}",
                           time.perf_counter() - t0))
    return out


def case_large_velocity(quick, broken):
    m = BipedModel()
    q0 = np.array([0.0, 100.0, math.pi - 0.3, math.pi + 0.3, 0.0])
    t0 = time.perf_counter()
    r = simulate(m, q0, np.array([0.0, 0.0, 1e3, -1e3, 5e2]), 0.1, stance_leg=0)
    ok, figs = _invariants(m, r, energy_rtol=1e-9)
    ok = ok and r.status == "completed"
    return [Verdict("extreme", "joint rates 1e3 rad/s", ok,
                    f"flight 0.1 s, {r.stats['steps']} steps; {figs}", time.perf_counter() - t0)]


def case_near_singular(quick, broken):
    """Both feet at (nearly) one point: the two contact Jacobians coincide; the double impact's
    matrix is (nearly) singular."""
    m = BipedModel()
    out = []
    for eps in (1e-6, 0.0):
        t0 = time.perf_counter()
        q0 = np.array([0.0, 1.01, math.pi - eps, math.pi + eps, 0.0])
        r = simulate(m, q0, np.zeros(5), 0.1, stance_leg=0)
        kinds = [e.kind for e in r.events]
        loss = [e.energy_loss for e in r.events if e.kind in ("touchdown", "double_touchdown")]
        ok = _finite(r) and _clear(r) and all(l >= -1e-9 for l in loss) and (
            r.status == "failed" or "double_touchdown" in kinds or "touchdown" in kinds)
        imp = [np.round(e.impulse, 3).tolist() for e in r.impacts]
        out.append(Verdict("extreme", f"coincident feet eps={eps:g}", ok,
                           f"{r.status} events {kinds} impulses {imp} energy loss {np.round(loss, 6).tolist()}"
                           + (f": {r.message[:90]}" if r.message else ""), time.perf_counter() - t0))
    return out


# -- hybrid edge cases ----------------------------------------------------------------------------
def case_grazing(quick, broken):
    """Free fall from rest in flight: foot 1 starts h0 above the ground, so it lands at exactly
    t* = sqrt(2 h0 / g) with vertical speed sqrt(2 g h0) (uniform gravity moves every point alike)."""
    m = BipedModel()
    out = []
    opts = dict(event_tol=1e-3) if broken == "event_tol" else {}
    for h0 in (1e-4, 1e-8):
        t0 = time.perf_counter()
        q0 = np.array([0.0, math.cos(0.3) + h0, math.pi - 0.3, math.pi + 0.5, 0.0])
        ts = math.sqrt(2 * h0 / m.parameters.g)
        r = simulate(m, q0, np.zeros(5), ts + 0.05, stance_leg=0, **opts)
        tds = [e for e in r.events if e.kind == "touchdown"]
        err = abs(tds[0].time - ts) if tds else math.inf
        ok = len(tds) == 1 and tds[0].leg == 1 and err <= 1e-9 and _finite(r) and _clear(r)
        out.append(Verdict("hybrid", f"grazing_touchdown h0={h0:g}", ok,
                           f"vertical speed {math.sqrt(2 * m.parameters.g * h0):.2g} m/s, {len(tds)} touchdown, "
                           f"|t - t*| = {err:.2g} s, {r.status}" + (f": {r.message[:80]}" if r.message else ""),
                           time.perf_counter() - t0))
    return out


def _rocking(m, zeno_opts, kp=1e4, kd=200.0):
    q0, dq0 = stance_state(m, [math.pi - 0.3, math.pi + 0.3, 0.0], [0.0, 0.0, 0.3])
    return simulate(m, q0, dq0, 5.0, controller=HipPD(kp, kd, q0[2:4]), touchdown_rule="any",
                    max_events=1000, **zeno_opts)


def case_near_zeno(quick, broken):
    """A rigid V (hips held by a PD) rocking from foot to foot: each plastic impact removes energy,
    the time between impacts shrinks geometrically (Zeno). With zeno_interval 0.07 s and zeno_count
    4 the engine must stop with a "zeno" event; with the default cap (20 impacts closer than 1e-6 s)
    it must stop as Zeno too, where the old stance foot no longer leaves the ground (the Zeno limit)."""
    m = BipedModel()
    t0 = time.perf_counter()
    opts = dict(zeno_interval=0.07, zeno_count=4)
    if broken == "zeno":
        opts = dict(zeno_interval=0.07, zeno_count=10**6, check_invariants=False)
    r = _rocking(m, opts)
    gaps = np.diff([e.time for e in r.impacts])
    last = r.events[-1] if r.events else None
    ok = (last is not None and last.kind == "zeno" and r.status == "stopped" and _finite(r)
          and len(gaps) >= 4 and bool(np.all(np.diff(gaps) < 0)))
    d = _rocking(m, {} if broken != "zeno" else dict(check_invariants=False))
    dgaps = np.diff([e.time for e in d.impacts])
    ok = ok and d.status == "stopped" and bool(d.events) and d.events[-1].kind == "zeno"
    return [Verdict("hybrid", "near_zeno", ok,
                    f"{len(r.impacts)} impacts, gaps {np.round(gaps[:3], 4).tolist()} .. "
                    f"{np.round(gaps[-3:], 5).tolist()} s, end: {last.kind if last else None} ({r.status}); "
                    f"default cap (1e-6 s x 20): {len(d.impacts)} impacts, last gap "
                    f"{dgaps[-1] if len(dgaps) else math.nan:.2g} s, {d.status}: {d.message[:90]}",
                    time.perf_counter() - t0)]


def case_double_touchdown(quick, broken):
    """Symmetric legs falling from rest in flight: both feet land at once, t* = sqrt(2 h / g)."""
    m = BipedModel()
    t0 = time.perf_counter()
    q0 = np.array([0.0, 0.96, math.pi - 0.3, math.pi + 0.3, 0.0])
    h = 0.96 - math.cos(0.3)
    ts = math.sqrt(2 * h / m.parameters.g)
    r = simulate(m, q0, np.zeros(5), ts + 0.05, stance_leg=0)
    dd = [e for e in r.events if e.kind == "double_touchdown"]
    err = abs(dd[0].time - ts) if dd else math.inf
    ok = len(dd) == 1 and err <= 1e-9 and len(dd[0].impulse) == 4 and _finite(r) and _clear(r) \
        and dd[0].energy_loss >= 0
    return [Verdict("hybrid", "double_touchdown", ok,
                    f"events {[e.kind for e in r.events]}, |t - t*| = {err:.2g} s, impulses "
                    f"{np.round(dd[0].impulse, 3).tolist() if dd else None} N s, {r.status}"
                    + (f": {r.message[:80]}" if r.message else ""), time.perf_counter() - t0)]


def case_guard_after_reset(quick, broken):
    """A swing foot exactly on the ground (guard = 0) at the start, and after every impact of the
    long walk: no touchdown may fire at once."""
    m = BipedModel()
    t0 = time.perf_counter()
    r = _rocking(m, dict(zeno_interval=0.07, zeno_count=4))
    first = r.impacts[0].time if r.impacts else math.inf
    c = WalkingController(m)
    w = simulate(m, *c.initial_state(), 5.0, controller=c)
    gaps = np.diff([0.0] + [e.time for e in w.impacts])
    ok = first > 1e-3 and len(w.impacts) == 10 and gaps.min() > 0.3
    return [Verdict("hybrid", "guard_zero_after_reset", ok,
                    f"swing foot on the ground at t=0: first touchdown at {first:.4g} s; walk: 10 resets, "
                    f"shortest step {gaps.min():.4g} s", time.perf_counter() - t0)]


# -- long runs -------------------------------------------------------------------------------------
def case_long_walk(quick, broken):
    m = BipedModel()
    c = WalkingController(m)
    n = 40 if quick else 1000
    t0 = time.perf_counter()
    sim = HybridSimulator(m, *c.initial_state(), max_events=n)
    sim.advance(n * 0.49 + 1.0, controller=c)
    r = sim.result()
    _RUNS.append(r)
    wall = time.perf_counter() - t0
    # energy-balance residual at each impact (after the reset): growth per step by least squares
    res = [abs(e) for i, e in enumerate(r.energy_balance[1:], 1) if r.t[i] == r.t[i - 1]]
    k = np.arange(1, len(res) + 1)
    slope = float(np.polyfit(k, res, 1)[0]) if len(res) > 2 else math.nan
    gaps = np.diff([e.time for e in r.impacts])
    ok, figs = _invariants(m, r, drift_tol=1e-9, energy_rtol=1e-8)
    ok = ok and len(r.impacts) == n and r.status == "stopped" and gaps.min() > 0.3
    return [Verdict("long", f"walk {n} steps", ok,
                    f"{len(r.impacts)} impacts in {r.t[-1]:.1f} s simulated, {wall:.1f} s wall; {figs}; "
                    f"energy-balance growth {slope:.2g} J/step (final {res[-1] if res else 0:.2g} J); "
                    f"step time {gaps.min():.4f}..{gaps.max():.4f} s", wall)]


def case_long_passive(quick, broken):
    """A long passive run: the free three-link chain spinning in flight without gravity (no contact,
    no torque): energy must stay constant; its drift per second is reported."""
    m = BipedModel(g=0.0)
    T = 20.0 if quick else 200.0
    q0 = np.array([0.0, 10.0, math.pi - 0.3, math.pi + 0.5, 0.2])
    dq0 = np.array([0.0, 0.0, 3.0, -2.0, 1.0])
    h = 1e-7    # base velocity that keeps the centre of mass at rest (it stays 10 m up, no contact)
    dq0[:2] -= (m.com_position(q0 + h * dq0) - m.com_position(q0 - h * dq0)) / (2 * h)
    t0 = time.perf_counter()
    r = simulate(m, q0, dq0, T, stance_leg=0)
    ok, figs = _invariants(m, r, energy_rtol=1e-8)
    ok = ok and r.status == "completed" and not r.events
    eb = r.stats["max_energy_balance_residual"]
    return [Verdict("long", f"passive spin {T:g} s", ok,
                    f"{r.stats['steps']} steps, {len(r.events)} events; {figs}; growth {eb / T:.2g} J/s",
                    time.perf_counter() - t0)]


# -- bad numbers ----------------------------------------------------------------------------------
def case_bad_numbers(quick, broken):
    m = BipedModel()
    c = WalkingController(m)
    q0, dq0 = c.initial_state()
    nan, inf = math.nan, math.inf
    checks = []

    def expect_value_error(label, fn, word):
        try:
            fn()
        except ValueError as exc:
            checks.append((label, word in str(exc), f"ValueError: {str(exc)[:70]}"))
            return
        checks.append((label, False, "no error"))

    expect_value_error("NaN in q0", lambda: simulate(m, np.where(np.arange(5) == 2, nan, q0), dq0, 1.0), "q0")
    expect_value_error("inf in dq0", lambda: simulate(m, q0, np.where(np.arange(5) == 0, inf, dq0), 1.0), "dq0")
    expect_value_error("NaN parameter", lambda: BipedModel(m_leg=nan), "m_leg")
    expect_value_error("inf t_final", lambda: simulate(m, q0, dq0, inf), "t_final")

    def advance_nan():
        sim = HybridSimulator(m, q0, dq0)
        sim.advance(0.1, u=[nan, 0.0])
    expect_value_error("NaN held torque", advance_nan, "u")
    for label, bad in (("NaN torque from controller", nan), ("inf torque from controller", inf)):
        r = simulate(m, q0, dq0, 1.0, controller=lambda t, q, dq, leg, b=bad: [b, 0.0])
        checks.append((label, r.status == "failed" and "controller" in r.message and _finite(r),
                       f"{r.status}: {r.message[:70]}"))
    r = simulate(m, q0, dq0, 1.0, controller=lambda t, q, dq, leg: [0.0, 0.0] if t < 0.3 else [nan, nan],
                 control_period=0.01)
    checks.append(("NaN torque at t=0.3 (held)", r.status == "failed" and "controller" in r.message and _finite(r),
                   f"{r.status}: {r.message[:70]}"))
    return [Verdict("bad", label, ok, fig) for label, ok, fig in checks]


def case_edges(quick, broken):
    """The hybrid edges (biped_sim/analysis/edge_cases.py)."""
    return edge_verdicts(quick, lambda name, ok, figures, seconds: Verdict("edge", name, ok, figures, seconds))


CASES = [case_stiff_pd, case_constraint_drift, case_compliant_ground, case_mass_ratios, case_large_torque,
         case_large_velocity, case_near_singular, case_grazing, case_near_zeno, case_double_touchdown,
         case_guard_after_reset, case_long_walk, case_long_passive, case_bad_numbers, case_edges]


def run_suite(quick=False, broken=None, report=None, only=None):
    """Run the cases; ``report(verdict)`` is called as each verdict is known. Returns the verdicts.
    An exception inside a case is a FAIL of that case with the exception in its figures."""
    if broken is not None and broken not in BREAKS:
        raise ValueError(f"unknown --break {broken!r}; choose one of {', '.join(BREAKS)}")
    out = []
    for case in CASES:
        name = case.__name__[5:]
        if only and name not in only:
            continue
        t0 = time.perf_counter()
        _RUNS.clear()
        try:
            vs = case(quick, broken)
        except Exception as exc:  # a case that crashes is a FAIL with the cause, never a silent pass
            vs = [Verdict("error", name, False, f"{type(exc).__name__}: {exc}", time.perf_counter() - t0)]
        # a row is PASS only if every sample of every run of its case keeps the invariants
        bad = [v for r in _RUNS for v in result_violations(BipedModel(), r)]
        if bad:
            for v in vs:
                if v.ok:
                    v.ok, v.figures = False, f"{v.figures}; INVARIANT: {bad[0]}"
        for v in vs:
            out.append(v)
            if report:
                report(v)
    return out
