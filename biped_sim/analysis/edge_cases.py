"""The hybrid edges of the stability suite (``biped-sim stability``, group "edge"): each a state that
once made a run end "completed" with a wrong answer, and what the engine must do there now.

The builders (``grazing_flight``, ``spinning_stance``, ``bouncing_landing``, ``swing_foot_just_above``,
``coincident_crossing``) are shared with the tests (test/unit/test_hybrid_edges.py).
"""
from __future__ import annotations

import math
import time

import numpy as np

from biped_sim.analysis.verify import result_violations
from biped_sim.config.scenes import load_scene
from biped_sim.engine.dynamics import stance_dynamics
from biped_sim.engine.model import BipedModel
from biped_sim.engine.simulate import simulate as _simulate, stance_state


def grazing_flight():
    """In flight, leg 2 swings through the vertical at 10 rad/s while the hip passes its highest point:
    foot 2 dips 20 micrometres below the ground for about 1.5 ms, at about 5 cm/s, and comes back up.
    (The hip height was tuned by bisection against the free flight at 1e-12 for that depth.)"""
    q = np.array([0.0, 1.0032407457377306, math.pi + 1.0, math.pi - 0.3, 0.0])
    dq = np.array([0.3, 9.81 * 0.03, 0.0, 10.0, 0.0])
    return q, dq


def spinning_stance(model):
    """The whole robot rotating about the stance foot at 4 rad/s: the hip's centripetal acceleration
    (16 m/s^2) exceeds g, so the ground would have to pull (Fy = -83 N at t = 0)."""
    return stance_state(model, [math.pi - 0.1, math.pi + 0.1, 0.0], [0.0, 0.0, 4.0])


def bouncing_landing():
    """A fast horizontal landing on a straight leg, from flight: after the impact the body would swing
    over the foot at 5 rad/s, more than the ground can hold down."""
    return np.array([0.0, math.cos(0.05) + 0.01, math.pi + 0.05, math.pi - 0.3, 0.0]), np.array([5.0, -0.5, 0, 0, 0])


def swing_foot_just_above(model, height, swing_rate=0.0):
    """Stance leg 1 behind the hip, swing foot 2 in front at ``height`` above the ground (a positive
    ``swing_rate`` of its hip moves it down)."""
    a = 0.2
    delta = math.acos(math.cos(a) - height)
    return stance_state(model, [math.pi + a, math.pi - delta, 0.0], [0.0, swing_rate, 0.0])


def coincident_crossing(model):
    """The swing leg rotates onto the stance leg: its foot reaches the ground exactly at the stance
    foot (the legs coincide), then moves under the ground in front of it."""
    return stance_state(model, [math.pi + 0.2, math.pi + 0.25, 0.0], [0.0, -1.0, 0.0])


def walk_that_scuffs(model, lag=-0.15, clearance=0.5, control_period=1e-3, t_final=10.0, **options):
    """The reference law with its mid-stance graze moved behind the stance foot: with lag -0.15 the swing
    foot scuffs 3.8 mm deep, with lag -0.01 and clearance 0.3 into the front of the stance foot. Round 2's
    rule (scuff_rule "behind", scuff_depth 3 mm) stopped both within the first step."""
    from biped_sim.control.walking import WalkingController
    q0, dq0 = WalkingController(model).initial_state()
    return _simulate(model, q0, dq0, t_final, controller=WalkingController(model, lag=lag, clearance=clearance),
                     control_period=control_period, **options)


def pd_walk_without_clearance(model, control_period=1e-3, t_final=10.0, **options):
    """The PD walking law (``PDWalkingController``) with no swing-foot clearance (``clearance=0``) from the
    walk scene's state: its swing foot scuffs 2.2 mm deep and, late in some steps, under the ground into
    the front of the stance foot, which round 2's rule stopped at 3.948 s."""
    from biped_sim.control.walking import PDWalkingController
    walk = load_scene("walk").engine_arguments()
    return _simulate(model, np.asarray(walk["q0"]), np.asarray(walk["dq0"]), t_final,
                     controller=PDWalkingController(model, clearance=0.0), control_period=control_period, **options)


