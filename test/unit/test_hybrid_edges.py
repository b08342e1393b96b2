"""Hybrid edges (issue 14): bad arguments are refused before a run, a controller fault ends the run
"failed" with its message in both control modes, and no run ends "completed" with a wrong answer."""
import math
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings, strategies as st

import biped_sim as bs
from biped_sim.analysis.edge_cases import (
    bouncing_landing,
    coincident_crossing,
    grazing_flight,
    spinning_stance,
    swing_foot_just_above,
)
from biped_sim.analysis.verify import violations
from biped_sim.engine import compiled_loop

MODEL = bs.BipedModel()
WALKER = bs.WalkingController(MODEL)
Q0, DQ0 = WALKER.initial_state()


def _run(t_final=0.05, **kw):
    return bs.simulate(MODEL, Q0, DQ0, t_final, **kw)


@pytest.mark.parametrize("index, vector, value", [(0, "q", math.nan), (1, "q", math.nan),
                                                  (0, "dq", math.inf), (1, "dq", -math.inf)])
def test_stance_dynamics_refuses_non_finite_base_coordinates(index, vector, value):
    # x, y and their rates do not enter the dynamics, so the closed form alone would not notice
    q, dq = Q0.copy(), DQ0.copy()
    (q if vector == "q" else dq)[index] = value
    with pytest.raises(ValueError, match=rf"{vector} has non-finite entries at index \[{index}\]"):
        bs.stance_dynamics(MODEL, q, dq)


BAD_TORQUES = ["ab", {"a": 1.0}, 1 + 2j, [1.0], [1.0, 2.0, 3.0], [math.nan, 0.0], None,
               # what float() or numpy would take without a word: two characters, a dict's keys, bools, a
               # complex array's real parts, a None entry, a column
               "12", {1: 0.0, 2: 0.0}, [True, False], (0.5, True), np.array([True, False]), np.array([1 + 0j, 2 + 0j]),
               [0.5, 1j], ["1", "2"], [0.5, None], [[0.5], [0.5]], {1.0, 2.0}, b"12"]


@pytest.fixture(params=["compiled loop", "Python loop"])
def loop(request):
    compiled_loop.enabled = request.param == "compiled loop"
    yield request.param
    compiled_loop.enabled = True


@pytest.mark.parametrize("control_period", [None, 0.01])
@pytest.mark.parametrize("bad", BAD_TORQUES, ids=repr)
def test_a_controller_returning_anything_but_two_finite_torques_fails_the_run(bad, control_period, loop):
    r = _run(controller=lambda *a: bad, control_period=control_period)
    assert r.status == "failed"
    assert f"the controller returned {bad!r}" in r.message and "two finite torques" in r.message
    assert r.events[-1].kind == "error"


def _pushed_sim(v):
    return bs.HybridSimulator(MODEL, Q0, DQ0).push(v)


def _held(v, how):
    sim = bs.HybridSimulator(MODEL, Q0, DQ0)
    sim.advance_period(1e-3, [0.0, 0.0])
    sim.advance_period(1e-3, [0.0, 0.0])    # (on the compiled loop, this one in one C call: Loop.period)
    return sim.advance(0.01, u=v) if how == "advance" else sim.advance_period(1e-3, u=v)


#: (the argument's name in the message, how many numbers it takes, a call that gives it v)
ENTRY_POINTS = [
    ("q0", 5, lambda v: bs.simulate(MODEL, v, DQ0, 0.01)),
    ("dq0", 5, lambda v: bs.HybridSimulator(MODEL, Q0, v)),
    ("joints", 3, lambda v: bs.stance_state(MODEL, v, [0.0, 0.0, 0.0])),
    ("joint_rates", 3, lambda v: bs.stance_state(MODEL, [3.0, 3.2, 0.1], v)),
    ("foot", 2, lambda v: bs.stance_state(MODEL, [3.0, 3.2, 0.1], [0.0, 0.0, 0.0], foot=v)),
    ("pushes[0] impulse", 2, lambda v: bs.simulate(MODEL, Q0, DQ0, 0.01, pushes=[(0.005, v)])),
    ("impulse", 2, _pushed_sim),
    ("u", 2, lambda v: _held(v, "advance")),
    ("u", 2, lambda v: _held(v, "advance_period")),
    ("q", 5, lambda v: bs.stance_dynamics(MODEL, v, DQ0)),
    ("u", 2, lambda v: bs.stance_dynamics(MODEL, Q0, DQ0, v)),
    ("dq", 5, lambda v: bs.flight_dynamics(MODEL, Q0, v)),
    ("dq_minus", 5, lambda v: bs.impact_map(MODEL, Q0, v)),
    ("q", 5, lambda v: bs.relabel(v, DQ0)),
    ("q", 5, lambda v: MODEL.mass_matrix(v)),
]


