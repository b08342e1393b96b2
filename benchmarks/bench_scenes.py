"""Benchmark of what a scene leaves out: ``python -m benchmarks.bench_scenes``.

Owns two measurements (median of repeated runs, wall seconds per simulated second, lower is better):

1. the ``stance_fixed`` scene (fixed-base method: the 3-coordinate chain, a 7-dimensional integrated
   state, no constraint projection) against the same scene with ``base: floating`` (the
   5-coordinate KKT stance, an 11-dimensional state, projection after every step); with the
   scene's controller, both continuous feedback and torques held over the 1 ms control period as
   the node runs it;
2. the ``walk`` scene run in lockstep as the node runs it (``record_run.run_recorded``: the same
   messages built) without a recorder against with the bag recorder (``recorder.BagRecorder``).
"""
from __future__ import annotations

import statistics
import tempfile
import time

from biped_sim.config.scenes import load_scene


def _per_sim_second(fn, repeat):
    costs = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        simulated = fn()
        costs.append((time.perf_counter() - t0) / simulated)
    return statistics.median(costs)


def bench_base(repeat=5):
    scene = load_scene("stance_fixed")
    rows = []
    for label, hold, extra in (("u = 0 (engine only)", False, {"controller": None}),
                               ("continuous feedback", False, {}), ("held over 1 ms", True, {})):
        costs, rhs = {}, {}
        for base in ("fixed", "floating"):
            def run():
                r = scene.simulate(hold=hold, base=base, **extra)
                assert r.status == "completed", r.message
                rhs[base] = r.stats["rhs_evaluations"] / r.stats["simulated_time"]
                return r.stats["simulated_time"]
            costs[base] = _per_sim_second(run, repeat)
        rows.append((label, costs["fixed"], costs["floating"], rhs["fixed"], rhs["floating"]))
    return rows


def bench_recording(duration=2.0, repeat=3):
    from biped_sim.config.parameters import validate
    from biped_sim.recording.record_run import run_recorded
    scene = load_scene("walk")
    params = validate(dict(scene.given, duration=duration))
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        from biped_sim.recording.recorder import BagRecorder
        for label in ("without recording", "with recording"):
            k = [0]

            def run():
                rec = None
                if label == "with recording":
                    k[0] += 1
                    rec = BagRecorder(f"{tmp}/bag{k[0]}", parameters=params)
                try:
                    sim = run_recorded(params, scene.controller(), rec, build_messages=True)
                finally:
                    if rec is not None:
                        rec.close()
                return sim.t
            out[label] = _per_sim_second(run, repeat)
    return out


def main():
    print("biped_sim scene benchmark: wall seconds per simulated second (median), lower is better")
    print("\n1. stance_fixed scene (0.4 s, one stance phase, walking controller): fixed base vs floating base")
    print(f"   {'torques':<20} {'fixed (3 coords)':>17} {'floating (5 + KKT)':>19} {'floating/fixed':>15}"
          f"   rhs evaluations per simulated s (fixed / floating)")
    for label, fixed, floating, rf, rfl in bench_base():
        print(f"   {label:<20} {fixed:17.4f} {floating:19.4f} {floating / fixed:15.2f}   {rf:.0f} / {rfl:.0f}")
    print("\n2. walk scene, lockstep as the node runs it (2 s, 1 ms control period): recording off vs on")
    try:
        rec = bench_recording()
    except ImportError as exc:
        print(f"   skipped: the recorder is not available ({exc})")
        return 0
    base = rec["without recording"]
    for label, cost in rec.items():
        print(f"   {label:<18} {cost:8.4f}   ({cost / base:5.2f} x)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
