"""What a researcher waits for at the command line: ``python -m benchmarks.bench_cli``.

Owns one measurement: the wall time of whole ``biped-sim`` processes (interpreter start, imports,
work, exit), the minimum of ``repeat`` runs each (the least disturbed run on a shared machine), and
their CPU time (user + system of the process and its children), which another job on the machine
moves less than the wall time:

* ``biped-sim --help``;
* ``biped-sim simulate --duration 0.1`` (a run of milliseconds: the rest is the process's imports);
* ``biped-sim inspect BAG`` of a 10 s walk recorded here first, with its PNG and with ``--no-png``.

The goals of issue 33 on the 2-core machine of docs/performance.md: 0.5 s for the first two, 1 s for
inspect.
"""
from __future__ import annotations

import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _cli():
    """The console script of this interpreter's environment (a process as the user starts it)."""
    script = Path(sys.executable).with_name("biped-sim")
    main = "import sys; from biped_sim.cli import main; sys.exit(main())"
    return [str(script)] if script.exists() else [sys.executable, "-c", main]


def _children_cpu():
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def wall_seconds(argv, repeat):
    """(minimum wall time, minimum CPU time) of ``repeat`` runs of ``argv`` (output discarded; a
    failure raises)."""
    best, best_cpu = float("inf"), float("inf")
    for _ in range(repeat):
        cpu0, t0 = _children_cpu(), time.perf_counter()
        subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, _children_cpu() - cpu0)
    return best, best_cpu


def main(argv=None, repeat=5):
    cli = _cli()
    folder = tempfile.mkdtemp(prefix="bench_cli_")
    try:
        subprocess.run(cli + ["simulate", "--scene", "walk", "--duration", "10", "--record", folder], check=True,
                       stdout=subprocess.DEVNULL)
        (bag,) = [p for p in Path(folder).iterdir() if p.is_dir()]
        rows = [
            ("biped-sim --help", cli + ["--help"]),
            ("biped-sim simulate --duration 0.1", cli + ["simulate", "--duration", "0.1"]),
            ("biped-sim inspect (10 s walk bag, PNG)",
             cli + ["inspect", str(bag), "--png", os.path.join(folder, "f.png")]),
            ("biped-sim inspect --no-png (10 s walk bag)", cli + ["inspect", str(bag), "--no-png"]),
        ]
        print(f"\n== command-line processes, min of {repeat} runs: wall time, CPU time (user + system) ==")
        out = {}
        for label, args in rows:
            out[label], cpu = wall_seconds(args, repeat)
            print(f"  {label:44s} {out[label]:6.2f} s  cpu {cpu:5.2f} s")
        return out
    finally:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
