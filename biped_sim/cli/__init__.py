"""``biped-sim``: the command line of the headless simulator (no ROS needed).

Owns argument parsing and dispatch only; each subcommand lives in ``biped_sim/cli/<name>.py``
with ``register(subparsers)`` (adds its parser, sets ``func``).
"""
from __future__ import annotations

import argparse
import importlib
import sys

from biped_sim.config.command_errors import run_command

COMMANDS = ("simulate", "accuracy", "stability", "gait", "sweep", "basin", "resim", "inspect", "recover", "replay",
            "animate")


def build_parser(only=None) -> argparse.ArgumentParser:
    """The parser of every command, or of the command ``only`` alone (a command's run imports its
    module only, not the analysis modules of the others: ~0.1 s of a short command)."""
    parser = argparse.ArgumentParser(
        prog="biped-sim",
        description="Headless hybrid-dynamics simulation of the planar three-link biped\n(docs/model.md).",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Run 'biped-sim COMMAND --help' for the options of a command.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS if only is None else (only,):
        importlib.import_module(f"biped_sim.cli.{name}").register(sub)
    return parser


def main(argv=None) -> int:
    """``biped-sim ARGS``: the exit code; an error ends it with one line (config.command_errors)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    program = f"biped-sim {argv[0]}" if argv[:1] and argv[0] in COMMANDS else "biped-sim"
    return run_command(program, _dispatch, argv)


def _dispatch(argv) -> int:
    if argv[:1] == ["replay"]:
        # its own parser (a ROS tool's arguments, --ros-args included): argparse would take a
        # leading '--help' for biped-sim's rather than hand it on
        from biped_sim.cli.replay import run_argv
        return run_argv(argv[1:])
    args = build_parser(argv[0] if argv[:1] and argv[0] in COMMANDS else None).parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
