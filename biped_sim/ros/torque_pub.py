"""``torque_pub``: publish hip torque commands to ``sim_node`` without the ``ros2`` command line.

Owns a small command-line publisher of ``std_msgs/Float64MultiArray`` on ``hip_torque``: once, at
a rate, from a function of time, or one command per received state (to drive a ``lockstep`` node).
"""
from __future__ import annotations

import argparse
import math
import sys
import time

EPILOG = """examples:
  torque_pub 5 -5                                  # once: u1 = 5 N m (hip 1), u2 = -5 N m (hip 2)
  torque_pub 5 -5 --rate 100 --duration 2          # 100 Hz for 2 s (wall clock)
  torque_pub --expr "10*sin(2*pi*t)" "0" --rate 200
                                                   # a function of t (s since the first command)
  torque_pub --expr "3*cos(t)" "-3*cos(t)" --lockstep --steps 500
                                                   # lockstep node: one command per joint_states
                                                   # message, t = its stamp (simulated time)
Expressions may use t, pi, e and the functions of Python's math module (sin, cos, exp, ...)."""


def compile_expr(text):
    """A function f(t) of an expression in t (math functions only)."""
    names = {k: getattr(math, k) for k in dir(math) if not k.startswith("_")}
    names.update(abs=abs, min=min, max=max)
    try:
        code = compile(text.strip(), "<expr>", "eval")
    except SyntaxError as exc:
        raise ValueError(f"cannot parse expression {text!r}: {exc.msg}") from None
    for name in code.co_names:
        if name != "t" and name not in names:
            raise ValueError(f"unknown name {name!r} in expression {text!r} (use t and math functions)")

    def f(t):
        try:
            return float(eval(code, {"__builtins__": {}}, dict(names, t=t)))  # noqa: S307 - names restricted above
        except (ArithmeticError, ValueError, TypeError) as exc:   # 1/t at t = 0, log(t - 1), ...
            raise ValueError(f"expression {text.strip()!r} failed at t = {t:g} s: {exc}; write one that is defined "
                             "at every t of the run (t starts at 0)") from None
    f(0.0)
    return f


def negative_numbers_as_values(argv):
    """``argv`` with every single-dash word but ``-h`` (``-1e8``, ``-3*cos(t)``, ``-t``; the options of
    torque_pub are all ``--long``) marked as a value: argparse takes a word that starts with '-' for
    an option unless it is a plain ``-5`` or ``-0.5``, so ``torque_pub 1e8 -1e8`` was refused. The
    mark is a leading space, which float() and the expressions ignore. Words after ``--`` are left alone."""
    out = []
    for i, word in enumerate(argv):
        if word == "--":
            return out + list(argv[i:])
        is_value = word.startswith("-") and not word.startswith("--") and word != "-h" and len(word) > 1
        out.append(" " + word if is_value else word)
    return out


def build_parser():
    p = argparse.ArgumentParser(
        prog="torque_pub", formatter_class=argparse.RawDescriptionHelpFormatter, epilog=EPILOG,
        description="Publish hip torque commands (std_msgs/Float64MultiArray, [u1, u2] in N m: hip of leg 1, "
                    "then leg 2; another robot: one torque per actuated joint) for the biped_sim node. Without "
                    "--rate or --lockstep it publishes once, after a subscriber is found, and exits.")
    p.add_argument("torques", nargs="*", type=float, metavar="U",
                   help="the torques, one per actuated joint of --robot: u1 u2 (N m) for the three-link biped; "
                        "default zeros")
    p.add_argument("--expr", nargs="+", metavar="E", help="torques as expressions of t (s), one per actuated joint")
    p.add_argument("--robot", default="three_link", metavar="NAME|PATH",
                   help="the node's robot (its scene's robot parameter), which says how many torques a command "
                        "holds: a shipped name or a description file [default: three_link]")
    p.add_argument("--rate", type=float, help="publish at this rate (Hz, wall clock) until --duration or Ctrl-C")
    p.add_argument("--duration", type=float, default=0.0, help="with --rate: stop after this many s (0: never)")
    p.add_argument("--lockstep", action="store_true",
                   help="answer every joint_states message with one command (t = the message's stamp)")
    p.add_argument("--steps", type=int, default=0, help="with --lockstep: stop after this many commands (0: never)")
    p.add_argument("--topic", default="hip_torque", help="command topic")
    p.add_argument("--states", default="joint_states", help="state topic (--lockstep)")
    p.add_argument("--wait", type=float, default=10.0, help="s to wait for the node to subscribe")
    p.add_argument("--state-timeout", type=float, default=10.0,
                   help="with --lockstep: stop when no new joint_states message came for this many s (wall "
                        "clock) after the first; the end of the node's run (its 'biped_sim/run' status on "
                        "diagnostics) stops it at once")
    return p


