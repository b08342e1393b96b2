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
#: long enough that the runs (about 1 s each on the compiled loop; 4 s took 15 ms) outweigh a pool's start-up
#: (0.1 to 1.7 s here), so that the scaling figure measures the runs
DURATION = 300.0
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
    parser.add_argument("--scaling", action="store_true",
                        help="instead: the figures of docs/scaling.md (a run compiled and in pure Python, Ray on a "
                             "local multi-process cluster, a row's size and memory, the CSV writer)")
    args = parser.parse_args(argv)
    if args.scaling:
        return scaling_figures()
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


def scaling_figures():
    """The figures docs/scaling.md plans with."""
    import pickle
    import signal
    import socket
    import subprocess
    import sys
    import tempfile
    import tracemalloc

    from biped_sim.analysis.sweep import write_csv
    print("== one run of the walk scene (10 s simulated, torques held 1 ms), in this process ==")
    for env in ({}, {"BIPED_SIM_PURE_PYTHON": "1"}):
        code = ("import time; from biped_sim.analysis.sweep import run_one; run_one('walk', {}, 1.0); "
                "t = time.perf_counter(); [run_one('walk', {}) for _ in range(3)]; "
                "print((time.perf_counter() - t) / 3)")
        out = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, **env), capture_output=True,
                             text=True, check=True).stdout
        print(f"  {'pure Python' if env else 'compiled twin':14s} {float(out):.3f} s a run (mean of 3)"
              f"  [{_load()}]")
    row = run_one("walk", {"kp": 200.0}, 1.0)
    size = len(pickle.dumps(row))
    tracemalloc.start()
    rows = [pickle.loads(pickle.dumps(dict(row, index=i))) for i in range(10_000)]
    mem = tracemalloc.get_traced_memory()[0] / len(rows)
    tracemalloc.stop()
    with tempfile.TemporaryDirectory() as tmp:
        rows = rows * 10
        for i, r in enumerate(rows):
            r["index"] = i
        t = time.perf_counter()
        write_csv(rows, ["kp"], os.path.join(tmp, "rows.csv"))
        wall = time.perf_counter() - t
        csv_bytes = os.path.getsize(os.path.join(tmp, "rows.csv")) / len(rows)
    print(f"== a row: {size} bytes pickled (what a worker sends back), {mem:.0f} bytes in memory, "
          f"{csv_bytes:.0f} bytes of CSV; the CSV writer: {len(rows) / wall:,.0f} rows/s  [{_load()}]")
    try:
        import ray
    except ImportError:
        print("  Ray: not installed; no cluster figures")
        return 0
    with socket.socket() as sk:
        sk.bind(("127.0.0.1", 0))
        port = sk.getsockname()[1]
    cores = default_workers()
    # a throw-away cluster on this machine, without Ray's token authentication (both ends say so)
    os.environ["RAY_AUTH_MODE"] = "disabled"
    print(f"== Ray on a local multi-process cluster: ray start --head --num-cpus {cores} --port {port} --block ==")
    t0 = time.perf_counter()
    head = subprocess.Popen([os.path.join(os.path.dirname(sys.executable), "ray"), "start", "--head", "--block",
                             f"--num-cpus={cores}", f"--port={port}", "--include-dashboard=false",
                             "--disable-usage-stats"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True, env=dict(os.environ, RAY_AUTH_MODE="disabled"))
    try:
        address = f"127.0.0.1:{port}"
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                if time.perf_counter() - t0 > 120 or head.poll() is not None:
                    raise RuntimeError("the Ray head did not start") from None
                time.sleep(0.2)
        print(f"  head up in {time.perf_counter() - t0:.1f} s  [{_load()}]")
        ray.init(address=address, log_to_driver=False)   # the sweep below joins this driver's connection
        m = len(TINY_GRID["model.g"])
        for attempt in ("first (workers start, import the engine)", "second (workers warm)"):
            wall, rows, startup = timed_sweep("passive", TINY_GRID, None, cores, backend="ray")
            own = sum(r["wall_time"] for r in rows) / cores
            print(f"  {m} runs of 1 ms, {attempt}: {wall:.2f} s, {(wall - own) / m * 1e3:.2f} ms a task beyond "
                  f"the runs' own time  [{_load()}]")
        refs = [ray.put(dict(row, index=i)) for i in range(2000)]
        t = time.perf_counter()
        for ref in refs:
            ray.get(ref)
        print(f"  fetching a row's result in the driver: {(time.perf_counter() - t) / len(refs) * 1e6:.0f} us "
              f"(ray.get of one {size}-byte row, 2000 times)  [{_load()}]")
        wall, rows, startup = timed_sweep("walk", GRID, DURATION, cores, backend="ray")
        n = len(rows)
        print(f"  {n} walk runs of {DURATION:g} s: {wall:.2f} s, {n / wall:.2f} runs/s  [{_load()}]")
        ray.shutdown()
    finally:
        os.killpg(head.pid, signal.SIGTERM)    # the head's process group: ray start --block and what it started
        head.wait(timeout=60)
        # ray start leaves the address of its cluster here, and a later ray.init() would try to join it
        marker = os.path.join(tempfile.gettempdir(), "ray", "ray_current_cluster")
        if os.path.exists(marker) and open(marker).read().strip().endswith(f":{port}"):
            os.remove(marker)
    return 0


def _outcome(rows):
    return [{k: v for k, v in r.items() if k != "wall_time"} for r in rows]


if __name__ == "__main__":
    raise SystemExit(main())
