"""The compiled hybrid loop (biped_sim/engine/_core.c, driven by compiled_loop.py) gives the runs of the
Python loop of hybrid.py: the same status, events, event times within 1e-12 s and states within
1e-10, on every scene and on the edges (slips, pushes, scuffs, thinning, no projection, the other
touchdown rule), and its compiled walking laws give the Python laws' torques bit for bit.
``BIPED_SIM_PURE_PYTHON=1`` runs everything in Python."""
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import event, example, given, settings, strategies as st
from test_generic_engine import _rabbit_on_foot_1

import biped_sim as bs
from biped_sim.analysis.edge_cases import on_both_loops, pd_walk_without_clearance, rocking_v, walk_that_scuffs
from biped_sim.analysis.verify import violations
from biped_sim.control.walking import PDWalkingController, WalkingController
from biped_sim.engine import compiled_loop, guards as G, hybrid, loop_state, torque_hook
from biped_sim.engine.model import BipedModel

ROOT = Path(__file__).resolve().parents[2]
MODEL = BipedModel()

pytestmark = pytest.mark.skipif(not compiled_loop.AVAILABLE, reason=f"no compiled loop: {compiled_loop.WHY_NOT}")


#: run() on the compiled loop and on the Python loop: (compiled, python)
both_loops = on_both_loops


def assert_same_run(a, b, what=""):
    assert (a.status, a.message) == (b.status, b.message), what
    assert [(e.kind, e.leg) for e in a.events] == [(e.kind, e.leg) for e in b.events], what
    np.testing.assert_allclose([e.time for e in a.events], [e.time for e in b.events], rtol=0, atol=1e-12,
                               err_msg=what)
    assert len(a.t) == len(b.t), what
    np.testing.assert_allclose(a.t, b.t, rtol=0, atol=1e-12, err_msg=what)
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-10, err_msg=what)
    np.testing.assert_allclose(a.dq, b.dq, rtol=0, atol=1e-10, err_msg=what)
    np.testing.assert_allclose(a.u, b.u, rtol=1e-9, atol=1e-9, err_msg=what)
    np.testing.assert_allclose(a.grf, b.grf, rtol=1e-9, atol=1e-9, err_msg=what)
    np.testing.assert_array_equal(a.stance_leg, b.stance_leg, err_msg=what)
    for key in ("impacts", "events", "scuffs_ignored", "steps", "rejected_steps", "rhs_evaluations"):
        assert a.stats[key] == b.stats[key], (what, key)


SCENES = ["walk", "slope", "passive", "drop", "stance_fixed"]


@pytest.mark.parametrize("hold", [True, False])
@pytest.mark.parametrize("method", ["dopri5", "dop853"])
@pytest.mark.parametrize("name", SCENES)
def test_every_scene_runs_the_same_on_both_loops(name, method, hold):
    scene = bs.load_scene(name)
    a, b = both_loops(lambda: scene.simulate(hold=hold, t_final=min(scene.duration, 2.5), method=method))
    assert_same_run(a, b, f"{name} {method} hold={hold}")


def _walk(controller_cls=PDWalkingController, t_final=2.0, **kw):
    ctrl = controller_cls(MODEL)
    q0, dq0 = ctrl.initial_state()
    return lambda: bs.simulate(MODEL, q0, dq0, t_final, controller=ctrl, **kw)


EDGES = {
    "walking law, continuous": dict(controller_cls=WalkingController),
    "walking law held 1 ms, dopri5": dict(controller_cls=WalkingController, control_period=1e-3, method="dopri5"),
    "held 5 ms dop853": dict(control_period=5e-3),
    "friction that holds": dict(mu=0.8),
    "friction that slips": dict(mu=0.05),
    "slip, foot kept pinned": dict(mu=0.05, stop_on_slip=False),
    "pushes": dict(control_period=1e-3, method="dopri5", pushes=[(0.3, [2.0, 0.0]), (0.9, [-1.5, 1.0])]),
    "a push that lifts the foot": dict(control_period=1e-3, pushes=[(0.3, [0.0, 60.0])],
                                       phases={"stance", "impact", "flight"}),
    "every 7th sample": dict(keep_samples=7),
    "events only": dict(keep_samples="events"),
    "the last sample only": dict(keep_samples=False),
    "no projection": dict(project_constraints=False),
    "touchdown rule any": dict(touchdown_rule="any"),
    "no invariant checks": dict(check_invariants=False),
    "loose tolerance": dict(rtol=1e-5, atol=1e-5),
    "max_step": dict(max_step=2e-3),
    "shallow scuffs": dict(scuff_depth=1e-5),
    "scuffs of round 2's rule": dict(scuff_rule="behind", scuff_depth=3e-3),
    "max_speed reached": dict(max_speed=1.0),
    "an event limit": dict(max_events=3),
}


@pytest.mark.parametrize("case", list(EDGES))
def test_the_edges_run_the_same_on_both_loops(case):
    a, b = both_loops(_walk(**EDGES[case]))
    assert_same_run(a, b, case)


SCUFF_RULE_RUNS = {     # (edge_cases' builders)
    "a deep scuff, continuous": lambda: walk_that_scuffs(MODEL, lag=-0.15, control_period=None, t_final=3.0),
    "a deep scuff, held 2 ms": lambda: walk_that_scuffs(MODEL, lag=-0.15, control_period=2e-3, t_final=3.0),
    "a scuff into the front": lambda: walk_that_scuffs(MODEL, lag=-0.01, clearance=0.3, t_final=3.0),
    "the PD law without clearance": lambda: pd_walk_without_clearance(MODEL, t_final=5.0),
    "a fall back onto the rear foot": lambda: bs.load_scene("passive").simulate(t_final=2.0),
    "the rocking V's Zeno limit": lambda: rocking_v(MODEL),
}


@pytest.mark.parametrize("case", list(SCUFF_RULE_RUNS))
def test_the_scuff_rule_runs_the_same_on_both_loops(case):
    a, b = both_loops(SCUFF_RULE_RUNS[case])
    assert_same_run(a, b, case)
    assert a.stats["compiled_loop_steps"] > 0


