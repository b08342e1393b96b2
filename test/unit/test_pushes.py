"""Pushes (docs/engine.md "Pushes"): an impulse P on the hip as a velocity jump with the stance foot
held. Properties of ``push_response`` over random stance and flight states (momentum balance, the
foot stays pinned, the energy change is the work of the impulse, a zero push is the identity),
the hard cases (a push that lifts the foot, bad pushes, the fixed base), and ``simulate(pushes=...)``
against the same push through ``HybridSimulator``."""
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import biped_sim as bs
from biped_sim.engine.dynamics import J_HIP, push_response
from biped_sim.engine.resets import PUSH_IMPULSE_LIMIT

MODEL = bs.BipedModel()
impulse = st.tuples(st.floats(-20.0, 20.0), st.floats(-20.0, 20.0))


@st.composite
def stance_state(draw):
    leg = draw(st.sampled_from([1, 2]))
    a, torso = draw(st.floats(-0.6, 0.6)), draw(st.floats(-0.4, 0.4))
    b = math.copysign(abs(a) + draw(st.floats(0.05, 0.3)), draw(st.sampled_from([-1.0, 1.0])))   # swing foot up
    joints = [math.pi + a - torso, math.pi + b - torso, torso]
    if leg == 2:
        joints[0], joints[1] = joints[1], joints[0]
    rates = draw(st.tuples(*[st.floats(-2.0, 2.0)] * 3))
    q, dq = bs.stance_state(MODEL, joints, rates, stance_leg=leg)
    return q, dq, leg


@settings(max_examples=60, deadline=None)
@given(stance_state(), impulse)
def test_stance_push_balances_momentum_holds_the_foot_and_does_the_impulse_work(state, P):
    q, dq, leg = state
    P = np.array(P)
    dq_plus, ground = push_response(MODEL, q, dq, P, leg)
    D = MODEL.mass_matrix(q)
    J = MODEL.foot_jacobian(q, leg)
    # D dq+ - D dq = J_hip^T P + J_st^T Lambda; rows x, y: total linear momentum change = P + Lambda
    assert np.allclose(D @ dq_plus - D @ dq, J_HIP.T @ P + J.T @ ground, atol=1e-10)
    assert np.allclose((D @ (dq_plus - dq))[:2], P + ground, atol=1e-10)
    assert np.allclose(J @ dq_plus, 0.0, atol=1e-12)        # the foot stays pinned
    # the impulse's work: P . (v_hip- + v_hip+) / 2 (the pinned foot does none)
    dE = 0.5 * dq_plus @ D @ dq_plus - 0.5 * dq @ D @ dq
    assert dE == pytest.approx(P @ (dq[:2] + dq_plus[:2]) / 2, abs=1e-9)
    assert MODEL.energy(q, dq_plus) - MODEL.energy(q, dq) == pytest.approx(dE, abs=1e-9)


@settings(max_examples=30, deadline=None)
@given(stance_state(), impulse)
def test_flight_push_changes_momentum_by_the_impulse(state, P):
    q, dq, _leg = state
    P = np.array(P)
    dq_plus, ground = push_response(MODEL, q, dq, P, 0)
    D = MODEL.mass_matrix(q)
    assert ground.tolist() == [0.0, 0.0]
    assert np.allclose(D @ (dq_plus - dq), J_HIP.T @ P, atol=1e-10)


@settings(max_examples=20, deadline=None)
@given(stance_state())
def test_a_zero_push_is_the_identity(state):
    q, dq, leg = state
    for stance in (leg, 0):
        dq_plus, ground = push_response(MODEL, q, dq, [0.0, 0.0], stance)
        assert dq_plus.tolist() == dq.tolist() and ground.tolist() == [0.0, 0.0]
    sim = bs.HybridSimulator(MODEL, q, dq, leg, phases={"stance", "impact", "flight"})
    events = sim.push([0.0, 0.0])
    # (a start whose normal force is already negative then lifts off, as it would at its first advance)
    assert events[0].kind == "push" and events[0].dq_plus.tolist() == dq.tolist() == sim.dq.tolist()
    assert events[0].energy_loss == 0.0 and sim.push_work == 0.0


def walk_state():
    scene = bs.load_scene("walk")
    args = scene.engine_arguments()
    return args["q0"], args["dq0"]


def test_push_event_and_the_energy_balance_of_a_pushed_run():
    r = bs.load_scene("walk").simulate(t_final=0.8, pushes=[(0.3, [-3.0, 0.0])])
    pushes = [e for e in r.events if e.kind == "push"]
    assert r.status == "completed", r.message
    assert len(pushes) == 1
    ev = pushes[0]
    assert ev.time == pytest.approx(0.3, abs=1e-3) and ev.push.tolist() == [-3.0, 0.0]
    assert ev.stance_leg_before == ev.stance_leg_after == 1 and ev.impulse[1] > 0
    assert ev.dq_plus[0] < ev.dq_minus[0]                      # pushed backwards
    assert r.stats["pushes"] == 1 and r.stats["push_work"] == pytest.approx(-ev.energy_loss)
    assert r.stats["max_energy_balance_residual"] < 1e-6       # the push's work is accounted for


