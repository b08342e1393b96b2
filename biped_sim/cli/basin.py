"""``biped-sim basin``: the basin of attraction of a scene's periodic gait on a 2-D slice (a sweep)."""
from __future__ import annotations

import time

from biped_sim.analysis import basin as bn, sweep as sw
from biped_sim.cli.sweep import ProgressLine
from biped_sim.config.controllers import CLI_HELP, cli_law
from biped_sim.config.help_format import HelpFormatter


def register(sub):
    p = sub.add_parser(
        "basin", help="basin of attraction of a scene's periodic gait on a 2-D slice of initial states",
        description="Find the fixed point z* of the scene's step-to-step map (as biped-sim gait does), then "
                    "start a run from each point of a NUM x NUM grid of post-impact states around it: the "
                    "stance-leg rate and the torso rate (the rates of q[2] and of the base link's angle) moved by up "
                    "to +-SPAN rad/s (angles at z*, the hip "
                    "velocity consistent with the stance foot at rest), continuous feedback. Writes one CSV row "
                    "per run (biped-sim sweep's columns) and a map of the distance walked, z*, falls and refused "
                    "starts marked.",
        formatter_class=HelpFormatter)
    p.add_argument("scene", help="a scene (walk, slope, compass_gait, ...): its controller, or u = 0 "
                   "without a walk_controller section")
    p.add_argument("--span", default="1.0,2.0", help="largest offsets of the stance-leg rate and the torso rate "
                                                     "(rad/s), as DQ_STANCE,DQ_TORSO")
    p.add_argument("--controller", metavar="MODULE:ATTR|walk|none", help=CLI_HELP + " [default: the scene's]")
    p.add_argument("--num", type=int, default=11, help="points along each axis")
    p.add_argument("--duration", type=float, default=5.0, help="simulated seconds per run")
    p.add_argument("--workers", type=int, default=None, help="parallel runs (default: every core)")
    p.add_argument("--backend", choices=sw.BACKENDS, default="process",
                   help="where the runs go: a process pool on this machine, or a Ray cluster (biped_sim[ray])")
    p.add_argument("-o", "--output", required=True, help="the CSV to write")
    p.add_argument("--plot", default=None, help="the PNG of the basin")
    p.add_argument("--no-progress", action="store_true", help="no progress line on stderr")
    p.set_defaults(func=run)


def run(args):
    try:
        span = tuple(float(v) for v in args.span.split(","))
    except ValueError:
        raise ValueError(f"--span {args.span!r}: expected two numbers, DQ_STANCE,DQ_TORSO") from None
    sw.check_writable(args.output, "-o")   # before any run: found after them, it lost them all
    if args.plot:
        sw.check_writable(args.plot, "--plot")
    progress = None if args.no_progress else ProgressLine(args.num ** 2, label="basin")
    t0 = time.perf_counter()
    controller = cli_law(args.controller)
    gait, rows = bn.basin(args.scene, span=span, num=args.num, duration=args.duration, workers=args.workers,
                          backend=args.backend, progress=progress, controller=controller)
    if progress:
        progress.end()
    robots = sw.grid_robots(args.scene, {})
    sw.write_csv(rows, list(bn.AXES), args.output, max(len(c) for c in robots.values()))
    ok = int(bn.walked(rows, 1).sum())
    joints = next(iter(robots.values()))[2:]
    print(f"z* = [{', '.join(f'{v:.6f}' for v in gait.z)}] ({', '.join(joints)} and their rates, leg 1 the stance "
          f"leg); {len(rows)} runs in {time.perf_counter() - t0:.1f} s, {ok} completed {args.duration:g} s; "
          f"wrote {args.output}")
    print(sw.columns_line(robots))
    if args.plot:
        sw.plot(rows, list(bn.AXES), args.plot,
                title=f"biped-sim basin {args.scene}: distance walked in {args.duration:g} s from z* + offsets (rad/s)",
                fixed_point={axis: 0.0 for axis in bn.AXES})
        print(f"wrote {args.plot}")
    return 0
