"""``biped-sim resim BAG``: re-simulate a recorded run and compare (biped_sim.recording.resim)."""
from __future__ import annotations


def register(sub):
    p = sub.add_parser(
        "resim", help="feed a bag's torque commands through a fresh simulation and compare the states",
        description="Re-simulate a recorded run: build the engine with the bag's recorded settings (its "
                    "'biped_sim' metadata record), feed it the recorded hip_torque commands one control period "
                    "at a time as the node does, and report the largest difference to the recorded joint_states "
                    "and impacts. A lockstep run of the same version and settings reproduces exactly; a "
                    "mismatch names the first message that differs. Exit code 0: identical (or within --tol), "
                    "1: different.")
    p.add_argument("bag", metavar="BAG", help="bag directory (or its .mcap file)")
    p.add_argument("--tol", type=float, default=0.0,
                   help="accept differences up to this (default 0: bit-identical)")
    p.set_defaults(func=run)


def run(args):
    from biped_sim.recording.resim import format_report, resim
    rep = resim(args.bag)
    print(format_report(rep))
    ok = rep["identical"] or (rep["states"] > 0 and max(rep["max_q"], rep["max_dq"], rep["impact_dt"]) <= args.tol)
    return 0 if ok else 1
