"""``replay``: publish a bag's messages on their topics with their original timing.

What ``ros2 bag play`` does, for machines without rosbag2: the recorded CDR bytes are published
as they are (no decode), each message at ``start + (t - t_first) / rate`` on the wall clock, with
a topic selection, a start offset, looping, and ``/clock``: without ``--clock`` the bag's own
``/clock`` messages are replayed like any topic; with ``--clock [HZ]`` the player publishes
``/clock`` at HZ from the playback time (as ``ros2 bag play --clock``) instead, so that nodes
with ``use_sim_time`` follow the replay. Publishers use the recorded QoS (reliability,
durability) with a queue deep enough to not drop at high rates.
"""
from __future__ import annotations

import argparse
import sys
import time

from biped_sim.config.help_format import HelpFormatter
from biped_sim.config.progress import Progress
from biped_sim.recording import bagio


def build_parser():
    p = argparse.ArgumentParser(
        prog="biped-sim replay",
        description="Publish a recorded bag's messages on their topics with their original timing "
                    "(like 'ros2 bag play'). Times are the bag's simulation times; --rate scales them. A topic "
                    "whose message package is not installed here (the /tf of our bags: tf2_msgs is not on "
                    "PyPI) is left out, and the first line says so.",
        formatter_class=HelpFormatter,
        epilog="examples:\n"
               "  biped-sim replay bags/walk-20261122T025314059Z\n"
               "  biped-sim replay BAG --rate 0.5 --loop --topics /joint_states /impact\n"
               "  biped-sim replay BAG --start-offset 2.0 --clock 100\n"
               "      (/clock at 100 Hz; run the other nodes with use_sim_time)\n"
               "Other ROS arguments go after --ros-args (e.g. --ros-args -r __ns:=/replay).")
    p.add_argument("bag", metavar="BAG", help="bag directory (or its .mcap file)")
    p.add_argument("-r", "--rate", type=float, default=1.0, help="playback speed factor (2: twice as fast)")
    p.add_argument("-l", "--loop", action="store_true", help="play the bag again and again until stopped")
    p.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics (all when not given)")
    p.add_argument("--exclude", nargs="+", metavar="TOPIC", default=[], help="leave out these topics (default: "
                   "none)")
    p.add_argument("-s", "--start-offset", type=float, default=0.0, metavar="S",
                   help="start this many seconds after the bag's first message")
    p.add_argument("--clock", type=float, nargs="?", const=100.0, default=None, metavar="HZ",
                   help="publish /clock at HZ (default 100) from the playback time instead of the bag's /clock")
    p.add_argument("--wait-subscribers", type=float, default=0.0, metavar="S",
                   help="before playing, wait up to S seconds until every topic with messages has a subscriber")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress line")
    p.add_argument("--list", action="store_true", help="list the bag's topics and exit")
    return p