@st.composite
def not_real_numbers(draw, n):
    """n "numbers" that numpy or float() would convert without a word (or a NaN, an infinity among them)."""
    whole = ["12345"[:n], b"12345"[:n], {i: 0.0 for i in range(1, n + 1)}, set(range(1, n + 1)), None,
             np.ones(n, bool), np.zeros(n, complex), np.array(["1"] * n), np.zeros((n, 1))]
    entries = [True, np.bool_(False), 1j, 2 + 0j, "1", b"1", None, [0.5], {0.5}, math.nan, -math.inf]
    if draw(st.booleans()):
        return draw(st.sampled_from(whole))
    v = [0.1 * i for i in range(n)]
    v[draw(st.integers(0, n - 1))] = draw(st.sampled_from(entries))
    return draw(st.sampled_from([list, tuple]))(v)


@pytest.mark.parametrize("name, n, call", ENTRY_POINTS, ids=[f"{e[0]}-{i}" for i, e in enumerate(ENTRY_POINTS)])
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())   # (the loop fixture holds for every example)
def test_arguments_that_are_not_finite_real_numbers_are_refused_by_name(loop, name, n, call, data):
    bad = data.draw(not_real_numbers(n))
    assume(not (name == "u" and bad is None))     # (u=None: the torque held stays)
    with pytest.raises(ValueError) as exc:
        call(bad)
    message = str(exc.value)
    assert message.startswith(name + " ")
    shown = repr(bad)[:40]
    assert shown in message or "non-finite entries" in message or f"must have shape ({n},)" in message


@pytest.mark.parametrize("good", [[1, 2], (np.float32(1.0), np.int64(2)), np.array([1, 2]), np.array([1.0, 2.0]),
                                  [np.array(1.0), 2.0], (1.0, 2.0)], ids=repr)
def test_a_torque_of_real_numbers_of_any_type_is_held_as_floats(loop, good):
    runs = []
    for u in (good, [1.0, 2.0]):
        sim = bs.HybridSimulator(MODEL, Q0, DQ0)
        for _ in range(3):
            sim.advance_period(1e-3, u)
        assert sim.u == [1.0, 2.0] and all(type(v) is float for v in sim.u)
        runs.append(sim.result())
    np.testing.assert_array_equal(runs[0].q, runs[1].q)


@pytest.mark.parametrize("bad", [[True, False], (0.5, True), [0.5, 1j], [np.float64(0.5), False]], ids=repr)
def test_a_held_torque_of_bools_or_complex_numbers_begins_no_period_on_either_loop(loop, bad):
    sim = bs.HybridSimulator(MODEL, Q0, DQ0)
    for _ in range(2):
        sim.advance_period(1e-3, [0.5, -0.5])
    quiet = sim._q is None    # the second period ran in one C call (Loop.period), which sees the next one first
    assert quiet == (loop == "compiled loop")
    with pytest.raises(ValueError, match=r"u must be two finite torques .*got " + re.escape(repr(bad))):
        sim.advance_period(1e-3, bad)
    assert sim.control_periods == 2 and sim.u == [0.5, -0.5] and sim.t == 2e-3


@pytest.mark.parametrize("control_period", [None, 0.01])
def test_a_controller_that_raises_fails_the_run_with_its_message(control_period):
    def controller(t, q, dq, stance_leg):
        if t > 0.02:
            raise RuntimeError("gain table missing")
        return [0.0, 0.0]
    r = _run(controller=controller, control_period=control_period)
    assert r.status == "failed"
    assert "the controller raised RuntimeError" in r.message and "gain table missing" in r.message
    # the run stops at the last accepted state before the fault (continuous feedback: the start of
    # the step in which a stage asked past t = 0.02; held torque: the period that would start after it)
    assert r.t[-1] <= 0.03 and (control_period is None or r.t[-1] >= 0.02)


