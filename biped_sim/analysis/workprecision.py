"""Error against run time (work-precision) of the integrators, on three hybrid cases.

Owns the accuracy benchmark behind ``biped-sim accuracy``. Every integrator of
``integrators.py`` runs through the same engine (``hybrid.simulate``) over a ladder of tolerances
(adaptive methods) or step sizes (fixed-step methods) on:

  * ``passive_fall``  stance on leg 1, u = 0, ``phases={"stance"}``, the swing leg raised behind:
                      the pure constrained ODE for 1 s, until just before the liftoff (1.08 s);
  * ``walking``       the reference ``WalkingController`` for 5 s: 10 impacts;
  * ``drop``          from flight (``stance_leg=0``), u = 0, 0.9 s: lands on foot 1 and falls in stance.

Errors are measured against a reference run (``dop853`` at rtol = atol = 1e-13) whose own 7th-order
dense output is kept for every step, so that it can be evaluated at any time. The reference's own
error is estimated by a second, independent run
(``radau``, an implicit collocation method, or ``scipy_dop853``, scipy's separate implementation)
measured exactly like a test run. Per run:

  * ``err_end``   max-norm of (q, dq) at the last sample minus the reference's (SI units mixed:
                  m, rad, m/s, rad/s);
  * ``err_run``   max over the run's samples (every accepted step) of the same norm against the
                  reference's dense output at the sample's time *on the same hybrid segment* (between
                  the same two impacts);
                  samples that lie between a run's event time and the reference's are skipped: that
                  mismatch is the event-time error;
  * ``err_event`` max |t_event - t_event_ref| over the impacts (inf when the number of impacts
                  differs: the run is then wrong, whatever its state error says);
  * ``drift``     the largest stance-foot position drift seen before projection (m);
  * ``energy``    the largest |energy-balance residual| (J);
  * ``time``      the median wall time of ``repeats`` runs in this process.

The plain ``scipy.integrate.solve_ivp(method="DOP853", events=...)`` on the passive fall (own
right-hand side, terminal event on the swing foot's height, no projection) is the baseline
outside the engine.
"""
from __future__ import annotations

import csv
import math
import statistics
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from biped_sim.config.progress import Progress as _Display
from biped_sim.control.walking import WalkingController
from biped_sim.engine.dynamics import stance_floating_fast
from biped_sim.engine.hybrid import HybridSimulator
from biped_sim.engine.integrators import FIXED_STEP_METHODS
from biped_sim.engine.model import BipedModel
from biped_sim.engine.simulate import simulate, stance_state

DEFAULT = ("dop853", 1e-9)  # simulate()'s default: method dop853, rtol = atol = 1e-9

# (method, settings): tolerances for adaptive methods, step sizes (s) for fixed-step ones
LADDER_FULL = {
    "dop853": [1e-3, 1e-5, 1e-7, 1e-9, 1e-11],
    "scipy_dop853": [1e-3, 1e-5, 1e-7, 1e-9, 1e-11],
    "scipy_rk45": [1e-3, 1e-5, 1e-7, 1e-9],
    "dopri5": [1e-3, 1e-5, 1e-7, 1e-9],
    "radau": [1e-3, 1e-5, 1e-7, 1e-9],
    "bdf": [1e-3, 1e-5, 1e-7],
    "rk4": [1e-2, 5e-3, 2.5e-3, 1.25e-3],
    "semi_implicit_euler": [4e-3, 1e-3, 2.5e-4],
    "solve_ivp_DOP853": [1e-3, 1e-5, 1e-7, 1e-9, 1e-11],
}
LADDER_QUICK = {
    "dop853": [1e-5, 1e-9],
    "scipy_dop853": [1e-5, 1e-9],
    "scipy_rk45": [1e-5],
    "dopri5": [1e-5],
    "radau": [1e-5],
    "rk4": [1e-2, 5e-3],
    "semi_implicit_euler": [2e-3],
    "solve_ivp_DOP853": [1e-5, 1e-9],
}
STYLE = {  # colour, marker
    "dop853": ("tab:blue", "o"), "scipy_dop853": ("tab:cyan", "s"), "scipy_rk45": ("tab:green", "^"),
    "dopri5": ("tab:olive", "<"),
    "radau": ("tab:red", "D"), "bdf": ("tab:purple", "v"), "rk4": ("tab:orange", "P"),
    "semi_implicit_euler": ("tab:brown", "X"), "solve_ivp_DOP853": ("tab:gray", "*"),
}


