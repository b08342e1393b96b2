"""``biped-sim sweep``: a scene run over a parameter grid on every core (or Ray), to a CSV and a map.

Owns the command line only: parsing ``--set NAME=START:STOP:NUM`` / ``NAME=v1,v2,...``, the progress
line, the CSV, the exit status; the sweep, its rows and its figure are biped_sim.analysis.sweep's.
"""
from __future__ import annotations

import contextlib
import math
import signal
import sys
import time
from pathlib import Path

from biped_sim.analysis import sweep as sw
from biped_sim.config.controllers import CLI_HELP, cli_controller
from biped_sim.config.help_format import HelpFormatter
from biped_sim.config.progress import Progress

#: from this many runs on, the command says how many and about how long before it starts them
ANNOUNCED_GRID = 1_000
#: past this many runs the command asks for --yes: hours of runs, and every row held in memory
LARGE_GRID = 100_000


def register(sub):
    p = sub.add_parser(
        "sweep", help="run a scene over a parameter grid on every core (or a Ray cluster): CSV and map",
        description="Run SCENE at every point of the product of the --set grids (row-major: the last --set "
                    "varies fastest), in parallel, and write one CSV row per run: the parameter values, status, "
                    "message, impacts (steps walked), t_end, x_end (distance the hip travelled), mean_speed, "
                    "energy_residual and drift (the run's own error estimate), wall_time, q_end[i] and dq_end[i] "
                    "(i = 0..n-1 over the robot's n coordinates, named in the last line; a grid over robot values of "
                    "different sizes leaves a smaller robot's cells past its n empty). "
                    "Names are those of the scene file: kp, step_angle, duration, initial_q[0], "
                    "walk_controller.torque_limit, ..., and controller.NAME for an argument of --controller's class "
                    "(docs/sweeps.md). A failed run is a row; Ctrl-C, SIGTERM "
                    "or SIGHUP writes the runs done.",
        formatter_class=HelpFormatter)
    p.add_argument("scene", help="a scene name in msg_configs/ (walk, slope, ...) or a path to a .yaml file")
    p.add_argument("--set", dest="grid", action="append", required=True, metavar="NAME=VALUES",
                   help="a swept parameter: NAME=START:STOP:NUM (NUM values evenly spaced, both ends included) or "
                        "NAME=v1,v2,... (repeatable; the first two make the map's axes)")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds per run (default: the scene's)")
    p.add_argument("--workers", type=int, default=None, help="parallel runs (default: every core; Ray: its CPUs)")
    p.add_argument("--backend", choices=sw.BACKENDS, default="process",
                   help="process: a pool of processes on this machine; ray: Ray tasks (pip install biped_sim[ray])")
    p.add_argument("--ray-address", default=None, help="a running Ray cluster (ray start --head; 'auto'); "
                                                      "default: a local Ray started for this sweep")
    p.add_argument("--continuous", action="store_true",
                   help="continuous feedback instead of torques held over control_period (the node's run)")
    p.add_argument("--controller", metavar="MODULE:ATTR|walk|none",
                   help=CLI_HELP + "; --set controller.NAME=... sweeps an argument of your class or factory "
                                   "[default: the scene's]")
    p.add_argument("-o", "--output", required=True, help="the CSV to write (one row per run)")
    p.add_argument("--plot", default=None, help="a PNG: distance walked over the first two swept names (a heat map, "
                                                "falls and refused starts marked) or along the one swept name")
    p.add_argument("--no-progress", action="store_true", help="no progress line on stderr")
    p.add_argument("--yes", action="store_true",
                   help=f"start a grid of more than {LARGE_GRID:,} runs (without it such a grid is refused, "
                        "saying how long it would take)")
    p.set_defaults(func=run)


def parse_set(text: str) -> tuple[str, list]:
    """``NAME=START:STOP:NUM`` or ``NAME=v1,v2,...`` -> (NAME, values); ValueError for a malformed one."""
    name, eq, spec = text.partition("=")
    name, spec = name.strip(), spec.strip()
    if not eq or not name or not spec:
        raise ValueError(f"--set {text!r}: expected NAME=START:STOP:NUM or NAME=v1,v2,...")
    if "[" in spec or "]" in spec:       # a YAML list: it was split at its commas into '[1.0' and '2.0]'
        values = spec.strip("[] ")
        raise ValueError(f"--set {text!r}: give the values without brackets, separated by commas: "
                         f"--set {name}={values} (a list parameter is swept by element, e.g. initial_q[0]=...)")
    if ":" in spec:
        parts = spec.split(":")
        try:
            start, stop, num = float(parts[0]), float(parts[1]), int(parts[2])
            if len(parts) != 3:
                raise IndexError
        except (ValueError, IndexError):
            raise ValueError(f"--set {text!r}: START:STOP:NUM needs two numbers and a count, "
                             "e.g. kp=50:500:10") from None
        if num < 1 or not (math.isfinite(start) and math.isfinite(stop)):
            raise ValueError(f"--set {text!r}: NUM must be >= 1 and START, STOP finite")
        if num == 1:
            return name, [start]
        # each value computed alone (not accumulated), so that the CSV shows the value a run used
        return name, [start + (stop - start) * i / (num - 1) for i in range(num)]
    return name, [_scalar(v.strip()) for v in spec.split(",")]


def _scalar(text: str):
    """A value as a scene file would mean it: an integer, a number, true/false, else a string."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def run(args):
    grid = {}
    for text in args.grid:
        name, values = parse_set(text)
        if name in grid:
            raise ValueError(f"--set {name} given twice: give its values in one --set")
        grid[name] = values
    out = Path(args.output)
    sw.check_writable(out, "-o")   # before any run: found after them, it lost them all
    if args.plot:
        sw.check_writable(args.plot, "--plot")
    total = math.prod(len(v) for v in grid.values())
    robots = sw.grid_robots(args.scene, grid)     # the CSV's q_end[i], dq_end[i] run over their coordinates
    size = max(len(c) for c in robots.values())
    options = {"hold": False} if args.continuous else {}
    choice = cli_controller(args.controller)
    if choice not in (None, "walk"):
        options["controller"] = None if choice == "none" else choice
    if total >= ANNOUNCED_GRID:   # a large grid said nothing for minutes (building its runs, starting its pool)
        plan = _plan(args, grid, total, options)
        if total > LARGE_GRID and not args.yes:
            raise ValueError(f"{plan}; more than {LARGE_GRID:,}: add --yes to start them")
        print(plan, file=sys.stderr, flush=True)
    progress = None if args.no_progress else ProgressLine(total)
    t0 = time.perf_counter()
    try:
        rows = sw.sweep(args.scene, grid, duration=args.duration, workers=args.workers, backend=args.backend,
                        ray_address=args.ray_address, progress=progress, **options)
    except sw.SweepInterrupted as stop:
        with _stop_signals_ignored():   # a second SIGTERM must not cut the CSV short
            if progress:
                progress.end()
            sw.write_csv(stop.rows, list(grid), out, size)
        how = "interrupted" if stop.signal == signal.SIGINT else f"stopped by {stop.signal.name}"
        _say(f"{how}: {len(stop.rows)} of {stop.total} runs done, written to {out}")
        return 128 + stop.signal
    if progress:
        progress.end()
    wall = time.perf_counter() - t0
    sw.write_csv(rows, list(grid), out, size)
    failed = sum(r["status"] != "completed" for r in rows)
    print(f"{len(rows)} runs of {args.scene} ({failed} not completed) in {wall:.1f} s, {len(rows) / wall:.2f} runs/s "
          f"({args.backend}, {args.workers or 'all'} workers); wrote {out}")
    print(sw.columns_line(robots))
    if args.plot:
        title = f"biped-sim sweep {args.scene}" + (f", {args.duration:g} s a run" if args.duration else "")
        sw.plot(rows, list(grid), args.plot, title=title)
        print(f"wrote {args.plot}")
    return 0


#: grid points timed for the estimate of a large grid: spread over it (its first point alone, low
#: gains that fall at once, made 1,600 runs of 12 s read as 3 s)
TIMED_POINTS = 5


def _plan(args, grid, total, options) -> str:
    """'N runs of SCENE, D s each: about T on W workers (a run took X ms here)': the mean wall time of
    a few points spread over the grid, each run in this process (after one run that pays for
    importing the engine)."""
    names, columns = list(grid), list(grid.values())
    points = [_point(names, columns, round(i * (total - 1) / max(1, TIMED_POINTS - 1)))
              for i in range(min(TIMED_POINTS, total))]
    sw.run_one(args.scene, points[0], args.duration, options)
    rows = [sw.run_one(args.scene, point, args.duration, options) for point in points]
    line = f"{total:,} runs of {args.scene}" + (f", {args.duration:g} s each" if args.duration else "")
    errors = [r for r in rows if r["status"] == "error"]
    if errors:
        return f"{line} (a run is an error: {errors[0]['message']})"
    run_time = sum(r["wall_time"] for r in rows) / len(rows)
    if args.backend == "ray" and not args.workers:
        return f"{line}: about {_duration_text(total * run_time)} of one core's time " \
               f"(a run took {run_time * 1e3:.0f} ms here)"
    workers = min(args.workers or sw.default_workers(), total)
    return f"{line}: about {_duration_text(total * run_time / workers)} on {workers} workers " \
           f"(a run took {run_time * 1e3:.0f} ms here)"


def _point(names, columns, index) -> dict:
    """The grid's point ``index`` (row-major, the last name fastest) without building the others."""
    point = {}
    for name, values in zip(reversed(names), reversed(columns)):
        index, i = divmod(index, len(values))
        point[name] = values[i]
    return {name: point[name] for name in names}


def _duration_text(seconds) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 90 * 60:
        return f"{seconds / 60:.0f} min"
    if seconds < 48 * 3600:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} days"


@contextlib.contextmanager
def _stop_signals_ignored():
    old = {signum: signal.signal(signum, signal.SIG_IGN) for signum in sw.STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, handler in old.items():
            signal.signal(signum, handler)


def _say(line):
    """A line on stderr, which may have gone with its terminal (SIGHUP): the CSV is written already."""
    try:
        print(line, file=sys.stderr, flush=True)
    except OSError:
        pass


class ProgressLine:
    """A sweep's (or basin's) progress, ``progress(done, total, row)``: runs done, those not completed,
    the time left (config.progress: a bar on a terminal, a line every 10 % or 10 s elsewhere)."""

    def __init__(self, total, label="sweep", stream=None):
        self.failures = 0
        self.display = Progress(total, label, unit="runs", stream=stream)

    def __call__(self, done, total, row):
        self.failures += row["status"] != "completed"
        self.display.update(done, f"{self.failures} not completed")

    def end(self):
        self.display.close()
