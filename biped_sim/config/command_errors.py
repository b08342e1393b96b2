"""The one place where an exception becomes a command's one-line message and exit code.

Owns what every command (``biped-sim`` and its sub-commands, the nodes, ``torque_pub``,
``biped_echo``, ``make demo``) prints when it stops on an error: one line on stderr, ``PROGRAM:
error: what is wrong; what to do``, never a Python traceback for a mistake of the user's or a
fault of the machine. It lives in ``config/`` (the layer that reads the user's input) and imports
only the standard library, so that ``ros/`` and ``cli/`` both use it without importing rclpy.

=====================  =========  ===========================================================
exception              exit code  message
=====================  =========  ===========================================================
CommandError           its code   its text (a refusal that is not bad input: "nothing to
                                  recover", a run cut short)
ValueError             2          its text (the user's input is wrong: the text says which)
OSError                1          the path and the system's reason, and what to do about it
ImportError            2          the missing package and how to install it
StoppedAtStart         128 + sig  one line: the signal came before the command started its work
KeyboardInterrupt      130        nothing (Ctrl-C is the user's own stop)
BrokenPipeError        1          nothing (the reader of our output has gone: ``... | head``)
SystemExit             its code   argparse's usage line has been printed already
anything else          1          one line, "this is a bug", and how to get the traceback
=====================  =========  ===========================================================

``BIPED_SIM_DEBUG=1`` prints the traceback as well (before the line).
"""
from __future__ import annotations

import errno
import os
import sys
import traceback

DEBUG_VARIABLE = "BIPED_SIM_DEBUG"
EXIT_ERROR = 1
EXIT_USAGE = 2
EXIT_SIGINT = 130          # 128 + SIGINT, what a shell reports for a command stopped by Ctrl-C
EXIT_SIGTERM = 143         # 128 + SIGTERM

#: what to do, by errno of an OSError
_WHAT_TO_DO = {
    errno.ENOENT: "check the path",
    errno.ENOTDIR: "check the path: a part of it is a file, not a folder",
    errno.EISDIR: "give a file, not a folder",
    errno.EACCES: "choose a folder you can write to, or change its permissions",
    errno.EPERM: "choose a folder you can write to, or change its permissions",
    errno.EROFS: "choose a folder on a writable file system",
    errno.ENOSPC: "free some disk space or choose another disk",
    errno.EDQUOT: "free some disk space or choose another disk",
    errno.EEXIST: "choose a new path",
}


class StoppedAtStart(KeyboardInterrupt):
    """A stop signal (SIGINT, SIGTERM, SIGHUP) that came while a command was starting, before it
    installed its own handlers (a node's imports take about half a second): ``signum`` says which."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


#: the stop signals that came while a command was starting (an import may turn the StoppedAtStart raised
#: inside a C extension's initialisation into an ImportError: "initialization failed")
STOPPED_AT_START: list = []


def raise_on_stop_signals():
    """Until the command installs its own handlers, SIGINT, SIGTERM and SIGHUP raise
    :class:`StoppedAtStart`: Ctrl-C printed a KeyboardInterrupt traceback from deep in an import, and
    SIGTERM or SIGHUP killed the process without a word. A SIGHUP ignored on entry (``nohup``) stays so."""
    import signal

    def stop(signum, _frame):
        STOPPED_AT_START.append(signum)
        raise StoppedAtStart(signum)
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        if signum == signal.SIGHUP and signal.getsignal(signum) is signal.SIG_IGN:
            continue
        signal.signal(signum, stop)


class CommandError(Exception):
    """A command refuses or stops for a reason that is not bad input; ``code`` is its exit code."""

    def __init__(self, message: str, code: int = EXIT_ERROR):
        super().__init__(message)
        self.code = code


def debugging() -> bool:
    return os.environ.get(DEBUG_VARIABLE, "") not in ("", "0")


def describe_os_error(exc: OSError) -> str:
    """An OSError as 'path: the system's reason; what to do' (the path where the error names one)."""
    reason = exc.strerror or str(exc) or type(exc).__name__
    paths = [p for p in (exc.filename, getattr(exc, "filename2", None)) if p is not None]
    where = " -> ".join(os.fsdecode(p) for p in paths)
    line = f"{where}: {reason}" if where else reason
    todo = _WHAT_TO_DO.get(exc.errno)
    return f"{line}; {todo}" if todo else line


def explain(program: str, exc: BaseException) -> tuple[int, str | None]:
    """(exit code, the line to print or None) for an exception that ended ``program``."""
    if isinstance(exc, SystemExit):
        code = exc.code
        if code is None or isinstance(code, int):
            return int(code or 0), None
        return EXIT_ERROR, f"{program}: error: {code}"
    if isinstance(exc, StoppedAtStart):
        import signal
        return 128 + exc.signum, (f"{program}: {signal.Signals(exc.signum).name} during start-up: stopped before "
                                  "it ran anything (nothing was simulated, sent or recorded)")
    if isinstance(exc, KeyboardInterrupt):
        return EXIT_SIGINT, None
    if isinstance(exc, BrokenPipeError):
        return EXIT_ERROR, None
    if isinstance(exc, CommandError):
        return exc.code, f"{program}: error: {exc}"
    if isinstance(exc, ValueError):
        return EXIT_USAGE, f"{program}: error: {exc}"
    if isinstance(exc, OSError):
        return EXIT_ERROR, f"{program}: error: {describe_os_error(exc)}"
    if isinstance(exc, ImportError):
        name = exc.name or str(exc)
        return EXIT_USAGE, (f"{program}: error: cannot import {name} ({exc}); install the pinned packages "
                            "(make venv does) or source a ROS 2 Jazzy install")
    return EXIT_ERROR, (f"{program}: error: unexpected {type(exc).__name__}: {exc} -- this is a bug, please report "
                        f"it with {DEBUG_VARIABLE}=1 for the traceback")


def run_command(program: str, main, *args, **kwargs) -> int:
    """``main(*args, **kwargs)``'s exit code; an exception it raises is printed as one line (see the table)."""
    try:
        return int(main(*args, **kwargs) or 0)
    except BaseException as exc:  # noqa: BLE001 - this is the one place that catches everything
        if isinstance(exc, BrokenPipeError):
            # Python's recipe: stdout to /dev/null, so that the flush at exit does not fail again
            try:
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            except (OSError, ValueError):
                pass
        code, line = explain(program, exc)
        if debugging() and not isinstance(exc, (SystemExit, KeyboardInterrupt, BrokenPipeError)):
            traceback.print_exc()
        if line:
            try:
                print(line, file=sys.stderr, flush=True)
            except (OSError, ValueError):
                pass
        return code
