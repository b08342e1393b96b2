"""``biped-sim accuracy``: error against run time of every integrator (work-precision; workprecision.py)."""
from __future__ import annotations

import os
import time

from biped_sim.analysis import workprecision as wp
from biped_sim.config.help_format import HelpFormatter


def register(sub):
    p = sub.add_parser(
        "accuracy", help="error against run time of every integrator (work-precision diagram)",
        description="Run every integrator over a ladder of tolerances (adaptive) and step sizes (fixed-step) "
                    "on a passive stance fall, a walking run of 10 impacts and a drop from flight; measure the "
                    "error against a tight reference (whose own error a second method estimates), the "
                    "event-time error, the constraint drift, the energy-balance residual and the median wall "
                    "time. Writes accuracy.md, accuracy.csv and work_precision.png to --out.",
        formatter_class=HelpFormatter)
    p.add_argument("--quick", action="store_true", help="short ladder, one repeat (what the tests run)")
    p.add_argument("--repeats", type=int, default=None, help="timed repeats per setting (default 3, quick 1)")
    p.add_argument("--case", action="append", choices=("passive_fall", "walking", "drop"),
                   help="run only this case (repeatable)")
    p.add_argument("--out", default=os.path.join("bench_out", "accuracy"), help="output directory")
    p.add_argument("--no-progress", action="store_true", help="no progress line on stderr")
    p.set_defaults(func=run)


def run(args):
    if args.repeats is not None and args.repeats < 1:
        raise ValueError(f"--repeats must be >= 1, got {args.repeats}")
    os.makedirs(args.out, exist_ok=True)     # before the minutes of work: a bad --out fails at once
    t0 = time.perf_counter()
    rows, refs = wp.run_benchmark(quick=args.quick, repeats=args.repeats, progress=not args.no_progress,
                                  cases_filter=args.case)
    md = wp.markdown(rows, refs)
    front = wp.front(rows)
    md += "\n### On the front (no other run both faster and more accurate over the run)\n\n"
    for case, pts in front.items():
        by_time = sorted(pts, key=lambda r: r["time"])
        md += f"- {case}: " + ", ".join(f"{r['method']} {r['setting']}" for r in by_time) + "\n"
    with open(os.path.join(args.out, "accuracy.md"), "w") as f:
        f.write(md)
    wp.write_csv(rows, os.path.join(args.out, "accuracy.csv"))
    wp.plot(rows, refs, os.path.join(args.out, "work_precision.png"))
    print(md)
    d = [r for r in rows if r["default"]]
    for r in d:
        on = any(o is r for o in front[r["case"]])
        print(f"default dop853 tol=1e-9 on {r['case']}: err_run {r['err_run']:.3g}, {r['time']:.3g} s, "
              f"{'on' if on else 'NOT on'} the front")
    print(f"wrote {args.out}/accuracy.md, accuracy.csv, work_precision.png in {time.perf_counter() - t0:.1f} s")
    return 0