def _qos(bag, topic):
    """The recorded offered QoS of a topic, as an rclpy QoSProfile (deep queue)."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    rel, dur = ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE
    try:
        import yaml
        from mcap.reader import make_reader
        with open(bagio.mcap_path(bag), "rb") as f:
            s = make_reader(f).get_summary()
        for c in s.channels.values():
            if c.topic == topic:
                prof = (yaml.safe_load(c.metadata.get("offered_qos_profiles", "")) or [{}])[0]
                if str(prof.get("reliability", "")).lower() == "best_effort":
                    rel = ReliabilityPolicy.BEST_EFFORT
                if str(prof.get("durability", "")).lower() == "transient_local":
                    dur = DurabilityPolicy.TRANSIENT_LOCAL
    except Exception:  # noqa: BLE001 - a truncated bag: the defaults
        pass
    return QoSProfile(depth=1000, reliability=rel, durability=dur)


class _Progress:
    """The messages published of each pass over the bag, with its bag time (config.progress: a bar on a
    terminal, a line every 10 % or 10 s elsewhere); a new display for each loop."""

    def __init__(self, quiet, total, t_first, t_last):
        self.quiet, self.total, self.t_first, self.t_last = quiet, total, t_first, t_last
        self.display, self.loop = None, None

    def show(self, t_ns, n, loop, rate, force=False):
        if self.quiet:
            return
        if self.display is None or loop != self.loop:
            if self.display is not None:
                self.display.close()
            label = f"replay, loop {loop}" if loop else "replay"
            self.display, self.loop = Progress(self.total, label, unit="messages"), loop
        span = (self.t_last - self.t_first) / 1e9
        self.display.update(n, f"bag time {(t_ns - self.t_first) / 1e9:.3f} / {span:.3f} s, rate {rate:g}x")
        if force:
            self.display.close()
            self.display = None


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ros_args = []
    if "--ros-args" in argv:
        i = argv.index("--ros-args")
        argv, ros_args = argv[:i], argv[i:]
    args = build_parser().parse_args(argv)
    if not args.rate > 0:
        print("biped-sim replay: error: --rate must be > 0", file=sys.stderr)
        return 2
    try:
        channels = bagio.channels(args.bag)
    except (ValueError, OSError) as exc:
        print(f"biped-sim replay: error: {exc}", file=sys.stderr)
        return 2
    cut = bagio.cut_short(args.bag)
    if cut and not channels:
        print(f"biped-sim replay: error: {args.bag} is {cut} and holds no complete message: nothing to play",
              file=sys.stderr)
        return 1
    if cut:
        print(f"biped-sim replay: {args.bag} is {cut}: playing it up to its last complete chunk "
              f"('biped-sim recover {args.bag}' repairs the file)", file=sys.stderr)
    if args.list:
        for t, typ in channels.items():
            print(f"{t:28s} {typ}")
        return 0
    unknown = [t for t in (args.topics or []) + args.exclude if t not in channels]
    if unknown:
        print(f"biped-sim replay: error: topic(s) {unknown} not in the bag; it has {sorted(channels)}", file=sys.stderr)
        return 2
    topics = [t for t in (args.topics or list(channels)) if t not in args.exclude]
    if args.clock is not None:
        if not args.clock > 0:
            print("biped-sim replay: error: --clock HZ must be > 0", file=sys.stderr)
            return 2
        topics = [t for t in topics if t != "/clock"]   # the player's clock replaces the recorded one

    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from biped_sim.recording.messages import message_class
    from biped_sim.ros.startup import catch_stop_signals
    rclpy.init(args=["replay"] + ros_args, signal_handler_options=SignalHandlerOptions.NO)
    stop = catch_stop_signals([])     # SIGINT, SIGTERM, SIGHUP: stop playing, say so, close cleanly
    node = rclpy.create_node("biped_sim_replay")
    classes = {}
    for t in topics:
        try:
            classes[t] = message_class(channels[t])
        except (ImportError, AttributeError):      # e.g. /tf of our bags: tf2_msgs is not on PyPI
            pass
    skipped = [t for t in topics if t not in classes]
    if skipped:
        print("biped-sim replay: not playing " + ", ".join(f"{t} ({channels[t]})" for t in skipped)
              + ": its message package is not installed here", file=sys.stderr)
        topics = [t for t in topics if t in classes]
    pubs = {t: node.create_publisher(classes[t], t, _qos(args.bag, t)) for t in topics}
    clock_pub = None
    if args.clock is not None:
        from rclpy.qos import QoSProfile
        from rosgraph_msgs.msg import Clock
        clock_pub = node.create_publisher(Clock, "/clock", QoSProfile(depth=100))
    all_pubs = list(pubs.values()) + ([clock_pub] if clock_pub else [])
    msgs = list(bagio.messages(args.bag, topics=topics))
    if args.wait_subscribers > 0:     # wait on the topics that have something to play
        used = {m[0] for m in msgs}
        waiting = [p for t, p in pubs.items() if t in used] + ([clock_pub] if clock_pub else [])
        deadline = time.monotonic() + args.wait_subscribers
        while not stop and time.monotonic() < deadline and any(p.get_subscription_count() == 0 for p in waiting):
            time.sleep(0.02)
    if not msgs and clock_pub is None:
        print("biped-sim replay: nothing to play", file=sys.stderr)
        node.destroy_node()
        rclpy.shutdown()
        return 0
    t_all = [m[2] for m in msgs]
    t_first = (min(t_all) if t_all else 0) + int(round(args.start_offset * 1e9))
    t_last = max(t_all) if t_all else t_first
    msgs = [m for m in msgs if m[2] >= t_first]
    prog = _Progress(args.quiet, len(msgs), t_first, t_last)
    loop = 0
    sent = 0
    clock_step = int(round(1e9 / args.clock)) if clock_pub else None
    try:
        while not stop:
            loop += 1
            w0 = time.monotonic()
            n = 0
            next_clock = t_first
            i = 0
            while not stop and (i < len(msgs) or (clock_pub and next_clock <= t_last)):
                # the next event: a message, or a /clock tick (ticks first at equal times)
                if clock_pub is not None and next_clock <= t_last and (i >= len(msgs) or next_clock <= msgs[i][2]):
                    t_ev, item = next_clock, None
                    next_clock += clock_step
                else:
                    t_ev, item = msgs[i][2], msgs[i]
                    i += 1
                due = w0 + (t_ev - t_first) / 1e9 / args.rate
                while not stop:
                    left = due - time.monotonic()
                    if left <= 0:
                        break
                    time.sleep(min(left, 0.05))
                if stop:
                    break
                if item is None:
                    from builtin_interfaces.msg import Time
                    from rosgraph_msgs.msg import Clock
                    clock_pub.publish(Clock(clock=Time(sec=t_ev // 1_000_000_000, nanosec=t_ev % 1_000_000_000)))
                else:
                    pubs[item[0]].publish(bytes(item[3]))
                    n += 1
                    sent += 1
                prog.show(t_ev, n, loop if args.loop else 0, args.rate)
            prog.show(t_last, n, loop if args.loop else 0, args.rate, force=True)
            if not args.loop:
                break
    finally:
        from rclpy.duration import Duration
        for p in all_pubs:   # let reliable subscribers receive everything before we go
            try:
                p.wait_for_all_acked(Duration(seconds=2.0))
            except Exception:  # noqa: BLE001
                pass
        if not args.quiet:
            sys.stderr.write(f"[replay] published {sent} messages on {len(pubs)} topics"
                             + (" and /clock" if clock_pub else "") + ("" if not stop else " (stopped)") + "\n")
        node.destroy_node()
        rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
