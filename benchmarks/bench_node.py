"""Benchmark of ``sim_node`` (prints figures, asserts nothing): ``python -m benchmarks.bench_node``.

Owns the node's speed figures (issue 3):
  * realtime at a 1 kHz publish rate: achieved rate of joint_states at a subscriber in another process
    and the p50/p99 jitter of the arrival period;
  * lockstep with a Python controller client in another process: control steps per second and the
    round-trip latency, beside a bare rclpy round trip between two processes (an echo node that
    answers at once, no physics) measured in the same run, and their ratio (target >= 70 %).
Every process runs on a free ROS domain (domain_coordinator) with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST.
"""
from __future__ import annotations

import argparse
import contextlib
import json
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


# -- roles run in their own processes -------------------------------------------------------------
def role_echo():
    """The bare round trip's far end: answers each hip_torque at once with a fixed JointState."""
    import rclpy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from biped_sim.recording.messages import joint_state_message
    _, q0, dq0 = _walking_start()
    rclpy.init()
    node = rclpy.create_node("bare_echo")
    pub = node.create_publisher(JointState, "joint_states", _qos(True))
    state = {"t": 0.0, "n": 0}

    def on_cmd(msg):
        if state["n"] == 0:
            state["cpu0"] = time.process_time()
        state["n"] += 1
        state["t"] += 0.001
        pub.publish(joint_state_message(state["t"], q0, dq0, msg.data, 1))
    node.create_subscription(Float64MultiArray, "hip_torque", on_cmd, _qos())
    pub.publish(joint_state_message(0.0, q0, dq0, [0.0, 0.0], 1))
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    while not stop:
        rclpy.spin_once(node, timeout_sec=0.1)
    if state["n"] > 1:
        print(f"[INFO] [echo]: {state['n']} control periods to t=0: process CPU "
              f"{1e3 * (time.process_time() - state['cpu0']) / (state['n'] - 1):.3f} ms per round trip", flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


def role_client(steps):
    """A controller in the loop (the walking controller): prints JSON figures."""
    import rclpy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    ctrl, _, _ = _walking_start()
    import numpy as np
    rclpy.init()
    node = rclpy.create_node("bench_client")
    box = []
    node.create_subscription(JointState, "joint_states", box.append, _qos(True))
    pub = node.create_publisher(Float64MultiArray, "hip_torque", _qos())
    end = time.monotonic() + 30
    while (pub.get_subscription_count() == 0 or not box) and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    if not box:
        print(json.dumps({"error": "no state from the node"}))
        return
    rtt, ctrl_time = [], []
    t_start = time.perf_counter()
    for _ in range(steps):
        m = box[-1]
        n = len(box)
        c0 = time.perf_counter()
        leg = int(m.header.frame_id[-1]) if m.header.frame_id.startswith("foot_") else 0
        u = ctrl(0.0, np.array(m.position), np.array(m.velocity), leg)
        t0 = time.perf_counter()
        ctrl_time.append(t0 - c0)
        pub.publish(Float64MultiArray(data=[float(u[0]), float(u[1])]))
        while len(box) == n:
            rclpy.spin_once(node, timeout_sec=1.0)
            if time.perf_counter() - t0 > 5:
                print(json.dumps({"error": f"no answer after {len(rtt)} steps"}))
                return
        rtt.append(time.perf_counter() - t0)
    wall = time.perf_counter() - t_start
    print(json.dumps(dict(steps=steps, wall=wall, rate=steps / wall, rtt_p50=_percentile(rtt, 50),
                          rtt_p99=_percentile(rtt, 99), ctrl_mean=sum(ctrl_time) / len(ctrl_time))))
    node.destroy_node()
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


def _round_trip(far_argv, steps, dom):
    far = subprocess.Popen(far_argv, env=_env(dom), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        client = subprocess.run([sys.executable, "-m", "benchmarks.bench_node", "--role", "client", "--steps",
                                 str(steps)], env=_env(dom), capture_output=True, text=True, timeout=300)
    finally:
        _stop(far)
    log = far.stdout.read()
    lines = [ln for ln in client.stdout.splitlines() if ln.startswith("{")]
    if not lines:
        return dict(error=f"client failed: {client.stdout[-2000:]} {client.stderr[-2000:]}", log=log)
    out = json.loads(lines[-1])
    out["log"] = log
    out["node"] = next((ln.split("]: ", 1)[1] for ln in log.splitlines() if "control periods to" in ln), "")
    return out


def bench_lockstep(steps=2000, control_period=0.001, rounds=4):
    """Bare and sim round trips, measured alternately (``rounds`` times each) so that a change of the
    machine's load during the run affects both alike; returns the totals and the per-run rates."""
    _, q0, dq0 = _walking_start()
    runs = {"bare": [], "sim": []}
    for _ in range(rounds):
        with _domain() as dom:
            runs["bare"].append(_round_trip([sys.executable, "-m", "benchmarks.bench_node", "--role", "echo"],
                                            steps // rounds, dom))
        with _domain() as dom:
            runs["sim"].append(_round_trip(
                [str(BIN / "sim_node"), *_params(dict(time_mode="lockstep", control_period=control_period,
                                                      initial_q=q0, initial_dq=dq0, record=False))],
                steps // rounds, dom))
    out = []
    for name in ("bare", "sim"):
        rs = runs[name]
        bad = [r for r in rs if "error" in r]
        if bad:
            out.append(bad[0])
            continue
        n, wall = sum(r["steps"] for r in rs), sum(r["wall"] for r in rs)
        out.append(dict(steps=n, wall=wall, rate=n / wall, median_rate=statistics.median(r["rate"] for r in rs),
                        rtt_p50=statistics.median(r["rtt_p50"] for r in rs),
                        rtt_p99=max(r["rtt_p99"] for r in rs), ctrl_mean=sum(r["ctrl_mean"] for r in rs) / len(rs),
                        parts=[round(r["rate"]) for r in rs], node=rs[-1]["node"]))
    return tuple(out)


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


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m benchmarks.bench_node", description=__doc__.splitlines()[0])
    p.add_argument("--role", choices=("echo", "client"), help=argparse.SUPPRESS)
    p.add_argument("--steps", type=int, default=2000, help="lockstep control steps per round-trip measurement")
    p.add_argument("--seconds", type=float, default=5.0, help="wall seconds of the realtime measurement")
    args = p.parse_args(argv)
    if args.role == "echo":
        return role_echo()
    if args.role == "client":
        return role_client(args.steps)
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
    bare, sim = bench_lockstep(args.steps)
    for name, r in (("bare rclpy round trip (echo node, no physics)", bare),
                    ("lockstep sim_node (walking, 1 ms control period)", sim)):
        if "error" in r:
            print(f"{name}: {r['error']}\n{r.get('log', '')[-3000:]}")
        else:
            print(f"{name}: {r['rate']:.0f} steps/s (runs: {r['parts']}), round trip p50 {r['rtt_p50'] * 1e3:.3f} ms, "
                  f"p99 {r['rtt_p99'] * 1e3:.3f} ms ({r['steps']} steps; "
                  f"controller {r['ctrl_mean'] * 1e3:.3f} ms/step)")
            if r.get("node"):
                print(f"    node: {r['node']}")
    if "error" not in bare and "error" not in sim:
        print(f"lockstep / bare round-trip rate: {100 * sim['rate'] / bare['rate']:.0f} % over all steps, "
              f"{100 * sim['median_rate'] / bare['median_rate']:.0f} % median of the runs' rates, "
              f"{100 * bare['rtt_p50'] / sim['rtt_p50']:.0f} % by the median round trips (target >= 70 %)")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