@dataclass
class Case:
    name: str
    description: str
    q0: np.ndarray
    dq0: np.ndarray
    t_final: float
    stance_leg: int = 1
    walking: bool = False
    options: dict = field(default_factory=dict)


def cases(model):
    ctrl = WalkingController(model)
    # swing leg raised behind (1.2 rad), so that its foot stays clear of the ground until the liftoff
    qf, dqf = stance_state(model, [math.pi - 0.1, math.pi + 1.2, 0.0], [0.5, 0.0, 0.0])
    qw, dqw = ctrl.initial_state()
    qd = np.array([0.0, 1.3, math.pi - 0.3, math.pi + 0.25, 0.1])
    dqd = np.array([0.3, 0.0, 0.5, -0.5, 0.0])
    return [
        Case("passive_fall", "stance on leg 1, u=0, phases={stance}: the pure constrained ODE, 1 s "
             "(the foot would lift off at 1.08 s)", qf, dqf, 1.0,
             # the swing foot grazes the ground behind the stance foot 1 cm deep (no impact phase)
             options=dict(phases=frozenset({"stance"}), scuff_rule="behind", scuff_depth=0.05)),
        Case("walking", "WalkingController, 5 s, 10 impacts", qw, dqw, 5.0, walking=True),
        # after the landing, the unpowered swing foot grazes the ground behind the stance foot 7.7 mm
        # deep (a scuff: straight legs, no knees), deeper than the default scuff_depth of 3 mm
        Case("drop", "from flight (hip 1.3 m), u=0: lands on foot 1, 0.65 s of stance", qd, dqd, 0.9, stance_leg=0,
             options=dict(scuff_depth=0.01)),
    ]


def run_case(model, case, method, setting, max_step=np.inf):
    """One engine run; returns (result, wall seconds)."""
    ctrl = WalkingController(model) if case.walking else None
    kw = dict(case.options)
    if method in FIXED_STEP_METHODS:
        kw["step"] = setting
        tol = 1e-9
    else:
        tol = setting
        kw["max_step"] = max_step
    t0 = time.perf_counter()
    r = simulate(model, case.q0, case.dq0, case.t_final, controller=ctrl, stance_leg=case.stance_leg,
                 rtol=tol, atol=tol, method=method, **kw)
    return r, time.perf_counter() - t0


# -- trajectories as (segments, event times) ----------------------------------------------------
@dataclass
class Trajectory:
    t: np.ndarray
    y: np.ndarray           # (n, 10): q then dq
    leg: np.ndarray
    event_times: list       # impacts
    status: str
    drift: float = 0.0
    energy: float = 0.0

    def segments(self):
        """Index ranges between impacts (an impact is recorded twice at the same time)."""
        cut = [0] + [i for i in range(1, len(self.t)) if self.t[i] == self.t[i - 1]] + [len(self.t)]
        return [(a, b) for a, b in zip(cut, cut[1:]) if b > a]


def trajectory(result):
    return Trajectory(result.t, np.hstack([result.q, result.dq]), result.stance_leg,
                      [e.time for e in result.impacts], result.status,
                      result.stats["max_constraint_drift_position"], result.stats["max_energy_balance_residual"])


