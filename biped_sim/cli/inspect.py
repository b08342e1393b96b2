"""``biped-sim inspect BAG``: a summary of a recorded run and a PNG (biped_sim.recording.inspect_bag)."""
from __future__ import annotations

import argparse
from pathlib import Path


def _at_least_one(text):
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {n}")
    return n


def register(sub):
    p = sub.add_parser(
        "inspect", help="summarise a bag and plot it (joint angles, ground forces, impacts, gait strip)",
        description="Print a summary of a recorded run (duration, topics with counts and rates, impacts, "
                    "distance, speed, steps, torques, ground forces, how the run ended) and write a PNG with "
                    "the joint angles, ground reaction forces, hip torques, impact markers and a stick-figure "
                    "strip of the gait. A bag cut short (its recording was killed) is summarised up to its "
                    "last complete chunk and said to be cut short; a bag of another program is summarised by "
                    "its topics.")
    p.add_argument("bag", metavar="BAG", help="bag directory (or its .mcap file)")
    p.add_argument("--png", metavar="FILE", help="figure path (default: BAG.png, beside the bag directory)")
    p.add_argument("--no-png", action="store_true", help="print the summary only")
    p.add_argument("--frames", type=_at_least_one, default=14, help="stick figures in the gait strip (at least 1)")
    p.set_defaults(func=run)


def run(args):
    from biped_sim.recording import bagio
    from biped_sim.recording.inspect_bag import load_run, plot, summary
    bag = Path(args.bag)
    bagio.mcap_path(bag)                 # ValueError: no bag, or not MCAP
    png = None
    if not args.no_png:
        png = Path(args.png or (bag.with_name(bag.name + ".png") if bag.is_dir() else bag.with_suffix(".png")))
        if not png.parent.is_dir():     # before the work, not after it
            raise ValueError(f"cannot write the figure {png}: the folder {png.parent} does not exist; "
                             "create it or give another --png path")
    run_ = load_run(args.bag)
    if not run_["counts"]:
        cut = bagio.cut_short(bag)
        if cut:
            raise ValueError(f"{bag} is {cut} and holds no complete message: nothing to inspect (the "
                             "recording was killed before its first chunk)")
    print(summary(args.bag, run_))
    if png is not None:
        if not len(run_["t"]):
            print("figure      none (no joint_states in this bag)")
            return 0
        try:
            run_["robot"].model()        # the figure draws the robot's links
        except ValueError as exc:
            print("figure      none (" + ("the robot cannot be loaded: see the robot line" if run_["robot"].problem
                                          else str(exc)) + ")")
            return 0
        plot(args.bag, str(png), run_, frames=args.frames)
        print(f"figure      {png}")
    return 0