def test_the_walk_is_bit_for_bit_the_python_walk():
    a, b = both_loops(_walk(controller_cls=WalkingController, t_final=3.0))
    assert a.status == "completed" and len(a.impacts) >= 4
    for name in ("t", "q", "dq", "u", "grf", "energy_balance"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert [e.time for e in a.events] == [e.time for e in b.events]


def test_the_loop_steps_in_c():
    """Not a vacuous comparison: the compiled loop took the walk's quiet steps (its own statistics)."""
    ctrl = PDWalkingController(MODEL)
    q0, dq0 = ctrl.initial_state()
    sim = bs.HybridSimulator(MODEL, q0, dq0, method="dopri5")
    for _ in range(200):
        sim.advance_period(1e-3, controller=ctrl)
    assert isinstance(sim._stepper, compiled_loop.CompiledStepper)
    steps, *_ = compiled_loop.take_stats(sim.S)
    assert steps >= 150
    # a control period's command of a reference law is computed in C, with the law's own torque
    u = sim._compiled.command(ctrl)
    assert u is not None and np.array(u).tobytes() == np.array(sim.command(ctrl), dtype=float).tobytes()


class UsersController:
    """A user's own controller, in Python (lists in, a tuple out): the loop calls it back."""

    def __init__(self, fail_at=None, bad_at=None):
        self.pd = PDWalkingController(MODEL)
        self.fail_at, self.bad_at, self.calls = fail_at, bad_at, 0

    def __call__(self, t, q, dq, stance_leg):
        self.calls += 1
        if self.fail_at is not None and t > self.fail_at:
            raise RuntimeError("my controller broke")
        if self.bad_at is not None and t > self.bad_at:
            return (float("nan"), 0.0)
        u = self.pd(t, q, dq, stance_leg)
        return (0.9 * u[0], 0.9 * u[1])


@pytest.mark.parametrize("case", ["continuous", "held 1 ms", "raises", "returns NaN", "a plain function"])
def test_a_users_python_controller_is_called_back_with_the_same_run(case):
    kw = dict(fail_at=0.7) if case == "raises" else dict(bad_at=0.6) if case == "returns NaN" else {}
    period = 1e-3 if case == "held 1 ms" else None

    def run():
        ctrl = UsersController(**kw)
        if case == "a plain function":
            pd = PDWalkingController(MODEL)
            ctrl = lambda t, q, dq, leg: pd(t, q, dq, leg)   # noqa: E731
        q0, dq0 = PDWalkingController(MODEL).initial_state()
        return bs.simulate(MODEL, q0, dq0, 1.5, controller=ctrl, control_period=period)
    a, b = both_loops(run)
    assert_same_run(a, b, case)
    if case in ("raises", "returns NaN"):
        assert a.status == "failed" and "controller" in a.message, a.message
    else:
        assert a.status == "completed" and len(a.impacts) >= 2


# -- issue 30: a plain Python controller costs its own time -------------------------------------------------
def _stance_evaluations_from_python(monkeypatch):
    """A counter of the stance right-hand side evaluated from Python (outside the compiled loop)."""
    from biped_sim.engine.compiled import gen
    count = [0]
    for name in ("stance_floating_1", "stance_floating_2"):
        f = getattr(gen, name)

        def counted(*args, f=f):
            count[0] += 1
            return f(*args)
        monkeypatch.setattr(gen, name, counted)
    return count


def _bits(r):
    return [getattr(r, n).tobytes() for n in ("t", "q", "dq", "u", "grf", "stance_leg", "energy_balance")] + \
        [(e.kind, e.leg, e.time) for e in r.events] + [r.status, r.message]


def test_a_plain_python_controllers_held_periods_run_in_the_compiled_loop(monkeypatch):
    """The scene's law wrapped in a plain function (no compiled law): called once a period, at its start, with
    lists q and dq, and the rest of each period in C (no stance right-hand side evaluated from Python but
    around a few events); the run is the built-in law's, bit for bit."""
    scene = bs.load_scene("walk")
    ctrl = scene.controller()
    calls = []

    def plain(t, q, dq, leg):
        calls.append((type(q), type(dq)))
        return ctrl(t, q, dq, leg)
    built_in = scene.simulate(t_final=1.0)
    evaluations = _stance_evaluations_from_python(monkeypatch)
    r = scene.simulate(controller=plain, t_final=1.0)
    periods = round(1.0 / scene.params["control_period"])
    assert r.status == "completed" and len(r.impacts) >= 2
    assert evaluations[0] <= periods / 50, evaluations[0]
    assert _bits(r) == _bits(built_in)
    assert len(calls) == periods and set(calls) == {(list, list)}
    assert r.stats["compiled_loop_steps"] >= 0.9 * r.stats["steps"]


@pytest.mark.parametrize("hold", [False, True])
def test_a_controller_gets_lists_on_both_loops(hold):
    """q and dq reach a controller as lists of floats, on both loops, held or under continuous feedback."""
    pd = PDWalkingController(MODEL)
    q0, dq0 = pd.initial_state()
    seen = set()

    def mine(t, q, dq, leg):
        seen.add((type(q), type(dq), type(q[0]), type(dq[4])))
        return pd(t, q, dq, leg)
    a, b = both_loops(lambda: bs.simulate(MODEL, q0, dq0, 0.8, controller=mine, control_period=1e-3 if hold else None))
    assert_same_run(a, b)
    assert a.status == "completed" and seen == {(list, list, float, float)}


def test_a_python_command_the_ground_refuses_is_a_liftoff_and_the_controller_is_called_once_a_period():
    """The period whose command the stance guards refuse at its start (the ground would pull) is handed back to
    the Python code with that command: a liftoff at the period's start, the controller not called again."""
    harsh = PDWalkingController(MODEL, torso_pitch=1.0, torque_limit=300.0)
    walker = WalkingController(MODEL)
    calls = []

    def late_harsh(t, q, dq, leg):      # the walk, then from 0.1 s a command that pulls the stance foot up
        calls.append(t)
        return (harsh if t >= 0.1 - 1e-12 else walker)(t, q, dq, leg)

    def run():
        calls.clear()
        r = bs.simulate(MODEL, *walker.initial_state(), 0.2, controller=late_harsh, control_period=1e-3,
                        phases=("stance", "impact", "flight"))
        return r, list(calls)
    (a, calls_a), (b, calls_b) = both_loops(run)
    assert_same_run(a, b)
    liftoffs = [e.time for e in a.events if e.kind == "liftoff"]
    assert liftoffs and abs(liftoffs[0] - 0.1) < 1e-12, a.events
    assert calls_a == calls_b and len(calls_a) == len(set(calls_a))   # once a period, on both loops


def test_a_python_controller_runs_inside_the_compiled_loop():
    ctrl = UsersController()
    q0, dq0 = ctrl.pd.initial_state()
    sim = bs.HybridSimulator(MODEL, q0, dq0)
    sim.advance(0.3, controller=ctrl)
    assert isinstance(sim._stepper, compiled_loop.CompiledStepper)
    assert compiled_loop.take_stats(sim.S)[0] > 10 and ctrl.calls > 100


@settings(max_examples=30, deadline=None)
@given(st.floats(-0.05, 0.05), st.floats(-0.3, 0.3), st.floats(0.7, 1.3), st.floats(50.0, 400.0),
       st.sampled_from([None, 1e-3, 4e-3]), st.sampled_from(["dop853", "dopri5"]),
       st.sampled_from([None, 0.6, 0.08]))
def test_perturbed_walks_run_the_same_on_both_loops(dq_torso, dspeed, speed, kp, period, method, mu):
    """(with a friction coefficient that slips, the foot kept pinned: steps go back and forth between
    the loops while the slip guard is latched)"""
    ctrl = PDWalkingController(MODEL, kp=kp)
    q0, dq0 = ctrl.initial_state(speed=speed)
    q0, dq0 = bs.stance_state(MODEL, q0[2:], dq0[2:] + [0.0, dspeed, dq_torso])
    a, b = both_loops(lambda: bs.simulate(MODEL, q0, dq0, 1.2, controller=ctrl, control_period=period,
                                          method=method, mu=mu, stop_on_slip=False))
    assert_same_run(a, b, f"{dq_torso} {dspeed} {speed} {kp} {period} {method} {mu}")


@settings(max_examples=25, deadline=None)
@given(st.floats(-30.0, 30.0), st.floats(-30.0, 30.0), st.floats(0.5, 1.5))
def test_held_torques_run_the_same_on_both_loops(u1, u2, speed):
    q0, dq0 = WalkingController(MODEL).initial_state(speed=speed)

    def run():
        sim = bs.HybridSimulator(MODEL, q0, dq0)
        for k in range(60):
            sim.advance((k + 1) * 0.01, u=[u1 * math.cos(k), u2])
        return sim.result()
    a, b = both_loops(run)
    assert_same_run(a, b, f"{u1} {u2} {speed}")


def _node_periods(period, method, t_final, keep, gain, push_at, bad_at, mu):
    """The node's loop (sim_node.step): a command computed outside the engine, held for a period by
    advance_period(u=...); a push between two periods, torques the engine refuses, and the state read
    after every period."""
    ctrl = PDWalkingController(MODEL)
    q0, dq0 = ctrl.initial_state()
    sim = bs.HybridSimulator(MODEL, q0, dq0, method=method, keep_samples=keep, mu=mu, stop_on_slip=False)
    seen = []
    while sim.status == "running" and sim.t < t_final:
        k = sim.control_periods
        if k == bad_at:
            for bad in ([math.nan, 0.0], [1.0], [math.inf, -math.inf], "ab", [1e308, 1e308]):
                with pytest.raises(ValueError, match="two finite torques"):
                    sim.advance_period(period, u=bad, t_final=t_final)
        if k == push_at:
            sim.push([1.5, 0.0])
            if sim.status != "running":
                break
        u = [gain * v for v in sim.command(ctrl)]
        if k % 5 == 1:
            u = np.array([u[0], int(u[1])])      # an array, which the C loop leaves to the Python code
        events = sim.advance_period(period, u=u, t_final=t_final)
        seen.append((sim.t, sim.q.tolist(), sim.dq.tolist(), sim.control_periods, sim.u, sim.stance_leg,
                     [(e.kind, e.time) for e in events]))
    return sim.result(), seen


@settings(max_examples=25, deadline=None)
@given(st.sampled_from([1e-3, 2.5e-3, 4e-3]), st.sampled_from(["dopri5", "dop853"]), st.floats(0.6, 1.3),
       st.sampled_from([True, 7, False, "events"]), st.floats(0.6, 1.2), st.integers(0, 300), st.integers(0, 300),
       st.sampled_from([None, 0.6, 0.08]))
@example(1e-3, "dopri5", 1.0, True, 1.0, 51, 0, 0.08)   # a push at a period's end: the next step starts from it
def test_the_nodes_held_periods_run_the_same_on_both_loops(period, method, t_final, keep, gain, push_at, bad_at, mu):
    """advance_period(u=...) runs a quiet period in one C call (Loop.period) and hands anything else to the
    Python code: the same run, period by period, as the Python loop's (with a friction coefficient that
    slips, the foot kept pinned: the slip guard latched, which only the Python code follows)."""
    (a, seen_a), (b, seen_b) = both_loops(lambda: _node_periods(period, method, t_final, keep, gain, push_at,
                                                                 bad_at, mu))
    what = f"{period} {method} {t_final} {keep} {gain} {push_at} {bad_at} {mu}"
    assert_same_run(a, b, what)
    assert len(seen_a) == len(seen_b), what
    for ra, rb in zip(seen_a, seen_b):
        assert ra[3:] == rb[3:], what
        assert abs(ra[0] - rb[0]) <= 1e-12, what
        np.testing.assert_allclose(ra[1] + ra[2], rb[1] + rb[2], rtol=0, atol=1e-10, err_msg=what)


def test_a_quiet_held_period_is_one_c_call_and_its_state_a_new_array():
    """Not a vacuous comparison: the node's periods ran in Loop.period (which leaves q and dq to be made
    when read), the state read is new each period, never an array changed in place, and state_lists()
    gives its values."""
    ctrl = PDWalkingController(MODEL)
    q0, dq0 = ctrl.initial_state()
    sim = bs.HybridSimulator(MODEL, q0, dq0, method="dopri5")
    quiet, before, kept = 0, None, None
    for _ in range(300):
        events = sim.advance_period(1e-3, u=sim.command(ctrl))
        quiet += not events and bool(sim.S[loop_state.SIM_STATE_UNMADE])
        lists = sim.state_lists()
        q = sim.q
        assert lists == (q.tolist(), sim.dq.tolist())
        assert q is not before and np.array_equal(q, sim.result().q[-1])
        if before is not None:     # the last period's array is as it was read: nothing wrote into it
            assert not np.array_equal(before, q) and np.array_equal(before, kept)
        before, kept = q, q.copy()
    assert sim.status == "running" and quiet >= 250


def compiled_torque(controller, stance_leg, q, dq):
    """The compiled law's torque at (q, dq) (lists) in stance on ``stance_leg``, computed by a C Loop."""
    loop = compiled_loop.new_loop(MODEL)
    loop_state.write(memoryview(loop).cast("d"), method=loop_state.METHODS["dop853"], stance_leg=stance_leg,
                     y=list(q) + list(dq) + [0.0])
    loop.begin(None)
    return np.array(loop.law_torque(torque_hook.hook_argument(torque_hook.reference_law(controller, MODEL))))


@pytest.mark.parametrize("cls", [WalkingController, PDWalkingController])
def test_the_compiled_laws_give_the_python_torques_bit_for_bit(cls):
    rng = np.random.default_rng(3)
    for params in ({}, dict(torso_pitch=0.05, step_angle=0.3, clearance=0.2, lag=0.01, kp=80.0, kd=9.0,
                            torque_limit=20.0)):
        ctrl = cls(MODEL, **params)
        for _ in range(300):
            q = (rng.uniform(-1, 1, 5) + [0, 0.9, math.pi, math.pi, 0]).tolist()
            dq = rng.uniform(-4, 4, 5).tolist()
            for leg in (1, 2):
                expected = np.asarray(ctrl(0.0, q, dq, leg), dtype=float)
                got = compiled_torque(ctrl, leg, q, dq)
                assert got.tobytes() == expected.tobytes(), (q, dq, leg, got, expected)


def test_a_changed_law_is_not_compiled():
    class Mine(PDWalkingController):
        def __call__(self, t, q, dq, stance_leg):
            return [0.0, 0.0]
    assert torque_hook.offered_law(Mine(MODEL), MODEL) is None
    assert torque_hook.offered_law(lambda t, q, dq, leg: (0.0, 0.0), MODEL) is None
    assert torque_hook.offered_law(PDWalkingController(MODEL), MODEL)[0] == "pd_walking"


# -- issue 28, R2: a law runs compiled only where the result is the controller's own ------------------------
class SwingAhead(WalkingController):
    """Another swing target, the swing foot 0.05 rad further forward: not the compiled law."""
    def swing_target(self, phi_s):
        f, df, ddf = super().swing_target(phi_s)
        return f - 0.05, df, ddf


class StiffTorso(WalkingController):
    """Other outputs: the torso held 0.05 rad further forward."""
    def outputs(self, q, dq, stance_leg):
        (y0, y1), dy, H, bias = super().outputs(q, dq, stance_leg)
        return (y0 - 0.05, y1), dy, H, bias


class PDSwingAhead(PDWalkingController):
    def swing_target(self, phi_s):
        f, df, ddf = super().swing_target(phi_s)
        return f - 0.05, df, ddf


def _swing_on_the_instance():
    ctrl = WalkingController(MODEL)
    plain = ctrl.swing_target
    ctrl.swing_target = lambda phi_s: tuple(v - 0.05 * (i == 0) for i, v in enumerate(plain(phi_s)))
    return ctrl


OWN_LAWS = {
    "a subclass with its own swing_target": lambda: SwingAhead(MODEL),
    "a subclass with its own outputs": lambda: StiffTorso(MODEL),
    "a PD subclass with its own swing_target": lambda: PDSwingAhead(MODEL),
    "swing_target replaced on the instance": _swing_on_the_instance,
    "a controller on another model (m_leg 4)": lambda: WalkingController(BipedModel(m_leg=4.0)),
}


def _commanded(ctrl, mode, t_final=0.6):
    """A walk of the simulator's MODEL under ctrl: continuous feedback, simulate's held 1 ms periods
    (advance_periods), or advance_period(controller=...) one period at a time."""
    q0, dq0 = WalkingController(MODEL).initial_state()
    if mode != "advance_period":
        return bs.simulate(MODEL, q0, dq0, t_final, controller=ctrl, control_period=mode)
    sim = bs.HybridSimulator(MODEL, q0, dq0)
    while sim.status == "running" and sim.t < t_final - 1e-12:
        sim.advance_period(1e-3, controller=ctrl, t_final=t_final)
    return sim.result()


def _assert_the_controllers_own_torques(ctrl, r, period):
    assert r.status == "completed" and len(r.t) > 20, r.message
    if period is None:       # at each sample's own state (the projection moves it by the drift only)
        expected = [ctrl(t, q, dq, int(leg)) for t, q, dq, leg in zip(r.t, r.q, r.dq, r.stance_leg)]
        np.testing.assert_allclose(r.u, expected, rtol=0, atol=1e-9)
        return
    # held: the sample after a period's start carries the command at that start's state, bit for bit
    starts = 0
    for i in range(len(r.t) - 1):
        k = round(r.t[i] / period)
        if abs(r.t[i] - k * period) < 1e-12 and k * period < r.t[i + 1] <= (k + 1) * period + 1e-12:
            expected = np.asarray(ctrl(r.t[i], r.q[i], r.dq[i], int(r.stance_leg[i])), dtype=float)
            assert r.u[i + 1].tobytes() == expected.tobytes(), (r.t[i], r.u[i + 1], expected)
            starts += 1
    assert starts > 100


@pytest.mark.parametrize("mode", [None, 1e-3, "advance_period"])
@pytest.mark.parametrize("case", list(OWN_LAWS))
def test_a_law_that_is_not_the_compiled_one_gives_the_controllers_own_torques_on_both_loops(case, mode):
    ctrl = OWN_LAWS[case]()
    a, b = both_loops(lambda: _commanded(ctrl, mode))
    assert a.stats["compiled_loop_steps"] > 0      # the loop ran, calling the controller back
    _assert_the_controllers_own_torques(ctrl, a, 1e-3 if mode else None)
    assert_same_run(a, b, case)
    assert np.array_equal(a.u, b.u) and np.array_equal(a.q, b.q)


@pytest.mark.parametrize("mode", [None, 1e-3, "advance_period"])
@pytest.mark.parametrize("cls", [WalkingController, PDWalkingController])
def test_the_reference_laws_on_the_simulators_model_still_run_compiled(cls, mode):
    ctrl = cls(BipedModel())      # another object, the same parameters: the same constants
    assert torque_hook.reference_law(ctrl, MODEL)[0] == {WalkingController: "walking"}.get(cls, "pd_walking")
    a, b = both_loops(lambda: _commanded(ctrl, mode))
    assert a.stats["compiled_loop_steps"] > 0
    _assert_the_controllers_own_torques(ctrl, a, 1e-3 if mode else None)
    assert np.array_equal(a.u, b.u) and np.array_equal(a.q, b.q)


def test_which_controllers_the_loop_compiles():
    other = BipedModel(m_leg=4.0)
    assert torque_hook.reference_law(WalkingController(other), MODEL) is None
    assert torque_hook.reference_law(WalkingController(other), other)[0] == "walking"
    # the PD law in stance uses no model constant: the same torques on any model
    assert torque_hook.reference_law(PDWalkingController(other), MODEL)[0] == "pd_walking"
    for make in OWN_LAWS.values():
        assert torque_hook.reference_law(make(), MODEL) is None
    changed = WalkingController(MODEL)
    changed.kp = 120        # a gain set after __init__: the law's parameters are read at each use
    assert torque_hook.reference_law(changed, MODEL)[1][5] == 120
    changed.kd = np.float32(20.0)       # another precision than C's doubles: called back
    assert torque_hook.reference_law(changed, MODEL) is None


WALK = """
import json
import biped_sim as bs
from biped_sim.engine import compiled_loop
r = bs.load_scene("walk").simulate(hold=True, t_final=1.0)
print(json.dumps({"available": compiled_loop.AVAILABLE, "why": compiled_loop.WHY_NOT,
                  "t": r.t.tolist(), "q": r.q.ravel().tolist(), "events": [e.time for e in r.events]}))
"""


def test_pure_python_switch_runs_the_python_loop_with_the_same_run():
    runs = {}
    for forced in ("1", ""):
        out = subprocess.run([sys.executable, "-c", WALK], capture_output=True, text=True, cwd=ROOT,
                             env=dict(os.environ, BIPED_SIM_PURE_PYTHON=forced), timeout=300)
        assert out.returncode == 0, out.stderr
        runs[forced] = json.loads(out.stdout)
    assert (runs["1"]["available"], runs["1"]["why"]) == (False, "BIPED_SIM_PURE_PYTHON is set")
    assert runs[""]["available"] is True
    a, b = runs[""], runs["1"]
    assert a["events"] == b["events"] and a["t"] == b["t"] and a["q"] == b["q"]


@st.composite
def _landing(draw):
    """A start from which a foot lands: in stance on either foot, the torque held over 10 ms periods (the
    compiled loop's touchdowns), or in flight (a V that may land on both feet at once)."""
    a, torso = draw(st.floats(-0.6, 0.6)), draw(st.floats(-0.4, 0.4))
    rates = [draw(st.floats(-2.0, 2.0)) for _ in range(3)]
    leg = draw(st.sampled_from([0, 1, 2]))
    if leg:
        b = math.copysign(abs(a) + draw(st.floats(1e-3, 0.4)), draw(st.sampled_from([-1.0, 1.0])))  # swing foot up
        joints = [math.pi + a - torso, math.pi + b - torso, torso]
        q, dq = bs.stance_state(MODEL, joints if leg == 1 else joints[1::-1] + [torso], rates, stance_leg=leg)
        return q, dq, leg
    b = -a if draw(st.booleans()) else draw(st.floats(-0.6, 0.6))
    height = max(math.cos(a), math.cos(b)) * MODEL.parameters.l_leg + draw(st.floats(1e-6, 0.2))
    q = np.array([0.0, height, math.pi + a - torso, math.pi + b - torso, torso])
    return q, np.array([draw(st.floats(-2.0, 2.0)), draw(st.floats(-1.5, 0.0))] + rates), 0


def _impulses_outside_the_cone(r, mu):
    """(impact, foot) of every landing impulse outside the friction cone by more than impulse_tol."""
    ground = G.Ground.of(r.options.slope)
    out = []
    for e in r.impacts:
        for j, leg in enumerate([1, 2] if e.kind == "double_touchdown" else [e.leg]):
            n, tg = G.normal_tangent(e.impulse[2 * j: 2 * j + 2], ground)
            if abs(tg) - mu * n > r.options.impulse_tol:
                out.append((e, leg))
    return out


# a flight landing on foot 1 at 0.57 |Lambda_t|/Lambda_n (mu 0.338), and one on foot 1 from stance on foot
# 2 under a held torque (the compiled loop's touchdown, which hands it back: why 19), both "completed"
# with the sticking impact kept and a warning before the cone held at impacts
_FLIGHT_LANDING = (np.array([-0.198669330795062, 1.030066577841242, 2.791592653589793, 3.191592653589794, 0.15]),
                   np.array([1.489, -1.672, -1.744, 2.43, -0.966]), 0)
_STANCE_LANDING = bs.stance_state(MODEL, [3.087, 3.3423, -0.3322], [-1.5488, 1.8369, -1.6192], stance_leg=2) + (2,)


# found by hypothesis: foot 2 lands 38 ns after the start and its impulse pulls (Lambda_n = -6.7e-7 N s): no ratio
# |Lambda_t|/Lambda_n to give
_PULLING_LANDING = (*bs.stance_state(MODEL, [math.pi + 0.8125, math.pi - 0.5625, -0.25], [0.25, 0.0, 1.375]), 1)


@settings(max_examples=30, deadline=None)
@example(start=_FLIGHT_LANDING, u=(0.0, 0.0), mu=0.338)
@example(start=_STANCE_LANDING, u=(55.29, -31.728), mu=0.639)
@example(start=_PULLING_LANDING, u=(0.0, 39.0), mu=1.0)
@given(start=_landing(), u=st.tuples(st.floats(-60.0, 60.0), st.floats(-60.0, 60.0)), mu=st.floats(0.05, 1.0))
def test_no_run_completes_with_a_landing_impulse_outside_the_friction_cone(start, u, mu):
    """With mu (and stop_on_slip), a run either completes with every impact impulse inside the friction
    cone, or ends at the impact whose impulse leaves it, saying why; on both loops, the same run."""
    q, dq, leg = start
    a, b = both_loops(lambda: bs.simulate(MODEL, q, dq, 0.3, controller=lambda t, q, dq, s: u, stance_leg=leg,
                                          mu=mu, control_period=0.01))
    assert_same_run(a, b, f"{start} {u} {mu}")
    outside = _impulses_outside_the_cone(a, mu)
    event(f"{a.status}, {'flight' if leg == 0 else 'stance'} start, {len(a.impacts)} impacts, "
          f"{'an impulse outside the cone' if outside else 'inside'}")
    if a.status == "completed":
        assert not outside, [e.warnings for e, _ in outside]
        return
    assert a.message
    if outside:
        impact, foot = outside[0]
        assert impact is a.impacts[-1] and a.events[-1].time == impact.time, a.message   # it ended there
        if "friction cone" in a.message:
            assert a.status == "stopped"
            assert f"the {impact.kind.replace('_', ' ')} at t={impact.time:.9g} s" in a.message
            assert f"on foot {foot}" in a.message and f"mu = {mu:g}" in a.message
            # (the ratio where the normal impulse pushes; where it pulls, that it pulls)
            assert "|Lambda_t|/Lambda_n = " in a.message or "its normal part pulls: Lambda_n = -" in a.message
            assert "stop_on_slip=False" in a.message


def _legs_together_landing():
    """Found by hypothesis (test_hybrid_properties): a flight start on a 0.125 rad slope, both feet 1 um up, under
    the held torque (38, 0), whose foot 2 lands at t=0.19141 s with the legs together (foot 1 at the same
    point): foot 1, disarmed by the reset, leaves the ground at 5 um/s and is pushed back into it at once."""
    q = np.array([0.0, 0.96891242, 2.89159265, 2.57909265, 0.0])
    tan = math.tan(0.125)
    q[1] += max(0.0, -min(MODEL.foot_position(q, k)[1] + tan * MODEL.foot_position(q, k)[0] for k in (1, 2))) + 1e-6
    return q, np.array([0.5, 0.0, 0.0, 0.5, 1.25])


def test_a_resting_foot_pushed_into_the_ground_inside_a_step_touches_down_on_both_loops():
    """A free foot that no touchdown witness watches (disarmed by the reset that put the other foot down) and that
    goes under the ground and back inside one step touches down where it goes in, as one under the ground at the
    step's end does; the run no longer completes with that foot 95 um under the ground at the liftoff's sample."""
    q, dq = _legs_together_landing()
    a, b = both_loops(lambda: bs.simulate(MODEL, q, dq, 0.4, controller=lambda t, q, dq, s: (38.0, 0.0),
                                          stance_leg=0, slope=0.125))
    assert_same_run(a, b)
    legs_together = next(e for e in a.events if e.kind == "touchdown" and abs(e.time - 0.19141021) < 1e-8)
    assert abs(G.foot_xy(MODEL, list(legs_together.q), 1)[0] - G.foot_xy(MODEL, list(legs_together.q), 2)[0]) < 1e-9
    after = a.events[a.events.index(legs_together) + 1]
    assert (after.kind, after.leg) == ("touchdown", 1) and 0 < after.time - legs_together.time < 1e-5, after
    # both feet then stay on the ground: the model's Zeno stop, which names it
    assert a.status == "stopped" and "the old stance foot (leg 2) no longer leaves the ground" in a.message
    assert not violations(MODEL, a)


def test_a_resting_foot_that_dips_inside_a_quiet_step_is_handed_to_the_python_loop():
    """Stance on foot 1 with the legs together (foot 2 resting at the stance foot, disarmed) under a held torque:
    foot 2 goes 16 um under the ground in front of foot 1 and is above it again at the first 10 ms step's end.
    The compiled loop's quiet step finds that dip (loop_rules.ev_resting_foot_dips) and hands the step back;
    both loops land foot 2 there."""
    q, dq = bs.stance_state(MODEL, [math.pi + 0.049, math.pi + 0.049, -0.05], [0.75, 0.71, 0.43], stance_leg=1)
    a, b = both_loops(lambda: bs.simulate(MODEL, q, dq, 0.01, controller=lambda t, q, dq, s: (-20.0, 53.0),
                                          stance_leg=1, control_period=0.01))
    assert_same_run(a, b)
    assert a.events, f"{a.status}: foot 2's dip went unseen"
    first = a.events[0]
    assert (first.kind, first.leg) == ("touchdown", 2) and 0 < first.time < 1e-3, first
    assert not violations(MODEL, a)


#: found by a search of random stance starts: stance on foot 2, foot 1 0.0665 m under the ground behind it, swinging
#: forward (the start check accepts it: its crossing would be a scuff), the torque (29.98, -48.99) held every 10 ms;
#: the stance force is negative at t=0, a liftoff at once
SCUFF_START_LIFTING_OFF = (
    [-0.36549383763290955, 0.930813759380666, 2.8191592023338132, 2.3717608397421572, 0.3956685220223073],
    [3.868391032148796, 1.51896452921532, -0.003182759977025107, 2.8782764377115093, 1.2776473366885392],
    (29.978434637164156, -48.98574220990462))


def test_a_start_accepted_as_a_scuff_that_lifts_off_at_once_stops_as_the_scuffs_rule_says_on_both_loops():
    """A start whose free foot lies under the ground where its crossing would be a scuff begins as a scuff (flag,
    row, count, deepest_scuff): a liftoff with that foot under the ground stops the run (no mode has a free foot
    below the ground), where the run used to land the foot at t=0 with an impulse that pulls it and fail."""
    q, dq, u = SCUFF_START_LIFTING_OFF
    feet = G.foot_states(MODEL, q, dq)
    assert feet[0].height < -0.066 and G.starts_scuff(feet[0], feet[1], bs.Options())
    a, b = both_loops(lambda: bs.simulate(MODEL, np.array(q), np.array(dq), 0.4, controller=lambda t, q, dq, s: u,
                                          stance_leg=2, control_period=0.01))
    assert_same_run(a, b)
    assert a.status == "stopped", a.message
    assert ("the stance foot (leg 2) liftoff at t=0 s while foot 1 is still below the ground, passing through it "
            "(a scuff since t=0 s)") in a.message
    assert [e.kind for e in a.events] == ["error"]
    for r in (a, b):
        assert r.stats["scuffs_ignored"] == 1 and r.stats["deepest_scuff"] == -feet[0].height


@pytest.mark.parametrize("depth", [2e-7, 4e-3])
def test_a_start_under_the_ground_as_a_scuff_swings_through_and_comes_out_on_both_loops(depth):
    """Stance on foot 1, foot 2 straight under the hip ``depth`` under the ground behind the stance foot, swinging
    forward (the leg at 1 rad/s): a scuff from t=0, followed by both loops (the compiled one in its quiet steps)
    until the foot is above the ground, with its Event, the count and deepest_scuff, the start's depth. (At 0.2 um
    the run used to complete with no scuff reported and its first sample under the ground.)"""
    a_leg = -math.acos(1.0 - depth / MODEL.parameters.l_leg)
    q, dq = bs.stance_state(MODEL, [math.pi + a_leg, math.pi, 0.0], [0.0, -1.0, 0.0], stance_leg=1)
    a, b = both_loops(lambda: bs.simulate(MODEL, q, dq, 0.2))
    assert_same_run(a, b)
    assert a.status == "completed" and not violations(MODEL, a), violations(MODEL, a)
    assert a.stats["compiled_loop_steps"] > 0
    for r in (a, b):
        assert [(e.kind, e.leg, e.time) for e in r.events] == [("scuff", 2, 0.0)]
        assert r.stats["scuffs_ignored"] == 1 and r.stats["deepest_scuff"] == pytest.approx(depth, rel=1e-6)
        assert f"{depth:.3g} m deep at t=0 s" in r.events[0].message
        t_up = float(re.search(r"to t=(\S+) s", r.events[0].message).group(1))
        assert 0.0 < t_up < 0.2 and MODEL.foot_position(r.q[r.t.searchsorted(t_up)], 2)[1] > 0.0


def _period_index_counted(t, period, k):
    while (k + 1) * period <= t:
        k += 1
    return k


@settings(max_examples=300, deadline=None)
@given(period=st.floats(1e-6, 10.0), m=st.integers(0, 3000), shift=st.sampled_from([-2, -1, 0, 1, 2, 0.5]),
       behind=st.integers(0, 5))
@example(period=1e-3, m=100, shift=0, behind=0).via("a period boundary met exactly")
@example(period=0.1, m=3, shift=0, behind=0).via("3 * 0.1 > 0.3 in floating point")
def test_the_first_periods_index_is_the_one_counted_from_the_periods_begun(period, m, shift, behind):
    # t at a boundary (m * period), a few ulps either side of it, or inside a period; k periods begun, k <= m + 2
    t = (m + shift) * period if shift == 0.5 else m * period
    for _ in range(abs(shift) if shift != 0.5 else 0):
        t = math.nextafter(t, math.inf if shift > 0 else -math.inf)
    k = max(0, m + 2 - behind * (m // 4 + 1))
    assert hybrid.period_index(t, period, k) == _period_index_counted(t, period, k)


@settings(max_examples=100, deadline=None)
@given(t=st.floats(1.0, 1e10), period=st.floats(1e-5, 1.0))   # (fewer than 2**53 periods)
@example(t=1e5, period=1e-3).via("issue 28 R6: 16 s counted one by one")
def test_the_first_periods_index_at_a_late_t_is_the_first_period_ending_after_t(t, period):
    k = hybrid.period_index(t, period, 0)
    assert (k + 1) * period > t and k * period <= t


@pytest.mark.parametrize("t0", [1e5, 1e9])
def test_a_run_from_a_late_t0_begins_the_period_under_way_on_both_loops(t0):
    """The first period of a run from t0 (Python), and a period begun mid-period after advance() with no
    period counted yet (on the compiled loop, one C call: Loop.period), end at the first (k + 1) period after t."""
    period, q0, dq0 = 1e-3, *PDWalkingController(MODEL).initial_state()

    def run():
        out = []
        for first in ("advance_period", "advance"):
            sim = bs.HybridSimulator(MODEL, q0, dq0, t0=t0)
            if first == "advance":
                sim.advance(t0 + 0.35 * period)
            t_start = sim.t
            sim.advance_period(period, [0.0, 0.0])
            k = sim.control_periods - 1
            assert sim.status == "running" and sim.t == (k + 1) * period > t_start >= k * period
            out.append((sim.t, sim.control_periods, bool(sim.S[loop_state.SIM_STATE_UNMADE])))
        return out

    compiled, python = both_loops(run)
    assert [r[:2] for r in compiled] == [r[:2] for r in python]
    assert compiled[1][2] and not python[1][2]     # the compiled loop's period in C, the Python loop's not


def test_a_period_too_short_to_count_up_to_t_is_refused():
    sim = bs.HybridSimulator(MODEL, *PDWalkingController(MODEL).initial_state(), t0=1e5)
    with pytest.raises(ValueError, match=r"period=1e-12 s is too short for a run at t=100000.0 s"):
        sim.advance_period(1e-12, [0.0, 0.0])
    assert sim.control_periods == 0 and sim.status == "running"


def test_the_simulator_its_samples_and_the_compiled_loop_share_one_state():
    """The run's fields that the compiled loop reads and writes (the Samples' counters, the energy terms, the
    control periods, the simulator's time, work, torque and step size, the locator's armed feet and the feet
    kept of the last step's end) are fields of one state, the
    simulator's for its life (loop_state.py): with the compiled loop built its S is the Loop's own memory, so
    that the periods the loop ran in C are read in Python from where C wrote them, with nothing handed over."""
    ls = loop_state

    def run():
        sim = bs.HybridSimulator(MODEL, *PDWalkingController(MODEL).initial_state(), keep_samples=3)
        for _ in range(40):
            sim.advance_period(1e-3, u=[0.5, -0.5])
        S, s = sim.S, sim._samples
        assert s.S is S and (sim.t, sim.work, sim._h, sim.control_periods, sim.u, sim.E0, sim.energy_lost) == (
            S[ls.SIM_T], S[ls.SIM_WORK], S[ls.SIM_H], S[ls.CONTROL_PERIODS], [S[ls.SIM_U], S[ls.SIM_U + 1]],
            S[ls.E0], S[ls.ENERGY_LOST])
        assert (s.n, s.appended, s.provisional, s.every) == (S[ls.N_SAMPLES], S[ls.APPENDED], S[ls.PROVISIONAL], 3)
        loc = sim.locator
        assert loc.S is S and loc.armed == [S[ls.ARMED] == 1.0, S[ls.ARMED + 1] == 1.0] and loc._feet_end[0] == sim.t
        return sim, sim.result()

    (sim_c, compiled), (sim_p, python) = both_loops(run)
    if compiled_loop.AVAILABLE:
        assert sim_c.S.obj is sim_c._loop and sim_c._compiled.loop is sim_c._loop
        assert sim_c.stats["compiled_loop_steps"] > 20       # the periods ran in C
    assert compiled.t.tolist() == python.t.tolist() and np.array_equal(compiled.q, python.q)
    assert sim_c.control_periods == sim_p.control_periods == 40


@pytest.mark.skipif(not compiled_loop.AVAILABLE, reason=compiled_loop.WHY_NOT or "no compiled loop")
def test_the_loop_takes_its_options_and_its_mode_from_the_state():
    """No positional lists of options or of a mode's start: the compiled loop runs with the options and the mode
    (stance leg, pin, held torque) that the Python code wrote by name into the state, and begin() takes the
    torque law only."""
    ls = loop_state
    sim = bs.HybridSimulator(MODEL, *PDWalkingController(MODEL).initial_state(), mu=0.6, arm_height=0.02,
                             stop_on_slip=False, slope=0.01)
    for _ in range(5):
        sim.advance_period(1e-3, [0.5, -0.5])
    S = sim.S
    assert sim.stats["compiled_loop_steps"] > 0
    assert (S[ls.ARM_HEIGHT], S[ls.HAS_MU], S[ls.MU], S[ls.STOP_ON_SLIP], S[ls.SIN_S]) == (
        0.02, 1.0, 0.6, 0.0, math.sin(0.01))
    assert (S[ls.STANCE_LEG], [S[ls.PIN], S[ls.PIN + 1]], [S[ls.U_HOLD], S[ls.U_HOLD + 1]]) == (
        sim.stance_leg, sim.pin, [0.5, -0.5])
    assert not any(hasattr(sim._loop, name) for name in ("set_options", "set_events", "set_counters", "state"))
    with pytest.raises(TypeError):
        sim._loop.begin(None, 1, 0.0)


@pytest.mark.skipif(not compiled_loop.AVAILABLE, reason=compiled_loop.WHY_NOT or "no compiled loop")
def test_every_entry_point_of_the_loop_ends_with_one_outcome():
    """run, held, period, periods and step return a loop_state.Outcome and leave the rest in the state (the end of
    the period under way, the failure, the records waiting); the outcomes, the kinds of records and the reasons
    a step is handed back are named once, in loop_state.py, and generated into _loop_state.h."""
    ls = loop_state
    header = (Path(compiled_loop.__file__).parent / "_loop_state.h").read_text()
    core = (Path(compiled_loop.__file__).parent / "_core.c").read_text()
    for enum, prefix in ((ls.Outcome, "OUTCOME"), (ls.Record, "RECORD"), (ls.Reason, "WHY")):
        assert all(f"#define {prefix}_{m.name} {m.value}\n" in header for m in enum)
    assert not re.search(r"why = \d", core)
    sim = bs.HybridSimulator(MODEL, *PDWalkingController(MODEL).initial_state())
    for _ in range(3):
        sim.advance_period(1e-3, [0.5, -0.5])
    loop, data = sim._loop, sim._samples._data
    assert ls.Outcome(loop.period(1e-3, [0.5, -0.5], 0.0, data)) == ls.Outcome.DONE and sim.S[ls.T_NEXT] == 4e-3
    assert ls.Outcome(loop.held(4.5e-3, data)) == ls.Outcome.DONE
    assert ls.Outcome(loop.run(4.5e-3, data)) == ls.Outcome.DONE and sim.S[ls.T] == 4.5e-3     # (at its t_bound)
    assert ls.Outcome(loop.step()) == ls.Outcome.DONE
    assert ls.Outcome(loop.period(1e-3, "not a torque", 0.0, data)) == ls.Outcome.DECLINED


@pytest.mark.skipif(not compiled_loop.AVAILABLE, reason=compiled_loop.WHY_NOT or "no compiled loop")
def test_every_method_of_the_loop_is_one_the_engine_calls():
    """The C Loop's methods are entry points the engine's Python calls by name, none kept for tests only, and the
    module sets its Python checks in one call; the last step's dense rows are read from the state, where
    Loop.dense writes them; a wrong count of arguments to an entry point says how many were given."""
    engine = Path(compiled_loop.__file__).parent
    source = "".join(path.read_text() for path in sorted(engine.glob("*.py")))
    methods = {name for name in dir(compiled_loop._core.Loop) if not name.startswith("_")}
    assert methods == {"begin", "dense", "dense_at", "held", "law_torque", "locate_crossing", "period", "periods",
                       "raise_error", "rhs", "run", "set_kernels", "set_model", "step"}
    assert [name for name in sorted(methods) if not re.search(rf"loop\.{name}\b", source)] == []
    assert {name for name in dir(compiled_loop._core) if not name.startswith("_")} == {
        "KERNELS_SHA256", "Loop", "set_python_checks"}
    sim = bs.HybridSimulator(MODEL, *PDWalkingController(MODEL).initial_state())
    sim.advance_period(1e-3, [0.5, -0.5])
    stepper = sim._compiled
    t = 0.5 * (stepper.t_old + stepper.t)
    assert stepper.t_old < t < stepper.t
    assert np.asarray(stepper.dense_output()(t)).tolist() == stepper.dense_at(t)
    with pytest.raises(TypeError, match=r"run\(\) takes 2 arguments \(1 given\)"):
        sim._loop.run(1.0)


@pytest.mark.skipif(not compiled_loop.AVAILABLE, reason=compiled_loop.WHY_NOT or "no compiled loop")
def test_the_compiled_steppers_fields_are_views_of_the_state():
    """The compiled stepper copies nothing out of the loop: after periods run quiet in C its t, y and step size
    are where C left them (the last sample's), and what the Python code writes into them the loop steps from."""
    sim = bs.HybridSimulator(MODEL, *PDWalkingController(MODEL).initial_state())
    for _ in range(20):
        sim.advance_period(1e-3, [0.5, -0.5])
    st, S = sim._compiled, sim.S
    assert sim.stats["compiled_loop_steps"] > 10 and st.t == sim.t == S[loop_state.T] == 0.02
    assert st.y[:10] == sim.q.tolist() + sim.dq.tolist() and st.h_abs == sim._h
    st.y = [*st.y[:10], 5.0]
    assert S[loop_state.Y + 10] == 5.0


def test_the_impact_history_and_the_mode_events_are_the_states():
    """What a touchdown is checked against (the last impacts, the mode events and the ring of the last 49 of
    their times) is the state's, written where an impact or a mode event happens, by the Python code or by the
    compiled loop, so that nothing is handed over between them (no set_history, no history_stale)."""
    ls = loop_state

    def run():
        sim = bs.HybridSimulator(MODEL, *PDWalkingController(MODEL).initial_state())
        ctrl = PDWalkingController(MODEL)
        while sim.t < 3.0 and sim.status == "running":
            sim.advance_period(1e-3, sim.command(ctrl))
        S, impacts = sim.S, [e.time for e in sim.events if e.kind == "touchdown"]
        modes = [e.time for e in sim.events if e.kind != "scuff"]
        assert len(impacts) >= 5 and (S[ls.N_IMPACTS], S[ls.LAST_IMPACT], S[ls.N_RECENT]) == (
            len(impacts), impacts[-1], min(4, len(impacts)))
        recent = list(S[ls.RECENT_IMPACTS:ls.RECENT_IMPACTS + 4])
        assert recent == impacts[-4:] == sim.impacts.times[-4:]
        assert S[ls.MODE_EVENTS] == len(modes) and all(S[ls.RING + i % 49] == t for i, t in enumerate(modes))
        return sim.result()

    compiled, python = both_loops(run)
    assert_same_run(compiled, python, "the walk")
    if compiled_loop.AVAILABLE:
        assert not any(hasattr(compiled_loop._core.Loop, name) for name in ("set_history", "history_stale"))


@pytest.mark.skipif(not compiled_loop.AVAILABLE, reason=compiled_loop.WHY_NOT or "no compiled loop")
def test_the_touchdowns_the_loop_applies_are_records_in_the_state():
    """A touchdown the compiled loop applies is a row of the state's records (loop_state.RECORD_ROW), which the
    Python code reads to make its Event: a touchdown's row holds its legs, time, q, dq- and dq+;
    no records wait once a period is done, and the Loop keeps none of its own (no take_events)."""
    ls = loop_state
    sim = bs.HybridSimulator(MODEL, *PDWalkingController(MODEL).initial_state())
    ctrl = PDWalkingController(MODEL)
    S, rows = sim.S, {}
    while sim.t < 1.5 and sim.status == "running":
        sim.advance_period(1e-3, sim.command(ctrl))
        row = S[ls.RECORDS:ls.RECORDS + ls.REC_WIDTH].tolist()     # the first record of the period's run
        rows[row[ls.REC_KIND], row[ls.REC_V]] = row
    touchdowns = [e for e in sim.events if e.kind == "touchdown"]
    applied = [e for e in touchdowns if (ls.Record.TOUCHDOWN, e.time) in rows]
    assert len(touchdowns) >= 2 and applied == touchdowns
    for e in applied:
        row = rows[ls.Record.TOUCHDOWN, e.time]
        v = row[ls.REC_V:]
        assert (row[ls.REC_A], row[ls.REC_B]) == (e.stance_leg_before, e.stance_leg_after)
        q, dqm, dqp = ls.REC_TD_Q, ls.REC_TD_DQ_MINUS, ls.REC_TD_DQ_PLUS     # (room for NQ_MAX; N = 5 in use)
        assert v[q:q + 5] == e.q.tolist() and v[dqm:dqm + 5] == e.dq_minus.tolist()
        assert v[dqp:dqp + 5] == e.dq_plus.tolist()
    assert S[ls.N_RECORDS] == 0.0 and not hasattr(compiled_loop._core.Loop, "take_events")


@pytest.mark.skipif(not compiled_loop.AVAILABLE, reason=compiled_loop.WHY_NOT or "no compiled loop")
def test_the_loops_statistics_and_the_step_it_hands_back_are_the_states():
    """Why the compiled loop handed a step back, that step's end torque and force, and the loop's statistics
    (steps, the maxima, the wall time) are fields of the state, which the Python code reads (the Loop has no
    stats() or handed()): a touchdown under a Python controller is handed back (CALLED_BACK_LAW), and the
    simulator's statistics take the loop's steps once, zeroing the state's count."""
    ls = loop_state
    sim = bs.HybridSimulator(MODEL, *PDWalkingController(MODEL).initial_state())
    sim.advance(0.6, controller=UsersController())
    S = sim.S
    assert [e.kind for e in sim.events if e.kind == "touchdown"] and S[ls.WHY] == ls.Reason.CALLED_BACK_LAW
    steps = S[ls.STEPS]
    assert steps > 10 and S[ls.MAX_DRIFT] >= 0.0 and S[ls.MAX_RESIDUAL] > 0.0
    assert sim.stats["compiled_loop_steps"] == steps and S[ls.STEPS] == 0.0 and S[ls.MAX_RESIDUAL] == 0.0
    assert sim.stats["compiled_loop_steps"] == steps
    assert not any(hasattr(compiled_loop._core.Loop, name) for name in ("stats", "handed"))


def test_the_simulators_stance_leg_and_pin_are_the_states():
    """The stance leg and the pin are one copy, the state's fields, on both loops: the simulator's stance_leg and
    pin read and write them (no copy into the state when a mode begins, none back after the compiled loop's
    touchdowns), across touchdowns and a push into flight (where the pin is None)."""
    ls = loop_state

    def run():
        sim = bs.HybridSimulator(MODEL, *PDWalkingController(MODEL).initial_state())
        ctrl = PDWalkingController(MODEL)
        S, legs = sim.S, set()
        while sim.t < 1.2 and sim.status == "running":
            sim.advance_period(1e-3, sim.command(ctrl))
            pin = [S[ls.PIN], S[ls.PIN + 1]]
            assert (sim.stance_leg, sim.pin) == (S[ls.STANCE_LEG], pin)
            legs.add(sim.stance_leg)
        assert legs == {1, 2}
        sim.stance_leg, sim.pin = 0, None
        assert S[ls.STANCE_LEG] == 0.0 and sim.pin is None
        return sim.result()

    compiled, python = both_loops(run)
    assert_same_run(compiled, python, "the walk")
    assert all(isinstance(vars(hybrid.HybridSimulator)[name], property) for name in ("stance_leg", "pin"))


def test_a_change_of_the_simulators_state_in_python_begins_the_loops_mode_again():
    """No hand-over flag: the loop's mode is begun at the simulator's state (mode_begun), and any write of that
    state by the Python code (a push's velocities here) clears it, so that the next period begins the mode again
    from the new state, as the Python loop's new stepper does: the same run on both loops."""
    ls = loop_state

    def run():
        sim = bs.HybridSimulator(MODEL, *PDWalkingController(MODEL).initial_state())
        for _ in range(20):
            sim.advance_period(1e-3, [0.5, -0.5])
        begun = sim.S[ls.MODE_BEGUN]
        sim.push([3.0, 0.0])
        assert sim.S[ls.MODE_BEGUN] == 0.0
        for _ in range(20):
            sim.advance_period(1e-3, [0.5, -0.5])
        return begun, sim.result()

    (begun_c, compiled), (_, python) = both_loops(run)
    assert_same_run(compiled, python, "a push between periods")
    assert begun_c == float(compiled_loop.AVAILABLE)
    assert not hasattr(compiled_loop.CompiledStepper, "python_changed")
    if compiled_loop.AVAILABLE:
        assert not hasattr(compiled_loop._core.Loop, "state_stale")


def described_loop(name):
    """(model, C Loop over the kernels of the shipped robot ``name``'s compiled twin, its state S)."""
    from biped_sim.config import models
    from biped_sim.engine import model_kernels
    model = models.generated_model(name)
    twin = model_kernels.compiled_kernels(model)
    assert twin is not None, "the shipped twin was not built: make venv"
    loop = compiled_loop._core.Loop()
    loop.set_kernels(twin.KERNEL_TABLE, list(model.actuated_indices), model.name)
    return model, loop, memoryview(loop).cast("d")


@pytest.mark.parametrize("name", ["rabbit", "compass_gait"])
def test_a_described_robots_right_hand_side_in_c_is_the_python_loops_bit_for_bit(name):
    """The C Loop over a described robot's kernel table (set_kernels) evaluates modes._generated_functions'
    right-hand side bit for bit: stance on each contact point and flight, y = q + dq + [work], the motors' power
    u . (B^T dq), under M held torques (rhs; begin's f) and a Python controller called back with N-entry q and dq
    (its M torques as a list or an array); a controller's failure is the same ControllerError."""
    from biped_sim.engine import modes
    model, loop, S = described_loop(name)
    n, m = model.n, model.m
    rng = np.random.default_rng(31)

    def controller(t, q, dq, leg):
        return [0.5 * q[2 + i] - 0.1 * dq[n - 1 - i] + t * leg for i in range(m)]

    def array_controller(t, q, dq, leg):
        return np.array(controller(t, q, dq, leg))

    for leg in [1, 2, 0]:
        for _ in range(3):
            y = rng.uniform(-1, 1, 2 * n + 1).tolist()
            y[1], t, u = rng.uniform(0.5, 1.2), float(rng.uniform(0, 2)), rng.uniform(-20, 20, m).tolist()
            loop_state.write(S, stance_leg=leg, u_hold=u, method=0, t=t, y=y, t_bound=t + 1.0)
            held, _, _ = modes.mode_functions(model, leg, "floating", [0.0, 0.0], u, None, lambda F, u: None)
            loop.begin(None)
            assert loop.rhs(t, y) == held(t, y), (leg, "held")
            assert S[loop_state.F:loop_state.F + 2 * n + 1].tolist() == held(t, y), (leg, "begin's f")
            for law in (controller, array_controller):
                control = modes.bind_controller(law, leg, m)
                called, _, _ = modes.mode_functions(model, leg, "floating", [0.0, 0.0], u, control, lambda F, u: None)
                loop.begin(law)
                assert loop.rhs(t, y) == called(t, y), (leg, law.__name__)

    def bad(t, q, dq, leg):
        return [1.0] * (m + 1)

    control = modes.bind_controller(bad, 1, m)
    called, _, _ = modes.mode_functions(model, 1, "floating", [0.0, 0.0], [0.0] * m, control, lambda F, u: None)
    loop_state.write(S, stance_leg=1, t=0.25, y=y)
    with pytest.raises(bs.ControllerError) as python_error:
        called(0.25, y)
    with pytest.raises(bs.ControllerError) as c_error:
        loop.begin(bad)     # (its f = rhs(t, y) calls the controller)
    assert str(c_error.value) == str(python_error.value)


def test_a_described_robots_loop_refuses_what_it_cannot_run_in_one_line():
    """The Loop over a described robot runs its steps, quiet steps and periods (begin, step, dense_at, run, held,
    periods) under a held torque or a Python controller; a compiled law (begin, periods, law_torque) is refused with
    one line, the node's period with other than M torques is declined (the Python code says why), and joints that are
    not entries of q are refused."""
    from biped_sim.engine import model_kernels
    model, loop, S = described_loop("rabbit")
    y = [0.0, 0.9, np.pi + 0.1, np.pi - 0.2, -0.05, 0.5, 0.05] + [0.0] * (model.n + 1)
    loop_state.write(S, stance_leg=1, u_hold=[0.0] * model.m, method=0, t=0.0, t_bound=1.0, h_abs=1e-3, y=y,
                     max_step=np.inf, rtol=1e-9, atol=1e-9)
    loop.begin(None)
    assert loop_state.Outcome(loop.step()) == loop_state.Outcome.DONE and S[loop_state.T] > 0.0
    assert len(loop.dense_at(S[loop_state.T])) == 2 * model.n + 1
    data = np.zeros((4, loop_state.sample_row(model.n, model.m)["ROW_WIDTH"]))
    law = (1, [0.0], "law")
    with pytest.raises(ValueError, match=r"^law_torque\(\): a compiled law runs the three-link biped only") as e:
        loop.law_torque(law)
    with pytest.raises(ValueError, match=r"^periods\(\): a described robot's law is a Python controller") as f:
        loop.periods(law, 1e-3, 1.0, np.inf, data)
    with pytest.raises(ValueError, match="a described robot runs dop853") as g:
        loop.begin(law)
    assert not any("\n" in str(x.value) for x in (e, f, g))
    assert loop_state.Outcome(loop.period(1e-3, [0.0] * 2, 1.0, data)) == loop_state.Outcome.DECLINED     # (not M)
    table = model_kernels.compiled_kernels(model).KERNEL_TABLE
    with pytest.raises(ValueError, match=r"joints\[0\] is not an entry of q \(0\.\.6\)"):
        loop.set_kernels(table, [99] * model.m, "rabbit")



def assert_same_bits(a, b, what=""):
    """The same run bit for bit: status, events (kinds, legs, times), samples and counters."""
    assert_same_run(a, b, what)
    assert [e.time for e in a.events] == [e.time for e in b.events], what
    for name in ("t", "q", "dq", "u", "grf", "stance_leg"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=f"{what} {name}")


def on_both_loops_counting_c_steps(run, monkeypatch):
    """(compiled, python, steps the compiled run took in C, touchdowns it located in C): both_loops with the steps
    taken in C (the quiet steps, compiled_loop_steps, and the steps handed to the Python code, CompiledStepper.step)
    and the touchdowns located in C (applied there: the loop's records; or handed back: Loop.locate_crossing's roots)
    counted."""
    taken, roots = [], []
    step, crossing = compiled_loop.CompiledStepper.step, compiled_loop.CompiledStepper.height_crossing
    records = compiled_loop.take_records
    monkeypatch.setattr(compiled_loop.CompiledStepper, "step", lambda self: (taken.append(1), step(self))[1])
    monkeypatch.setattr(compiled_loop.CompiledStepper, "height_crossing",
                        lambda self, *a: (lambda t: (roots.append(t is not None), t)[1])(crossing(self, *a)))

    def counted_records(S, n=5):
        out = records(S, n)
        roots.extend(r[0] == loop_state.Record.TOUCHDOWN for r in out)
        return out
    monkeypatch.setattr(compiled_loop, "take_records", counted_records)
    a, b = both_loops(run)
    return a, b, a.stats["compiled_loop_steps"] + len(taken), sum(roots)


DESCRIBED_RUNS = {
    # the rabbit scene's walk, the control period held and continuous
    "rabbit walk held": lambda: bs.load_scene("rabbit").simulate(hold=True, t_final=2.0),
    "rabbit walk continuous": lambda: bs.load_scene("rabbit").simulate(hold=False, t_final=2.0),
    # dropped from 5 cm in flight (the Python loop's mode), foot 1 lands, stance (the compiled loop's steps)
    "rabbit drop": lambda: bs.simulate(*_rabbit_on_foot_1(lift=0.05), 0.3, stance_leg=0),
    # a knee torque ramped up lifts the stance foot off: without the flight phase the liftoff stops the run; with
    # it, flight, a touchdown and impacts that accumulate (a Zeno stop)
    "rabbit liftoff stops": lambda: _kicking_rabbit(phases=frozenset({"stance", "impact"})),
    "rabbit liftoff, flight, zeno": lambda: _kicking_rabbit(),
    # the same kick held over 1 ms periods (their commands computed from C): the stance guards refuse a period's
    # command at its start, and the Python code runs that period
    "rabbit kick held": lambda: _kicking_rabbit(control_period=1e-3),
    # a law that raises in a period: the run fails with its ControllerError
    "rabbit law raises": lambda: _kicking_rabbit(control_period=1e-3, raise_at=0.02),
    # the node's periods: advance_period with M torques given, each period run whole in C (Loop.period)
    "rabbit node periods": lambda: _rabbit_node_periods(),
    # the compass gait's description as a GeneratedModel, passive down its slope: touchdowns and scuffs
    "compass gait": lambda: bs.simulate(_generated("compass_gait"), np.array([0.0, 1.0, np.pi, np.pi, 0.0]),
                                        np.array([0.4, 0.0, 0.4, -2.0, 0.0]), 3.0, rtol=1e-10, atol=1e-10,
                                        slope=0.0525, phases=frozenset({"stance", "impact"})),
}


def _generated(name):
    from biped_sim.config import models
    return models.generated_model(name)


def _rabbit_node_periods():
    from biped_sim.engine.hybrid import HybridSimulator
    rabbit, q0, dq0 = _rabbit_on_foot_1()
    sim = HybridSimulator(rabbit, q0, dq0, stance_leg=1)
    for k in range(300):
        sim.advance_period(1e-3, [0.0, 0.0, 5.0 * min(k / 100, 1.0), -2.0])
    return sim.result()


def _kicking_rabbit(raise_at=None, **options):
    rabbit, q0, dq0 = _rabbit_on_foot_1()

    def knee_kick(t, q, dq, leg):
        if raise_at is not None and t >= raise_at:
            raise RuntimeError("the knee law broke")
        return [0.0, 0.0, -50.0 * min(t / 0.05, 1.0), 0.0]
    return bs.simulate(rabbit, q0, dq0, 0.3, controller=knee_kick, stance_leg=1, **options)


@pytest.mark.parametrize("name", list(DESCRIBED_RUNS))
def test_a_described_robot_runs_the_same_on_both_loops_bit_for_bit(name, monkeypatch):
    """A described robot (a GeneratedModel) on the compiled loop, its stance steps taken in C on its kernels' C entry
    points (and its touchdowns' crossings located there) and each handled by the Python loop, gives the Python loop's
    run bit for bit."""
    a, b, c_steps, c_roots = on_both_loops_counting_c_steps(DESCRIBED_RUNS[name], monkeypatch)
    assert_same_bits(a, b, name)
    assert c_steps > (0.5 * a.stats["steps"] if "walk" in name else 0), (c_steps, a.stats["steps"])
    if "walk" in name or name == "compass gait":     # its touchdowns located in C (the table's foot positions)
        assert c_roots >= 1, name
    assert a.events or name == "rabbit law raises", name
    if name == "rabbit liftoff stops":
        assert a.status == "stopped" and "would lift off" in a.message, (a.status, a.message)
    if name == "rabbit law raises":
        assert a.status == "failed" and "the knee law broke" in a.message, (a.status, a.message)
    if name == "rabbit liftoff, flight, zeno":
        assert [e.kind for e in a.events[:2]] == ["liftoff", "touchdown"] and a.events[-1].kind == "zeno"


def test_a_users_description_runs_on_the_compiled_loop_after_its_build(tmp_path, monkeypatch):
    """A user's description (a YAML file in a folder of theirs: the three-link with 4 kg legs) is generated and its
    kernels built on first use; the compiled loop then steps it, and its run is the Python loop's bit for bit."""
    pytest.importorskip("sympy")
    import yaml

    from biped_sim.config import models
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    data = yaml.safe_load((models.ROBOTS_DIR / "three_link.yaml").read_text())
    data["name"] = "stilts"
    for leg in ("leg_1", "leg_2"):
        data["links"][leg]["mass"] = 4.0
    path = tmp_path / "stilts.yaml"
    path.write_text(yaml.safe_dump(data))
    model = models.generated_model(str(path))
    assert compiled_loop.why_not_described(model) == ""
    q0, dq0 = np.array([0.0, 1.0, np.pi, np.pi, 0.0]), np.array([0.4, 0.0, 0.4, -2.0, 0.0])
    a, b, c_steps, c_roots = on_both_loops_counting_c_steps(
        lambda: bs.simulate(model, q0, dq0, 1.5, slope=0.0525, phases=frozenset({"stance", "impact"})), monkeypatch)
    assert_same_bits(a, b, "stilts")
    assert a.impacts and c_steps > 0.5 * a.stats["steps"] and c_roots >= 1


def test_a_described_robots_node_period_runs_whole_in_c():
    """The node's period of a described robot (advance_period with its M torques) is one call of Loop.period, which
    runs it whole in C (DONE), as the three-link's."""
    from biped_sim.engine.hybrid import HybridSimulator
    rabbit, q0, dq0 = _rabbit_on_foot_1()
    sim = HybridSimulator(rabbit, q0, dq0, stance_leg=1)
    for _ in range(3):
        sim.advance_period(1e-3, [0.0, 0.0, 1.0, -1.0])
    assert sim._stepper is sim._compiled and sim._compiled.described
    outcome = sim._compiled.loop.period(1e-3, [0.0, 0.0, 1.0, -1.0], 0.0, sim._samples._data)
    assert loop_state.Outcome(outcome) == loop_state.Outcome.DONE and sim.t == pytest.approx(4e-3, abs=1e-15)
