"""Described robots on the hybrid engine (docs/models.md, "What the engine runs"): RABBIT's fall and its k_stance,
the compass gait and the three-link biped as BipedModel against GeneratedModel, the rabbit scene's 10 s on the
compiled loop (its steps in C) and on the Python loop. ``python -m benchmarks.bench_generic`` prints figures and
asserts nothing."""
from __future__ import annotations

import time

import numpy as np

import biped_sim as bs
from biped_sim.config import models
from biped_sim.engine import compiled_loop


def timed(run, repeats=7):
    """(the run's result, its median wall time in s)."""
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - t0)
    return result, sorted(times)[repeats // 2]


def on_both_loops(run, repeats):
    """(the run on the compiled loop, on the Python loop, their median wall times in s): ``run()`` timed on each
    in alternation, ``repeats`` times."""
    times, runs = {True: [], False: []}, {}
    for _ in range(repeats):
        for enabled in (True, False):
            compiled_loop.enabled = enabled
            try:
                t0 = time.perf_counter()
                runs[enabled] = run()
                times[enabled].append(time.perf_counter() - t0)
            finally:
                compiled_loop.enabled = True
    return runs[True], runs[False], sorted(times[True])[repeats // 2], sorted(times[False])[repeats // 2]


def rabbit_on_foot_1():
    """(RABBIT, q0): standing on foot 1 at the origin, leg 2 bent."""
    rabbit = bs.load_model("rabbit")
    q0 = np.array([0.0, 0.0, np.pi + 0.1, np.pi - 0.2, -0.05, 0.5, 0.05])
    q0[:2] -= rabbit.contact_position(q0, "foot_1")
    return rabbit, q0


def main():
    rabbit, q0 = rabbit_on_foot_1()
    r, wall = timed(lambda: bs.simulate(rabbit, q0, np.zeros(7), 0.2))
    print(f"RABBIT 0.2 s fall, u = 0: {r.status}, {[(e.kind, e.leg, round(e.time, 6)) for e in r.events]}, "
          f"{len(r.t)} samples, {r.stats['rhs_evaluations']} rhs evaluations, {wall * 1e3:.1f} ms (median of 7)")
    q, dq, u = q0.tolist(), [0.0] * 7, [0.0] * 4
    t0 = time.perf_counter()
    for _ in range(2000):
        rabbit.k_stance(q, dq, u, 0)
    print(f"RABBIT k_stance (numpy): {1e6 * (time.perf_counter() - t0) / 2000:.1f} us a call")
    q, dq = np.array([0.0, 1.0, np.pi, np.pi, 0.0]), np.array([0.4, 0.0, 0.4, -2.0, 0.0])
    options = dict(rtol=1e-10, atol=1e-10, slope=0.0525, phases=frozenset({"stance", "impact"}))
    for name, t_final in (("compass_gait", 10.0), ("three_link", 2.0)):
        a, wall_a = timed(lambda: bs.simulate(bs.load_model(name), q, dq, t_final, **options), 3)
        b, wall_b = timed(lambda: bs.simulate(models.generated_model(name), q, dq, t_final, **options), 3)
        apart = max(abs(x.time - y.time) for x, y in zip(a.impacts, b.impacts))
        print(f"{name} {t_final:g} s: {len(a.impacts)} and {len(b.impacts)} impacts, their times {apart:.1e} s apart, "
              f"end states {np.abs(a.q[-1] - b.q[-1]).max():.1e} apart; BipedModel {wall_a * 1e3:.1f} ms, "
              f"GeneratedModel {wall_b * 1e3:.1f} ms (median of 3)")
    bench_rabbit_loops()
    bench_rabbit_periods()


def bench_rabbit_periods(periods=250, repeats=7):
    """The node's periods of RABBIT (advance_period with its 4 torques given, 1 ms, held: the engine alone) from
    standing on foot 1 until foot 2 lands, on the compiled loop and on the Python loop, alternating: us a period."""
    from biped_sim.engine.hybrid import HybridSimulator
    rabbit, q0 = rabbit_on_foot_1()

    def run():
        sim = HybridSimulator(rabbit, q0, np.zeros(7), stance_leg=1)
        for k in range(periods):
            sim.advance_period(1e-3, [0.0, 0.0, 5.0 * min(k / 100, 1.0), -2.0])
        return sim.result()
    a, b, ca, py = on_both_loops(run, repeats)
    same = all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("t", "q", "dq", "u", "grf"))
    ca, py = ca / periods * 1e6, py / periods * 1e6
    print(f"RABBIT, {periods} node periods of 1 ms with its torques given ({a.status}, "
          f"{[(e.kind, e.leg) for e in a.events]}): compiled loop {ca:.1f} us a period, Python loop {py:.1f} us "
          f"({py / ca:.1f}x; medians of {repeats}, alternating); the same run bit for bit: {same}")


def bench_rabbit_loops(t_final=10.0, repeats=5):
    """The rabbit scene (its walking law called every 1 ms period, held) for t_final on the compiled loop and on the
    Python loop, alternating: their medians, and whether the two runs are the same bit for bit."""
    scene = bs.load_scene("rabbit")
    a, b, ca, py = on_both_loops(lambda: scene.simulate(hold=True, t_final=t_final), repeats)
    same = all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("t", "q", "dq", "u", "grf")) \
        and [e.time for e in a.events] == [e.time for e in b.events]
    # the walking law's own time: its calls of one run replayed alone, on the arguments the run gave it
    law, calls = scene.controller(), []
    scene.simulate(hold=True, t_final=t_final, controller=lambda t, q, dq, leg: (calls.append((t, q, dq, leg)),
                                                                                   law(t, q, dq, leg))[1])
    replays = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for call in calls:
            law(*call)
        replays.append(time.perf_counter() - t0)
    own = sorted(replays)[repeats // 2]
    print(f"rabbit scene {t_final:g} s ({a.status}, {len(a.impacts)} impacts, {a.stats['steps']} steps, "
          f"{a.stats['rhs_evaluations']} rhs evaluations, {a.stats['compiled_loop_steps']} steps in C): compiled loop "
          f"{ca:.3f} s, Python loop {py:.3f} s ({py / ca:.2f}x; medians of {repeats}, alternating); the same run bit "
          f"for bit: {same}; the walking law's own time {own:.3f} s ({len(calls)} calls), the engine's besides it: "
          f"compiled loop {ca - own:.3f} s, Python loop {py - own:.3f} s ({(py - own) / (ca - own):.1f}x)"
          + ("" if compiled_loop.AVAILABLE else f" (no compiled loop: {compiled_loop.WHY_NOT})"))


if __name__ == "__main__":
    main()
