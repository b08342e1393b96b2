"""``biped-sim animate BAG -o walk.gif`` / ``--scene walk``: a run as a GIF or MP4 (biped_sim.recording.animation)."""
from __future__ import annotations

import sys

from biped_sim.config.controllers import CLI_HELP, chosen_controller, cli_controller


def register(sub):
    p = sub.add_parser(
        "animate", help="a recorded run (BAG) or a scene run headless (--scene) as a GIF or MP4",
        description="Draw a run as a moving stick figure (leg 1 blue, leg 2 orange, torso green,\n"
                    "the stance foot red) with the ground reaction force as an arrow (400 N per m),\n"
                    "a flash at each touchdown and the simulated time; at real-time speed unless\n"
                    "--speed says otherwise. GIF through Pillow (its frame delays are whole\n"
                    "hundredths of a second: --fps is rounded to one, 30 to 33.3, at most 50); MP4\n"
                    "needs imageio-ffmpeg (pip install imageio-ffmpeg). A progress bar goes to\n"
                    "stderr.",
        epilog="examples:\n  biped-sim animate bags/walk-20261123T230501832Z -o walk.gif\n"
               "  biped-sim animate --scene walk --duration 5 -o walk.mp4 --fps 30\n"
               "  biped-sim animate --scene slope --speed 0.5 -o slow.gif",
        formatter_class=__import__("argparse").RawDescriptionHelpFormatter)
    p.add_argument("bag", metavar="BAG", nargs="?", help="a bag directory (or its .mcap) recorded by biped_sim")
    p.add_argument("--scene", metavar="NAME", help="instead of a bag: run this scene headless "
                   "(msg_configs/NAME.yaml, or a path to a .yaml) and draw it")
    p.add_argument("--controller", metavar="MODULE:ATTR|walk|none",
                   help="with --scene: " + CLI_HELP + " [default: the scene's]")
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="the file to write: .gif or .mp4")
    p.add_argument("--speed", type=float, default=1.0,
                   help="simulated seconds per second of the animation (default 1: real time)")
    p.add_argument("--fps", type=float, default=20.0, help="frames per second of the animation (default 20)")
    p.add_argument("--start", type=float, default=None, metavar="S", help="first simulated time drawn (s)")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="simulated seconds drawn (default: to the end of the run; with --scene, also how "
                        "long the scene runs)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _check(args):
    if (args.bag is None) == (args.scene is None):
        raise ValueError("give a BAG or --scene NAME (one of them)")
    if args.controller is not None and args.scene is None:
        raise ValueError("--controller goes with --scene (a bag's run has its controller already)")
    for name in ("speed", "fps"):
        v = getattr(args, name)
        if not v > 0 or v == float("inf"):
            raise ValueError(f"--{name} must be a positive number, got {v}")
    if args.duration is not None and not args.duration > 0:
        raise ValueError(f"--duration must be positive, got {args.duration}")
    if args.start is not None and not args.start >= 0:
        raise ValueError(f"--start must be >= 0, got {args.start}")


def run(args):
    from biped_sim.recording import animation as A
    _check(args)
    try:
        A.check_output(args.output)   # before any work: the suffix, and the MP4 encoder
    except A.MissingEncoder as exc:
        print(f"biped-sim animate: {exc}", file=sys.stderr)
        return 2
    if args.scene is not None:
        from biped_sim.config.scenes import load_scene
        scene = load_scene(args.scene)
        controller = chosen_controller(cli_controller(args.controller), scene)
        t_final = scene.duration if args.duration is None else (args.start or 0.0) + args.duration
        if not t_final > 0:
            raise ValueError(f"scene {scene.name} has no duration: give --duration")
        result = scene.simulate(t_final=t_final, compute_grf=True, controller=controller)
        if result.status != "completed":
            print(f"biped-sim animate: the run {result.status} at t={result.t[-1]:.6g} s: {result.message} "
                  "(drawn up to there)", file=sys.stderr)
        track = A.track_from_result(result, scene.engine_arguments()["model"], scene.params["slope"])
        bar = None if args.quiet else A.ProgressBar()
        n, fps = A.write(track, args.output, fps=args.fps, speed=args.speed, start=args.start,
                         duration=args.duration, progress=bar)
        source = f"scene {scene.name}"
    else:
        # a bag is read as a stream, frame by frame: the memory does not grow with the run's length
        bar = None if args.quiet else A.ProgressBar()
        n, fps, states = A.write_bag(args.bag, args.output, fps=args.fps, speed=args.speed, start=args.start,
                                     duration=args.duration, progress=bar)
        source = args.bag
        if states.cut:
            what = "is BEING RECORDED right now" if states.being_written else (
                f"is CUT SHORT{states.cut.removeprefix('cut short')}")
            print(f"biped-sim animate: the bag {what}: drawn up to its last complete chunk, t = "
                  f"{states.t_last:.6g} s (the run is longer)"
                  + ("" if states.being_written else f"; run 'biped-sim recover {args.bag}' to repair the file"),
                  file=sys.stderr)
    print(f"wrote {args.output}: {n} frames at {fps:.4g} fps, speed {args.speed:g}x, from {source}")
    return 0