class Reference:
    """The reference run, evaluated at any time of any of its hybrid segments by its dense output."""

    def __init__(self, model, case, tol=1e-13):
        ctrl = WalkingController(model) if case.walking else None
        t0 = time.perf_counter()
        pieces = []   # (hybrid segment, t_start, t_end, the integrator's own interpolant) of every step

        def keep(t_start, t_end, interpolant):
            pieces.append((sim.stats["impacts"], t_start, t_end, interpolant))
        sim = HybridSimulator(model, case.q0, case.dq0, case.stance_leg, tol, tol, "dop853", None,
                              on_step=keep, **case.options)
        sim.advance(case.t_final, controller=ctrl)
        self.wall = time.perf_counter() - t0
        self.result = sim.result()
        if self.result.status == "failed":
            raise RuntimeError(f"reference run of {case.name} failed: {self.result.message}")
        self.traj = trajectory(self.result)
        self.pieces = {}
        for seg, ta, tb, f in pieces:
            self.pieces.setdefault(seg, []).append((ta, tb, f))
        self.starts = {k: np.array([p[0] for p in v]) for k, v in self.pieces.items()}

    def at(self, seg, t):
        """The reference state (q, dq) at time t on hybrid segment seg, or None outside it."""
        ps = self.pieces.get(seg)
        if not ps or t < ps[0][0] or t > ps[-1][1]:
            return None
        i = max(0, int(np.searchsorted(self.starts[seg], t, side="right")) - 1)
        return ps[i][2](t)[:10]

    def compare(self, traj):
        """(err_end, err_run, err_event, n_impacts_match)."""
        ref = self.traj
        err_end = float(np.max(np.abs(traj.y[-1] - ref.y[-1])))
        match = len(traj.event_times) == len(ref.event_times) and traj.status == ref.status
        if match:
            err_event = max([abs(a - b) for a, b in zip(traj.event_times, ref.event_times)], default=math.nan)
        else:
            err_event = math.inf
        err_run = err_end
        for seg, (a, b) in enumerate(traj.segments()):
            for i in range(a, b):
                y = self.at(seg, traj.t[i])
                if y is not None:
                    err_run = max(err_run, float(np.max(np.abs(traj.y[i] - y))))
        return err_end, err_run, err_event, match


# -- the solve_ivp baseline (outside the engine) ------------------------------------------------
def solve_ivp_fall(model, case, tol):
    """The passive fall with plain solve_ivp(DOP853): own right-hand side, no projection, and the
    engine's stance guard (liftoff: normal force reaches zero) as a terminal event."""
    from scipy.integrate import solve_ivp  # here: every biped-sim command imports this module
    def rhs(t, y):
        q, dq = y[:5].tolist(), y[5:].tolist()
        return np.array(dq + list(stance_floating_fast(model, q, dq, (0.0, 0.0), 1)[0]))

    def liftoff(t, y):
        return stance_floating_fast(model, y[:5].tolist(), y[5:].tolist(), (0.0, 0.0), 1)[1][1]
    liftoff.terminal, liftoff.direction = True, -1
    t0 = time.perf_counter()
    sol = solve_ivp(rhs, (0.0, case.t_final), np.concatenate([case.q0, case.dq0]), method="DOP853",
                    rtol=tol, atol=tol, events=liftoff)
    wall = time.perf_counter() - t0
    y = sol.y.T
    pin = model.foot_position(case.q0, 1)
    drift = max(float(np.hypot(*(model.foot_position(yy[:5], 1) - pin))) for yy in y)
    E0 = model.energy(case.q0, case.dq0)
    energy = max(abs(model.energy(yy[:5], yy[5:]) - E0) for yy in y)
    status = "stopped" if sol.t_events[0].size else "completed"
    return (Trajectory(sol.t, y, np.ones(len(sol.t), dtype=int), [], status, drift, energy), wall,
            len(sol.t) - 1, sol.nfev)


# -- the benchmark ------------------------------------------------------------------------------
class Progress:
    """``progress(text)``: one more run of ``total`` done, ``text`` saying which (config.progress)."""

    def __init__(self, total, stream=sys.stderr):
        self.n, self.display = 0, _Display(total, "accuracy", unit="runs", stream=stream)

    def __call__(self, text):
        self.n += 1
        self.display.update(self.n, text)

    def done(self):
        self.display.close()


