"""What both node executables do around their node: start rclpy, catch the stop signals, refuse to start.

Owns the start and the refusal, so that a bad command line gives one line on stderr and exit code 2
(no traceback) in ``sim_node`` and ``walk_controller`` alike. rclpy's own signal handlers are off:
SIGINT and SIGTERM only append to a list that the node's loop polls, so that the node ends its run
cleanly (final status, bag closed) instead of being interrupted inside a callback.
"""
from __future__ import annotations

import signal
import sys

import rclpy
from rclpy.signals import SignalHandlerOptions

EXIT_REFUSED = 2


class StartupError(Exception):
    """The node cannot start: the message says why (printed without a traceback, exit code 2)."""


def refuse(program: str, why) -> int:
    """Print why ``program`` cannot start (one line on stderr); the exit code to return."""
    print(f"{program}: error: {why}", file=sys.stderr)
    return EXIT_REFUSED


def init(program: str, args: list) -> list | None:
    """``rclpy.init`` with ``args`` and the stop signals caught: returns the list each SIGINT/SIGTERM
    is appended to, or None (after :func:`refuse`) if the ROS arguments cannot be read."""
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # a bad --ros-args or params file; rcl says which, e.g. a list of mixed types
        refuse(program, f"cannot read the ROS arguments: {exc}")
        return None
    stop = []
    signal.signal(signal.SIGINT, lambda signum, _frame: stop.append(signum))
    signal.signal(signal.SIGTERM, lambda signum, _frame: stop.append(signum))
    return stop


def signal_name(signum: int) -> str:
    return signal.Signals(signum).name
