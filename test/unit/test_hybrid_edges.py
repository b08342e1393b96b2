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
    landing_outside_the_cone,
    pd_walk_without_clearance,
    rocking_v,
    spinning_stance,
    standing_v_pushed_up,
    swing_foot_just_above,
    walk_that_scuffs,
)
from biped_sim.analysis.verify import result_violations, violations
from biped_sim.engine import compiled_loop, loop_state
from biped_sim.engine.guards import foot_states

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
    # the second period ran in one C call (Loop.period), which sees the next one first
    quiet = bool(sim.S[loop_state.SIM_STATE_UNMADE])
    assert quiet == (loop == "compiled loop" and compiled_loop.AVAILABLE)   # (BIPED_SIM_PURE_PYTHON=1: no C loop)
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


@pytest.mark.parametrize("side, depth, swing_rate, options, refused", [
    (+1, 3e-8, 0.0, {}, True),      # in front, deeper than ground_tol: a touchdown that was never applied
    (+1, 5e-10, 0.0, {}, False),    # in front, within ground_tol
    (-1, 2e-7, -1.0, {}, False),    # behind, swinging forward: a scuff under way
    (-1, 4e-3, -1.0, {}, False),    # the same 4 mm deep: no depth bound by default
    (-1, 4e-3, -1.0, dict(scuff_depth=3e-3), True),   # ... deeper than a scuff_depth given
    (-1, 2e-7, 0.0, {}, True),      # behind at rest: the robot stands on that foot, a touchdown never applied
    (-1, 2e-7, 0.0, dict(scuff_rule="behind"), False),   # ... which scuff_rule "behind" lets pass
])
def test_a_swing_foot_below_the_ground_at_the_start_is_refused_by_the_runs_own_bounds(side, depth, swing_rate,
                                                                                       options, refused):
    """The start check and the invariant of every sample agree: what the run would call a violation is
    refused before it starts. The swing leg hangs straight under the hip (turning forward at
    ``swing_rate`` rad/s), the stance leg is tilted by ``a`` so that the hip is ``depth`` lower than a
    leg's length (side +1: the swing foot in front)."""
    a = side * math.acos(1.0 - depth / MODEL.parameters.l_leg)
    q, dq = bs.stance_state(MODEL, [math.pi + a, math.pi, 0.0], [0.0, swing_rate, 0.0], stance_leg=1)
    swing = MODEL.foot_position(q, 2)
    assert swing[1] == pytest.approx(-depth, rel=1e-6) and np.sign(swing[0]) == side
    if refused:
        with pytest.raises(ValueError, match=r"swing foot \(leg 2\) is .* below the ground"):
            bs.simulate(MODEL, q, dq, 0.05, **options)
    else:
        r = bs.simulate(MODEL, q, dq, 0.05, **options)
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


def test_falling_back_onto_the_rear_foot_lands_on_it_and_ends_honestly():
    r = bs.load_scene("passive").simulate(t_final=2.0)
    # it tips forward onto foot 2, then falls back: foot 1 comes down behind foot 2 moving backward, and lands
    fall = next(e for e in r.events if e.kind == "touchdown" and e.leg == 1)
    assert MODEL.foot_position(fall.q, 1)[0] < MODEL.foot_position(fall.q, 2)[0]
    assert MODEL.foot_velocity(fall.q, fall.dq_minus, 1)[0] < 0.0
    # and the rocking on both feet that follows ends where the impacts accumulate, with no foot under the ground
    assert r.status == "stopped" and r.events[-1].kind == "zeno", r.message
    assert not result_violations(MODEL, r), result_violations(MODEL, r)
    # round 2's rule, a depth bound, stops the same fall by its depth
    r2 = bs.load_scene("passive").simulate(t_final=2.0, scuff_rule="behind", scuff_depth=3e-3)
    assert r2.status == "stopped" and "deeper than scuff_depth=0.003 m" in r2.message, r2.message
    depth = float(r2.message.split("foot 1 went ")[1].split(" m below")[0])
    assert depth > 0.003
    assert bs.load_scene("passive").simulate(t_final=2.0, scuff_rule="behind", scuff_depth=1e-3).t[-1] <= r2.t[-1]


# -- round 3: the scuff rule tells a swing from a fall by its motion, not its depth ----------------------
#: walks of the reference law whose swing foot scuffs deeper than 3 mm (lag -0.15) or into the front of
#: the stance foot (lag -0.01, clearance 0.3), which round 2's rule (scuff_rule "behind", scuff_depth 3 mm)
#: stopped within the first step (edge_cases.walk_that_scuffs)
WALKS_THAT_SCUFF = [(dict(lag=-0.15), 1e-3), (dict(lag=-0.15), 2e-3), (dict(lag=-0.15), None),
                    (dict(lag=-0.01, clearance=0.3), 1e-3)]


