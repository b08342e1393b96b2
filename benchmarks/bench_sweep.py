"""Sweep scaling (issue 17): runs per second with 1 and with every worker, and Ray against the pool.

``python -m benchmarks.bench_sweep`` (or ``make bench`` / ``python -m benchmarks.bench --only sweep``).
All on one grid of the walk scene, in one process, one after the other:

* in-process: the runs one after the other in this process (:func:`run_one` in a loop), the cost
  of a run with nothing around it;
* the process pool with 1 worker and with every core; each sweep's wall time includes starting its
  pool (the time to the first row less that run's own wall time, reported apart), after a first
  one-run sweep has started the fork server that every pool of the process forks its workers
  from (its import of numpy and scipy, paid once per process, is printed first). Scaling =
  rate(all) / rate(1), the goal >= 0.8 x the cores;
* Ray, local (``ray.init`` by the sweep, every core), on the same grid; and on a grid of runs that
  cost next to nothing (0.001 s of the passive scene), the overhead per task of the pool and of Ray.

The machine may be shared: each figure is printed with the 1-minute load average at its end.
"""
from __future__ import annotations

import argparse
import os
import time

from biped_sim.analysis.sweep import default_workers, run_one, sweep

GRID = {"kp": [100.0, 200.0, 400.0, 800.0], "step_angle": [0.15, 0.18, 0.22, 0.25]}
DURATION = 4.0
TINY_GRID = {"duration": [0.001], "model.g": [9.81 + i * 1e-3 for i in range(200)]}


def _load():
    return f"load {os.getloadavg()[0]:.2f}"


def timed_sweep(scene, grid, duration, workers, backend="process"):
    """(wall s, rows, start-up s): start-up = time to the first row less that run's own wall time."""
    first = []
    t0 = time.perf_counter()
    rows = sweep(scene, grid, duration=duration, workers=workers, backend=backend,
                 progress=lambda done, total, row: first or first.append(time.perf_counter() - t0 - row["wall_time"]))
    return time.perf_counter() - t0, rows, first[0]


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_sweep", description=__doc__.split("\n")[0])
    parser.add_argument("--no-ray", action="store_true", help="leave out the Ray figures")
    args = parser.parse_args(argv)
    cores = default_workers()
    n = len(GRID["kp"]) * len(GRID["step_angle"])
    print(f"== sweep: {n} runs of the walk scene, {DURATION:g} s each (torques held 1 ms), {cores} cores ==")
    t0 = time.perf_counter()
    for kp in GRID["kp"]:
        for step_angle in GRID["step_angle"]:
            run_one("walk", {"kp": kp, "step_angle": step_angle}, DURATION)
    serial = time.perf_counter() - t0
    print(f"  in-process loop       {serial:7.2f} s  {n / serial:6.2f} runs/s  ({serial / n * 1e3:.0f} ms a run)  "
          f"[{_load()}]")
    wall, _, startup = timed_sweep("passive", {"duration": [0.001]}, None, 1)
    print(f"  the first pool of a process: {startup:.2f} s to start (its fork server imports the engine once; "
          f"every later pool forks from it)  [{_load()}]")
    rates, reference = {}, None
    for workers in (1, cores):
        wall, rows, startup = timed_sweep("walk", GRID, DURATION, workers)
        reference = reference or rows
        assert _outcome(rows) == _outcome(reference), "rows differ between worker counts"
        rates[workers] = n / wall
        steady = n / (wall - startup)
        label = f"pool, {workers} worker{'s' if workers > 1 else ''}"
        print(f"  {label:21s} {wall:7.2f} s  {rates[workers]:6.2f} runs/s  "
              f"(start-up {startup:.2f} s; without it {steady:.2f} runs/s)  [{_load()}]")
    scaling = rates[cores] / rates[1]
    print(f"  scaling {cores} workers / 1: {scaling:.2f}x = {scaling / cores:.2f} x cores (goal >= 0.8 x cores)")
    if args.no_ray:
        return 0
    try:
        import ray  # noqa: F401
    except ImportError:
        print("  Ray: not installed (pip install 'biped_sim[ray]'); no Ray figures")
        return 0
    wall, rows, startup = timed_sweep("walk", GRID, DURATION, cores, backend="ray")
    assert _outcome(rows) == _outcome(reference), "Ray's rows differ from the pool's"
    print(f"  Ray local, {cores} CPUs     {wall:7.2f} s  {n / wall:6.2f} runs/s  (start-up, ray.init included, "
          f"{startup:.2f} s; without it {n / (wall - startup):.2f} runs/s)  [{_load()}]")
    m = len(TINY_GRID["model.g"])
    print(f"== overhead per task: {m} runs of 0.001 s (passive scene) ==")
    for backend in ("process", "ray"):
        wall, rows, startup = timed_sweep("passive", TINY_GRID, None, cores, backend=backend)
        own = sum(r["wall_time"] for r in rows) / cores
        extra = (wall - startup - own) / m * 1e3
        print(f"  {backend:8s} {wall:6.2f} s, start-up {startup:.2f} s: {extra:.2f} ms a task beyond the runs' "
              f"own time ({own / m * cores * 1e3:.2f} ms a run)  [{_load()}]")
    return 0


def _outcome(rows):
    return [{k: v for k, v in r.items() if k != "wall_time"} for r in rows]


if __name__ == "__main__":
    raise SystemExit(main())
