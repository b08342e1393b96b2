"""Sweeps: one scene run over the product of a parameter grid, on every core or on a Ray cluster.

Owns the grid (its names and values checked before any run), the one task every backend runs
(:func:`run_one`: ``load_scene(scene, overrides=...).simulate(...)`` and its summary row), and the
two backends: a process pool of the standard library (``backend="process"``) and Ray
(``backend="ray"``, the optional extra ``pip install biped_sim[ray]``). Both keep a bounded number
of tasks in flight and put the rows back in grid order, so that the result does not depend on the
backend, the number of workers or the completion order (each run is one deterministic process-local
computation). docs/sweeps.md shows the API and ``biped-sim sweep``.
"""
from __future__ import annotations

import contextlib
import errno
import inspect
import io
import itertools
import math
import multiprocessing
import multiprocessing.context
import multiprocessing.util
import os
import pickle
import secrets
import signal
import tempfile
import threading
import time
import types
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import fields
from pathlib import Path

from biped_sim.config.controllers import controller_arguments, make_controller, portable
from biped_sim.config.joints import joint_layout
from biped_sim.config.scenes import load_scene, scene_path
from biped_sim.engine.options import Options
from biped_sim.engine.simulate import simulate

BACKENDS = ("process", "ray")
#: the outcome columns of a row, after the swept parameters (docs/sweeps.md says what each is)
OUTCOME = ("status", "message", "impacts", "t_end", "x_end", "mean_speed", "q_end", "dq_end",
           "energy_residual", "drift", "wall_time")
#: runs in flight per worker: enough that a worker never waits for the next task, few enough that a
#: grid of millions of runs is not turned into millions of pending futures at once
IN_FLIGHT_PER_WORKER = 4


#: the signals that end a sweep and keep its finished runs: Ctrl-C, and what ``timeout``, a batch
#: scheduler or systemd (SIGTERM) and a closed terminal (SIGHUP) send
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C (or SIGTERM, SIGHUP) during a sweep: the pool is stopped; ``rows`` holds the runs that
    finished, in grid order (each row carries its ``index`` in the grid), ``total`` the number of runs
    in the grid and ``signal`` the signal that stopped it (a :class:`signal.Signals`)."""

    def __init__(self, rows, total, signum=signal.SIGINT):
        self.signal = signal.Signals(signum)
        super().__init__(f"sweep stopped by {self.signal.name} after {len(rows)} of {total} runs")
        self.rows, self.total = rows, total


class _StopSignal(KeyboardInterrupt):
    """A stop signal (:data:`STOP_SIGNALS`) raised in the sweep's thread, so that it unwinds as Ctrl-C does."""

    def __init__(self, signum):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def grid_runs(grid) -> tuple[list[str], list[list], list[dict]]:
    """The swept names, their values (numpy scalars as Python numbers) and one overrides dict per run:
    the grid's product, row-major over the names in the order given (the last name varies fastest)."""
    if not isinstance(grid, dict) or not grid:
        raise ValueError(f"grid must be a non-empty mapping of parameter names to lists of values, got {grid!r}")
    names, columns = [], []
    for name, values in grid.items():
        if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
            raise ValueError(f"grid[{name!r}] must be a list of values, got {values!r}")
        values = [_plain_value(v) for v in values]
        if not values:
            raise ValueError(f"grid[{name!r}] is empty: give at least one value")
        names.append(name)
        columns.append(values)
    return names, columns, [dict(zip(names, combo)) for combo in itertools.product(*columns)]


def check_sweep(scene, grid, duration=None, run_options=None) -> list[dict]:
    """Everything a sweep can be refused for, before any run starts: the scene, every name and every
    value of the grid (each value with the other names at their first value, so that a bad value
    is named), ``duration`` and the run options (their names, and the engine's own check of those
    that are :class:`Options`). A value the engine refuses only when it starts (an initial state
    whose stance foot moves) is that run's "error" row. Returns the runs (:func:`grid_runs`);
    raises ValueError."""
    scene = _scene_argument(scene)
    names, columns, runs = grid_runs(grid)
    run_options = dict(run_options or {})
    for name, values in zip(names, columns):
        for value in values:
            point_scene, point_ctrl = controller_arguments(dict(runs[0], **{name: value}))
            loaded = load_scene(scene, overrides=point_scene)
            loaded.engine_arguments()   # a robot the engine cannot run is refused here, not in every run
            if point_ctrl:
                if run_options.get("controller") is None:
                    raise ValueError(f"grid name {name!r} sets an argument of the controller: give the controller "
                                     "as controller=... (a class, a factory or 'MODULE:ATTR'; --controller on the "
                                     "command line)")
                make_controller(run_options["controller"], loaded.engine_arguments()["model"], **point_ctrl)
    if duration is not None and (isinstance(duration, bool) or not isinstance(duration, (int, float))
                                 or not math.isfinite(duration) or duration <= 0):
        raise ValueError(f"duration must be a positive number of seconds (or None: the scene's), got {duration!r}")
    if "t_final" in run_options:
        raise ValueError("give the run's length as duration=..., not t_final")
    try:
        pickle.dumps(run_options)
    except Exception as exc:
        raise ValueError(f"run options must be picklable to reach the workers: {exc}") from None
    known = {"hold"} | (set(inspect.signature(simulate).parameters) - {"options", "t_final"}) \
        | {f.name for f in fields(Options)}
    unknown = sorted(set(run_options) - known)
    if unknown:
        raise ValueError(f"unknown run option(s) {unknown}; allowed: {', '.join(sorted(known))}")
    Options(**{k: v for k, v in run_options.items() if k in {f.name for f in fields(Options)}}).check()
    return runs