def rocking_v(model, touchdown_rule="front", **options):
    """A V whose hips a stiff PD holds, rocking from foot to foot until its impacts accumulate (Zeno)."""
    from biped_sim.analysis.stability import HipPD
    q0, dq0 = stance_state(model, [math.pi - 0.3, math.pi + 0.3, 0.0], [0.0, 0.0, 0.3])
    return _simulate(model, q0, dq0, 5.0, controller=HipPD(1e4, 200.0, q0[2:4]), touchdown_rule=touchdown_rule,
                     **options)


def standing_v_pushed_up(model, push, max_step=math.inf):
    """The robot standing at rest on both feet, pushed (N s) on the hip at t = 0: a small upward push lifts
    both feet, which land again within the first integration step."""
    q0, dq0 = stance_state(model, [math.pi - 0.2, math.pi + 0.2, 0.0], [0.0, 0.0, 0.0])
    return _simulate(model, q0, dq0, 0.05, pushes=[(0.0, list(push))], max_step=max_step,
                     phases=frozenset({"stance", "impact", "flight"}))


def landing_outside_the_cone():
    """(q, dq, mu) of a landing from flight whose impulse on foot 1 is outside the friction cone
    (|Lambda_t|/Lambda_n 0.575 > mu 0.338), the second touchdown at 63 ms."""
    return (np.array([-0.198669330795062, 1.030066577841242, 2.791592653589793, 3.191592653589794, 0.15]),
            np.array([1.489, -1.672, -1.744, 2.43, -0.966]), 0.338)


def on_both_loops(run):
    """run() on the compiled loop and on the Python loop: (compiled, python)."""
    from biped_sim.engine import compiled_loop
    out = []
    for enabled in (True, False):
        compiled_loop.enabled = enabled
        try:
            out.append(run())
        finally:
            compiled_loop.enabled = True
    return out


