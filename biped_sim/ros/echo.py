"""``biped_echo``: print the topics of ``sim_node`` readably, without the ``ros2`` command line.

Owns the echo tool: subscribes to joint_states, ground_reaction, impact, diagnostics and /clock
(or the ones named) and prints one line per message, stamped with its simulated time.
"""
from __future__ import annotations

import argparse
import sys
import time

TOPICS = ("joint_states", "ground_reaction", "impact", "diagnostics", "clock")
LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}


def _t(stamp):
    return f"{stamp.sec + stamp.nanosec * 1e-9:12.6f}"


def _v(values, digits):
    return "[" + ", ".join(f"{v:.{digits}f}" for v in values) + "]"


def format_message(topic, msg, digits=4):
    """One readable line (or block, for impacts) of a message of this node."""
    if topic == "joint_states":
        eff = list(msg.effort)
        head = (f"{_t(msg.header.stamp)} joint_states    stance={msg.header.frame_id:7s} q={_v(msg.position, digits)} "
                f"dq={_v(msg.velocity, digits)}")
        names = tuple(msg.name)
        if not names or len(names) == 5 and names[2:4] == ("hip_1", "hip_2"):   # a three-link robot: u1, u2
            return f"{head} u={_v(eff[2:4] if len(eff) >= 4 else [], 2)}"
        # another robot: which joints have a motor is its description's, not the message's; effort is B u
        # (each motor's torque on its joint), printed whole with the joints' names
        return f"{head} effort={{{', '.join(f'{n}: {v:.2f}' for n, v in zip(msg.name, eff))}}}"
    if topic == "ground_reaction":
        f = msg.wrench.force
        return (f"{_t(msg.header.stamp)} ground_reaction {msg.header.frame_id:7s} "
                f"F=[{f.x:.{digits}f}, {f.y:.{digits}f}] N")
    if topic == "clock":
        return f"{_t(msg.clock)} clock"
    lines = []
    for st in msg.status:
        lvl = st.level[0] if isinstance(st.level, (bytes, bytearray)) else int(st.level)
        lines.append(f"{_t(msg.header.stamp)} {topic:15s} [{LEVELS.get(lvl, lvl)}] {st.name}: {st.message}")
        if topic == "impact":
            for kv in st.values:
                lines.append(f"{'':28s}{kv.key:>18s}: {kv.value}")
    return "\n".join(lines)


def build_parser():
    p = argparse.ArgumentParser(
        prog="biped_echo", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Print the topics of the biped_sim node readably: one line per joint_states, ground_reaction "
                    "and /clock message, and every field of impact and diagnostics messages. Times are the "
                    "messages' stamps (simulated time, s).",
        epilog="examples:\n  biped_echo                       # every topic\n"
               "  biped_echo impact diagnostics    # events only\n"
               "  biped_echo joint_states --every 100 --count 10")
    p.add_argument("topics", nargs="*", metavar="TOPIC",
                   help=f"topics to echo, of {', '.join(TOPICS)} (default: all)")
    p.add_argument("--count", type=int, default=0, help="exit after printing this many messages (0: never)")
    p.add_argument("--every", type=int, default=1, help="print every n-th message of each topic")
    p.add_argument("--digits", type=int, default=4, help="decimals of the printed values")
    p.add_argument("--history", action="store_true",
                   help="also print the last messages the node kept (transient_local) from before we joined")
    p.add_argument("--timeout", type=float, default=0.0, help="exit after this many s (wall) (0: never)")
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    topics = args.topics or list(TOPICS)
    bad = [t for t in topics if t not in TOPICS]
    if bad:
        print(f"biped_echo: error: unknown topic(s) {bad}; choose from {', '.join(TOPICS)}", file=sys.stderr)
        return 2
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import WrenchStamped
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState

    from biped_sim.ros import startup
    types = dict(joint_states=JointState, ground_reaction=WrenchStamped, impact=DiagnosticArray,
                 diagnostics=DiagnosticArray, clock=Clock)
    # SIGINT, SIGTERM and SIGHUP set a flag the loop reads (rclpy's own handlers shut the context down under
    # a running wait, and spin_once then raises RCLError: a traceback for a plain stop)
    stop = startup.init("biped_echo", None)
    if stop is None:
        return startup.EXIT_REFUSED
    node = rclpy.create_node("biped_echo")
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL if args.history else DurabilityPolicy.VOLATILE)
    seen = {t: 0 for t in topics}
    printed = [0]

    def callback(topic):
        def on_msg(msg):
            seen[topic] += 1
            if (seen[topic] - 1) % max(1, args.every) == 0:
                print(format_message(topic, msg, args.digits), flush=True)
                printed[0] += 1
        return on_msg
    for t in topics:
        node.create_subscription(types[t], "/clock" if t == "clock" else t, callback(t), qos)
    end = time.monotonic() + args.timeout if args.timeout else None
    try:
        while not stop and not (args.count and printed[0] >= args.count) and not (end and time.monotonic() > end):
            rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):  # a stop that came another way
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