def run_one(scene, overrides: dict, duration=None, run_options=None) -> dict:
    """One run of a sweep and its row: ``load_scene(scene, overrides=overrides).simulate(t_final=
    duration, **run_options)`` (``duration=None``: the scene's). An exception inside the run is a
    row with status "error" and its message; it is never raised."""
    t0 = time.perf_counter()
    row = dict(overrides)
    try:
        point_scene, point_ctrl = controller_arguments(overrides)
        s = load_scene(scene, overrides=point_scene)
        kwargs = dict(run_options or {})
        if duration is not None:
            kwargs["t_final"] = duration
        if point_ctrl:
            kwargs["controller_args"] = point_ctrl
        row.update(summary(s.simulate(**kwargs), s.params["initial_q"][0]))
    except Exception as exc:   # a sweep's rows say what failed; the sweep goes on
        row.update(_empty_outcome("error", f"{type(exc).__name__}: {exc}", _coordinates(scene, overrides)))
    row["wall_time"] = time.perf_counter() - t0
    return row


def summary(result, x0: float) -> dict:
    """The outcome columns of a finished run (all but ``wall_time``): ``x_end`` is the distance the
    hip travelled along x from ``x0``, ``energy_residual`` the largest energy-balance residual of
    the run (J) and ``drift`` its largest constraint drift (m or m/s), both from ``result.stats``:
    the run's own error estimate, at no extra cost."""
    st = result.stats
    t_end = float(result.t[-1]) if len(result.t) else 0.0
    x_end = float(result.q[-1][0]) - x0 if len(result.q) else math.nan
    return dict(status=result.status, message=result.message, impacts=len(result.impacts), t_end=t_end,
                x_end=x_end, mean_speed=x_end / t_end if t_end > 0 else 0.0,
                q_end=[float(v) for v in result.q[-1]], dq_end=[float(v) for v in result.dq[-1]],
                energy_residual=float(st["max_energy_balance_residual"]),
                drift=float(max(st["max_constraint_drift_position"], st["max_constraint_drift_velocity"])))


def sweep(scene, grid, duration=None, workers=None, backend="process", *, ray_address=None, progress=None,
          **run_options) -> list[dict]:
    """Run ``scene`` at every point of ``grid`` and return one row (a dict) per run, in grid order.

    ``grid`` maps parameter names, as the scene file writes them (``kp``, ``initial_dq[2]``,
    ``walk_controller.kp``; :func:`biped_sim.config.scenes.override_targets`), to lists of values; the
    runs are its product, row-major over the names in the order given. A row holds the parameter
    values, then :data:`OUTCOME`; it equals, bit for bit, the single run
    ``load_scene(scene, overrides=point).simulate(t_final=duration, **run_options)``.
    ``controller=`` (a run option): your controller instead of the scene's: a controller, a class or
    factory, or ``"MODULE:ATTR"`` (:mod:`biped_sim.config.controllers`); grid names ``controller.NAME``
    are arguments of its class or factory (the row then equals ``...simulate(controller=...,
    controller_args={NAME: value})``).
    ``workers=None``: every core (Ray: the cluster's CPUs); ``backend`` "process" or "ray"
    (``ray_address`` for a running cluster, else a local one). ``progress(done, total, row)`` is
    called after each run. A failed run is a row with its status and message; a bad name, value or
    option is a ValueError before any run; Ctrl-C raises :class:`SweepInterrupted` with the rows done.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers must be a positive integer (or None: every core), got {workers!r}")
    if ray_address is not None and backend != "ray":
        raise ValueError("ray_address needs backend='ray'")
    scene = _scene_argument(scene)
    if run_options.get("controller") is not None:
        run_options["controller"] = portable(run_options["controller"])
    runs = check_sweep(scene, grid, duration, run_options)
    if backend == "process":   # (Ray pickles such a function by value)
        _check_not_from_main(run_options)
    tasks = [(scene, point, duration, run_options) for point in runs]
    execute = _run_ray if backend == "ray" else _run_processes
    rows = [None] * len(tasks)
    done = 0
    try:
        with _stop_signals_raised(), contextlib.closing(execute(tasks, workers, ray_address)) as finished:
            for index, row in finished:
                rows[index] = dict(index=index, **row)
                done += 1
                if progress is not None:
                    progress(done, len(tasks), rows[index])
    except KeyboardInterrupt as stop:
        raise SweepInterrupted([r for r in rows if r is not None], len(tasks),
                               getattr(stop, "signum", signal.SIGINT)) from None
    return rows


def default_workers() -> int:
    """Every core this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:   # not on Linux
        return os.cpu_count() or 1