@pytest.mark.parametrize("name, value, allowed", [
    ("slope", math.nan, "strictly between -pi/2 and pi/2"), ("slope", math.inf, "pi/2"),
    ("slope", math.pi / 2, "pi/2"), ("slope", -2.0, "pi/2"),
    ("event_tol", -1e-12, "event_tol"), ("event_tol", math.nan, "event_tol"),
    ("max_step", -1.0, "max_step"), ("max_step", math.nan, "max_step"),
    ("arm_height", -1e-9, "arm_height"), ("arm_height", math.nan, "arm_height"),
    ("contact_tol", -1e-6, "contact_tol"), ("contact_tol", math.nan, "contact_tol"),
    ("max_events", 0, "max_events"), ("zeno_count", 2.5, "zeno_count"),
])
def test_options_out_of_range_are_refused_by_name(name, value, allowed):
    with pytest.raises(ValueError, match=rf"{name} must be .*got {value!r}".replace("(", r"\(").replace(")", r"\)")):
        _run(**{name: value})
    with pytest.raises(ValueError, match=allowed.replace("(", r"\(")):
        _run(**{name: value})


@pytest.mark.parametrize("step", [-1e-3, 0.0, math.nan, math.inf])
def test_a_fixed_step_method_refuses_a_step_that_is_not_positive_and_finite(step):
    with pytest.raises(ValueError, match="step must be a number in"):
        _run(method="rk4", step=step)


def test_rtol_below_double_precision_is_refused():
    with pytest.raises(ValueError, match="rtol .*double precision"):
        _run(rtol=1e-20, atol=1e-20)
    assert _run(rtol=1e-13, atol=1e-13).status == "completed"


def test_t_final_accepts_numpy_numbers_and_refuses_booleans():
    assert _run(t_final=np.int64(0)).status == "completed"
    assert _run(t_final=np.float64(0.01)).t[-1] == 0.01
    with pytest.raises(ValueError, match="t_final .*got True"):
        _run(t_final=True)


@pytest.mark.parametrize("leg", [1.0, True, "1", 3, -1])
def test_stance_leg_must_be_the_integer_0_1_or_2(leg):
    with pytest.raises(ValueError, match="stance_leg must be 1, 2 or 0"):
        _run(stance_leg=leg)


def test_control_period_without_a_controller_is_refused():
    with pytest.raises(ValueError, match="control_period needs a controller"):
        _run(control_period=0.01)


@pytest.mark.parametrize("t_end", [math.nan, math.inf, "1", None])
def test_advance_refuses_a_time_that_is_not_a_finite_number(t_end):
    sim = bs.HybridSimulator(MODEL, Q0, DQ0)
    with pytest.raises(ValueError, match="t_end must be a finite number"):
        sim.advance(t_end)


# -- item 5: the torque at every sample is the one applied there --------------------------------------
@pytest.mark.parametrize("control_period", [None, 0.01])
def test_result_u_is_the_torque_applied_at_each_sample_and_grf0_is_under_it(control_period):
    r = _run(t_final=1.2, controller=WALKER, control_period=control_period)
    assert r.status == "completed" and len(r.impacts) >= 2
    assert np.abs(r.u).max() > 10.0                       # not all zeros
    if control_period is None:
        # continuous feedback: the controller's torque at the sample's own state (the projection
        # after a step moves the state by the constraint drift only)
        expected = np.array([WALKER(t, q, dq, int(leg)) for t, q, dq, leg in zip(r.t, r.q, r.dq, r.stance_leg)])
    else:
        # zero-order hold: the torque computed at the start of the sample's control period (the
        # period that ends at a sample is still under the torque it started with)
        period_start = np.floor(r.t / control_period - 1e-9) * control_period
        period_start[0] = 0.0
        first = {}
        for k in range(len(r.t)):
            first.setdefault(round(period_start[k] / control_period), k)
        expected = np.array([r.u[first[round(p / control_period)]] for p in period_start])
        assert np.array_equal(r.u[0], WALKER(0.0, Q0, DQ0, 1))
    assert np.allclose(r.u, expected, rtol=1e-9, atol=1e-9)
    F0 = bs.stance_dynamics(MODEL, Q0, DQ0, r.u[0])[1]
    assert np.allclose(r.grf[0], F0, rtol=1e-12, atol=1e-9)


# -- item 6: a free foot starting just above the ground, or on it moving down --------------------------
@pytest.mark.parametrize("height", [1e-9, 1e-12, 1e-6])
def test_a_free_foot_starting_just_above_the_ground_has_its_touchdown_found(height):
    q, dq = swing_foot_just_above(MODEL, height)
    r = bs.simulate(MODEL, q, dq, 0.05)
    assert r.events and r.events[0].kind == "touchdown" and r.events[0].leg == 2, (r.status, r.message)
    assert r.events[0].time < 0.01


