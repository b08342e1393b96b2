"""Tests of ``sim_node`` over real DDS: the node in a subprocess, a client node in this process.

Owns the node's contract tests (issue 3): topic names and types, torques move the robot, ground
reaction in stance, one impact message per engine impact at the engine's time, lockstep determinism
and equality with ``simulate``, every bad input, refusal to start, faults and signals.
"""
from __future__ import annotations

import ast
import math
import signal
import subprocess
import time

import numpy as np
import pytest

from ros_helpers import BIN, Client, ros_domain, ros_env, start_node

rclpy = pytest.importorskip("rclpy")
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from biped_sim.control.walking import WalkingController  # noqa: E402
from biped_sim.engine.model import BipedModel  # noqa: E402
from biped_sim.engine.simulate import simulate  # noqa: E402

BASE = {"record": False}
ERROR = 2


def ns(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def level(status):
    lv = status.level
    return lv[0] if isinstance(lv, (bytes, bytearray)) else int(lv)


def values(status):
    return {kv.key: kv.value for kv in status.values}


def statuses(arrays):
    return [s for a in arrays for s in a.status]


class Lockstep:
    """A controller in the loop: send one command, wait for the state it produces."""

    def __init__(self, client, proc):
        self.c, self.proc = client, proc
        self.js = client.collect("/joint_states", JointState)
        self.grf = client.collect("/ground_reaction", WrenchStamped)
        self.impact = client.collect("/impact", DiagnosticArray)
        self.diag = client.collect("/diagnostics", DiagnosticArray)
        self.clock = client.collect("/clock", Clock)
        self.pub = client.publisher("/hip_torque", Float64MultiArray)
        client.wait_matched(self.pub, proc=proc)
        client.spin_until(lambda: self.js, what="the state at t = 0", proc=proc)

    def send(self, u):
        n = len(self.js)
        self.pub.publish(Float64MultiArray(data=[float(v) for v in u]))
        self.c.spin_until(lambda: len(self.js) > n, timeout=10, what="the next state", proc=self.proc)
        return self.js[-1]

    def run_status(self, timeout=10):
        self.c.spin_until(lambda: any(s.name == "biped_sim/run" for s in statuses(self.diag)), timeout,
                          "the run's final status", self.proc)
        return values([s for s in statuses(self.diag) if s.name == "biped_sim/run"][-1])


def walking_run(dom, cp, duration):
    """The walking controller in the loop of a lockstep node: (states, impacts, grf) received."""
    model = BipedModel()
    ctrl = WalkingController(model)
    q0, dq0 = ctrl.initial_state()
    params = dict(BASE, time_mode="lockstep", control_period=cp, duration=duration,
                  initial_q=[float(v) for v in q0], initial_dq=[float(v) for v in dq0], initial_stance_leg=1)
    with start_node(params, dom) as proc, Client(dom) as c:
        ls = Lockstep(c, proc)
        for _ in range(round(duration / cp)):
            m = ls.js[-1]
            leg = int(m.header.frame_id.split("_")[1]) if m.header.frame_id.startswith("foot_") else 0
            u = ctrl(ns(m.header.stamp) * 1e-9, np.array(m.position), np.array(m.velocity), leg)
            ls.send(u)
        status = ls.run_status()
        c.spin_until(lambda: len(ls.clock) == len(ls.js), timeout=10, what="every /clock message", proc=proc)
        assert proc.wait(20) == 0
        return ls, status, (model, ctrl, q0, dq0)


def test_walking_lockstep_matches_simulate_and_is_deterministic():
    cp, duration = 0.01, 1.5
    with ros_domain() as dom:
        a, status_a, (model, ctrl, q0, dq0) = walking_run(dom, cp, duration)
    with ros_domain() as dom:
        b, _status_b, _ = walking_run(dom, cp, duration)
    # determinism: two runs, identical states (bit for bit)
    states = lambda ls: [(ns(m.header.stamp), list(m.position), list(m.velocity), list(m.effort)) for m in ls.js]  # noqa: E731
    assert len(a.js) == round(duration / cp) + 1
    assert states(a) == states(b)
    # the same run headless: simulate with a controller that returns those commands
    ref = simulate(model, q0, dq0, duration, controller=ctrl, control_period=cp)
    assert ref.status == "completed"
    impacts = [values(s) for s in statuses(a.impact)]
    assert len(ref.impacts) >= 3 and len(impacts) == len(ref.impacts) == int(status_a["impacts"])
    for msg, arr, ev in zip(impacts, a.impact, ref.impacts):
        assert float(msg["time"]) == ev.time and ns(arr.header.stamp) == round(ev.time * 1e9)
        assert msg["kind"] == "touchdown" and int(msg["foot"]) == ev.leg
        assert ast.literal_eval(msg["dq_plus"]) == ev.dq_plus.tolist()
        assert ast.literal_eval(msg["dq_minus"]) == ev.dq_minus.tolist()
        assert ast.literal_eval(msg["impulse"]) == ev.impulse.tolist()
    assert list(a.js[-1].position) == ref.q[-1].tolist() and list(a.js[-1].velocity) == ref.dq[-1].tolist()
    # the stance foot changes with each impact, in joint_states and ground_reaction alike
    feet = [m.header.frame_id for m in a.grf]
    assert feet[0] == "foot_1" and "foot_2" in feet
    assert all(m.wrench.force.y > 0 for m in a.grf)
    assert [ns(m.clock) for m in a.clock] == [ns(m.header.stamp) for m in a.js]


def test_topics_torques_ground_reaction_and_bad_commands():
    cp = 0.002
    params = dict(BASE, time_mode="lockstep", control_period=cp, duration=15 * cp, torque_limit=100.0)
    with ros_domain() as dom, start_node(params, dom) as proc, Client(dom) as c:
        ls = Lockstep(c, proc)
        c.spin_until(lambda: ls.grf and ls.clock, what="ground reaction and clock at t = 0", proc=proc)
        pubs, subs = c.wait_for_node_topics(
            "biped_sim", ["/joint_states", "/ground_reaction", "/impact", "/diagnostics", "/clock"], ["/hip_torque"],
            proc=proc)
        assert pubs["/joint_states"] == ["sensor_msgs/msg/JointState"]
        assert pubs["/ground_reaction"] == ["geometry_msgs/msg/WrenchStamped"]
        assert pubs["/impact"] == ["diagnostic_msgs/msg/DiagnosticArray"]
        assert pubs["/diagnostics"] == ["diagnostic_msgs/msg/DiagnosticArray"]
        assert pubs["/clock"] == ["rosgraph_msgs/msg/Clock"]
        assert subs["/hip_torque"] == ["std_msgs/msg/Float64MultiArray"]
        m0 = ls.js[0]
        assert list(m0.name) == ["base_x", "base_y", "hip_1", "hip_2", "torso_pitch"]
        assert ns(m0.header.stamp) == 0 and m0.header.frame_id == "foot_1"
        # standing still: the ground carries the weight (20 kg)
        g0 = ls.grf[0]
        assert g0.header.frame_id == "foot_1" and ns(g0.header.stamp) == 0
        assert g0.wrench.force.y == pytest.approx(20 * 9.81, rel=1e-9) and abs(g0.wrench.force.x) < 1e-9
        for _ in range(4):
            m = ls.send([0.0, 0.0])
        assert max(abs(v) for v in m.velocity) < 1e-9          # at rest without torque
        for _ in range(4):
            m = ls.send([2.0, -2.0])
        assert list(m.effort) == [0.0, 0.0, 2.0, -2.0, 0.0]
        assert abs(m.velocity[2]) > 1e-4 and abs(m.velocity[3]) > 1e-4    # the torques move the hips
        assert ns(m.header.stamp) == round(8 * cp * 1e9)
        # bad commands: rejected, counted, the last valid one held (lockstep still steps)
        for bad in ([math.nan, 0.0], [1.0, 2.0, 3.0], [500.0, 0.0], [math.inf, 1.0], [], [-101.0, 0.0]):
            m = ls.send(bad)
            assert list(m.effort) == [0.0, 0.0, 2.0, -2.0, 0.0], bad
        m = ls.send([1.0, 1.0])
        assert list(m.effort) == [0.0, 0.0, 1.0, 1.0, 0.0]
        status = ls.run_status()
        assert status["commands_rejected"] == "6" and status["commands_received"] == "15"
        assert status["status"] == "completed"
        # a stance foot under load all along, one ground reaction per state
        assert len(ls.grf) == len(ls.js) == 16 and all(g.header.frame_id == "foot_1" for g in ls.grf)
        assert proc.wait(20) == 0
        assert "rejected" in proc.output()


def test_clip_outputs_command_timeout_and_sigterm():
    """realtime: clipping, only the declared outputs, the command timeout, SIGTERM; and what realtime
    guarantees whatever the load: simulated time never runs ahead of the wall clock x rate_factor (a
    run as fast as it can fails this: this standing robot falls at about 3 s of simulated time, which
    fast mode reaches within a second) and keeps advancing (a stalled run times out). No bound that a
    slow machine could break; the achieved rate is measured by ``python -m benchmarks.bench_node``."""
    rate_factor, command_timeout = 0.2, 1.0        # a publication every 0.1 s of wall time
    params = dict(BASE, time_mode="realtime", rate_factor=rate_factor, publish_rate=50.0,
                  command_timeout=command_timeout, torque_limit=1.0, torque_limit_action="clip",
                  outputs=["joint_states", "clock"], phases=["stance", "impact"])
    arrivals = []                                   # (wall clock at arrival, stamp in s) of each state
    launched = time.monotonic()                     # the node's clock starts after this

    def assert_never_ahead():
        """The state at t is published at wall time (start + t / rate_factor) or later."""
        ahead = [(wall - launched, t) for wall, t in arrivals if t > (wall - launched) * rate_factor]
        assert not ahead, f"states ahead of the wall clock x rate_factor (wall s since launch, stamp): {ahead[:3]}"

    with ros_domain() as dom, start_node(params, dom) as proc, Client(dom) as c:
        js = c.collect("/joint_states", JointState, transient_local=False,
                       callback=lambda m: arrivals.append((time.monotonic(), ns(m.header.stamp) * 1e-9)))
        clock = c.collect("/clock", Clock, transient_local=False)
        pub = c.publisher("/hip_torque", Float64MultiArray)
        c.wait_matched(pub, proc=proc)
        c.spin_until(lambda: js, what="states", proc=proc)
        # only the declared outputs have publishers (no impact, no ground_reaction)
        pubs, _ = c.wait_for_node_topics("biped_sim", ["/joint_states", "/clock", "/diagnostics"], proc=proc)
        assert set(pubs) - {"/rosout", "/parameter_events"} == {"/joint_states", "/clock", "/diagnostics"}
        sent = time.monotonic()
        pub.publish(Float64MultiArray(data=[50.0, -1.0]))          # beyond the limit: clipped
        c.spin_until(lambda: js[-1].effort[2] != 0.0, timeout=10, what="the command applied", proc=proc)
        assert list(js[-1].effort) == [0.0, 0.0, 1.0, -1.0, 0.0]
        applied = len(js) - 1
        c.spin_until(lambda: arrivals[-1][1] >= 0.4, timeout=60, what="simulated time 0.4 s (2 s of wall time)",
                     proc=proc)
        assert_never_ahead()
        c.spin_until(lambda: js[-1].effort[2] == 0.0, timeout=10, what="zero torque after the timeout", proc=proc)
        zero = next(i for i in range(applied, len(js)) if js[i].effort[2] == 0.0)
        # held for command_timeout of wall time at least: the node counts from the command's arrival
        assert arrivals[zero][0] - sent >= command_timeout, arrivals[zero][0] - sent
        stamps = [t for _, t in arrivals]
        assert stamps == sorted(stamps) and clock
        assert_never_ahead()
        assert proc.stop(signal.SIGTERM) == 0
        out = proc.output()
        assert "clipped" in out and "command_timeout" in out and "SIGTERM: shutting down" in out
        assert "Traceback" not in out


def test_diverging_state_node_stays_up_and_sigint():
    params = dict(BASE, time_mode="lockstep", torque_limit=1e9)
    with ros_domain() as dom, start_node(params, dom) as proc, Client(dom) as c:
        ls = Lockstep(c, proc)
        errors = lambda: [s for s in statuses(ls.diag) if level(s) == ERROR]  # noqa: E731
        for _ in range(50):
            if errors():
                break
            ls.pub.publish(Float64MultiArray(data=[1e8, -1e8]))
            n = len(ls.js)
            c.spin_until(lambda: len(ls.js) > n or errors(), timeout=10, what="a state or an error", proc=proc)
        c.spin_until(lambda: any(s.name == "biped_sim/run" for s in errors()), timeout=10,
                     what="the run's error status", proc=proc)
        err = errors()[0]
        assert "at t=" in err.message and ("diverging" in err.message or "ground" in err.message), err.message
        ls.pub.publish(Float64MultiArray(data=[0.0, 0.0]))          # ignored, but the node answers the graph
        c.wait_for_node("biped_sim", proc=proc)
        assert proc.alive
        assert proc.stop(signal.SIGINT) == 0
        out = proc.output()
        assert "stays up for inspection" in out and "SIGINT: shutting down" in out and "Traceback" not in out


def test_refuses_bad_parameters(tmp_path):
    scene = tmp_path / "bad.yaml"
    scene.write_text("biped_sim:\n  ros__parameters:\n    time_mode: fast\n    contol_period: 0.01\n")
    cases = {
        "unknown": (["--ros-args", "-p", "frobnicate:=1"], ["'frobnicate'", "time_mode"]),
        "ill-typed": (["--ros-args", "-p", "control_period:=abc"], ["'control_period'", "[1e-05, 1.0]"]),
        "params file": (["--ros-args", "--params-file", str(scene)], ["'contol_period'", "control_period"]),
    }
    with ros_domain() as dom:
        procs = {k: subprocess.Popen([str(BIN / "sim_node"), *argv], env=ros_env(dom), stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True) for k, (argv, _) in cases.items()}
        for k, p in procs.items():
            out, err = p.communicate(timeout=60)
            assert p.returncode == 2, (k, out, err)
            assert "Traceback" not in err and err.startswith("sim_node: error:"), (k, err)
            for word in cases[k][1]:
                assert word in err, (k, word, err)


def test_in_realtime_the_loop_takes_the_commands_and_the_executor_sleeps_while_they_arrive():
    """Issue 35: each command woke the executor's thread, which built a wait set of every entity of
    the node to run the callback (0.2 ms of CPU a 1 kHz period). Now the realtime and fast loops take
    the commands at each period's start (``take_commands``, in order, the newest holds) and the
    executor, serving the services and timers, neither runs the callback nor wakes for a command:
    with 50 commands waiting, it sleeps."""
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from biped_sim.ros.sim_node import COMMAND_QOS, SimNode
    with ros_domain() as dom:
        ctx = Context()
        rclpy.init(context=ctx, domain_id=dom, args=["sim_node", "--ros-args", "-p", "record:=false",
                                                      "-p", "time_mode:=realtime", "-p", "torque_limit:=100.0"])
        try:
            node = SimNode(context=ctx, argv=["sim_node"])
            executor = SingleThreadedExecutor(context=ctx)
            executor.add_node(node)
            controller = rclpy.create_node("controller", context=ctx)
            pub = controller.create_publisher(Float64MultiArray, "hip_torque", COMMAND_QOS)
            end = time.monotonic() + 30
            while pub.get_subscription_count() == 0 and time.monotonic() < end:
                time.sleep(0.01)
            for k in range(50):
                pub.publish(Float64MultiArray(data=[float(k), -float(k)]))
            time.sleep(0.3)                     # delivered, waiting in the subscription
            wall, cpu = time.monotonic(), time.thread_time()
            while time.monotonic() - wall < 0.3:    # the executor serves what it has (the node's timers)
                executor.spin_once(timeout_sec=0.05)
            wall, cpu = time.monotonic() - wall, time.thread_time() - cpu
            assert node.counts["received"] == 0, node.counts        # the executor ran no command
            assert cpu < 0.5 * wall, (wall, cpu)    # and slept: no wake-up for the commands waiting
            node.take_commands()
            assert node.counts["received"] == 50 and node.u == [49.0, -49.0], (node.counts, node.u)
            node.take_commands()                # none left
            assert node.counts["received"] == 50
            controller.destroy_node()
            node.destroy_node()
        finally:
            ctx.try_shutdown()