def _run_processes(tasks, workers, _address):
    """(index, row) of every task, as the runs finish, on a pool of ``workers`` processes.

    Workers forked by the fork server (:func:`_start_method`) that ignore SIGINT: Ctrl-C reaches
    the parent only, which stops the pool and its workers (so do SIGTERM and SIGHUP, which the
    workers do not ignore: :func:`_worker_setup`).
    A worker that dies (a crash, the OOM killer, the fork server's end) fails the runs in flight as
    rows that say which process ended and how (:func:`_what_ended`), and a new pool takes the rest.
    """
    workers = min(workers or default_workers(), len(tasks))
    pending = iter(enumerate(tasks))
    pool = _new_pool(workers)
    in_flight = {}
    try:
        while True:
            with _stop_signals_held():   # the processes a submit starts must not take a Ctrl-C meant for us
                for index, task in itertools.islice(pending, workers * IN_FLIGHT_PER_WORKER - len(in_flight)):
                    in_flight[pool.submit(run_one, *task)] = index
            # the pool's workers, known before one dies: a broken pool forgets them
            workers_seen = dict(getattr(pool, "_processes", None) or {})
            if not in_flight:
                return
            finished, _ = wait(in_flight, return_when=FIRST_COMPLETED)
            ended = None
            for future in finished:
                index = in_flight.pop(future)
                try:
                    yield index, future.result()
                except BrokenProcessPool:
                    ended = ended or _what_ended(workers_seen)
                    yield index, _died(tasks[index], ended)
            if ended:   # the other runs in flight died with the pool
                for index in in_flight.values():
                    yield index, _died(tasks[index], ended)
                in_flight.clear()
                pool.shutdown(wait=False, cancel_futures=True)
                pool = _new_pool(workers)
    finally:
        _stop_pool(pool)


def _died(task, ended) -> dict:
    return dict(task[1], **_empty_outcome("error", f"during this run or one beside it, {ended}",
                                          _coordinates(task[0], task[1])), wall_time=0.0)


