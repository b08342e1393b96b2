"""``biped-sim stability``: the stability suite of stiff and extreme cases (stability.py)."""
from __future__ import annotations

import sys
import time

from biped_sim.analysis import stability
from biped_sim.config.help_format import HelpFormatter


def register(sub):
    p = sub.add_parser(
        "stability", help="run the stability suite: stiff, extreme, hybrid edge, long and bad-number cases",
        description="Run the stability suite and print one verdict (PASS/FAIL/SKIP) per case with its figures. "
                    "A case passes when the run keeps its invariants (finite numbers, bounded constraint drift, "
                    "energy balance within tolerance, the expected events) or stops with a clear error naming "
                    "the cause. Exit status 1 when a case fails.",
        epilog="--break SETTING: " + "; ".join(f"{k}: {v[1]} (case {v[0]} must FAIL)"
                                              for k, v in stability.BREAKS.items()),
        formatter_class=HelpFormatter)
    p.add_argument("--quick", action="store_true", help="smaller suite (40-step walk, fewer gains and ratios)")
    p.add_argument("--break", dest="broken", choices=sorted(stability.BREAKS),
                   help="run with a deliberately broken setting that must make one case fail")
    p.add_argument("--case", action="append", metavar="NAME",
                   help="run only this case (repeatable): " + ", ".join(c.__name__[5:] for c in stability.CASES))
    p.set_defaults(func=run)


def run(args):
    t0 = time.perf_counter()
    names = [c.__name__[5:] for c in stability.CASES]
    for c in args.case or []:
        if c not in names:
            raise ValueError(f"unknown case {c!r}; choose from {', '.join(names)}")
    if args.broken:
        case, why = stability.BREAKS[args.broken]
        print(f"deliberately broken setting {args.broken!r}: {why}; case {case} must FAIL")
    verdicts = stability.run_suite(quick=args.quick, broken=args.broken, only=args.case,
                                   report=lambda v: print(v.line(), flush=True))
    n = {w: sum(v.word == w for v in verdicts) for w in ("PASS", "FAIL", "SKIP")}
    print(f"{n['PASS']} passed, {n['FAIL']} failed, {n['SKIP']} not applicable in {time.perf_counter() - t0:.1f} s",
          file=sys.stdout)
    return 1 if n["FAIL"] else 0
