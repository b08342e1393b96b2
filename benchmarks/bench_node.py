"""Benchmark of ``sim_node`` (prints figures, asserts nothing): ``python -m benchmarks.bench_node``.

Owns the node's speed figures (issue 3):
  * realtime at a 1 kHz publish rate: achieved rate of joint_states at a subscriber in another process
    and the p50/p99 jitter of the arrival period;
  * lockstep (issue 15's row): sim_node on the walk scene driven by the walk_controller node, steps per
    wall second, beside a bare rclpy round trip between two processes with the same message types and
    QoS (no physics, no control law), alternating in the same run; the median of the back-to-back
    pairs' ratios (target >= 0.8). ``--lockstep-only`` runs just that.
  * the walk scene with the walk_controller node (issue 35's rows): the node process's CPU per 1 ms
    control period in realtime (no recording) and in lockstep with recording, the realtime period
    jitter p99 (the node's own figures line), and a realtime walk of ``--walk-seconds`` s with a
    CPU-bound process (``python3 -c "while True: pass"``) running beside: its jitter, and whether
    it runs to the end. ``--walk-only`` runs just these.
Every process runs on a free ROS domain (domain_coordinator) with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST.
"""
from __future__ import annotations

import argparse
import contextlib
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
BIN = Path(sys.executable).parent


def _qos(transient_local=False, depth=100):
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if transient_local else DurabilityPolicy.VOLATILE)


def _percentile(values, p):
    v = sorted(values)
    if not v:
        return float("nan")
    k = (len(v) - 1) * p / 100.0
    i = int(k)
    return v[i] if i + 1 >= len(v) else v[i] + (v[i + 1] - v[i]) * (k - i)


def _walking_start():
    from biped_sim.control.walking import WalkingController
    from biped_sim.engine.model import BipedModel
    ctrl = WalkingController(BipedModel())
    q0, dq0 = ctrl.initial_state()
    return ctrl, [float(v) for v in q0], [float(v) for v in dq0]


