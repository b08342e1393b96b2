"""``biped-sim replay BAG``: publish a bag's messages with their original timing (needs rclpy)."""
from __future__ import annotations

import argparse


def register(sub):
    p = sub.add_parser(
        "replay", add_help=False, help="publish a bag's messages on their topics with their original timing "
                                       "(like 'ros2 bag play'; needs rclpy)",
        description="See 'biped-sim replay --help'.")
    p.add_argument("argv", nargs=argparse.REMAINDER)
    p.set_defaults(func=run)


def run(args):
    return run_argv(args.argv)


def run_argv(argv):
    from biped_sim.ros.replay import main
    return main(argv)
