"""``biped-sim recover BAG``: make a bag whose recording was killed readable by every tool."""
from __future__ import annotations


def register(sub):
    p = sub.add_parser(
        "recover", help="rewrite a bag cut short by a kill (SIGKILL, power loss) into a clean one",
        description="A bag whose writer was killed has an MCAP file without its summary and no "
                    "metadata.yaml. This reads every complete chunk (all chunks written before the kill), "
                    "writes a clean MCAP (summary, indexes, the rosbag2 record) in its place, keeps the "
                    "original as <name>.mcap.truncated (or .truncated.1, ... if that exists), and regenerates "
                    "metadata.yaml. It changes nothing and exits non-zero for a complete bag, a bag being "
                    "recorded right now, a file that is not MCAP, or one without a complete message.")
    p.add_argument("bag", metavar="BAG", help="bag directory (or its .mcap file)")
    p.set_defaults(func=run)


def run(args):
    from biped_sim.recording.recover import recover
    info = recover(args.bag)
    if info["kept"] is None:
        print(f"{info['path']} is complete; wrote the bag's missing metadata.yaml ({info['messages']} messages)")
    else:
        print(f"recovered {info['messages']} messages into {info['path']} (original kept as {info['kept']})")
    for topic, n in info["topics"].items():
        print(f"  {topic:24s} {n}")
    if info["end"]:
        print(f"the original ended in an incomplete record ({info['end']}); it was dropped")
    return 0