def run_benchmark(quick=False, repeats=None, progress=True, cases_filter=None):
    model = BipedModel()
    ladder = LADDER_QUICK if quick else LADDER_FULL
    repeats = repeats or (1 if quick else 3)
    ref_tol = 1e-13
    second = ("scipy_dop853", 1e-12) if quick else ("radau", 1e-11)
    cs = [c for c in cases(model) if not cases_filter or c.name in cases_filter]
    n_runs = sum(len(v) for k, v in ladder.items() if k != "solve_ivp_DOP853") * len(cs) + 2 * len(cs)
    n_runs += len(ladder.get("solve_ivp_DOP853", [])) if any(c.name == "passive_fall" for c in cs) else 0
    prog = Progress(n_runs, sys.stderr if progress else _Null())
    rows, refs = [], {}
    for case in cs:
        prog(f"{case.name}: reference dop853 rtol {ref_tol:g}")
        ref = Reference(model, case, ref_tol)
        r_ref, wall_ref = ref.result, ref.wall
        prog(f"{case.name}: second reference {second[0]} rtol {second[1]:g}")
        r2, wall2 = run_case(model, case, *second)
        e_end, e_run, e_ev, match = ref.compare(trajectory(r2))
        refs[case.name] = dict(case=case.name, description=case.description,
                               reference=f"dop853 rtol=atol={ref_tol:g}", second=f"{second[0]} rtol=atol={second[1]:g}",
                               err_end=e_end, err_run=e_run, err_event=e_ev, impacts=len(ref.traj.event_times),
                               ref_time=wall_ref, ref_steps=r_ref.stats["steps"], second_time=wall2,
                               second_steps=r2.stats["steps"], match=match)
        for method, settings in ladder.items():
            if method == "solve_ivp_DOP853" and case.name != "passive_fall":
                continue
            for s in settings:
                prog(f"{case.name}: {method} {'step' if method in FIXED_STEP_METHODS else 'tol'} {s:g}")
                walls = []
                for _ in range(repeats):
                    if method == "solve_ivp_DOP853":
                        traj, wall, steps, rhs = solve_ivp_fall(model, case, s)
                        status, message = traj.status, ""
                    else:
                        r, wall = run_case(model, case, method, s)
                        traj, steps, status, message = trajectory(r), r.stats["steps"], r.status, r.message
                        rhs = r.stats["rhs_evaluations"]
                    walls.append(wall)
                if status == "failed":
                    e_end = e_run = e_ev = math.inf
                    match = False
                else:
                    e_end, e_run, e_ev, match = ref.compare(traj)
                rows.append(dict(case=case.name, method=method,
                                 setting=("step=" if method in FIXED_STEP_METHODS else "tol=") + f"{s:g}",
                                 value=s, default=(method, s) == DEFAULT, time=statistics.median(walls),
                                 repeats=repeats, steps=steps, rhs=rhs, impacts=len(traj.event_times),
                                 status=status, err_end=e_end, err_run=e_run, err_event=e_ev,
                                 drift=traj.drift, energy=traj.energy, message=message[:120]))
    prog.done()
    return rows, list(refs.values())


class _Null:
    def write(self, s):
        pass

    def flush(self):
        pass


# -- output -------------------------------------------------------------------------------------
COLUMNS = ["case", "method", "setting", "default", "time", "repeats", "steps", "rhs", "impacts", "status",
           "err_end", "err_run", "err_event", "drift", "energy", "message"]


def _fmt(v):
    if isinstance(v, bool):
        return "yes" if v else ""
    if isinstance(v, float):
        return "inf" if math.isinf(v) else "-" if math.isnan(v) else f"{v:.3g}"
    return "" if v is None else str(v)


def write_csv(rows, path):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})