@pytest.mark.parametrize("law, period", WALKS_THAT_SCUFF)
def test_a_walk_whose_swing_foot_scuffs_runs_to_its_end_with_default_options(law, period):
    round2 = walk_that_scuffs(MODEL, **law, control_period=period, t_final=2.0, scuff_rule="behind", scuff_depth=3e-3)
    assert round2.status == "stopped" and round2.t[-1] < 1.0, round2.message
    r = walk_that_scuffs(MODEL, **law, control_period=period)
    assert r.status == "completed" and len(r.impacts) >= 20, r.message
    assert not violations(MODEL, r), violations(MODEL, r)
    scuffs = [e for e in r.events if e.kind == "scuff"]
    assert len(scuffs) >= 20 and "scuff_rule='forward'" in scuffs[0].message
    assert r.stats["deepest_scuff"] > (3e-3 if law["lag"] == -0.15 else 0.0)


@pytest.mark.parametrize("period", [1e-3, 2e-3, None])
def test_the_pd_walking_law_without_swing_clearance_walks_to_its_end(period):
    """A plain PD law on the virtual constraints with no swing-foot clearance (PDWalkingController,
    clearance 0), from the walk scene's state: round 2's rule stopped it at 3.9-4.6 s."""
    round2 = pd_walk_without_clearance(MODEL, control_period=period, scuff_rule="behind", scuff_depth=3e-3)
    assert round2.status == "stopped" and round2.t[-1] < 5.0, round2.message
    r = pd_walk_without_clearance(MODEL, control_period=period)
    assert r.status == "completed" and len(r.impacts) >= 25, r.message
    assert not violations(MODEL, r), violations(MODEL, r)


def test_the_scuff_options_are_checked_by_name():
    q0, dq0 = bs.WalkingController(MODEL).initial_state()
    with pytest.raises(ValueError, match="scuff_rule must be one of 'forward', 'behind', got 'sideways'"):
        bs.simulate(MODEL, q0, dq0, 0.1, scuff_rule="sideways")
    with pytest.raises(ValueError, match="scuff_depth must be a number"):
        bs.simulate(MODEL, q0, dq0, 0.1, scuff_depth=0.0)


def test_touchdown_rule_any_takes_the_mid_stance_crossing_as_a_touchdown():
    r = bs.load_scene("walk").simulate(hold=False, t_final=0.3, touchdown_rule="any")
    assert r.events and r.events[0].kind == "touchdown" and r.events[0].time < 0.2


# -- item 4: a crossing at the stance foot's x is not decided by roundoff -------------------------------
def test_a_crossing_at_the_stance_foot_is_decided_the_same_at_every_tolerance():
    # the swing leg rotates onto the stance leg: its foot reaches the ground exactly at the stance
    # foot (the legs coincide), then moves under the ground in front of it
    q, dq = coincident_crossing(MODEL)
    # (under scuff_rule "forward" the foot swings on through the ground; under "behind" it may not pass the
    # stance foot)
    for rule, expected in (("forward", ("completed", (), False)), ("behind", ("stopped", ("error",), True))):
        outcomes = set()
        for tol in (1e-6, 1e-8, 1e-10, 1e-12):
            r = bs.simulate(MODEL, q, dq, 0.3, rtol=tol, atol=tol, scuff_rule=rule)
            outcomes.add((r.status, tuple(e.kind for e in r.events), "in front of the stance foot" in r.message))
        assert outcomes == {expected}, (rule, outcomes)


# -- item 7: the rocking V stops as Zeno -----------------------------------------------------------------
@pytest.mark.parametrize("touchdown_rule", ["front", "any"])
def test_a_rocking_v_whose_impacts_accumulate_stops_as_zeno_not_as_a_fall(touchdown_rule):
    r = rocking_v(MODEL, touchdown_rule)
    assert not result_violations(MODEL, r), result_violations(MODEL, r)     # no foot under the ground
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


# -- round 3 (R3): a foot that lifts off and lands again inside one step lands moving down ------------
@settings(max_examples=25, deadline=None)
@given(push_x=st.floats(-0.5, 0.5), push_y=st.floats(0.1, 1.0), compiled=st.booleans())
def test_a_foot_that_lifts_off_and_lands_inside_one_step_lands_moving_down(push_x, push_y, compiled):
    """A robot standing at rest on both feet, pushed up a little: its feet leave the ground and land
    again within the first integration step. The landing is where a foot comes down (the same as with
    steps of at most 0.1 ms), never the liftoff instant; on both loops."""
    compiled_loop.enabled = compiled
    try:
        runs = [standing_v_pushed_up(MODEL, (push_x, push_y), max_step) for max_step in (math.inf, 1e-4)]
    finally:
        compiled_loop.enabled = True
    landings = [next((e for e in r.events if e.kind in ("touchdown", "double_touchdown")), None) for r in runs]
    assert (landings[0] is None) == (landings[1] is None)
    if landings[0] is None:
        return
    assert landings[0].time == pytest.approx(landings[1].time, abs=1e-9)
    feet = foot_states(MODEL, landings[0].q.tolist(), landings[0].dq_minus.tolist())
    landed = [1, 2] if landings[0].kind == "double_touchdown" else [landings[0].leg]
    assert all(feet[leg - 1].dheight < 0.0 for leg in landed)


