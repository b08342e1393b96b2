"""``make bench``: speed figures of the engine (issue 2), then the node, recorder, scene, sweep, command-line,
MuJoCo, user-law (benchmarks/bench_user_law.py), Drake (benchmarks/bench_drake.py) and described robots'
kernels (benchmarks/bench_models.py) benchmarks.

Owns measurement only (no assertions: these machines are shared and noisy). Every figure is a
median over repeats measured in this one process, and comparisons are made side by side.

Engine figures:
  * ``stance_dynamics`` per call (public API, numpy in and out), beside the literal KKT solve of
    docs/model.md with ``np.linalg.solve`` on the same inputs and the Python closed form that the
    compiled twin replaces (``BIPED_SIM_PURE_PYTHON=1`` runs everything on the Python code);
  * a 10 s walking run (the PD walking law, continuous feedback, >= 14 impacts) integrated to a
    final-state error of 1e-9 by this engine and by ``scipy.integrate.solve_ivp(method="DOP853",
    events=...)`` driving the same right-hand side (``stance_floating_fast`` and the same
    controller) with the same impact map; each at the loosest tolerance of a ladder that reaches
    the error, against a reference run at rtol = atol = 1e-13 (its own error estimated by
    solve_ivp at the same tolerance);
  * what ``method:=auto`` of the node chooses between: a 2 s walk advanced one control period at a
    time as the node does (commands of the walking controller, recorded once from a 1e-13
    reference run that advances each period in 8 slices, and replayed to both methods), for
    periods of 1 to 20 ms: evaluations and wall time per period, and the largest state error at the
    period boundaries against the reference.
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import math
import statistics
import sys
import time
import timeit

import numpy as np
from scipy.integrate import solve_ivp

from biped_sim.config.parameters import AUTO_DOPRI5_MAX_PERIOD
from biped_sim.control.walking import PDWalkingController
from biped_sim.engine._gen import closed_forms as _generated
from biped_sim.engine.compiled import IMPLEMENTATION, WHY_PYTHON
from biped_sim.engine.dynamics import impact_map, stance_dynamics, stance_floating_fast
from biped_sim.engine.hybrid import HybridSimulator
from biped_sim.engine.model import BipedModel
from biped_sim.engine.simulate import simulate

# a fine ladder (ratio about 1.4 between rungs) so that neither method is charged for more accuracy
# than the target asks: each runs at its loosest rung that reaches TARGET_ERROR
TOLERANCES = (1e-8, 7e-9, 5e-9, 3e-9, 2e-9, 1.5e-9, 1e-9, 7e-10, 5e-10, 3e-10, 2e-10, 1.5e-10, 1e-10,
              7e-11, 5e-11, 3e-11, 2e-11, 1e-11, 5e-12, 2e-12, 1e-12)
TARGET_ERROR = 1e-9


def _median_us(fn, number, repeat=7):
    return statistics.median(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e6


def bench_stance(model):
    q = np.array([0.5, math.sqrt(3) / 2, 150 * math.pi / 180, 120 * math.pi / 180, 30 * math.pi / 180])
    dq = np.array([-0.8049, -0.4430, 0.0938, 0.9150, 0.9298])
    u = np.zeros(2)

    def literal_kkt():
        D, C, G = model.mass_matrix(q), model.coriolis(q, dq), model.gravity(q)
        J, Jd = model.foot_jacobian(q, 1), model.foot_jacobian_dot(q, dq, 1)
        K = np.block([[D, -J.T], [J, np.zeros((2, 2))]])
        return np.linalg.solve(K, np.concatenate([-C @ dq - G + model.B @ u, -Jd @ dq]))
    ql, dql = q.tolist(), dq.tolist()
    rows = [
        ("stance_dynamics (public API, numpy in/out)", _median_us(lambda: stance_dynamics(model, q, dq, u), 20000)),
        ("stance_floating_fast (engine hot path, lists)",
         _median_us(lambda: stance_floating_fast(model, ql, dql, (0.0, 0.0)), 20000)),
        ("the same closed form in Python (closed_forms.py)",
         _median_us(lambda: _generated.stance_floating_1(ql, dql, (0.0, 0.0), model.k_stance), 20000)),
        ("stance_dynamics(base='fixed') (pinned chain)",
         _median_us(lambda: stance_dynamics(model, q, dq, u, base="fixed"), 20000)),
        ("literal 7x7 KKT with np.linalg.solve", _median_us(literal_kkt, 2000)),
    ]
    print("\n== stance dynamics, median per call (7 repeats) ==")
    for name, us in rows:
        print(f"  {name:48s} {us:8.2f} us")
    return dict(rows)


def walk_solve_ivp(model, ctrl, q0, dq0, t_final, rtol, atol):
    """The same hybrid walk with solve_ivp(DOP853, events=...), restarted after each event.

    Written as a careful solve_ivp user would: a terminal touchdown event (swing foot height,
    direction -1); a crossing behind the stance foot is a scuff, after which the integration goes
    on with an 'emerge' event (height, direction +1) before the touchdown event is armed again --
    restarting on the touchdown event right at its own root would find that root again forever.
    """
    t, y, leg = 0.0, np.concatenate([q0, dq0]), 1
    impacts, nfev, scuffing = 0, 0, False
    while t < t_final:
        swing = 3 - leg

        def rhs(t, y, leg=leg):  # the engine's stance right-hand side, without the work quadrature
            yl = y.tolist()
            q, dq = yl[:5], yl[5:]
            u0, u1 = ctrl(t, q, dq, leg)
            ddq, _ = stance_floating_fast(model, q, dq, [float(u0), float(u1)], leg)
            return np.array(dq + ddq)

        def height(t, y, swing=swing):
            return model.foot_position(y[:5], swing)[1]
        height.terminal, height.direction = True, (1 if scuffing else -1)
        sol = solve_ivp(rhs, (t, t_final), y, method="DOP853", rtol=rtol, atol=atol, events=height)
        nfev += sol.nfev
        if sol.status != 1:
            y = sol.y[:, -1]
            break
        t, y = sol.t_events[0][0], sol.y_events[0][0].copy()
        if scuffing:
            scuffing = False
            continue
        q = y[:5]
        if model.foot_position(q, swing)[0] > model.foot_position(q, leg)[0]:   # in front: an impact
            y[5:], _ = impact_map(model, q, y[5:], swing)
            leg = swing
            impacts += 1
        else:
            scuffing = True
    return y, impacts, nfev


def walk_engine(model, ctrl, q0, dq0, t_final, rtol, atol):
    r = simulate(model, q0, dq0, t_final, controller=ctrl, rtol=rtol, atol=atol)
    return np.concatenate([r.q[-1], r.dq[-1]]), len(r.impacts), r.stats["rhs_evaluations"], r


def bench_walk(model, repeats=3, t_final=10.0):
    ctrl = PDWalkingController(model)
    q0, dq0 = ctrl.initial_state()
    print(f"\n== {t_final:g} s walk (PD walking law, continuous feedback) to a final-state error of "
          f"{TARGET_ERROR:g} ==")
    ref, n_ref, _, _ = walk_engine(model, ctrl, q0, dq0, t_final, 1e-13, 1e-13)
    ref_ivp, n_ivp, _ = walk_solve_ivp(model, ctrl, q0, dq0, t_final, 1e-13, 1e-13)
    ref_err = np.max(np.abs(ref - ref_ivp))
    print(f"  reference: this engine at rtol=atol=1e-13, {n_ref} impacts; solve_ivp at 1e-13 differs by "
          f"{ref_err:.2g} (its error estimate)")
    runs = {"biped_sim (dop853)": walk_engine, "solve_ivp DOP853 + events": walk_solve_ivp}
    found = {}
    for name, run in runs.items():
        for tol in TOLERANCES:
            out = run(model, ctrl, q0, dq0, t_final, tol, tol)
            err = np.max(np.abs(out[0] - ref))
            if out[1] == n_ref and err <= TARGET_ERROR:
                found[name] = [tol, err, [], out[2], out[1]]
                break
        else:
            found[name] = None
    # timed in alternation, so that a slow spell of this shared machine hits both alike
    for _ in range(repeats):
        for name, f in found.items():
            if f is not None:
                t0 = time.perf_counter()
                runs[name](model, ctrl, q0, dq0, t_final, f[0], f[0])
                f[2].append(time.perf_counter() - t0)
    for f in found.values():
        if f is not None:
            f[2] = statistics.median(f[2])
    for name, f in found.items():
        if f is None:
            print(f"  {name:28s} did not reach {TARGET_ERROR:g} on the ladder {TOLERANCES}")
            continue
        tol, err, wall, nfev, n = f
        print(f"  {name:28s} rtol=atol={tol:.2g}  error {err:.2g}  impacts {n}  rhs evals {nfev}  "
              f"median wall {wall:.3f} s  real-time factor {t_final / wall:.1f}")
    a, b = found.get("biped_sim (dop853)"), found.get("solve_ivp DOP853 + events")
    if a and b:
        print(f"  speed-up over solve_ivp at the same error: {b[2] / a[2]:.2f}x (median of {repeats}; target >= 2x)")
    return found


def bench_control_periods(model, periods=(0.001, 0.005, 0.01, 0.02), t_final=2.0, repeats=3):
    """dopri5 against dop853 per control period, as the node's ``method:=auto`` chooses (see the
    module docstring); returns {period: {method: (evaluations, ms, error)}}."""
    from biped_sim.control.walking import WalkingController
    ctrl = WalkingController(model)
    q0, dq0 = ctrl.initial_state()
    print(f"\n== one control period at a time, as the node advances ({t_final:g} s walk, rtol=atol=1e-9; "
          f"method:=auto takes dopri5 up to {AUTO_DOPRI5_MAX_PERIOD * 1e3:g} ms) ==")
    print(f"  {'period':>8s}  {'method':8s} {'evals/period':>12s} {'ms/period':>10s} {'max error':>10s}")
    out = {}
    for period in periods:
        n = int(round(t_final / period))
        # the reference advances each period in 8 slices: a period caps every step, and a run capped
        # like the measured ones would take their very steps (then 1e-9 and 1e-13 give the same bits)
        ref = HybridSimulator(model, q0, dq0, rtol=1e-13, atol=1e-13, method="dop853")
        commands, states = [], []
        for k in range(n):
            commands.append(ctrl(ref.t, ref.q, ref.dq, ref.stance_leg))
            for j in range(1, 9):
                ref.advance((k + j / 8) * period, u=commands[-1])
            states.append(np.concatenate([ref.q, ref.dq]))
        out[period] = {}
        for method in ("dopri5", "dop853"):
            walls, err = [], 0.0
            for r in range(repeats):
                sim = HybridSimulator(model, q0, dq0, rtol=1e-9, atol=1e-9, method=method)
                t0 = time.perf_counter()
                for k in range(n):
                    sim.advance((k + 1) * period, u=commands[k])
                walls.append(time.perf_counter() - t0)
                if r == 0:   # the runs are identical; the error is measured once, outside the timing
                    check = HybridSimulator(model, q0, dq0, rtol=1e-9, atol=1e-9, method=method)
                    for k in range(n):
                        check.advance((k + 1) * period, u=commands[k])
                        err = max(err, float(np.max(np.abs(np.concatenate([check.q, check.dq]) - states[k]))))
            evals = sim.stats["rhs_evaluations"] / n
            ms = statistics.median(walls) / n * 1e3
            out[period][method] = (evals, ms, err)
            print(f"  {period * 1e3:6g} ms  {method:8s} {evals:12.2f} {ms:10.4f} {err:10.2g}")
    return out


PYTHON_RHS_TIMING = """
import statistics, timeit
from biped_sim.control.walking import PDWalkingController
from biped_sim.engine.compiled import IMPLEMENTATION
from biped_sim.engine.model import BipedModel
from biped_sim.engine.modes import mode_functions
model = BipedModel()
q0, dq0 = PDWalkingController(model).initial_state()
rhs, _, _ = mode_functions(model, 1, "floating", [0.0, 0.0], [1.0, -2.0], None, lambda F, u: None)
y = q0.tolist() + dq0.tolist() + [0.0]
assert IMPLEMENTATION == "Python"
print(statistics.median(timeit.repeat(lambda: rhs(0.0, y), number=20000, repeat=7)) / 20000 * 1e6)
"""


def python_rhs_us():
    """One right-hand-side call of the model in pure Python (the Python loop's rhs on the closed form's
    Python code, BIPED_SIM_PURE_PYTHON=1), in us: the unit of the held-torque figure."""
    import os
    import subprocess
    out = subprocess.run([sys.executable, "-c", PYTHON_RHS_TIMING], capture_output=True, text=True, check=True,
                         env=dict(os.environ, BIPED_SIM_PURE_PYTHON="1"))
    return float(out.stdout)


def bench_compiled_loop(model, repeats=5):
    """The compiled hybrid loop (biped_sim/engine/_core.c) against the Python loop of hybrid.py, same
    process, in alternation: a held-torque period at 1 ms (engine time only: the PD law's commands
    recorded once and replayed), the 10 s walk under continuous feedback, and bytes a sample."""
    import tracemalloc

    from biped_sim.engine import compiled_loop
    print("\n== the compiled hybrid loop against the Python loop (same runs, bit for bit; "
          f"compiled loop: {'on' if compiled_loop.AVAILABLE else 'off: ' + compiled_loop.WHY_NOT}) ==")
    ctrl = PDWalkingController(model)
    q0, dq0 = ctrl.initial_state()
    rec = HybridSimulator(model, q0, dq0, method="dopri5")
    commands = []
    for _ in range(2000):
        commands.append(rec.command(ctrl))
        rec.advance_period(1e-3, u=commands[-1])

    def held():
        sim = HybridSimulator(model, q0, dq0, method="dopri5")
        t0 = time.perf_counter()
        for u in commands:
            sim.advance_period(1e-3, u=u)
        return (time.perf_counter() - t0) / len(commands) * 1e6

    def held_and_read():
        # as the node: the state read as lists every period, for its messages
        sim = HybridSimulator(model, q0, dq0, method="dopri5")
        t0 = time.perf_counter()
        for u in commands:
            sim.advance_period(1e-3, u=u)
            sim.state_lists()
        return (time.perf_counter() - t0) / len(commands) * 1e6

    def walk():
        t0 = time.perf_counter()
        r = simulate(model, q0, dq0, 10.0, controller=ctrl)
        return time.perf_counter() - t0, r

    def controller_us():
        return _median_us(lambda: rec.command(ctrl), 2000)

    times = {True: ([], []), False: ([], [])}
    read = []
    for _ in range(repeats):
        for enabled in (True, False):
            compiled_loop.enabled = enabled
            times[enabled][0].append(held())
            times[enabled][1].append(walk()[0])
        compiled_loop.enabled = True
        read.append(held_and_read())
    unit = python_rhs_us()
    (c_held, c_walk), (p_held, p_walk) = ([statistics.median(v) for v in times[e]] for e in (True, False))
    print(f"  one right-hand-side call in pure Python (the unit below): {unit:.2f} us; "
          f"the PD law's call through the engine: {controller_us():.2f} us")
    print(f"  held torque, 1 ms periods (dopri5, 2 s walk, engine only): compiled {c_held:.2f} us a period = "
          f"{c_held / unit:.2f} rhs calls (real-time factor {1e3 / c_held:.0f}); Python loop {p_held:.1f} us "
          f"= {p_held / unit:.1f}; x{p_held / c_held:.1f}")
    print(f"  the same with the state read every period as the node reads it (sim.state_lists()): "
          f"{statistics.median(read):.2f} us a period")
    print(f"  10 s walk, continuous feedback (dop853, 1e-9): compiled {c_walk * 1e3:.1f} ms (real-time factor "
          f"{10 / c_walk:.0f}); Python loop {p_walk * 1e3:.1f} ms; x{p_walk / c_walk:.1f}")
    tracemalloc.start()
    _, r = walk()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    print(f"  memory: {len(r.t)} samples of the 10 s walk, {r.q.itemsize * 17} bytes a sample in the result "
          f"(t, q, dq, stance leg, F, u, energy balance); peak traced {peak / len(r.t):.0f} bytes a sample "
          "while running")
    return dict(held_us=c_held, held_units=c_held / unit, python_held_us=p_held, walk_s=c_walk, python_walk_s=p_walk)


def bench_python_controller(repeats=7, t_final=10.0):
    """A user's law as a plain Python function against the built-in law, same process, in alternation: the
    walk scene, ``t_final`` s, torques held over its 1 ms control period (and under continuous feedback). The
    plain function (``lambda t, q, dq, leg: ctrl(t, q, dq, leg)``) offers no compiled law, so the engine calls
    it, once a period when held; the engine's time besides it is the run's wall time less the controller's
    own (its calls of that run replayed alone, on the arguments the run gave it, timed in the same
    alternation), in pure-Python right-hand-side calls."""
    from biped_sim.config.scenes import load_scene
    from biped_sim.engine import compiled_loop
    from biped_sim.engine.compiled import gen
    scene = load_scene("walk")
    ctrl = scene.controller()

    def plain(t, q, dq, leg):
        return ctrl(t, q, dq, leg)

    def run(controller, hold):
        t0 = time.perf_counter()
        r = scene.simulate(controller=controller, t_final=t_final, hold=hold)
        return time.perf_counter() - t0, r

    calls = {True: [], False: []}
    status = {}
    for hold in (True, False):
        def recording(t, q, dq, leg, kept=calls[hold]):
            kept.append((t, q, dq, leg))
            return ctrl(t, q, dq, leg)
        status[hold] = run(recording, hold)[1].status

    def replay(hold):
        t0 = time.perf_counter()
        for t, q, dq, leg in calls[hold]:
            plain(t, q, dq, leg)
        return time.perf_counter() - t0
    # the right-hand sides evaluated from Python (the stance closed form called outside the compiled loop;
    # the controller's own model terms are another function), counted on one held run
    counted = [0]
    originals = gen.stance_floating_1, gen.stance_floating_2

    def counting(f):
        def call(*args):
            counted[0] += 1
            return f(*args)
        return call
    gen.stance_floating_1, gen.stance_floating_2 = map(counting, originals)
    try:
        run(plain, True)
    finally:
        gen.stance_floating_1, gen.stance_floating_2 = originals
    # the unit, one pure-Python right-hand-side call (python_rhs_us's, on the generated Python closed form),
    # timed here in the same alternation, so that a busy spell of the machine moves it with the runs
    from biped_sim.engine._gen import closed_forms
    from biped_sim.engine.modes import mode_functions
    twin_stance = gen.stance_floating_1
    gen.stance_floating_1 = closed_forms.stance_floating_1
    try:
        rhs, _, _ = mode_functions(ctrl.model, 1, "floating", [0.0, 0.0], [1.0, -2.0], None, lambda F, u: None)
    finally:
        gen.stance_floating_1 = twin_stance
    q0, dq0 = ctrl.initial_state()
    y = q0.tolist() + dq0.tolist() + [0.0]
    walls = {(name, hold): [] for name in ("built-in", "plain", "own") for hold in (True, False)}
    units = []
    for _ in range(repeats):
        for hold in (True, False):
            walls["built-in", hold].append(run(ctrl, hold)[0])
            walls["plain", hold].append(run(plain, hold)[0])
            walls["own", hold].append(replay(hold))
        units.append(timeit.timeit(lambda: rhs(0.0, y), number=20000) / 20000 * 1e6)   # (as long as a run)
    med = {key: statistics.median(v) for key, v in walls.items()}
    unit = statistics.median(units)
    periods = round(t_final / scene.params["control_period"])
    built_in, wall, own = med["built-in", True], med["plain", True], med["own", True]
    engine_us = (wall - own) / periods * 1e6
    print(f"\n== your own law as a plain Python function (walk scene {t_final:g} s, torques held 1 ms; median of "
          f"{repeats}, alternating; compiled loop {'on' if compiled_loop.AVAILABLE else 'off'}) ==")
    print(f"  built-in law (compiled in the loop): {built_in * 1e3:.1f} ms, real-time factor {t_final / built_in:.0f}")
    print(f"  the same law as a plain Python function: {wall * 1e3:.1f} ms, real-time factor {t_final / wall:.0f} "
          f"({built_in / wall:.3f} of the built-in law's); {len(calls[True])} controller calls in {periods} periods "
          f"({status[True]})")
    print(f"  the controller's own time {own / len(calls[True]) * 1e6:.2f} us a call; the engine's time besides it "
          f"{engine_us:.2f} us a period = {engine_us / unit:.2f} pure-Python right-hand-side calls (unit "
          f"{unit:.2f} us; goal <= 1); right-hand sides evaluated from Python: {counted[0] / periods:.2f} a period")
    cb, cp, co = med["built-in", False], med["plain", False], med["own", False]
    print(f"  continuous feedback ({len(calls[False])} calls, {status[False]}): built-in {cb * 1e3:.1f} ms, plain "
          f"Python {cp * 1e3:.1f} ms, of which the controller's own {co * 1e3:.1f} ms; the engine besides it "
          f"{(cp - co) * 1e3:.1f} ms ({(cp - co) / cb:.2f} x the built-in law's run)")
    return dict(built_in_s=built_in, plain_s=wall, engine_us=engine_us, units=engine_us / unit,
                python_rhs_per_period=counted[0] / periods)


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench", description=__doc__.split("\n")[0])
    parser.add_argument("--only", help="run one group only",
                        choices=("engine", "node", "record", "scenes", "sweep", "cli", "sensitivity", "mujoco",
                                 "userlaw", "drake", "models"))
    parser.add_argument("--repeats", type=int, default=7, help="timed repeats of each walk (alternating)")
    args = parser.parse_args(argv)
    model = BipedModel()
    if args.only in (None, "engine"):
        print("biped_sim engine benchmark (python -m benchmarks.bench --only engine)")
        print(f"generated code: {IMPLEMENTATION}" + (f" ({WHY_PYTHON})" if WHY_PYTHON else " (the compiled twin)"))
        bench_stance(model)
        bench_walk(model, repeats=args.repeats)
        bench_control_periods(model)
        bench_compiled_loop(model)
        bench_python_controller()
        sys.stdout.flush()
    for group, module in (("node", "bench_node"), ("record", "bench_record"), ("scenes", "bench_scenes"),
                          ("sweep", "bench_sweep"), ("cli", "bench_cli"), ("sensitivity", "bench_sensitivity"),
                          ("mujoco", "bench_mujoco"), ("userlaw", "bench_user_law"), ("drake", "bench_drake"),
                          ("models", "bench_models")):
        if args.only in (None, group):
            try:
                mod = importlib.import_module(f"benchmarks.{module}")
            except ModuleNotFoundError as exc:
                if exc.name != f"benchmarks.{module}":
                    raise
                print(f"\n(no {module} yet)")
                continue
            print(f"\n==== benchmarks.{module} ====")
            sys.stdout.flush()
            mod.main([]) if _takes_argv(mod.main) else mod.main()
    return 0


def _takes_argv(fn):
    import inspect
    return len(inspect.signature(fn).parameters) > 0


if __name__ == "__main__":
    sys.exit(main())