def test_simulate_with_pushes_equals_the_push_through_the_simulator():
    scene = bs.load_scene("walk")
    kw = scene.simulate_kwargs()
    period = kw["control_period"]
    r = scene.simulate(t_final=0.6, pushes=[(0.25, [-3.0, -1.0]), (0.4005, [2.0, -1.0])])
    model, q0, dq0 = kw.pop("model"), kw.pop("q0"), kw.pop("dq0")
    controller, leg = kw.pop("controller"), kw.pop("stance_leg", 1)
    for name in ("t_final", "control_period", "pushes"):
        kw.pop(name, None)
    sim = bs.HybridSimulator(model, q0, dq0, leg, **kw)
    while sim.t < 0.6 and sim.status == "running":
        if abs(sim.t - 0.25) < 1e-12 or abs(sim.t - 0.401) < 1e-12:   # the period starts at or after each push
            sim.push([-3.0, -1.0] if sim.t < 0.3 else [2.0, -1.0])
        sim.advance_period(period, controller=controller, t_final=0.6)
    r2 = sim.result()
    assert r.status == "completed" and [e.kind for e in r.events].count("push") == 2
    assert [e.kind for e in r.events] == [e.kind for e in r2.events]
    assert np.array_equal(r.q, r2.q) and np.array_equal(r.dq, r2.dq)


def test_an_upward_push_lifts_the_foot_in_flight_scenes_and_stops_the_others():
    q, dq = walk_state()
    sim = bs.HybridSimulator(MODEL, q, dq, 1, phases={"stance", "impact", "flight"})
    events = sim.push([0.0, 30.0])
    assert [e.kind for e in events] == ["push", "liftoff"]
    assert events[0].stance_leg_after == 0 and events[0].impulse.tolist() == [0.0, 0.0]
    assert sim.stance_leg == 0 and sim.status == "running"
    assert MODEL.foot_velocity(q, sim.dq, 1)[1] > 0             # the foot leaves the ground
    sim.advance(0.05)
    assert sim.status == "running"

    stiff = bs.HybridSimulator(MODEL, q, dq, 1, phases={"stance", "impact"})
    events = stiff.push([0.0, 30.0])
    assert [e.kind for e in events] == ["error"] and stiff.status == "stopped"
    assert "lifts the stance foot (leg 1) off the ground" in stiff.message and "add 'flight'" in stiff.message
    assert stiff.dq.tolist() == list(dq)                        # nothing applied quietly


def test_fixed_base_push_equals_floating_base():
    q, dq = walk_state()
    a = bs.HybridSimulator(MODEL, q, dq, 1, base="floating", phases={"stance", "impact"})
    b = bs.HybridSimulator(MODEL, q, dq, 1, base="fixed", phases={"stance", "impact"})
    ea, eb = a.push([-4.0, -2.0]), b.push([-4.0, -2.0])
    assert ea[0].kind == eb[0].kind == "push"
    assert np.allclose(ea[0].dq_plus, eb[0].dq_plus, atol=1e-13)
    # the fixed base's chain (q1, q2, q3): D_s dqs+ = D_s dqs + J_hip,s^T P with J_hip,s = J_hip N,
    # N = d q / d qs (the pinned chain's motions, the null space of J_st)
    N = np.linalg.svd(MODEL.foot_jacobian(q, 1))[2][2:].T             # 5 x 3, J_st N = 0
    D = MODEL.mass_matrix(q)
    Ds = N.T @ D @ N
    dqs = np.linalg.lstsq(N, dq, rcond=None)[0]
    dqs_plus = dqs + np.linalg.solve(Ds, N.T @ J_HIP.T @ np.array([-4.0, -2.0]))
    assert np.allclose(N @ dqs_plus, eb[0].dq_plus, atol=1e-12)
    a.advance(0.03)
    b.advance(0.03)                       # the run goes on from there, on either base alike
    assert a.status == b.status == "running" and np.allclose(a.q, b.q, atol=1e-7)


@pytest.mark.parametrize("bad, what", [
    ([float("nan"), 0.0], "non-finite"), ([0.0, float("inf")], "non-finite"), ([1.0, 2.0, 0.0], "shape"),
    ([PUSH_IMPULSE_LIMIT, 1.0], "above the limit"), ("12", "2 real numbers"), (None, "impulse"),
    ({1: 0.0, 2: 0.0}, "2 real numbers"), ([True, False], "[True, False]"), (np.array([1 + 0j, 0j]), "complex"),
    ([0.5, None], "[0.5, None]")])
def test_bad_pushes_raise_naming_the_argument(bad, what):
    q, dq = walk_state()
    sim = bs.HybridSimulator(MODEL, q, dq, 1)
    with pytest.raises(ValueError, match="impulse") as exc:
        sim.push(bad)
    assert what in str(exc.value)
    assert sim.events == [] and sim.status == "running"
    with pytest.raises(ValueError, match=r"pushes\[0\]"):
        bs.simulate(MODEL, q, dq, 0.1, pushes=[(0.05, bad)])
    with pytest.raises(ValueError, match=r"pushes\[0\] time"):
        bs.simulate(MODEL, q, dq, 0.1, pushes=[(0.5, [1.0, 0.0])])