def markdown(rows, refs):
    out = ["### References", "",
           "| case | reference | steps | time (s) | impacts | second method | its err end | err run | "
           "err event (s) |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in refs:
        out.append(f"| {r['case']} | {r['reference']} | {r['ref_steps']} | {r['ref_time']:.3g} | {r['impacts']} | "
                   f"{r['second']} | {_fmt(r['err_end'])} | {_fmt(r['err_run'])} | {_fmt(r['err_event'])} |")
    out += ["", "### Runs (err: max-norm of (q, dq) in SI units; time: median wall time)", "",
            "| case | method | setting | time (s) | steps | impacts | err end | err run | err event (s) | "
            "drift (m) | energy resid. (J) | status |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        name = f"**{r['method']}**" if r["default"] else r["method"]
        setting = f"**{r['setting']}** (default)" if r["default"] else r["setting"]
        out.append(f"| {r['case']} | {name} | {setting} | {r['time']:.3g} | {r['steps']} | {r['impacts']} | "
                   f"{_fmt(r['err_end'])} | {_fmt(r['err_run'])} | {_fmt(r['err_event'])} | {_fmt(r['drift'])} | "
                   f"{_fmt(r['energy'])} | {r['status']} |")
    return "\n".join(out) + "\n"


def plot(rows, refs, path):
    """Top row: error over the run against median wall time; bottom row: against right-hand-side
    evaluations (the machine-independent cost). One line per method, from loose to tight."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    names = list(dict.fromkeys(r["case"] for r in rows))
    fig, axes = plt.subplots(2, len(names), figsize=(5.4 * len(names), 9.0), squeeze=False)
    floor = {r["case"]: r["err_run"] for r in refs}
    for col, case in enumerate(names):
        for row, (key, xlabel) in enumerate((("time", "median wall time per run (s)"),
                                             ("rhs", "right-hand-side evaluations per run"))):
            ax = axes[row][col]
            for method in dict.fromkeys(r["method"] for r in rows if r["case"] == case):
                pts = [r for r in rows if r["case"] == case and r["method"] == method
                       and math.isfinite(r["err_run"]) and r.get(key)]
                pts = sorted(pts, key=lambda r: -r["value"])          # the ladder, loose to tight
                if not pts:
                    continue
                c, mk = STYLE.get(method, ("k", "o"))
                x = [r[key] for r in pts]
                y = [max(r["err_run"], 1e-16) for r in pts]
                ax.loglog(x, y, marker=mk, color=c, label=method, lw=1.4, ms=6)
                for r, xx, yy in zip(pts, x, y):
                    ax.annotate(f"{r['value']:g}", (xx, yy), textcoords="offset points", xytext=(4, 3),
                                fontsize=6.5, color=c)
                    if r["default"]:
                        ax.plot(xx, yy, marker="o", ms=16, mfc="none", mec="k", mew=1.8, ls="none",
                                label="default (dop853, tol 1e-9)")
            if case in floor and floor[case] > 0:
                ax.axhline(floor[case], color="k", ls=":", lw=1, label="reference error estimate")
            ax.set_title(f"{case}: error against {'run time' if key == 'time' else 'evaluations'}", fontsize=10)
            ax.set_xlabel(xlabel)
            ax.xaxis.set_major_locator(matplotlib.ticker.LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
            ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            ax.grid(True, which="major", alpha=0.4)
            ax.grid(True, which="minor", alpha=0.1)
        axes[0][col].sharey(axes[1][col])
    for row in axes:
        row[0].set_ylabel("max state error over the run\n(max-norm of q, dq; SI units)")
    h, l = [], []
    for ax in axes.flat:
        for hh, ll in zip(*ax.get_legend_handles_labels()):
            if ll not in l:
                h.append(hh)
                l.append(ll)
    fig.legend(h, l, loc="lower center", ncol=min(len(l), 5), fontsize=9, frameon=False)
    fig.suptitle("Work-precision of the integrators (lower left is better; point labels: tolerance, or step in s)")
    fig.tight_layout(rect=(0, 0.07, 1, 0.97))
    fig.savefig(path, dpi=100)
    plt.close(fig)


def front(rows):
    """Per case, the runs on the Pareto front (no other run both faster and more accurate)."""
    out = {}
    for case in dict.fromkeys(r["case"] for r in rows):
        pts = [r for r in rows if r["case"] == case and math.isfinite(r["err_run"]) and not math.isinf(r["err_event"])]
        out[case] = [r for r in pts if not any(o["time"] < r["time"] and o["err_run"] < r["err_run"] for o in pts)]
    return out