def main(argv=None):
    args = build_parser().parse_args(negative_numbers_as_values(sys.argv[1:] if argv is None else argv))
    try:
        from biped_sim.config.joints import joint_layout
        try:
            layout = joint_layout(args.robot)
        except ValueError as exc:
            raise ValueError(f"--robot: {exc}") from None
        want = (f"{len(layout.actuated)} torques, one per actuated joint ({', '.join(layout.actuated)}) of robot "
                f"{args.robot}")
        if args.expr:
            if args.torques:
                raise ValueError(f"give either the torques or --expr with one expression each ({want}), not both")
            if len(args.expr) != len(layout.actuated):
                raise ValueError(f"--expr takes {want}; got {len(args.expr)} expression(s)")
            functions = [compile_expr(e) for e in args.expr]
            torques = lambda t: [f(t) for f in functions]  # noqa: E731
        else:
            vals = args.torques or [0.0] * len(layout.actuated)
            if len(vals) != len(layout.actuated):
                raise ValueError(f"give {want}; got {len(vals)}")
            torques = lambda t: list(vals)  # noqa: E731
        if args.rate is not None and not args.rate > 0:
            raise ValueError("--rate must be positive")
    except ValueError as exc:
        print(f"torque_pub: error: {exc}", file=sys.stderr)
        return 2

    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from biped_sim.recording.messages import stamp_ns, torque_msg
    from biped_sim.ros import startup
    # SIGINT, SIGTERM and SIGHUP set a flag the loops read (rclpy's own handlers shut the context down under
    # a running wait, and spin_once then raises RCLError: a traceback for a plain stop)
    stop = startup.init("torque_pub", None)
    if stop is None:
        return startup.EXIT_REFUSED
    node = rclpy.create_node("torque_pub")
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    pub = node.create_publisher(Float64MultiArray, args.topic, qos)
    topic = pub.topic_name
    sent = 0
    stopped_waiting = run_over = False

    def send(t, answers_ns=None):
        nonlocal sent
        u = torques(t)
        # --lockstep: tagged with the state it answers, so that the node can tell a stale command
        pub.publish(torque_msg(u, answers_ns) if answers_ns is not None else Float64MultiArray(data=u))
        sent += 1
        return u
    try:
        end = time.monotonic() + args.wait
        while pub.get_subscription_count() == 0 and not stop:
            if time.monotonic() > end:
                print(f"torque_pub: error: nobody subscribes to {topic} after {args.wait:g} s "
                      "(is sim_node running, on this ROS_DOMAIN_ID?)", file=sys.stderr)
                return 1
            rclpy.spin_once(node, timeout_sec=0.05)
        if args.lockstep:
            from diagnostic_msgs.msg import DiagnosticArray
            from rclpy.qos import DurabilityPolicy
            state_qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                   durability=DurabilityPolicy.TRANSIENT_LOCAL)
            last = dict(wall=None, t=None, ended=None)

            def on_state(msg):
                last["wall"], last["t"] = time.monotonic(), msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
                if args.steps and sent >= args.steps:
                    return
                send(last["t"], stamp_ns(msg.header.stamp))

            def on_diagnostics(msg):
                # the node's final status: the run is over, no state will come to answer
                for st in msg.status:
                    if st.name.endswith("/run") and st.message != "running":
                        last["ended"] = f"{st.name}: {st.message}"
            node.create_subscription(JointState, args.states, on_state, state_qos)
            node.create_subscription(DiagnosticArray, "diagnostics", on_diagnostics, state_qos)
            while not stop and (not args.steps or sent < args.steps):
                rclpy.spin_once(node, timeout_sec=0.1)
                if last["ended"]:
                    print(f"torque_pub: the node's run has ended ({last['ended']}); stopping", file=sys.stderr)
                    run_over = True
                    break
                if last["wall"] is not None and time.monotonic() - last["wall"] > args.state_timeout:
                    print(f"torque_pub: error: no new {args.states} message for {args.state_timeout:g} s (the "
                          f"last at t = {last['t']:.6g} s): the node's run has stopped or the node is gone; "
                          "stopping", file=sys.stderr)
                    stopped_waiting = run_over = True
                    break
        elif args.rate:
            t0 = time.monotonic()
            k = 0
            while not stop and (not args.duration or time.monotonic() - t0 < args.duration):
                send(k / args.rate)
                k += 1
                while time.monotonic() < t0 + k / args.rate:
                    rclpy.spin_once(node, timeout_sec=max(0.0, t0 + k / args.rate - time.monotonic()))
        else:
            u = send(0.0)
            print(f"published {u} on {topic}")
        if not run_over:      # (a node whose run is over acknowledges nothing more)
            from rclpy.duration import Duration
            pub.wait_for_all_acked(Duration(seconds=2.0))
    except (KeyboardInterrupt, ExternalShutdownException):  # a stop that came another way
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    if args.rate or args.lockstep:
        print(f"published {sent} commands on {topic}")
    return 1 if stopped_waiting else 0


if __name__ == "__main__":
    sys.exit(main())
