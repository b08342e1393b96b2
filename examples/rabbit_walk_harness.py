"""RABBIT walking under RabbitWalkingController, outside the hybrid engine: scipy's solve_ivp on the robot's
own stance dynamics, its impact map at each touchdown.

The hybrid engine cannot run RABBIT yet (docs/models.md); this harness is the check of its walking law and
of the scene's start (msg_configs/rabbit.yaml). Run it from the repository's root::

    python examples/rabbit_walk_harness.py                      # 10 s from the scene's start
    python examples/rabbit_walk_harness.py --hold 0.001         # each torque held over 1 ms, as the scene's node
    python examples/rabbit_walk_harness.py --rate 1.3           # a faster start on the constraints: it converges
    python examples/rabbit_walk_harness.py --perturb 0.3        # a start off the constraints
    python examples/rabbit_walk_harness.py --fixed-point        # the gait's rate, its multiplier, the start

The model (``bs.load_model("rabbit")``, a GeneratedModel): in stance on foot c, ``stance_dynamics(q, dq, u, c)``
gives (ddq, F), F the ground force on the foot (F[1] normal). A touchdown is the swing foot's height
crossing the flat ground downward in front of the stance foot (the engine's ``touchdown_rule: front``);
``impact_map(q, dq, landing foot)`` gives the rates after the rigid plastic impact and its impulse, and the
landing foot becomes the stance foot (physical coordinates: leg 1 stays leg 1, no swap). A crossing behind
the stance foot, a negative normal force, an impulse that pulls, an old stance foot that does not lift, or a
hip below 0.3 m ends the run with a line that says which.
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np
from scipy.integrate import solve_ivp

import biped_sim as bs

N = 7                   # RABBIT's coordinates
SAMPLES_PER_SECOND = 2000


def walk(ctrl, q0, dq0, stance_leg=1, t_final=10.0, hold=None, rtol=1e-10, atol=1e-10, max_steps=None):
    """The walk from (q0, dq0) on ``stance_leg``: (status, steps), one dict per step (its start ``t0``, and for
    a step that ended in a touchdown ``t``, ``step`` length, the state ``q``, ``dq_plus`` after the impact, the
    landing ``leg``, the impulse's ratio ``impulse_ratio`` = |P_t| / P_n), with the step's worst |F_t| / F_n
    ``ratio``, least normal force ``min_fn``, largest |u| ``max_u`` and the swing foot's least height
    ``clearance`` while |theta| < 0.8 step_angle (the step's middle, away from the liftoff and the touchdown),
    its highest ``peak``, and the least phase rate ``min_rate`` (theta' > 0: the phase is monotone), sampled
    at 2 kHz. ``hold``: each torque held over that control period (the law's torque at the period's
    start, held through a touchdown inside the period, as the engine holds it)."""
    model = ctrl.model
    t0, x = 0.0, np.concatenate([q0, dq0])
    steps = []
    carried = (None, None)      # (period index, torque): a torque held through a touchdown inside its period
    while t0 < t_final and (max_steps is None or len(steps) < max_steps):
        swing = 3 - stance_leg
        held = {"u": None}

        def torque(t, q, dq, stance=stance_leg, held=held):
            return ctrl(t, q, dq, stance) if hold is None else held["u"]

        def rhs(t, x, stance=stance_leg, torque=torque):
            ddq, _F = model.stance_dynamics(x[:N], x[N:], torque(t, x[:N], x[N:]), stance)
            return np.concatenate([x[N:], ddq])

        def touchdown(t, x, swing=swing):
            return model.contact_position(x[:N], swing)[1]
        touchdown.terminal, touchdown.direction = True, -1

        def fallen(t, x):
            return x[1] - 0.3
        fallen.terminal = True

        if hold is None:
            sol = solve_ivp(rhs, (t0, t_final), x, method="DOP853", rtol=rtol, atol=atol,
                            events=[touchdown, fallen], dense_output=True)
            pieces = [(sol, None)]
            hit, fell = sol.t_events[0], sol.t_events[1]
        else:                           # one solve per control period, the torque of the period's start
            pieces, t, y, hit, fell = [], t0, x, np.array([]), np.array([])
            while t < t_final - 1e-12:
                k = math.floor(t / hold + 1e-9)
                held["u"] = carried[1] if carried[0] == k else np.asarray(ctrl(t, y[:N], y[N:], stance_leg), float)
                carried = (k, held["u"])
                sol = solve_ivp(rhs, (t, min((k + 1) * hold, t_final)), y, method="DOP853", rtol=rtol, atol=atol,
                                events=[touchdown, fallen], dense_output=True)
                pieces.append((sol, held["u"]))
                t, y = sol.t[-1], sol.y[:, -1]
                if sol.t_events[0].size or sol.t_events[1].size:
                    hit, fell = sol.t_events[0], sol.t_events[1]
                    break
        step = dict(t0=t0, ratio=0.0, min_fn=math.inf, max_u=0.0, clearance=math.inf, min_rate=math.inf, peak=0.0)
        for sol, u_held in pieces:
            for t in np.linspace(sol.t[0], sol.t[-1], max(2, int((sol.t[-1] - sol.t[0]) * SAMPLES_PER_SECOND))):
                xs = sol.sol(t)
                q, dq = xs[:N], xs[N:]
                u = ctrl(t, q, dq, stance_leg) if u_held is None else u_held
                _ddq, F = model.stance_dynamics(q, dq, u, stance_leg)
                step["max_u"] = max(step["max_u"], float(np.max(np.abs(u))))
                step["min_fn"] = min(step["min_fn"], F[1])
                step["ratio"] = max(step["ratio"], abs(F[0]) / F[1] if F[1] > 0 else math.inf)
                height = model.contact_position(q, swing)[1]
                if abs(ctrl.phase(q, stance_leg)) < 0.8 * ctrl.step_angle:
                    step["clearance"] = min(step["clearance"], height)
                step["peak"] = max(step["peak"], height)
                step["min_rate"] = min(step["min_rate"], ctrl.phase_rate(dq, stance_leg))
        steps.append(step)
        if step["min_fn"] <= 0:
            return f"the stance foot lifts (F_n = {step['min_fn']:.3g} N) in the step from t = {t0:.3f} s", steps
        if fell.size:
            return f"fell: the hip below 0.3 m at t = {fell[0]:.3f} s", steps
        if not hit.size:
            return "completed", steps
        t0 = hit[0]
        xe = (pieces[-1][0]).y_events[0][0]
        q, dq = xe[:N], xe[N:]
        stance_x, swing_x = model.contact_position(q, stance_leg)[0], model.contact_position(q, swing)[0]
        if swing_x <= stance_x:
            return f"the swing foot crosses the ground behind the stance foot at t = {t0:.3f} s", steps
        dq_plus, impulse = model.impact_map(q, dq, swing)
        if impulse[1] <= 0 or model.contact_velocity(q, dq_plus, stance_leg)[1] < 0:
            return f"the impact at t = {t0:.3f} s pulls or keeps the old stance foot down", steps
        step.update(t=t0, step=swing_x - stance_x, q=q, dq_plus=dq_plus, leg=swing,
                    impulse_ratio=abs(impulse[0]) / impulse[1])
        x, stance_leg = np.concatenate([q, dq_plus]), swing
    return "completed", steps


def step_map(ctrl, rate, rtol=1e-11, atol=1e-11):
    """theta' just after the touchdown that ends one step from the gait's start at the rate ``rate`` (the
    gait's impact lands on the outputs, so the step's end is on the gait again: a map of one number)."""
    q, dq = ctrl.state_on_gait(rate)
    _status, steps = walk(ctrl, q, dq, t_final=5.0, rtol=rtol, atol=atol, max_steps=1)
    if "t" not in steps[0]:
        raise ValueError(f"no touchdown from the rate {rate}")
    return ctrl.phase_rate(steps[0]["dq_plus"], steps[0]["leg"])


def fixed_point(ctrl, rate=1.0, tol=1e-12):
    """The gait's rate theta'+ (the step map's fixed point, by secant steps) and the map's slope there."""
    a, fa = rate, step_map(ctrl, rate) - rate
    b = a + 0.05
    fb = step_map(ctrl, b) - b
    for _ in range(30):
        if abs(fb - fa) == 0.0 or abs(b - a) < tol:
            break
        a, fa, b = b, fb, b - fb * (b - a) / (fb - fa)
        fb = step_map(ctrl, b) - b
    d = 1e-5
    return b, (step_map(ctrl, b + d) - step_map(ctrl, b - d)) / (2 * d)


def perturbed(model, q, dq, size, stance_leg):
    """(q, dq) moved off the constraints by ``size`` (``--perturb``), the stance foot kept where it is and at rest
    (the base moved by the foot's shift, its rates from J_c dq = 0)."""
    q, dq = np.array(q, dtype=float), np.array(dq, dtype=float)
    foot = model.contact_position(q, stance_leg)
    q[6] += 0.05 * size
    q[5] += 0.1 * size
    dq[2:] += size * np.array([0.3, -0.3, 0.2, -0.2, 0.3])
    q[:2] -= model.contact_position(q, stance_leg) - foot
    J = model.contact_jacobian(q, stance_leg)
    dq[:2] = -np.linalg.solve(J[:, :2], J[:, 2:] @ dq[2:])
    return q, dq


def report(status, steps):
    ends = [s for s in steps if "t" in s]
    print(f"status: {status}; {len(ends)} touchdowns in {ends[-1]['t'] if ends else 0.0:.3f} s")
    if len(ends) >= 2:
        last, before = ends[-1], ends[-2]
        period = last["t"] - before["t"]
        print(f"the last step: {period:.4f} s, {last['step']:.4f} m, {last['step'] / period:.4f} m/s")
    for label, part in (("the whole run", steps), ("after the first step", steps[1:])):
        if part:
            print(f"{label}: worst |F_t|/F_n {max(s['ratio'] for s in part):.3f}, least F_n "
                  f"{min(s['min_fn'] for s in part):.1f} N, largest |u| {max(s['max_u'] for s in part):.1f} N m, "
                  f"worst impulse |P_t|/P_n {max((s.get('impulse_ratio', 0.0) for s in part)):.3f}, swing foot's "
                  f"least height mid-step {min(s['clearance'] for s in part) * 1000:.1f} mm, highest "
                  f"{max(s['peak'] for s in part) * 1000:.1f} mm, least theta' {min(s['min_rate'] for s in part):.3f} "
                  "rad/s")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--hold", type=float, default=None, help="control period (s): torques held over it")
    parser.add_argument("--rate", type=float, default=None,
                        help="start on the constraints at the start of a step at this theta' (rad/s) instead of the "
                             "scene's state")
    parser.add_argument("--perturb", type=float, default=0.0, metavar="S",
                        help="move the start off the constraints: torso_pitch + 0.05 S, knee_2 + 0.1 S (rad), "
                             "the joint rates + S (0.3, -0.3, 0.2, -0.2, 0.3) rad/s, the stance foot kept at the "
                             "origin and at rest")
    parser.add_argument("--fixed-point", action="store_true", help="find the gait's rate and print its start")
    args = parser.parse_args(argv)
    scene = bs.load_scene("rabbit")
    ctrl = scene.controller()
    if args.fixed_point:
        rate, slope = fixed_point(ctrl)
        q, dq = ctrl.state_on_gait(rate)
        print(f"the gait's rate theta'+ = {float(rate)!r} rad/s, the step map's slope there {slope:.4f}")
        print(f"initial_q: {[float(v) for v in q]}\ninitial_dq: {[float(v) for v in dq]}")
        return 0
    if args.rate is None:
        q0, dq0 = np.array(scene.params["initial_q"]), np.array(scene.params["initial_dq"])
    else:
        q0, dq0 = ctrl.state_on_gait(args.rate)
    if args.perturb:
        q0, dq0 = perturbed(ctrl.model, q0, dq0, args.perturb, scene.params["initial_stance_leg"])
    started = time.perf_counter()
    status, steps = walk(ctrl, q0, dq0, scene.params["initial_stance_leg"], args.duration, args.hold)
    report(status, steps)
    print(f"({time.perf_counter() - started:.1f} s of wall time)")
    return 0 if status == "completed" else 1


if __name__ == "__main__":
    raise SystemExit(main())
