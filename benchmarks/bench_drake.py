"""Drake side by side on the compass gait (issue 31): ``python -m benchmarks.bench_drake`` (also in ``make bench``).

Drake's ``pydrake.examples.CompassGait`` (``drake`` 1.58 from PyPI, for Python 3.12 only: a venv of its own,
``make venv-drake``, benchmark-only) and this project's ``compass_gait`` scene (today's three-link engine, the
torso carrying the hip mass: docs/models.md) walk 10 s passively down the 0.0525 rad slope from Drake's example
state. benchmarks/drake_compass_gait.py runs Drake in its venv and prints its impacts; this compares, for
each impact, the time and the state just before it (Drake's angles: stance = q[stance] + q3 - pi, the same
for swing), and the wall time of each at a ladder of accuracies, the error of every run measured against this
engine's run at rtol = atol = 1e-13 (which Drake's best run confirms; its figure is printed). Without
.venv-drake the comparison is skipped with one line.
"""
from __future__ import annotations

import json
import math
import statistics
import subprocess
import time
from pathlib import Path

import numpy as np

import biped_sim as bs

ROOT = Path(__file__).resolve().parents[1]
DRAKE_PYTHON = ROOT / ".venv-drake" / "bin" / "python"
TOLERANCES = (1e-6, 1e-8, 1e-10, 1e-12, 1e-13)
DRAKE_ACCURACIES = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-13)


def drake_angles(event):
    """(t, stance, swing, stancedot, swingdot) of an impact Event just before it, in Drake's angles."""
    q, dq, st = event.q, event.dq_minus, event.stance_leg_before
    sw = 3 - st
    return (event.time, q[1 + st] + q[4] - math.pi, q[1 + sw] + q[4] - math.pi, dq[1 + st] + dq[4], dq[1 + sw] + dq[4])


def ours(tol, repeats=5):
    scene = bs.load_scene("compass_gait")
    kw = scene.simulate_kwargs()
    kw.update(rtol=tol, atol=tol)
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        r = bs.simulate(**kw)
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls), np.array([drake_angles(e) for e in r.impacts])


def errors(impacts, reference):
    if len(impacts) != len(reference):
        return math.inf, math.inf
    d = np.abs(np.asarray(impacts) - reference)
    return d[:, 0].max(), d[:, 1:].max()


def main(argv=None):
    print("compass gait, 10 s passive walk down 0.0525 rad from (stance, swing, stancedot, swingdot) = "
          "(0, 0, 0.4, -2.0)")
    _, reference = ours(1e-13, repeats=1)
    print(f"  this engine at rtol = atol = 1e-13 (the reference below): {len(reference)} impacts, the last at "
          f"t = {reference[-1, 0]:.12f} s")
    print(f"  {'run':34s} {'impacts':>7s} {'time error (s)':>15s} {'state error':>12s} {'wall (ms)':>10s}")
    for tol in TOLERANCES:
        wall, imp = ours(tol)
        et, ex = errors(imp, reference)
        print(f"  {'biped_sim, rtol = atol = ' + format(tol, '.0e'):34s} {len(imp):7d} {et:15.1e} {ex:12.1e} "
              f"{wall * 1e3:10.2f}")
    if not DRAKE_PYTHON.exists():
        print("  Drake: skipped, no .venv-drake (make venv-drake installs drake 1.58 for Python 3.12)")
        return 0
    out = subprocess.run([str(DRAKE_PYTHON), str(ROOT / "benchmarks" / "drake_compass_gait.py"), "--accuracy",
                          *map(str, DRAKE_ACCURACIES)], capture_output=True, text=True, timeout=600)
    if out.returncode != 0:
        print(f"  Drake: failed ({out.stderr.strip().splitlines()[-1] if out.stderr.strip() else out.returncode})")
        return 0
    for line in out.stdout.splitlines():
        d = json.loads(line)
        imp = np.array(d["impacts"])
        et, ex = errors(imp, reference)
        print(f"  {'Drake RK5, accuracy ' + format(d['accuracy'], '.0e'):34s} {len(imp):7d} {et:15.1e} {ex:12.1e} "
              f"{d['wall_s'] * 1e3:10.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
