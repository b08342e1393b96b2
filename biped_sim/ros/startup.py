"""What both node executables do around their node: start rclpy, catch the stop signals, refuse to start.

Owns the start and the refusal, so that a bad command line gives one line on stderr and exit code 2
(no traceback) in ``sim_node`` and ``walk_controller`` alike. rclpy's own signal handlers are off:
the stop signals (:data:`STOP_SIGNALS`: SIGINT, SIGTERM and SIGHUP, every signal that ends a process
in normal use) only append to a list that the node's loop polls, so that the node ends its run
cleanly (final status, bag closed) instead of being interrupted inside a callback or, for SIGHUP
(the terminal or the ssh session closed), killed without a word.
"""
from __future__ import annotations

import contextlib
import os
import re
import signal
import sys
import tempfile
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


def missing_params_file(argv: list) -> str | None:
    """Why a ``--params-file`` of ``argv`` cannot be read (it does not exist, is a folder, is not
    readable), or None. rcl's own words for it were "Error opening YAML file, at .../parser.c:271"."""
    from biped_sim.ros.params_files import params_files  # it imports this module
    for name in params_files(argv):
        path = Path(name)
        if not path.exists():
            return (f"the parameters file {name} does not exist ({Path.cwd()} is the current folder): check the "
                    "path, e.g. --params-file msg_configs/walk.yaml from the repository's root")
        if path.is_dir():
            return f"the parameters file {name} is a folder: give a .yaml file in it, e.g. {name}/walk.yaml"
        try:
            with open(path, "rb"):
                pass
        except OSError as exc:
            return f"the parameters file {name} cannot be read ({exc.strerror}): check its permissions"
    return None


def ros_arguments_message(text: str) -> str:
    """rcl's refusal of the ROS arguments as one line that says what to fix: without the C source
    locations (", at /project/src/rcl/arguments.c:415") and the lexer's internals."""
    text = re.sub(r",? at /\S+?:\d+", "", text).strip()
    text = re.sub(r"^failed to initialize rcl: ", "", text)
    text = re.sub(r"\s*Error: Expected lexeme type \(\d+\) not found, search ended at index \d+", "", text)
    params = re.match(r"Couldn't parse params file: '--params-file (.+?)'\. Error: (.*)$", text)
    if params:
        return (f"the parameters file {params.group(1)} is not one rcl can read: {params.group(2).rstrip('.')}; fix "
                "it there (its form, as in msg_configs/walk.yaml: the node's name, under it 'ros__parameters:', "
                "under that 'NAME: VALUE' a line)")
    return (f"cannot read the ROS arguments: {text.rstrip('.')}; write them after --ros-args as -p NAME:=VALUE, "
            "--params-file FILE or -r __node:=NAME")


@contextlib.contextmanager
def stderr_held():
    """File descriptor 2 into a temporary file while the body runs; yields a callable that returns
    what was written. rcl logs its own ERROR line ("Failed to parse global arguments") before it
    raises: the refusal says the same in one line, so a refusal drops it; a start writes it out.
    The stop signals wait (blocked) until descriptor 2 is back: a signal whose handler raised between
    the two dup2 calls left it in the temporary file, and the line that said the signal was lost (an
    exit code 129 with no output, once in a loaded make test)."""
    sys.stderr.flush()
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        saved = os.dup(2)
        with tempfile.TemporaryFile() as held:
            os.dup2(held.fileno(), 2)
            try:
                yield lambda: (held.seek(0), held.read())[1].decode(errors="replace")
            finally:
                sys.stderr.flush()
                os.dup2(saved, 2)
                os.close(saved)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def init(program: str, args: list) -> list | None:
    """``rclpy.init`` with ``args`` and the stop signals caught: returns the list each stop signal
    (:data:`STOP_SIGNALS`) is appended to, or None (after :func:`refuse`) if the ROS arguments cannot
    be read."""
    missing = missing_params_file(sys.argv if args is None else args)
    if missing:
        refuse(program, missing)
        return None
    with stderr_held() as rcl_said:
        try:
            rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
            failure = None
        except Exception as exc:  # a bad --ros-args or params file; rcl says which, e.g. a list of mixed types
            failure = exc
        said = rcl_said()
    if failure is not None:
        refuse(program, mixed_list_message(str(failure)) or ros_arguments_message(str(failure)))
        return None
    if said:
        sys.stderr.write(said)
    return catch_stop_signals([])


def signal_name(signum: int) -> str:
    return signal.Signals(signum).name