def _what_ended(workers_seen) -> str:
    """Which process of a broken pool ended, and how: "worker pid 123 was killed by SIGKILL (the
    out-of-memory killer sends it)", "... exited with code 3", or the fork server's end, which
    takes its workers with it (each then reads as exit code 255: the fork server that would report
    it has gone). The executor itself terminates the other workers (SIGTERM) once one has died: a
    worker ended otherwise is the one that broke the pool."""
    codes = {}
    deadline = time.monotonic() + 5.0
    # the pool's own thread reads each worker's exit code as it ends the broken pool (terminate, then join):
    # wait for it to have read them all
    while len(codes) < len(workers_seen) and time.monotonic() < deadline:
        codes = {pid: code for pid, p in workers_seen.items() if (code := _exit_code(p)) is not None}
        time.sleep(0 if len(codes) == len(workers_seen) else 0.01)
    server_pid = getattr(getattr(_forkserver, "_forkserver", None), "_forkserver_pid", None) \
        if _popen_forkserver is not None else None
    deadline = time.monotonic() + 1.0
    # 255: no exit code came from the fork server. Its pipes close as it dies, a moment before
    # the kernel has its exit status: wait for that moment
    while server_pid is not None and 255 in codes.values() and time.monotonic() < deadline:
        try:
            # WNOWAIT: multiprocessing reaps it itself (and starts another for the next pool)
            status = os.waitid(os.P_PID, server_pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
        except OSError:
            break
        if status is not None:
            return f"the fork server (pid {server_pid}) {_how(status)}, and its workers with it"
        time.sleep(0.01)
    culprits = {pid: code for pid, code in codes.items() if code != -signal.SIGTERM} or codes
    if not culprits:
        return "a worker process ended (how is not known)"
    return "; ".join(f"worker pid {pid} {_exit_description(code)}" for pid, code in sorted(culprits.items()))


def _exit_code(process):
    """A pool worker's exit code as the pool's own thread has read it, else None. Not ``Process.exitcode``: that
    polls, and a forked-by-the-fork-server worker's code comes once, on a pipe from the fork server; read here
    and in the pool's thread at once, one of the two reads the end of the pipe instead, which multiprocessing
    takes for exit code 255 (the fork server gone), and the last of the two to finish sets it."""
    popen = getattr(process, "_popen", None)
    return None if popen is None else popen.returncode


def _how(status) -> str:
    """A waitid result as 'was killed by SIGKILL' or 'exited with code 3'."""
    if status.si_code in (os.CLD_KILLED, os.CLD_DUMPED):
        return _exit_description(-status.si_status)
    return _exit_description(status.si_status)


def _exit_description(code) -> str:
    """A Process.exitcode (-N: signal N) as 'was killed by SIGKILL (...)' or 'exited with code 3'."""
    if code >= 0:
        return f"exited with code {code}"
    try:
        name = signal.Signals(-code).name
    except ValueError:
        name = f"signal {-code}"
    why = {signal.SIGKILL: " (the out-of-memory killer sends it)", signal.SIGSEGV: " (a crash)",
           signal.SIGBUS: " (a crash)", signal.SIGABRT: " (a crash)"}.get(-code, "")
    return f"was killed by {name}{why}"


def _new_pool(workers):
    return ProcessPoolExecutor(max_workers=workers, mp_context=_start_method(), initializer=_worker_setup)


def _start_method():
    """The fork server where there is one (POSIX): a clean single-threaded process that imports the
    engine once (numpy, scipy: seconds on a loaded machine) and forks the workers of every pool this
    process starts, so that a pool costs that import once and not once per worker or per sweep.
    Its workers do not run the caller's ``__main__`` (:class:`_WorkerPopen`).
    Elsewhere spawned processes. Never a fork of this process, which may hold threads."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        context = _WorkerContext()
        context.set_forkserver_preload([__name__])
        return context
    return multiprocessing.get_context("spawn")


try:
    from multiprocessing import forkserver as _forkserver, popen_forkserver as _popen_forkserver, spawn as _spawn
except ImportError:   # no fork server here (Windows): spawned workers, which run __main__ as multiprocessing does
    _popen_forkserver = None
else:
    class _WorkerPopen(_popen_forkserver.Popen):
        """The fork server's start of a worker, less the caller's main module.

        multiprocessing has every worker run the caller's ``__main__`` (the script, as
        ``__mp_main__``) before its task, so that objects defined there unpickle. A script that calls
        :func:`sweep` at its top level, unguarded (as most first scripts are), then has each worker
        start a sweep of its own while it starts: a RuntimeError ("... before the current process
        has finished its bootstrapping phase") in every worker, and error rows. A worker needs
        nothing from ``__main__`` (:func:`run_one` and its arguments live in this package; a run
        option defined in ``__main__`` is refused by :func:`_check_not_from_main`), so it is not run.
        The rest is ``popen_forkserver.Popen._launch`` (CPython 3.8 to 3.13) as it is.
        """

        def _launch(self, process_obj):
            prep_data = _spawn.get_preparation_data(process_obj._name)
            prep_data.pop("init_main_from_path", None)
            prep_data.pop("init_main_from_name", None)
            buf = io.BytesIO()
            multiprocessing.context.set_spawning_popen(self)
            try:
                multiprocessing.context.reduction.dump(prep_data, buf)
                multiprocessing.context.reduction.dump(process_obj, buf)
            finally:
                multiprocessing.context.set_spawning_popen(None)
            self.sentinel, w = _forkserver.connect_to_new_process(self._fds)
            _parent_w = os.dup(w)
            self.finalizer = multiprocessing.util.Finalize(self, multiprocessing.util.close_fds,
                                                           (_parent_w, self.sentinel))
            with open(w, "wb", closefd=True) as f:
                f.write(buf.getbuffer())
            self.pid = _forkserver.read_signed(self.sentinel)

    class _WorkerProcess(multiprocessing.context.ForkServerProcess):
        @staticmethod
        def _Popen(process_obj):
            return _WorkerPopen(process_obj)

    class _WorkerContext(multiprocessing.context.ForkServerContext):
        Process = _WorkerProcess


def _check_not_from_main(run_options):
    """A ValueError for a run option that is (or holds) a function or class defined in ``__main__``:
    the process pool's workers do not run the caller's script (:class:`_WorkerPopen`), so they could
    not unpickle it."""
    for name, value in run_options.items():
        found = []

        class _Finder(pickle.Pickler):
            def reducer_override(self, obj):
                kind = obj if isinstance(obj, (type, types.FunctionType)) else type(obj)
                if getattr(kind, "__module__", None) == "__main__":
                    found.append(getattr(kind, "__qualname__", repr(kind)))
                return NotImplemented

        _Finder(io.BytesIO()).dump(value)
        if found:
            raise ValueError(f"run option {name!r}: {found[0]} is defined in the script (__main__), which the "
                             "workers do not run: define it in a module of its own and import it from there")


def _worker_setup():
    """A worker's signals, and its end with the sweep's process whatever way that ends.

    SIGINT ignored (Ctrl-C reaches the whole process group: the parent stops the pool). SIGTERM and
    SIGHUP at their default, unblocked (a worker inherits the mask of the submit that started the
    fork server, :func:`_stop_signals_held`): the pool's own shutdown of a broken pool terminates
    its workers, and waits for them.

    A worker inherits the write end of the pipe whose end tells the fork server that its client has
    gone; while any worker held it, a sweep process that died (SIGTERM at its default, SIGKILL)
    left the fork server and its workers running for ever, re-parented to init. Closed here, the
    fork server ends with the sweep's process, and the workers with the fork server (the
    kernel's parent-death signal, Linux).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for signum in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM, signal.SIGHUP})
    server = getattr(_forkserver, "_forkserver", None) if _popen_forkserver is not None else None
    alive_fd = getattr(server, "_forkserver_alive_fd", None)
    if alive_fd is not None:
        with contextlib.suppress(OSError):
            os.close(alive_fd)
        server._forkserver_alive_fd = None
    if os.uname().sysname == "Linux":
        import ctypes
        pr_set_pdeathsig = 1
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0)