def test_a_free_foot_on_the_ground_moving_into_it_is_refused_as_ambiguous():
    q, dq = swing_foot_just_above(MODEL, 0.0, swing_rate=0.5)
    with pytest.raises(ValueError, match="contact of foot 2 is ambiguous"):
        bs.simulate(MODEL, q, dq, 0.1)


@pytest.mark.parametrize("side, depth, refused", [
    (+1, 3e-8, True),      # in front, deeper than ground_tol: a touchdown that was never applied
    (+1, 5e-10, False),    # in front, within ground_tol
    (-1, 2e-7, False),     # behind the stance foot: a scuff within scuff_depth (a perturbed post-impact state)
    (-1, 4e-3, True),      # behind, deeper than scuff_depth
])
def test_a_swing_foot_below_the_ground_at_the_start_is_refused_by_the_runs_own_bounds(side, depth, refused):
    """The start check and the invariant of every sample agree: what the run would call a violation is
    refused before it starts. The swing leg hangs straight under the hip, the stance leg is tilted by
    ``a`` so that the hip is ``depth`` lower than a leg's length (side +1: the swing foot in front)."""
    a = side * math.acos(1.0 - depth / MODEL.parameters.l_leg)
    q, dq = bs.stance_state(MODEL, [math.pi + a, math.pi, 0.0], [0.0, 0.0, 0.0], stance_leg=1)
    swing = MODEL.foot_position(q, 2)
    assert swing[1] == pytest.approx(-depth, rel=1e-6) and np.sign(swing[0]) == side
    if refused:
        with pytest.raises(ValueError, match=r"swing foot \(leg 2\) is .* below the ground"):
            bs.simulate(MODEL, q, dq, 0.05)
    else:
        r = bs.simulate(MODEL, q, dq, 0.05)
        assert r.status != "completed" or not violations(MODEL, r), violations(MODEL, r)


# -- item 2: a stance that starts with the ground pulling on the foot ---------------------------------
def test_a_negative_normal_force_at_t0_is_a_liftoff_at_t0_or_a_clear_stop():
    q, dq = spinning_stance(MODEL)
    assert bs.stance_dynamics(MODEL, q, dq)[1][1] < -80.0
    r = bs.simulate(MODEL, q, dq, 0.2)
    assert r.events[0].kind == "liftoff" and r.events[0].time == 0.0
    assert r.stance_leg[0] == 0 and not np.any((r.stance_leg > 0) & (r.grf[:, 1] < -1e-9))
    stopped = bs.simulate(MODEL, q, dq, 0.2, phases=frozenset({"stance", "impact"}))
    assert stopped.status == "stopped" and "would lift off at t=0 s" in stopped.message
    assert "add 'flight'" in stopped.message


def test_a_negative_normal_force_right_after_an_impact_is_a_liftoff_at_that_impact():
    # a fast horizontal landing on a straight leg: after the impact the body swings over the foot at
    # 5 rad/s, more than the ground can hold down; the robot bounces from foot to foot
    q, dq = bouncing_landing()
    r = bs.simulate(MODEL, q, dq, 0.3, stance_leg=0)
    kinds = [(e.kind, e.time) for e in r.events]
    assert kinds[0][0] == "touchdown" and kinds[1] == ("liftoff", kinds[0][1])
    assert not np.any((r.stance_leg > 0) & (r.grf[:, 1] < -1e-9)), "a stance sample with the ground pulling"


# -- item 1: the scuffs of touchdown_rule "front" are reported and bounded ------------------------------
def test_the_walk_reports_each_scuff_and_stays_within_scuff_depth():
    r = bs.load_scene("walk").simulate(hold=False)
    scuffs = [e for e in r.events if e.kind == "scuff"]
    assert r.status == "completed" and len(scuffs) == r.stats["scuffs_ignored"] >= 20
    assert 1e-4 < r.stats["deepest_scuff"] < 1e-3            # the gait dips 0.6 mm near mid-stance
    first = scuffs[0]
    assert first.leg == 2 and "scuffed the ground behind the stance foot" in first.message
    assert " deep at " in first.message
    # each scuff lies between two impacts and is reported once, in time order
    assert [e.time for e in r.events] == sorted(e.time for e in r.events)