# -- round 3 (R5): no cached value outlives the state it was computed from --------------------------------
@pytest.mark.parametrize("compiled", [True, False])
def test_no_cached_foot_or_force_outlives_its_state_across_periods_with_resets(compiled):
    """Landings from flight that lift off again at once (bouncing_landing and variations), held 1 ms: at
    every period boundary the locator's cached feet and force at the simulator's time are those of its
    state (a stale cache hid the next crossing)."""
    from biped_sim.engine import compiled_loop
    q, dq = bouncing_landing()
    rng = np.random.default_rng(7)
    compiled_loop.enabled = compiled
    checked = 0
    try:
        for _ in range(12):
            q1, dq1 = q.copy(), dq.copy()
            dq1[0], dq1[1], dq1[3] = rng.uniform(2.0, 6.0), rng.uniform(-1.5, -0.1), rng.uniform(-3.0, 3.0)
            sim = bs.HybridSimulator(MODEL, q1, dq1, stance_leg=0, phases=frozenset({"stance", "impact", "flight"}))
            while sim.status == "running" and sim.t < 0.2:
                sim.advance_period(1e-3, u=[rng.uniform(-50, 50), rng.uniform(-50, 50)])
                loc = sim.locator
                t_feet, feet = loc._feet_end
                if t_feet == sim.t and feet is not None:
                    now = sim.feet(sim.q.tolist(), sim.dq.tolist())
                    np.testing.assert_allclose(np.ravel(feet), np.ravel(now), atol=1e-9)
                    checked += 1
                t_force, F = loc._force_end
                if t_force == sim.t and F is not None and sim.stance_leg:
                    np.testing.assert_allclose(F, sim._force_at(sim.t, sim.q.tolist(), sim.dq.tolist()), atol=1e-6)
    finally:
        compiled_loop.enabled = True
    assert checked > 0


# landings whose impulse is outside the friction cone: on foot 1 from flight, the second touchdown
# (|Lambda_t|/Lambda_n 0.575, mu 0.338), and a V landing on both feet at once (foot 1 at 0.70, mu 0.3)
L_LEG = MODEL.parameters.l_leg
CONE_LANDINGS = {
    "touchdown": (*landing_outside_the_cone(), "the touchdown at t=0.063205574 s", "0.574565"),
    "double touchdown": (np.array([0.0, math.cos(0.3) * L_LEG + 0.05, math.pi + 0.3, math.pi - 0.3, 0.0]),
                         np.array([0.5, -0.5, 0.0, 0.0, 0.0]), 0.3, "the double touchdown at t=0.062130927 s",
                         "0.703793"),
}


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("kind", sorted(CONE_LANDINGS))
def test_a_landing_impulse_outside_the_friction_cone_stops_the_run(kind, compiled):
    """As a stance force outside the cone (a slip) and a push's ground impulse outside it do: a sticking
    impact the ground cannot give; the message says which foot, when, |Lambda_t|/Lambda_n, mu and what to
    change. stop_on_slip=False keeps the sticking impact, with the event's warning."""
    q, dq, mu, when, ratio = CONE_LANDINGS[kind]
    compiled_loop.enabled = compiled
    try:
        stopped = bs.simulate(MODEL, q, dq, 0.08, stance_leg=0, mu=mu)
        kept = bs.simulate(MODEL, q, dq, 0.08, stance_leg=0, mu=mu, stop_on_slip=False)
    finally:
        compiled_loop.enabled = True
    assert stopped.status == "stopped" and stopped.events[-1].kind == kind.replace(" ", "_"), stopped.message
    assert stopped.message.startswith(when + ": the ground's impulse on foot 1 is outside the friction cone "
                                      f"(|Lambda_t|/Lambda_n = {ratio} > mu = {mu:g}"), stopped.message
    assert "raise mu, or set stop_on_slip=False to keep the sticking impact with a warning" in stopped.message
    impact = next(e for e in kept.impacts if e.time == stopped.events[-1].time)     # the same impact, kept
    assert kept.status == "completed" and any("friction cone" in w for w in impact.warnings)


@pytest.mark.parametrize("compiled", [True, False])
def test_a_push_and_a_landing_outside_the_cone_stop_by_the_same_rule(compiled):
    compiled_loop.enabled = compiled
    try:
        r = bs.load_scene("walk").simulate(t_final=1.0, pushes=[(0.3, [-3.0, 0.0])], mu=1.0)
    finally:
        compiled_loop.enabled = True
    assert r.status == "stopped" and r.events[-1].kind == "push"
    assert r.message == ("the push at t=0.3 s: the ground's impulse on foot 1 is outside the friction cone "
                         "(|Lambda_t|/Lambda_n = 1.36767 > mu = 1: |Lambda_t| = 0.23089 N s > mu Lambda_n = "
                         "0.16882 N s); the model has no sliding phase (raise mu, or set stop_on_slip=False to "
                         "keep the foot pinned with a warning)")
