"""Drake side by side on the compass gait (issue 31): ``python -m benchmarks.bench_drake`` (also in ``make bench``).

Drake's ``pydrake.examples.CompassGait`` (``drake`` 1.58 from PyPI, for Python 3.12 only: a venv of its own,
``make venv-drake``, benchmark-only) and this project's ``compass_gait`` scene (today's three-link engine, the
torso carrying the hip mass: docs/models.md) walk 10 s passively down the 0.0525 rad slope from Drake's example
state. benchmarks/drake_compass_gait.py runs Drake in its venv and prints its impacts; this compares, for
each impact, the time and the state just before it (Drake's angles: stance = q[stance] + q3 - pi, the same
for swing), and the wall time of each at a ladder of accuracies, the error of every run measured against this
engine's run at rtol = atol = 1e-13 (which Drake's best run confirms; its figure is printed). Without
.venv-drake the comparison is skipped with one line.

Then the passive limit cycle's Floquet multipliers (issue 32): Drake's (``drake_compass_gait.py --limit-cycle``:
Newton's method on central differences of Drake's own step-to-step map, at the accuracies
``LIMIT_CYCLE_ACCURACIES``) beside this project's (``compass_gait()``: the exact Jacobian, the legs' three
multipliers; the torso rotor's two at 1 are not the compass gait's) and issue 32's reference digits.
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
LIMIT_CYCLE_ACCURACIES = (1e-10, 1e-12, 1e-13)
#: issue 32's reference: the compass gait's multipliers (Drake's CompassGait defaults), to 7 digits
REFERENCE_MULTIPLIERS = np.array([-0.2022161 + 0.5434150j, -0.2022161 - 0.5434150j, 0.1313867])


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
    limit_cycle()
    return 0


def legs(multipliers):
    """The compass gait's three multipliers among ours (the torso rotor's two, at 1, left out), in a fixed order."""
    m = np.asarray(multipliers, complex)
    return np.sort_complex(m[np.abs(m - 1.0) > 1e-3])


def _fmt(m):
    return ", ".join(f"{z.real:.9f}" if abs(z.imag) < 1e-12 else f"{z.real:.9f} {z.imag:+.9f}j" for z in m)


def limit_cycle():
    """Drake's passive limit cycle and its multipliers beside ours and the issue's reference."""
    from biped_sim.analysis.gait import compass_gait
    t0 = time.perf_counter()
    g = compass_gait()
    wall = time.perf_counter() - t0
    mine = legs(g.multipliers)
    ref = np.sort_complex(REFERENCE_MULTIPLIERS)
    print("\ncompass gait's passive limit cycle: Floquet multipliers (the legs' three)")
    print(f"  {'run':34s} {'period (s)':>14s}  {'multipliers':64s} {'vs ours':>8s} {'vs ref.':>8s} {'wall (s)':>8s}")
    print(f"  {'biped_sim compass_gait(), exact':34s} {g.period:14.10f}  {_fmt(mine):64s} {'':>8s} "
          f"{np.max(np.abs(mine - ref)):8.1e} {wall:8.2f}")
    out = subprocess.run([str(DRAKE_PYTHON), str(ROOT / "benchmarks" / "drake_compass_gait.py"), "--limit-cycle",
                          "--accuracy", *map(str, LIMIT_CYCLE_ACCURACIES)], capture_output=True, text=True,
                         timeout=600)
    if out.returncode != 0:
        print(f"  Drake: failed ({out.stderr.strip().splitlines()[-1] if out.stderr.strip() else out.returncode})")
        return
    for line in out.stdout.splitlines():
        d = json.loads(line)
        drake = np.sort_complex(np.array([complex(re, im) for re, im in d["multipliers"]]))
        print(f"  {'Drake RK5, accuracy ' + format(d['accuracy'], '.0e'):34s} {d['period']:14.10f}  "
              f"{_fmt(drake):64s} {np.max(np.abs(drake - mine)):8.1e} {np.max(np.abs(drake - ref)):8.1e} "
              f"{d['wall_s']:8.2f}")
    print(f"  {'issue 32 reference':34s} {'':14s}  {_fmt(ref):64s} {np.max(np.abs(ref - mine)):8.1e}")


if __name__ == "__main__":
    raise SystemExit(main())