@contextlib.contextmanager
def _stop_signals_raised():
    """SIGTERM and SIGHUP (where they are at their default, which ends the process on the spot and
    lost every finished run) and Ctrl-C (where Python's own handler has it) raise
    :class:`_StopSignal` in the sweep's thread, once: the sweep unwinds (its pool stopped) and
    returns its rows in :class:`SweepInterrupted`. A second signal during that unwinding is
    ignored, so that the cleanup is not cut short. Only in the main thread (Python's signal
    handlers run there); a handler of the caller's own is left alone."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    stopped = []

    def stop(signum, _frame):
        if not stopped:
            stopped.append(signum)
            raise _StopSignal(signum)

    replaced = {}
    for signum in STOP_SIGNALS:
        default = signal.default_int_handler if signum == signal.SIGINT else signal.SIG_DFL
        if signal.getsignal(signum) is default:
            replaced[signum] = signal.signal(signum, stop)
    try:
        yield
    finally:
        for signum, handler in replaced.items():
            signal.signal(signum, handler)


@contextlib.contextmanager
def _stop_signals_held():
    """A stop signal (:data:`STOP_SIGNALS`) held back while a submit may start the fork server or a
    worker. Blocked in this thread, so that they (which inherit the mask) cannot take it while they
    import the engine, before a worker's initializer sets its signals: each printed a
    KeyboardInterrupt traceback. And deferred in Python, because the kernel may hand it to another
    thread of ours, and the interpreter would then raise it in the middle of a submit: a worker
    started but not yet known to the pool, left alive to fail once we are gone. The signal held
    back goes to its handler when the block ends."""
    deferred = []
    old_handlers = {}
    # (a process started with SIGINT ignored, as by a shell's '&', keeps ignoring it here too)
    if threading.current_thread() is threading.main_thread():
        for signum in STOP_SIGNALS:
            if callable(signal.getsignal(signum)):
                old_handlers[signum] = signal.signal(signum, lambda signum, _: deferred.append(signum))
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, set(STOP_SIGNALS))
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
        for signum, handler in old_handlers.items():
            signal.signal(signum, handler)
    if deferred:
        old_handlers[deferred[0]](deferred[0], None)


def _stop_pool(pool):
    """Shut the pool down without waiting for the runs in flight (after Ctrl-C they are not wanted).
    The executor has no public way to stop a running task: its worker processes are terminated
    (killed, should one outlive SIGTERM for 5 s)."""
    processes = list(getattr(pool, "_processes", {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        if p.is_alive():
            p.terminate()
    for p in processes:
        p.join(timeout=5)
        if p.is_alive():
            p.kill()
            p.join(timeout=5)


def _run_ray(tasks, workers, address):
    """(index, row) of every task, as the runs finish, as Ray tasks of :func:`run_one` (one CPU each).

    Joins the cluster at ``address`` (or Ray's own ``RAY_ADDRESS``), else starts a local one with
    ``workers`` CPUs and stops it at the end; Ctrl-C cancels the tasks in flight.
    """
    try:
        import ray
    except ImportError:
        raise ValueError("backend 'ray' needs Ray: pip install 'biped_sim[ray]' (or ray==2.60.0)") from None
    started = not ray.is_initialized()
    if started:
        if address is None and not os.environ.get("RAY_ADDRESS"):
            # "local": a new Ray of our own, even where a cluster of this machine (ray start) is running
            ray.init(address="local", num_cpus=workers or default_workers(), include_dashboard=False,
                     log_to_driver=False)
        else:
            address = address or os.environ["RAY_ADDRESS"]
            _check_reachable(address)
            try:
                ray.init(address=address, log_to_driver=False)
            except ConnectionError as exc:
                raise ValueError(f"no Ray cluster at {address}: {exc}") from None
    slots = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
    remote = ray.remote(num_cpus=1, max_retries=0)(run_one)
    pending = iter(enumerate(tasks))
    in_flight = {}
    try:
        while True:
            for index, task in itertools.islice(pending, slots * IN_FLIGHT_PER_WORKER - len(in_flight)):
                in_flight[remote.remote(*task)] = index
            if not in_flight:
                return
            ready, _ = ray.wait(list(in_flight), num_returns=1)
            for ref in ready:
                index = in_flight.pop(ref)
                try:
                    yield index, ray.get(ref)
                except ray.exceptions.RayError as exc:   # the worker died; run_one itself never raises
                    yield index, dict(tasks[index][1], **_empty_outcome("error", f"Ray: {exc}",
                                                                        _coordinates(*tasks[index][:2])),
                                      wall_time=0.0)
    finally:
        for ref in in_flight:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()


#: what an HTTP/2 client sends first (RFC 9113, 3.4), then an empty SETTINGS frame; the server of
#: a Ray cluster (its GCS, gRPC) answers with its own SETTINGS frame
_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
_HTTP2_SETTINGS = 4


def _check_reachable(address, timeout=5.0):
    """A ValueError, within ``timeout`` seconds, unless a server that speaks gRPC (as a Ray head's GCS
    does) listens at a ``host:port`` address: ``ray.init`` retries one where nothing listens, or
    where something else does (a web server, a database), for minutes. "auto" and ``ray://``
    addresses are left to Ray."""
    import socket
    host, sep, port = address.rpartition(":")
    if address == "auto" or "://" in address or not sep or not port.isdigit():
        return
    try:
        with socket.create_connection((host, int(port)), timeout=timeout) as connection:
            connection.sendall(_HTTP2_PREFACE)
            answer = b""
            while len(answer) < 9:
                chunk = connection.recv(9 - len(answer))
                if not chunk:
                    break
                answer += chunk
    except socket.timeout:
        raise ValueError(f"no Ray cluster at {address}: something listens there but did not answer within "
                         f"{timeout:g} s (a Ray head listens on its GCS port, 6379 by default)") from None
    except OSError as exc:
        raise ValueError(f"no Ray cluster at {address}: {exc} (start one with: ray start --head)") from None
    if len(answer) < 9 or answer[3] != _HTTP2_SETTINGS:
        shown = answer[:9].decode("ascii", "replace").strip() or "nothing"
        raise ValueError(f"no Ray cluster at {address}: something else listens there (it answered {shown!r}, "
                         "not gRPC); give the Ray head's GCS port, 6379 by default") from None


def _empty_outcome(status, message, size) -> dict:
    """The outcome of a run that did not run: q_end and dq_end are ``size`` NaNs (the run's robot's n)."""
    return dict(status=status, message=message, impacts=0, t_end=math.nan, x_end=math.nan, mean_speed=math.nan,
                q_end=[math.nan] * size, dq_end=[math.nan] * size, energy_residual=math.nan, drift=math.nan)


def _coordinates(scene, overrides) -> int:
    """n, the number of coordinates of the robot of a run (the scene's, or the grid point's ``robot``); 0 where
    the point's scene does not load (its q_end and dq_end are then empty: the CSV's cells left empty)."""
    try:
        return len(joint_layout(load_scene(scene, overrides=controller_arguments(overrides)[0]).robot).coordinates)
    except Exception:   # (the row already says why the run failed)
        return 0


def grid_robots(scene, grid) -> dict:
    """{robot: its q's names (``config.joints.joint_layout``)} of the runs of ``grid`` on ``scene``: the scene's
    robot, or each robot a swept ``robot`` (``biped_sim.robot``, ...) gives, in the order of the grid."""
    scene = _scene_argument(scene)
    swept = [name for name in grid if name.rpartition(".")[2].partition("[")[0] == "robot"]
    robots = {}
    # the point's robot itself, where the grid sweeps it: its scene need not load (e.g. without its initial state)
    simulation = [name for name in swept if name in ("robot", "biped_sim.robot")]
    for robot in (grid[simulation[-1]] if simulation else [load_scene(scene).robot]):
        robots.setdefault(robot, joint_layout(robot).coordinates)
    return robots


def columns_line(robots: dict) -> str:
    """What the CSV's per-coordinate columns q_end[i], dq_end[i] are, in one line: the robot's names of q, or,
    for a grid of robots of different sizes, each robot's and that a smaller robot's cells past its n are
    empty."""
    size = max((len(c) for c in robots.values()), default=0)
    names = "; ".join(f"{robot}: {', '.join(c)}" for robot, c in robots.items())
    line = f"q_end[i], dq_end[i] (i = 0..{size - 1}) are q and dq of {names}"
    if len({len(c) for c in robots.values()}) > 1:
        line += ("; the grid mixes robots of different sizes: a row's cells past its robot's n coordinates are "
                 "left empty")
    return line


def _plain_value(v):
    """A grid value as load_scene's overrides take it: a numpy scalar as the Python number."""
    return v.item() if hasattr(v, "item") and hasattr(v, "dtype") and getattr(v, "ndim", 1) == 0 else v


def _scene_argument(scene) -> str:
    """The scene as the workers load it: a name in msg_configs/ stays a name (a cluster's nodes find
    their own copy); a path becomes absolute (the fork server keeps the directory it started in)."""
    if not isinstance(scene, (str, Path)):
        raise ValueError(f"scene must be a scene name or a path to a scene file, got {scene!r}")
    path = scene_path(scene)   # ValueError: unknown scene, with the available ones
    text = str(scene)
    is_path = text.endswith((".yaml", ".yml")) or Path(text).parent != Path(".")
    return str(path.resolve()) if is_path else text


def csv_columns(names, size) -> list[str]:
    """The CSV's columns: the grid index, the swept names, the outcome, q_end[i] and dq_end[i] for i < ``size``
    (the robot's n coordinates; the largest n of a grid that mixes robots)."""
    scalars = [c for c in OUTCOME if c not in ("q_end", "dq_end")]
    return ["index", *names, *scalars] + [f"q_end[{i}]" for i in range(size)] + [f"dq_end[{i}]" for i in range(size)]


def check_writable(path, what="-o"):
    """An OSError (or ValueError for a missing folder) now, before any run, if ``path`` cannot be
    written: a read-only file system or folder, a folder in the way. Found only after every run, it
    lost them all. A device or a pipe (``/dev/stdout``) is opened for appending (nothing written);
    a file is tried as :func:`write_csv` writes it, by a file created beside it and removed."""
    path = Path(path)
    if not path.parent.is_dir():
        raise ValueError(f"{what} {path}: folder {path.parent} does not exist")
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(path))
    try:
        if path.exists() and not path.is_file():
            with open(path, "ab"):
                return
        fd, temporary = _new_file_beside(path)
        os.close(fd)
        os.unlink(temporary)
    except OSError as exc:   # the destination named, not the file tried beside it
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None