def test_falling_back_onto_the_rear_foot_stops_with_which_foot_when_and_how_deep():
    r = bs.load_scene("passive").simulate(t_final=2.0)
    assert r.status == "stopped", r.message
    assert "foot 1 went" in r.message and "deeper than scuff_depth=0.003 m" in r.message
    depth = float(r.message.split("foot 1 went ")[1].split(" m below")[0])
    assert depth > 0.003
    # a larger bound lets the same fall go on further, a tighter one stops it earlier
    assert bs.load_scene("passive").simulate(t_final=2.0, scuff_depth=1e-3).t[-1] <= r.t[-1]


def test_touchdown_rule_any_takes_the_mid_stance_crossing_as_a_touchdown():
    r = bs.load_scene("walk").simulate(hold=False, t_final=0.3, touchdown_rule="any")
    assert r.events and r.events[0].kind == "touchdown" and r.events[0].time < 0.2


# -- item 4: a crossing at the stance foot's x is not decided by roundoff -------------------------------
def test_a_crossing_at_the_stance_foot_is_decided_the_same_at_every_tolerance():
    # the swing leg rotates onto the stance leg: its foot reaches the ground exactly at the stance
    # foot (the legs coincide), then moves under the ground in front of it
    q, dq = coincident_crossing(MODEL)
    outcomes = set()
    for tol in (1e-6, 1e-8, 1e-10, 1e-12):
        r = bs.simulate(MODEL, q, dq, 0.3, rtol=tol, atol=tol)
        outcomes.add((r.status, tuple(e.kind for e in r.events), "in front of the stance foot" in r.message))
    assert outcomes == {("stopped", ("error",), True)}, outcomes


# -- item 7: the rocking V stops as Zeno -----------------------------------------------------------------
def test_a_rocking_v_whose_impacts_accumulate_stops_as_zeno_not_as_a_fall():
    from biped_sim.analysis.stability import HipPD
    q0, dq0 = bs.stance_state(MODEL, [math.pi - 0.3, math.pi + 0.3, 0.0], [0.0, 0.0, 0.3])
    r = bs.simulate(MODEL, q0, dq0, 5.0, controller=HipPD(1e4, 200.0, q0[2:4]), touchdown_rule="any")
    gaps = np.diff([e.time for e in r.impacts])
    assert r.status == "stopped" and r.events[-1].kind == "zeno", r.message
    assert "impacts accumulate (Zeno" in r.message and "fell" not in r.message
    assert len(gaps) >= 4 and np.all(np.diff(gaps[-4:]) < 0)


# -- the invariants: what "completed" means ------------------------------------------------------------
def test_every_sample_of_a_completed_run_keeps_the_invariants():
    for scene, kw in (("walk", dict(hold=False)), ("walk", dict(hold=True)), ("slope", {}), ("drop", {})):
        r = bs.load_scene(scene).simulate(**kw)
        assert r.status == "completed", (scene, r.message)
        assert not violations(MODEL, r), violations(MODEL, r)


# -- item 3: a dip inside one step is found, with a stated guarantee -----------------------------------
def test_the_grazing_flight_dips_20_micrometres():
    from scipy.integrate import solve_ivp
    q, dq = grazing_flight()
    sol = solve_ivp(lambda t, y: np.r_[y[5:], bs.flight_dynamics(MODEL, y[:5], y[5:])], (0.0, 0.06), np.r_[q, dq],
                    rtol=1e-12, atol=1e-12, dense_output=True)
    heights = np.array([MODEL.foot_position(sol.sol(t)[:5], 2)[1] for t in np.linspace(0.0, 0.06, 6001)])
    assert heights[0] > 0.04 and heights[-1] > 0 and -2.1e-5 < heights.min() < -1.9e-5


@pytest.mark.parametrize("tol", [1e-6, 1e-9, 1e-12])
@pytest.mark.parametrize("method", ["dop853", "dopri5"])
def test_a_dip_of_micrometres_inside_one_step_is_a_touchdown(method, tol):
    q, dq = grazing_flight()
    r = bs.simulate(MODEL, q, dq, 0.06, stance_leg=0, method=method, rtol=tol, atol=tol)
    assert r.events and r.events[0].kind == "touchdown" and r.events[0].leg == 2, (r.status, r.events)
    assert abs(r.events[0].time - 0.034733) < 1e-4
    # the located time is where the foot reaches the ground
    assert abs(MODEL.foot_position(r.events[0].q, 2)[1]) < 1e-10