def edge_verdicts(quick, verdict):
    """The rows of group "edge": ``verdict(name, ok, figures, seconds)`` builds each. A row passes only
    if every sample of every run in it keeps the invariants (``verify.result_violations``)."""
    m = BipedModel()
    rows, runs = [], []

    def simulate(*a, **k):
        runs.append(_simulate(*a, **k))
        return runs[-1]

    def row(name, fn):
        t0 = time.perf_counter()
        runs.clear()
        ok, figures = fn()
        bad = [v for r in runs for v in result_violations(m, r)]
        if bad:
            ok, figures = False, f"{figures}; INVARIANT: {bad[0]}"
        rows.append(verdict(name, ok, figures, time.perf_counter() - t0))

    def scuffs():
        r = load_scene("walk").simulate(hold=False, t_final=5.0 if quick else 10.0)
        n = sum(e.kind == "scuff" for e in r.events)
        fall = load_scene("passive").simulate(t_final=2.0)
        runs.extend([r, fall])
        # (a scuff still under way when the run ends is counted, not yet reported)
        ok = (r.status == "completed" and 0 < n <= r.stats["scuffs_ignored"] <= n + 1
              and r.stats["deepest_scuff"] < 3e-3
              and fall.status == "stopped" and any(e.kind == "touchdown" and e.leg == 1 for e in fall.events))
        land = next((e.time for e in fall.events if e.kind == "touchdown" and e.leg == 1), math.nan)
        return ok, (f"walk: {n} scuffs, deepest {r.stats['deepest_scuff'] * 1e3:.2f} mm; falling back onto the rear "
                    f"foot: lands on it at {land:.3f} s, then {fall.events[-1].kind}, {fall.status} at "
                    f"{fall.t[-1]:.3f} s")

    def liftoff_at_start():
        q, dq = spinning_stance(m)
        r = simulate(m, q, dq, 0.2)
        qb, dqb = bouncing_landing()
        b = simulate(m, qb, dqb, 0.3, stance_leg=0)
        ok = (r.events and r.events[0].kind == "liftoff" and r.events[0].time == 0.0 and len(b.events) > 1
              and b.events[0].kind == "touchdown" and b.events[1].kind == "liftoff"
              and b.events[1].time == b.events[0].time)
        return ok, (f"Fy(0) = {stance_dynamics(m, q, dq)[1][1]:.1f} N: {r.events[0].kind} at {r.events[0].time:g} s; "
                    f"landing: {b.events[0].kind} then {b.events[1].kind} at the same instant")

    def grazing_dip():
        q, dq = grazing_flight()
        found = []
        for method in ("dop853", "dopri5"):
            for tol in ((1e-6, 1e-12) if quick else (1e-6, 1e-9, 1e-12)):
                r = simulate(m, q, dq, 0.06, stance_leg=0, method=method, rtol=tol, atol=tol)
                found.append(bool(r.events) and r.events[0].kind == "touchdown" and r.events[0].leg == 2)
        return all(found), f"20 um dip in flight found as a touchdown in {sum(found)} of {len(found)} runs"

    def coincident():
        q, dq = coincident_crossing(m)
        outcomes = {(r.status, tuple(e.kind for e in r.events))
                    for r in (simulate(m, q, dq, 0.3, rtol=t, atol=t) for t in (1e-6, 1e-8, 1e-10, 1e-12))}
        return len(outcomes) == 1, f"outcomes over rtol 1e-6 .. 1e-12: {sorted(outcomes)}"

    def just_above():
        q, dq = swing_foot_just_above(m, 1e-9)
        r = simulate(m, q, dq, 0.05)
        ok = bool(r.events) and r.events[0].kind == "touchdown" and r.events[0].time < 0.01
        return ok, f"swing foot 1e-9 m above the ground: {r.events[0].kind if r.events else 'no event'}"

    def scuff_is_a_swing():     # issue 28: a scuff is told from a fall by the foot's motion, not its depth
        t_final = 3.0 if quick else 10.0
        deep = walk_that_scuffs(m, lag=-0.15, t_final=t_final)
        front = walk_that_scuffs(m, lag=-0.01, clearance=0.3, t_final=t_final)
        pd = pd_walk_without_clearance(m, t_final=t_final)
        old = [walk_that_scuffs(m, lag=lag, clearance=c, t_final=1.0, scuff_rule="behind", scuff_depth=3e-3)
               for lag, c in ((-0.15, 0.5), (-0.01, 0.3))]
        old.append(pd_walk_without_clearance(m, t_final=5.0, scuff_rule="behind", scuff_depth=3e-3))
        runs.extend([deep, front, pd, *old])
        ok = deep.status == front.status == pd.status == "completed" and all(r.status == "stopped" for r in old)
        return ok, (f"scuffing 3.8 mm deep: {deep.status} {deep.t[-1]:g} s, {len(deep.impacts)} impacts, deepest "
                    f"{deep.stats['deepest_scuff'] * 1e3:.2f} mm; into the front: {front.status} {front.t[-1]:g} s; "
                    f"the PD law without clearance: {pd.status} {pd.t[-1]:g} s, {len(pd.impacts)} impacts; round 2's "
                    f"rule stopped them at {old[0].t[-1]:.3f}, {old[1].t[-1]:.3f} and {old[2].t[-1]:.3f} s")

    def zeno_rocking_v():       # issue 28, D7l: the Zeno limit under the default rule
        r = rocking_v(m)
        runs.append(r)
        ok = r.status == "stopped" and r.events[-1].kind == "zeno" and "Zeno" in r.message
        return ok, f"{len(r.impacts)} impacts, end: {r.events[-1].kind} at {r.t[-1]:.6f} s ({r.status})"

    def relanding_in_a_step():   # issue 28, R3: a landing needs the foot moving down
        pushed, fine = (standing_v_pushed_up(m, (0.0, 0.125), max_step=s) for s in (math.inf, 1e-4))
        runs.extend([pushed, fine])
        land = [next(e for e in r.events if e.kind in ("touchdown", "double_touchdown")) for r in (pushed, fine)]
        ok = land[0].time > 0.0 and abs(land[0].time - land[1].time) < 1e-9
        return ok, (f"pushed up 0.125 N s: lands at {land[0].time * 1e3:.4f} ms ({land[0].kind}); with steps of "
                    f"0.1 ms at {land[1].time * 1e3:.4f} ms")

    def torque_change_is_an_event():    # R1: the guards under the new torque at the instant it changes
        from biped_sim.control.walking import WalkingController
        from biped_sim.engine.hybrid import HybridSimulator
        ctrl = WalkingController(m)

        def run():
            sim = HybridSimulator(m, *ctrl.initial_state())
            sim.advance_periods(1e-3, ctrl, 0.1)
            t_change = sim.t
            events = sim.advance_period(1e-3, u=[-300.0, -300.0])   # the ground would pull with -489 N
            runs.append(sim.result())
            return t_change, [(e.kind, e.time) for e in events]
        (t_c, ev_c), (t_p, ev_p) = on_both_loops(run)
        ok = ev_c == ev_p and bool(ev_c) and ev_c[0] == ("liftoff", t_c)
        return ok, (f"walk at t={t_c:.3f} s, then u = (-300, -300) N m: {ev_c[0][0] if ev_c else 'no event'} at "
                    f"{ev_c[0][1] if ev_c else math.nan:.6f} s on the compiled loop, {ev_p[0][0] if ev_p else 'none'} "
                    f"at {ev_p[0][1] if ev_p else math.nan:.6f} s on the Python loop")

    def compiled_law_is_own():       # R2: a law runs compiled only where its torques are the controller's
        from biped_sim.control.walking import WalkingController
        other = WalkingController(BipedModel(m_leg=4.0))    # a controller built on another model
        q0, dq0 = WalkingController(m).initial_state()
        r = simulate(m, q0, dq0, 0.3, controller=other)
        off = max(float(np.max(np.abs(np.asarray(other(t, q, dq, int(leg))) - u)))
                  for t, q, dq, leg, u in zip(r.t, r.q, r.dq, r.stance_leg, r.u))
        return off < 1e-9, (f"a law built on m_leg = 4 kg driving the 5 kg robot: its torques at every sample within "
                            f"{off:.1g} N m of its own ({r.stats['steps']} steps)")

    def impact_outside_the_cone():   # R4: the cone holds at impacts as in stance and at pushes
        q, dq, mu = landing_outside_the_cone()
        stopped = simulate(m, q, dq, 0.08, stance_leg=0, mu=mu)
        kept = simulate(m, q, dq, 0.08, stance_leg=0, mu=mu, stop_on_slip=False)
        ok = stopped.status == "stopped" and "outside the friction cone" in stopped.message \
            and kept.status == "completed"
        return ok, (f"landing at |Lambda_t|/Lambda_n 0.575, mu {mu}: {stopped.status} at {stopped.t[-1]:.6f} s; "
                    f"stop_on_slip=False: {kept.status}")

    def bounces_on_both_loops():     # R5: no cache outlives its state (a stale one hid a crossing)
        rng = np.random.default_rng(7)
        qb, dqb = bouncing_landing()
        same = 0
        n = 4 if quick else 12
        for _ in range(n):
            dq1 = dqb.copy()
            dq1[0], dq1[1], dq1[3] = rng.uniform(2.0, 6.0), rng.uniform(-1.5, -0.1), rng.uniform(-3.0, 3.0)
            a, b = on_both_loops(lambda dq1=dq1: _simulate(
                m, qb, dq1, 0.2, stance_leg=0, control_period=1e-3, controller=lambda t, q, dq, leg: [0.0, 0.0],
                phases=frozenset({"stance", "impact", "flight"})))
            runs.extend([a, b])
            same += (a.status, [(e.kind, e.time) for e in a.events]) == (b.status, [(e.kind, e.time) for e in b.events])
        return same == n, f"landings from flight that lift off at once, held 1 ms: {same} of {n} the same on both loops"

    def late_start_periods():        # R6: the first period from a late t0 is computed, not counted
        from biped_sim.control.walking import WalkingController
        from biped_sim.engine.hybrid import HybridSimulator
        t0w = time.perf_counter()
        sim = HybridSimulator(m, *WalkingController(m).initial_state(), t0=1e5 + 2.5e-4)
        sim.advance_period(1e-3, u=[0.0, 0.0])
        wall = time.perf_counter() - t0w
        k = sim.control_periods
        ok = sim.status == "running" and sim.t == k * 1e-3 and (k - 1) * 1e-3 <= 1e5 + 2.5e-4 < k * 1e-3
        return ok, f"from t0 = 100000.00025 s: the period ends at {sim.t:.6f} s (period {k}), in {wall * 1e3:.1f} ms"

    def inputs_not_cast():           # R7: anything but finite real numbers is refused by name
        q0, dq0 = stance_state(m, [math.pi - 0.1, math.pi + 0.1, 0.0], [0.0, 0.0, 0.0])
        named = 0
        for argument, fn in (("q0", lambda: _simulate(m, "12345", dq0, 0.01)),     # a string, bools, a complex
                             ("dq0", lambda: _simulate(m, q0, [True, False, False, False, False], 0.01)),
                             ("pushes[0]", lambda: _simulate(m, q0, dq0, 0.01, pushes=[(0.0, [1j, 0.0])]))):
            try:
                fn()
            except ValueError as exc:
                named += str(exc).startswith(argument)
        r = simulate(m, q0, dq0, 0.01, controller=lambda t, q, dq, leg: "12")
        failed = r.status == "failed" and "'12'" in r.message
        return named == 3 and failed, (f"{named} of 3 bad arguments refused naming the argument; a controller "
                                       f"returning '12': {r.status}")

    def projection_reaches_scipy():  # R8: the projection reaches scipy's steppers
        from biped_sim.control.walking import WalkingController
        ctrl = WalkingController(m)
        q0, dq0 = ctrl.initial_state()
        kw = dict(controller=ctrl, method="scipy_rk45", rtol=1e-6, atol=1e-6, max_step=1e-2)
        on, off = (simulate(m, q0, dq0, 1.0, project_constraints=p, **kw) for p in (True, False))
        d_on, d_off = (r.stats["max_constraint_drift_velocity"] for r in (on, off))
        return d_on < 0.5 * d_off, f"scipy_rk45, walk 1 s: velocity drift {d_on:.2g} projected, {d_off:.2g} not"

    for name, fn in (("scuffs_bounded", scuffs), ("liftoff_at_start", liftoff_at_start),
                     ("grazing_dip_20um", grazing_dip), ("crossing_at_stance_x", coincident),
                     ("foot_just_above_ground", just_above), ("scuff_is_a_swing", scuff_is_a_swing),
                     ("zeno_rocking_v", zeno_rocking_v), ("relanding_in_a_step", relanding_in_a_step),
                     ("torque_change_is_an_event", torque_change_is_an_event),
                     ("compiled_law_is_own", compiled_law_is_own), ("impact_outside_the_cone", impact_outside_the_cone),
                     ("bounces_on_both_loops", bounces_on_both_loops), ("late_start_periods", late_start_periods),
                     ("inputs_not_cast", inputs_not_cast), ("projection_reaches_scipy", projection_reaches_scipy)):
        row(name, fn)
    return rows