def write_csv(rows, names, path, size=None):
    """One line per row (numbers as Python's repr: they read back to the same bits).

    The columns q_end[i] and dq_end[i] run to ``size`` (default: the largest robot's n among the rows; give it
    for a file that may have no rows): a row of a smaller robot (a grid over ``robot``) leaves its cells past
    its n empty.

    The whole file or none: written to a new file beside ``path`` and renamed onto it (a full disk
    left a CSV cut mid-row where the result should be). Should that fail (a full disk, a removed
    folder), the rows are kept in a new file in the system's temp folder and the OSError raised
    names ``path``, the reason and that file. A device or a pipe (``/dev/stdout``) is written in
    place."""
    path = Path(path)
    size = max([len(r["q_end"]) for r in rows] + ([size] if size is not None else []), default=0)
    if path.is_symlink():   # the file it points to is replaced, not the link
        path = Path(os.path.realpath(path))
    try:
        if path.exists() and not path.is_file():
            with open(path, "w", newline="") as f:
                _write_rows(f, rows, names, size)
            return
        fd, temporary = _new_file_beside(path)
        try:
            with open(fd, "w", newline="") as f:
                _write_rows(f, rows, names, size)
                f.flush()
                os.fsync(f.fileno())
            if path.exists():   # the result keeps the permissions of the file it replaces
                os.chmod(temporary, os.stat(path).st_mode & 0o7777)
            os.replace(temporary, path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(temporary)
            raise
    except OSError as exc:
        raise OSError(exc.errno, f"{exc.strerror or exc}; {_keep_rows(rows, names, path, size)}", str(path)) from exc


def _new_file_beside(path: Path) -> tuple[int, Path]:
    """A new, empty, hidden file in ``path``'s folder (its descriptor and path), with the mode a new
    file gets there (the umask's)."""
    while True:
        temporary = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
        try:
            return os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666), temporary
        except FileExistsError:
            continue