# -- the bare round trip's two processes -----------------------------------------------------------
def role_bare_sim(steps):
    """Where sim_node stands, without physics: publishes a JointState (the node's QoS, the walk's first
    state, restamped), and answers each hip_torque with the next one; prints the same figures line as
    sim_node (periods per wall s from the first command to the last state published)."""
    import rclpy
    from rclpy.task import Future
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from biped_sim.recording.messages import joint_state_message, stamp
    _, q0, dq0 = _walking_start()
    rclpy.init()
    node = rclpy.create_node("bare_sim")
    pub = node.create_publisher(JointState, "joint_states", _qos(True))
    msg = joint_state_message(0.0, q0, dq0, [0.0, 0.0], 1)
    done = Future()
    state = {"n": 0}

    def on_command(_cmd):
        if state["n"] == 0:
            state["wall0"], state["cpu0"] = time.monotonic(), time.process_time()
        state["n"] += 1
        msg.header.stamp = stamp(state["n"] * 0.001)
        pub.publish(msg)
        if state["n"] == steps:
            state["wall"], state["cpu"] = time.monotonic() - state["wall0"], time.process_time() - state["cpu0"]
            done.set_result(True)
    node.create_subscription(Float64MultiArray, "hip_torque", on_command, _qos())
    pub.publish(msg)
    rclpy.spin_until_future_complete(node, done)
    n, wall = state["n"], state["wall"]
    print(f"[INFO] [bare_sim]: {n} control periods: process CPU {1e3 * state['cpu'] / n:.3f} ms per period; "
          f"wall {wall:.4f} s from the first control period ({n / wall:.1f} periods/s)", flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


def role_bare_controller():
    """Where walk_controller stands, without a control law: answers each JointState at once with the
    same tagged Float64MultiArray (the controller's QoS), spun by ``rclpy.spin``."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from biped_sim.recording.messages import torque_msg
    rclpy.init()
    node = rclpy.create_node("bare_controller")
    pub = node.create_publisher(Float64MultiArray, "hip_torque", _qos())
    command = torque_msg([0.0, 0.0], answers_ns=0)
    end = time.monotonic() + 30     # as walk_controller: no answer before the command publisher matched
    while pub.get_subscription_count() == 0 and time.monotonic() < end:
        time.sleep(0.01)
    node.create_subscription(JointState, "joint_states", lambda _state: pub.publish(command), _qos(True))
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    rclpy.try_shutdown()


# -- the driver -------------------------------------------------------------------------------------
@contextlib.contextmanager
def _domain():
    try:
        import domain_coordinator
    except ImportError:
        yield int(os.environ.get("ROS_DOMAIN_ID", "0"))
        return
    with domain_coordinator.domain_id() as d:
        yield int(d)


def _env(dom):
    return dict(os.environ, ROS_DOMAIN_ID=str(dom), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")


def _params(d):
    out = ["--ros-args"]
    for k, v in d.items():
        if isinstance(v, bool):
            v = "true" if v else "false"
        elif isinstance(v, list):
            v = "[" + ", ".join(repr(x) for x in v) + "]"
        out += ["-p", f"{k}:={v}"]
    return out


def _stop(proc):
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def bench_realtime(seconds=5.0, rate=1000.0):
    import rclpy
    from rclpy.context import Context
    from sensor_msgs.msg import JointState
    with _domain() as dom:  # the default state: standing upright at rest (u = 0 keeps it there)
        node_proc = subprocess.Popen(
            [str(BIN / "sim_node"), *_params(dict(time_mode="realtime", publish_rate=rate, control_period=1.0 / rate,
                                                  record=False, command_timeout=0.0))],
            env=_env(dom), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        ctx = Context()
        rclpy.init(context=ctx, domain_id=dom)
        try:
            node = rclpy.create_node("bench_rt", context=ctx)
            from rclpy.executors import SingleThreadedExecutor
            ex = SingleThreadedExecutor(context=ctx)
            ex.add_node(node)
            arrivals = []
            node.create_subscription(JointState, "joint_states",
                                     lambda m: arrivals.append((time.perf_counter(), m.header.stamp)), _qos())
            end = time.monotonic() + 60
            while not arrivals and time.monotonic() < end:
                ex.spin_once(timeout_sec=0.05)
            arrivals.clear()
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < seconds:
                ex.spin_once(timeout_sec=0.01)
            node.destroy_node()
        finally:
            ctx.try_shutdown()
            _stop(node_proc)
        log = node_proc.stdout.read()
    if len(arrivals) < 3:
        return dict(error="no joint_states received", log=log)
    times = [a[0] for a in arrivals]
    periods = [b - a for a, b in zip(times, times[1:])]
    jitter = [abs(p - 1.0 / rate) for p in periods]
    sim = [(a[1].sec + a[1].nanosec * 1e-9) for a in arrivals]
    node_line = next((ln.split("realtime figures: ", 1)[1] for ln in log.splitlines() if "realtime figures" in ln),
                     "(none)")
    return dict(node=node_line, rate=len(periods) / (times[-1] - times[0]), target=rate,
                jitter_p50=_percentile(jitter, 50),
                jitter_p99=_percentile(jitter, 99), period_p50=_percentile(periods, 50),
                period_p99=_percentile(periods, 99), rtf=(sim[-1] - sim[0]) / (times[-1] - times[0]),
                lag_warnings=log.count("cannot keep up"))


def _figures(log):
    """{periods, wall, rate, cpu_ms} from the figures line of sim_node or the bare sim ("... control
    periods ...: ... process CPU X ms per period; wall W s from the first control period (R periods/s)")."""
    import re
    m = re.search(r"(\d+) control periods.*process CPU ([\d.]+) ms per period; wall ([\d.]+) s from the first "
                  r"control period \(([\d.]+) periods/s\)", log)
    if not m:
        return None
    return dict(periods=int(m.group(1)), cpu_ms=float(m.group(2)), wall=float(m.group(3)), rate=float(m.group(4)))


def _lockstep_run(sim_argv, controller_argv, dom):
    """One run of a sim (that ends by itself) and its controller (stopped after it): the sim's figures."""
    sim = subprocess.Popen(sim_argv, env=_env(dom), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    ctl = subprocess.Popen(controller_argv, env=_env(dom), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        log, _ = sim.communicate(timeout=300)
    except subprocess.TimeoutExpired:
        _stop(sim)
        log = sim.stdout.read()
    finally:
        _stop(ctl)
    ctl_log = ctl.stdout.read()
    f = _figures(log)
    if f is None or sim.returncode != 0:
        return dict(error=f"run failed (exit code {sim.returncode}):\n{log[-3000:]}\n{ctl_log[-2000:]}")
    return f


WALK_PARAMS = Path(__file__).resolve().parent.parent / "msg_configs" / "walk.yaml"


def bench_lockstep(steps=2000, rounds=6):
    """Issue 15's lockstep row, measured alternately ``rounds`` times each so that a change of the
    machine's load hits both alike: ``sim``, sim_node in lockstep on the walk scene
    (msg_configs/walk.yaml: its outputs, method auto, 1 ms control period; record:=false) driven by the
    walk_controller node, ``steps`` control periods; ``bare``, the same number of round trips between two
    bare rclpy processes with the same message types and QoS (a state out, a command back, no physics, no
    control law: role_bare_sim and role_bare_controller); bare first in every other pair. Both rates
    are periods per wall second from the first command to the last state published, as the sim side
    reports them. Returns {"sim": [figures per run], "bare": [...]} (figures: periods, wall, rate,
    cpu_ms; or error)."""
    runs = {"bare": [], "sim": []}
    me = [sys.executable, "-m", "benchmarks.bench_node", "--role"]
    argv = {"bare": ([*me, "bare_sim", "--steps", str(steps)], [*me, "bare_controller"]),
            "sim": ([str(BIN / "sim_node"), "--ros-args", "--params-file", str(WALK_PARAMS),
                     *_params(dict(record=False, duration=steps * 0.001))[1:]],
                    [str(BIN / "walk_controller"), "--ros-args", "--params-file", str(WALK_PARAMS)])}
    for i in range(rounds):
        for name in ("bare", "sim") if i % 2 == 0 else ("sim", "bare"):    # the order alternates
            with _domain() as dom:
                runs[name].append(_lockstep_run(*argv[name], dom))
    return runs


def _engine_cost(control_period=0.001, steps=2000):
    """The engine alone, walking, one advance per control period (ms per period)."""
    from biped_sim.engine.hybrid import HybridSimulator
    from biped_sim.engine.model import BipedModel
    ctrl, q0, dq0 = _walking_start()
    sim = HybridSimulator(BipedModel(), q0, dq0)
    us = []
    for k in range(steps):
        us.append(ctrl(sim.t, sim.q, sim.dq, sim.stance_leg))
        sim.advance((k + 1) * control_period, u=us[-1])
    return 1e3 * sim.stats["wall_time"] / steps


def walk_run(mode, seconds, record=False, hog=False):
    """sim_node on the walk scene (msg_configs/walk.yaml: markers, ground reaction, impact, /clock; a
    1 ms control and publish period) in ``mode`` for ``seconds`` of simulated time, driven by the
    walk_controller node; with ``hog``, a CPU-bound process beside them. Returns the node's figures:
    periods, cpu_ms (process CPU per period), t (simulated time reached), completed (the duration
    reached), jitter_p50/jitter_p99 (s) and rtf (realtime), lag_warnings; or error."""
    import re
    import tempfile
    hog_proc = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if hog else None
    try:
        with tempfile.TemporaryDirectory(prefix="bench-walk-") as bags, _domain() as dom:
            sim_argv = [str(BIN / "sim_node"), "--ros-args", "--params-file", str(WALK_PARAMS),
                        *_params(dict(time_mode=mode, duration=float(seconds), record=record, bag_dir=bags))[1:]]
            ctl_argv = [str(BIN / "walk_controller"), "--ros-args", "--params-file", str(WALK_PARAMS)]
            sim = subprocess.Popen(sim_argv, env=_env(dom), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                   text=True)
            ctl = subprocess.Popen(ctl_argv, env=_env(dom), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            try:
                log, _ = sim.communicate(timeout=seconds * 3 + 120)
            except subprocess.TimeoutExpired:
                _stop(sim)
                log = sim.stdout.read()
            finally:
                _stop(ctl)
    finally:
        if hog_proc is not None:
            hog_proc.kill()
            hog_proc.wait()
    f = _figures(log)
    if f is None:
        return dict(error=f"no figures line (exit code {sim.returncode}):\n{log[-3000:]}")
    t = re.search(r"control periods.*? to t=([\d.]+) s", log)
    f.update(t=float(t.group(1)) if t else float("nan"), completed=f"duration {float(seconds):g} s reached" in log,
             lag_warnings=log.count("cannot keep up"))
    stop = re.search(r"the engine (\w+) at t=([\d.]+) s: ([^.]*)", log)
    f["stop"] = f"the engine {stop.group(1)} at t={float(stop.group(2)):.3f} s: {stop.group(3)[:90]}" if stop else ""
    rt = re.search(r"period jitter p50 (\d+) us, p99 (\d+) us, real-time factor ([\d.]+)", log)
    if rt:
        f.update(jitter_p50=int(rt.group(1)) * 1e-6, jitter_p99=int(rt.group(2)) * 1e-6, rtf=float(rt.group(3)))
    return f


def print_walk(seconds=8.0, hog_seconds=60.0):
    """Issue 35's rows (goals: CPU <= 0.15 ms realtime, <= 0.2 ms lockstep with recording; jitter
    p99 <= 0.5 ms quiet, <= 1 ms beside a CPU-bound process; the walk beside it runs to the end)."""
    def verdict(ok):
        return "met" if ok else "not met"
    print(f"load average before the walk rows: {os.getloadavg()[0]:.2f}")
    rt = walk_run("realtime", seconds)
    if "error" in rt:
        print(f"realtime walk: {rt['error']}")
    else:
        print(f"realtime walk with walk_controller, {seconds:g} s, no recording: node process CPU "
              f"{rt['cpu_ms']:.3f} ms per 1 ms period (goal <= 0.15: {verdict(rt['cpu_ms'] <= 0.15)}); period "
              f"jitter p50 {rt.get('jitter_p50', float('nan')) * 1e6:.0f} us, p99 "
              f"{rt.get('jitter_p99', float('nan')) * 1e6:.0f} us (goal <= 500 us: "
              f"{verdict(rt.get('jitter_p99', 1.0) <= 5e-4)}); real-time factor {rt.get('rtf', float('nan')):.3f}; "
              f"'cannot keep up' warnings: {rt['lag_warnings']}; "
              + ("ran to the end" if rt["completed"] else f"stopped: {rt['stop']}"))
    ls = walk_run("lockstep", seconds, record=True)
    if "error" in ls:
        print(f"lockstep walk: {ls['error']}")
    else:
        print(f"lockstep walk with walk_controller, {seconds:g} s, recording: node process CPU {ls['cpu_ms']:.3f} ms "
              f"per period (goal <= 0.2: {verdict(ls['cpu_ms'] <= 0.2)})")
    load = os.getloadavg()[0]
    hog = walk_run("realtime", hog_seconds, hog=True)
    if "error" in hog:
        print(f"realtime walk beside a CPU-bound process: {hog['error']}")
    else:
        print(f"realtime walk with walk_controller, {hog_seconds:g} s, a CPU-bound process beside (load average "
              f"{load:.2f} before): period jitter p50 {hog.get('jitter_p50', float('nan')) * 1e6:.0f} us, p99 "
              f"{hog.get('jitter_p99', float('nan')) * 1e6:.0f} us (goal <= 1000 us: "
              f"{verdict(hog.get('jitter_p99', 1.0) <= 1e-3)}); node process CPU {hog['cpu_ms']:.3f} ms per period; "
              f"'cannot keep up' warnings: {hog['lag_warnings']}; "
              + ("ran to the end (goal: met)" if hog["completed"] else f"stopped (goal: not met): {hog['stop']}"))


def print_lockstep(runs, steps):
    for name, what in (("bare", "bare rclpy round trip (two processes, the same message types, no physics)"),
                       ("sim", "lockstep sim_node (walk scene, record:=false) with the walk_controller node")):
        bad = [r for r in runs[name] if "error" in r]
        if bad:
            print(f"{what}: {bad[0]['error']}")
            return None
        rates = [r["rate"] for r in runs[name]]
        print(f"{what}: {statistics.median(rates):.0f} steps/s median of {len(rates)} runs of {steps} steps "
              f"(runs: {[round(v) for v in rates]}); its sim side's CPU "
              f"{statistics.median(r['cpu_ms'] for r in runs[name]):.3f} ms per step")
    pairs = sorted(s["rate"] / b["rate"] for s, b in zip(runs["sim"], runs["bare"]))
    ratio = statistics.median(pairs)
    print(f"lockstep ratio (sim_node + walk_controller steps/s / bare round trips/s, median of {len(pairs)} "
          f"back-to-back pairs): {ratio:.2f} (pairs {[round(v, 2) for v in pairs]}; target >= 0.8: "
          f"{'met' if ratio >= 0.8 else 'not met'})")
    return ratio


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m benchmarks.bench_node", description=__doc__.splitlines()[0])
    p.add_argument("--role", choices=("bare_sim", "bare_controller"), help=argparse.SUPPRESS)
    p.add_argument("--steps", type=int, default=2000, help="lockstep control steps per run")
    p.add_argument("--rounds", type=int, default=6, help="lockstep runs of each (alternating)")
    p.add_argument("--lockstep-only", action="store_true", help="only the lockstep ratio (issue 15's row)")
    p.add_argument("--seconds", type=float, default=5.0, help="wall seconds of the realtime measurement")
    p.add_argument("--walk-only", action="store_true", help="only the walk rows (issue 35's)")
    p.add_argument("--walk-seconds", type=float, default=60.0,
                   help="simulated seconds of the realtime walk beside a CPU-bound process")
    args = p.parse_args(argv)
    if args.role == "bare_sim":
        return role_bare_sim(args.steps)
    if args.role == "bare_controller":
        return role_bare_controller()
    if args.lockstep_only:
        print_lockstep(bench_lockstep(args.steps, args.rounds), args.steps)
        return 0
    if args.walk_only:
        print_walk(hog_seconds=args.walk_seconds)
        return 0
    print(f"load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    print(f"engine alone (walking, DOP853 rtol=atol=1e-9): {_engine_cost():.3f} ms per 1 ms control period")
    rt = bench_realtime(args.seconds)
    if "error" in rt:
        print(f"realtime: {rt['error']}\n{rt['log']}")
    else:
        print(f"realtime, publish_rate 1000 Hz, control_period 1 ms, standing at rest; at the node, whole run: "
              f"{rt['node']}")
        print(f"realtime, the same run, {args.seconds:g} s at a subscriber in another process: "
              f"{rt['rate']:.1f} Hz (real-time factor {rt['rtf']:.3f}); period p50 "
              f"{rt['period_p50'] * 1e3:.3f} ms, p99 {rt['period_p99'] * 1e3:.3f} ms; jitter |period - 1 ms| p50 "
              f"{rt['jitter_p50'] * 1e6:.0f} us, p99 {rt['jitter_p99'] * 1e6:.0f} us; "
              f"'cannot keep up' warnings: {rt['lag_warnings']}")
    print_lockstep(bench_lockstep(args.steps, args.rounds), args.steps)
    print_walk(hog_seconds=args.walk_seconds)
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
