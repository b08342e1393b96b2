"""A user's torque law at compiled speed: ``python -m benchmarks.bench_user_law`` (also run by ``make bench``).

The walk scene, 10 s, torques held 1 ms, in one process (median of alternating repeats):

* the built-in law (``WalkingController``: control/_laws.c through the hook);
* the same law written by a user in Python (:func:`walking_law` below, the form of
  ``biped_sim.control.compiled_laws``) and compiled by numba through the hook;
* the HZD law of examples/hzd_bezier.py, compiled the same way;
* each user law as plain Python (the controller called back), and in MuJoCo (``mj_step`` at 1 ms,
  benchmarks/bench_mujoco.py's MJCF and loop, the law's plain Python call each tick: it walks the 10 s).

Figures: the compiled user law's real-time factor over the built-in law's (issue 30's goal >= 0.7) and
over MuJoCo's with the same law called from Python (goal >= 10). Skipped without numba.
"""
from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

from biped_sim.config.scenes import load_scene
from biped_sim.control import compiled_laws
from biped_sim.control.compiled_laws import STANCE_CONSTANTS, stance_joint_affine, torque_law

TORSO_PITCH, A2, DDB, CLEARANCE, LAG, KP, KD, LIMIT, K = range(9)


def walking_law(t, q, dq, stance_leg, p, u):
    """control/walking.py's WalkingController as a user writes it: the parameters of its
    ``_law_parameters()`` and then the model's STANCE_CONSTANTS."""
    if stance_leg == 0:
        u[0] = -p[KD] * dq[2]
        u[1] = -p[KD] * dq[3]
        return 0
    s, w = (2, 3) if stance_leg == 1 else (3, 2)
    phi_s = q[s] + q[4] - math.pi
    dphi_s = dq[s] + dq[4]
    b = 1.0 - phi_s * phi_s / p[A2]
    db = -2.0 * phi_s / p[A2]
    c, lag = p[CLEARANCE], p[LAG]
    f = -phi_s * (1.0 + c * b) + lag * b
    df = -(1.0 + c * b) - phi_s * c * db + lag * db
    ddf = -2.0 * c * db - phi_s * c * p[DDB] + lag * p[DDB]
    y0, y1 = q[4] - p[TORSO_PITCH], q[w] + q[4] - math.pi - f
    h_s, h_w, h_3 = -df, 1.0, 1.0 - df
    h0, h1 = (h_s, h_w) if stance_leg == 1 else (h_w, h_s)
    dy0, dy1 = dq[4], h0 * dq[2] + h1 * dq[3] + h_3 * dq[4]
    a0, a1, a2, B00, B01, B10, B11, B20, B21 = stance_joint_affine(q, dq, stance_leg, p[K:])
    kp, kd, lim = p[KP], p[KD], p[LIMIT]
    r0 = -kp * y0 - kd * dy0 - a2 - 0.0
    r1 = -kp * y1 - kd * dy1 - (h0 * a0 + h1 * a1 + h_3 * a2) - (-ddf * dphi_s * dphi_s)
    m10 = h0 * B00 + h1 * B10 + h_3 * B20
    m11 = h0 * B01 + h1 * B11 + h_3 * B21
    det = B20 * m11 - B21 * m10
    u[0] = min(lim, max(-lim, (m11 * r0 - B21 * r1) / det))
    u[1] = min(lim, max(-lim, (B20 * r1 - m10 * r0) / det))
    return 0


class CalledBack:
    """A law offered as a Python controller only (no compiled_law): what a law costs as plain Python."""
    accepts_lists = True

    def __init__(self, law):
        self.law = law

    def __call__(self, t, q, dq, stance_leg):
        return self.law(t, q, dq, stance_leg)


def bench(repeats=5, t_final=10.0, plain_t_final=2.0):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from examples.hzd_bezier import hzd_controller

    scene = load_scene("walk")
    kw = scene.simulate_kwargs(hold=True)
    model, builtin = kw["model"], kw["controller"]
    user_walking = torque_law(walking_law, builtin._law_parameters() + model.k[STANCE_CONSTANTS], "walking_law")
    hzd = hzd_controller(model)
    compile_s = {}
    for name, law in (("walking_law", user_walking), ("hzd_bezier", hzd)):
        t0 = time.perf_counter()
        law.compiled_law(model)
        compile_s[name] = time.perf_counter() - t0
    runs = {"built-in WalkingController (C, through the hook)": (builtin, t_final),
            "walking_law in Python, compiled by numba": (user_walking, t_final),
            "hzd_bezier in Python, compiled by numba": (hzd, t_final),
            "walking_law as plain Python (called back)": (CalledBack(user_walking), plain_t_final),
            "hzd_bezier as plain Python (called back)": (CalledBack(hzd), plain_t_final)}
    try:
        from benchmarks import bench_mujoco
        mujoco = bench_mujoco.mujoco
    except ImportError:
        mujoco = None
    if mujoco is not None:
        mj = bench_mujoco.mujoco_model(model, timestep=1e-3)
        q0, dq0 = kw["q0"], kw["dq0"]
        for name, law in (("walking_law", user_walking), ("hzd_bezier", hzd)):
            runs[f"MuJoCo mj_step 1 ms, {name} as plain Python"] = (
                lambda law=law: bench_mujoco.walk_mujoco(mj, law, q0, dq0, t_final), t_final)
    walls, outcome, bits = {name: [] for name in runs}, {}, {}
    for _ in range(repeats):
        for name, (ctrl, T) in runs.items():
            t0 = time.perf_counter()
            if name.startswith("MuJoCo"):
                n, _low, q_end = ctrl()
                outcome[name] = f"{n} touchdowns, hip x {q_end[0]:.3f} m"
            else:
                r = scene.simulate(controller=ctrl, t_final=T)
                bits[name] = r.q.tobytes() + r.u.tobytes()
                outcome[name] = f"{r.status}, {len(r.impacts)} impacts, hip x {r.q[-1, 0]:.3f} m"
            walls[name].append((time.perf_counter() - t0) / T)
    rtf = {name: 1.0 / statistics.median(w) for name, w in walls.items()}
    print(f"\n== a user's law, walk scene, torques held 1 ms (median of {repeats}, alternating; compiled runs "
          f"and MuJoCo {t_final:g} s, plain Python {plain_t_final:g} s) ==")
    print("  first compile in this process: " + ", ".join(f"{n} {s:.2f} s" for n, s in compile_s.items()))
    for name in runs:
        print(f"  {name:52s} RTF {rtf[name]:7.1f}  ({outcome[name]})")
    same = bits["walking_law in Python, compiled by numba"] == bits["built-in WalkingController (C, through the hook)"]
    print(f"  walking_law compiled gives the built-in law's run bit for bit (q and u): {same}")
    base = rtf["built-in WalkingController (C, through the hook)"]
    for name in ("walking_law", "hzd_bezier"):
        ratio = rtf[f"{name} in Python, compiled by numba"] / base
        print(f"  {name} compiled RTF / built-in law's: {ratio:.2f} (issue 30 goal >= 0.7)")
        mj_name = f"MuJoCo mj_step 1 ms, {name} as plain Python"
        if mj_name in rtf:
            print(f"  {name} compiled RTF / MuJoCo's with it called from Python: "
                  f"{rtf[f'{name} in Python, compiled by numba'] / rtf[mj_name]:.1f} (goal >= 10)")
    return rtf


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_user_law", description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats of each run (alternating)")
    args = parser.parse_args(argv)
    ok, why = compiled_laws.numba_available()
    if not ok:
        print(f"{why}: skipped")
        return 0
    bench(repeats=args.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