def _keep_rows(rows, names, path: Path, size) -> str:
    """The rows written to a new file in the system's temp folder; what became of them, as a clause."""
    try:
        fd, kept = tempfile.mkstemp(prefix=f"{path.stem}-", suffix=path.suffix or ".csv")
        with open(fd, "w", newline="") as f:
            _write_rows(f, rows, names, size)
    except OSError as exc:
        return f"the {len(rows)} rows could not be kept in the temp folder either ({exc.strerror or exc})"
    return f"the {len(rows)} rows are kept in {kept}"


def _write_rows(f, rows, names, size):
    import csv
    w = csv.writer(f)
    w.writerow(csv_columns(names, size))
    for r in rows:
        empty = [""] * (size - len(r["q_end"]))    # a robot of fewer coordinates than the grid's largest
        w.writerow([r["index"], *(r[n] for n in names), *(r[c] for c in OUTCOME if c not in ("q_end", "dq_end")),
                    *r["q_end"], *empty, *r["dq_end"], *empty])


#: the quantity the maps colour by: the distance walked (m), a measure of the gait; the step count
#: rewarded cadence (short quick steps counted more than long ones over the same ground)
MAP_QUANTITY = ("x_end", "distance walked (m)")


def figure(rows, names, title="sweep", fixed_point=None):
    """The matplotlib Figure of :func:`plot`: the distance walked (``x_end``, m) over the first two
    swept names as a heat map (along the one swept name as a line). Runs that stopped or failed (a
    fall) are red crosses; runs the engine refused to start (status ``error``: no run was made) are
    grey squares with their cell left empty; ``fixed_point`` ({name: value}, e.g. the basin's z*
    at offsets 0) is a white star. With more than two names the map is the slice at the first value
    of the others (the title says so)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    key, label = MAP_QUANTITY
    rest = {n: rows[0][n] for n in names[2:]}
    sl = [r for r in rows if all(r[n] == v for n, v in rest.items())]
    if rest:
        title += " (at " + ", ".join(f"{n}={v}" for n, v in rest.items()) + ")"
    fell = [r for r in sl if r["status"] not in ("completed", "error")]
    refused = [r for r in sl if r["status"] == "error"]
    fig, ax = plt.subplots(figsize=(7.5, 6.0) if len(names) > 1 else (7, 4))
    if len(names) == 1:
        ran = [r for r in sl if r["status"] != "error"]
        ax.plot([r[names[0]] for r in ran], [r[key] for r in ran], "o-", color="tab:blue", label=label)
        ax.plot([r[names[0]] for r in fell], [r[key] for r in fell], "x", color="tab:red", ms=10, mew=2,
                label="fell or stopped")
        ax.plot([r[names[0]] for r in refused], [0.0] * len(refused), "s", color="0.45", ms=7,
                label="refused start (no run)")
        ax.set_xlabel(names[0])
        ax.set_ylabel(label)
        ax.legend(fontsize=8)
    else:
        ys = list(dict.fromkeys(r[names[0]] for r in sl))
        xs = list(dict.fromkeys(r[names[1]] for r in sl))
        grid = [[math.nan] * len(xs) for _ in ys]
        for r in sl:
            if r["status"] != "error":
                grid[ys.index(r[names[0]])][xs.index(r[names[1]])] = r[key]
        im = ax.imshow(grid, origin="lower", aspect="auto", cmap="viridis", interpolation="nearest")
        fig.colorbar(im, ax=ax, label=label)
        if fell:      # a legend entry only for what the map shows
            ax.plot([xs.index(r[names[1]]) for r in fell], [ys.index(r[names[0]]) for r in fell], "x",
                    color="tab:red", ms=7, mew=1.5, label="fell or stopped (its distance until then)")
        if refused:
            ax.plot([xs.index(r[names[1]]) for r in refused], [ys.index(r[names[0]]) for r in refused], "s",
                    color="0.45", ms=5, label="refused start: the engine rejects the state (no run)")
        if fixed_point is not None:
            ax.plot(_index_of(xs, fixed_point[names[1]]), _index_of(ys, fixed_point[names[0]]), "*",
                    color="white", mec="black", ms=16, label="fixed point z*")
        for values, setter, labels in ((xs, ax.set_xticks, ax.set_xticklabels),
                                       (ys, ax.set_yticks, ax.set_yticklabels)):
            every = max(1, len(values) // 8)
            ticks = list(range(0, len(values), every))
            setter(ticks)
            labels([f"{values[i]:.4g}" if isinstance(values[i], float) else str(values[i]) for i in ticks])
        ax.set_xlabel(names[1])
        ax.set_ylabel(names[0])
        if fell or refused or fixed_point is not None:
            # below the map: inside, it hid a corner of it
            ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, fontsize=8, frameon=False)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


def _index_of(values, v) -> float:
    """Where ``v`` falls on the image's index axis of the sorted grid ``values`` (between two cells
    when it is not a grid value: z* of a basin with an even number of points)."""
    if v in values:
        return float(values.index(v))
    for i in range(len(values) - 1):
        a, b = values[i], values[i + 1]
        if min(a, b) <= v <= max(a, b):
            return i + (v - a) / (b - a)
    return math.nan


def plot(rows, names, path, title="sweep", fixed_point=None):
    """Write :func:`figure` to ``path`` (a PNG)."""
    import matplotlib.pyplot as plt
    fig = figure(rows, names, title, fixed_point)
    fig.savefig(path, dpi=110)
    plt.close(fig)
