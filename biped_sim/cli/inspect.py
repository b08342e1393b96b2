"""``biped-sim inspect BAG``: a summary of a recorded run and a PNG (biped_sim.recording.inspect_bag)."""
from __future__ import annotations

from pathlib import Path


def register(sub):
    p = sub.add_parser(
        "inspect", help="summarise a bag and plot it (joint angles, ground forces, impacts, gait strip)",
        description="Print a summary of a recorded run (duration, topics with counts and rates, impacts, "
                    "distance, speed, steps, torques, ground forces, how the run ended) and write a PNG with "
                    "the joint angles, ground reaction forces, hip torques, impact markers and a stick-figure "
                    "strip of the gait.")
    p.add_argument("bag", metavar="BAG", help="bag directory (or its .mcap file)")
    p.add_argument("--png", metavar="FILE", help="figure path (default: BAG.png, beside the bag directory)")
    p.add_argument("--no-png", action="store_true", help="print the summary only")
    p.add_argument("--frames", type=int, default=14, help="stick figures in the gait strip")
    p.set_defaults(func=run)


def run(args):
    from biped_sim.recording.inspect_bag import load_run, plot, summary
    run_ = load_run(args.bag)
    print(summary(args.bag, run_))
    if not args.no_png:
        bag = Path(args.bag)
        png = args.png or str(bag.with_name(bag.name + ".png") if bag.is_dir() else bag.with_suffix(".png"))
        plot(args.bag, png, run_, frames=args.frames)
        print(f"figure      {png}")
    return 0
