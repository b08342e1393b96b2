"""What both node executables do around their node: start rclpy, catch the stop signals, refuse to start.

Owns the start and the refusal, so that a bad command line gives one line on stderr and exit code 2
(no traceback) in ``sim_node`` and ``walk_controller`` alike. rclpy's own signal handlers are off:
the stop signals (:data:`STOP_SIGNALS`: SIGINT, SIGTERM and SIGHUP, every signal that ends a process
in normal use) only append to a list that the node's loop polls, so that the node ends its run
cleanly (final status, bag closed) instead of being interrupted inside a callback or, for SIGHUP
(the terminal or the ssh session closed), killed without a word.
"""
from __future__ import annotations

import re
import signal
import sys
from pathlib import Path

import rclpy
from rclpy.signals import SignalHandlerOptions

EXIT_REFUSED = 2


class StartupError(Exception):
    """The node cannot start: the message says why (printed without a traceback, exit code 2)."""


def refuse(program: str, why) -> int:
    """Print why ``program`` cannot start (one line on stderr); the exit code to return."""
    print(f"{program}: error: {why}", file=sys.stderr)
    return EXIT_REFUSED


def own_arguments(args: list) -> list:
    """The arguments of ``args`` (without the program name) that are not ROS's: those outside
    ``--ros-args ... [--]`` (rcl's grammar: ``--`` ends the ROS arguments, ``--ros-args`` opens them)."""
    own, in_ros = [], False
    for a in args:
        if a == "--ros-args":
            in_ros = True
        elif in_ros and a == "--":
            in_ros = False
        elif not in_ros:
            own.append(a)
    return own


def read_command_line(program: str, argv: list, usage) -> int | None:
    """The nodes take no arguments of their own, only ROS's: None to go on and start the node, or
    the exit code after printing ``usage()`` (``-h``/``--help``: 0) or refusing anything else (2).
    Without it an argument before ``--ros-args`` was ignored and ``--help`` started a recording node."""
    own = own_arguments(argv[1:])
    if not own:
        return None
    if "-h" in own or "--help" in own:
        print(usage())
        return 0
    return refuse(program, f"unknown argument(s) {' '.join(own)}: {program} takes only ROS arguments, after "
                           f"--ros-args (e.g. {program} --ros-args -p NAME:=VALUE); {program} --help lists them")


def mixed_list_message(text: str) -> str | None:
    """The refusal for rcl's "Sequence should be of same type" (a list of integers and doubles, e.g.
    ``initial_q:=[0, 1, 3.14, 3.14, 0]``), naming the parameter where the arguments show it; None
    for any other error. rcl's YAML reader types each number by its spelling and refuses a mix."""
    if "Sequence should be of same type" not in text:
        return None
    name = None
    rule = re.search(r"override rule: '-p ([^:=']+):=", text)
    if rule:
        name = rule.group(1)
    else:  # a params file: rcl names the file and the line (1-based) of the list
        where = re.search(r"params file: '--params-file ([^']+)'.*?line_num (\d+)", text)
        if where:
            try:
                line = Path(where.group(1)).read_text().splitlines()[int(where.group(2)) - 1]
                name = line.split(":")[0].strip().lstrip("- ") or None
            except (OSError, IndexError, ValueError):
                pass
    what = f"parameter '{name}' mixes" if name else "a list parameter mixes"
    return (f"{what} integers and floats (rcl refuses a list of mixed types): write every number of the "
            "list as a float, e.g. [0.0, 1.0, 3.14, 3.14, 0.0]")


#: the signals that end a process in normal use: Ctrl-C, kill (and systemd, docker stop), and the
#: terminal or ssh session closing (SIGHUP: its default action killed the node with no log line)
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def catch_stop_signals(stop: list) -> list:
    """Make each of :data:`STOP_SIGNALS` append its number to ``stop`` (and return ``stop``). A SIGHUP
    ignored on entry stays ignored: ``nohup`` asks for a process that outlives its terminal."""
    for signum in STOP_SIGNALS:
        if signum == signal.SIGHUP and signal.getsignal(signum) is signal.SIG_IGN:
            continue
        signal.signal(signum, lambda signum, _frame: stop.append(signum))
    return stop


def init(program: str, args: list) -> list | None:
    """``rclpy.init`` with ``args`` and the stop signals caught: returns the list each stop signal
    (:data:`STOP_SIGNALS`) is appended to, or None (after :func:`refuse`) if the ROS arguments cannot
    be read."""
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # a bad --ros-args or params file; rcl says which, e.g. a list of mixed types
        refuse(program, mixed_list_message(str(exc)) or f"cannot read the ROS arguments: {exc}")
        return None
    return catch_stop_signals([])


def signal_name(signum: int) -> str:
    return signal.Signals(signum).name
