"""The hybrid engine: conservation, agreement of methods, events, guards, resets and bad input."""
import math
import random

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from biped_sim.control.walking import WalkingController
from biped_sim.engine.dynamics import flight_dynamics
from biped_sim.engine.hybrid import HybridSimulator
from biped_sim.engine.model import BipedModel
from biped_sim.engine.simulate import simulate, stance_state

STANCE_ONLY = frozenset({"stance"})
# the pinned chain's ODE: the unpowered swing foot passes centimetres under the ground behind the
# stance foot (a scuff, which a scene without impacts bounds by scuff_depth too)
PINNED_CHAIN = dict(phases=STANCE_ONLY, scuff_rule="behind", scuff_depth=1.0)


@pytest.fixture(scope="module")
def model():
    return BipedModel()


@pytest.fixture(scope="module")
def walker(model):
    return WalkingController(model)


@pytest.fixture(scope="module")
def walk10(model, walker):
    """10 s of walking with the reference controller (shared by several tests)."""
    return simulate(model, *walker.initial_state(), 10.0, controller=walker)


def passive_state(model):
    return stance_state(model, [math.pi - 0.1, math.pi + 0.3, 0.0], [0.3, -0.3, 0.0])


def test_passive_stance_conserves_energy(model):
    q0, dq0 = passive_state(model)
    r = simulate(model, q0, dq0, 1.0, rtol=1e-12, atol=1e-12, **PINNED_CHAIN)
    assert r.status == "completed" and r.t[-1] == 1.0
    E = np.array([model.energy(q, dq) for q, dq in zip(r.q, r.dq)])
    assert np.max(np.abs(E - E[0])) / abs(E[0]) < 1e-9
    assert r.stats["max_energy_balance_residual"] / abs(E[0]) < 1e-9
    assert np.all(r.grf[:, 1] > 0)


def test_fixed_and_floating_base_agree_along_a_trajectory(model, walker):
    q0, dq0 = walker.initial_state()
    kw = dict(controller=walker, rtol=1e-12, atol=1e-12, phases=frozenset({"stance", "impact"}))
    a = simulate(model, q0, dq0, 1.5, base="floating", **kw)
    b = simulate(model, q0, dq0, 1.5, base="fixed", **kw)
    assert a.status == b.status == "completed"
    assert len(a.impacts) == len(b.impacts) >= 3
    for ea, eb in zip(a.impacts, b.impacts):
        assert abs(ea.time - eb.time) < 1e-9
        np.testing.assert_allclose(ea.dq_plus, eb.dq_plus, atol=1e-9)
    np.testing.assert_allclose(a.q[-1], b.q[-1], atol=1e-9)
    np.testing.assert_allclose(a.dq[-1], b.dq[-1], atol=1e-9)
    assert b.stats["max_constraint_drift_position"] == 0.0  # the pinned chain cannot drift


def test_the_hip_hung_from_the_pinned_foot_is_one_function():
    """BipedModel.base_hung_from (GeneratedModel.base_hung_from's meaning): the hip that puts foot i at the pin c, at
    rest. stance_state and the fixed-base mode's to_phys give its numbers to the last bit (200 random states a leg, a
    0.9 m leg, a pin off the origin), and the three-link described as a robot hangs its base there too."""
    from biped_sim.config.models import generated_model
    from biped_sim.engine.modes import mode_functions

    def bits(*vectors):
        return [float(v).hex() for vector in vectors for v in vector]

    model, described, rng = BipedModel(l_leg=0.9), generated_model("three_link"), random.Random(7)
    for leg in (1, 2):
        pin = [0.3, -0.05]
        _, to_phys, _ = mode_functions(model, leg, "fixed", pin, [0.0, 0.0], None, lambda F, u: None)
        for _ in range(200):
            angles, rates = [rng.uniform(-7.0, 7.0) for _ in range(3)], [rng.uniform(-9.0, 9.0) for _ in range(3)]
            hip, dhip = model.base_hung_from(leg - 1, pin, angles, rates)
            q, dq = stance_state(model, angles, rates, leg, foot=pin)
            assert bits(q, dq) == bits(hip, angles, dhip, rates)
            for y in (angles + rates + [2.5], np.array(angles + rates + [2.5])):
                q_y, dq_y, w = to_phys(y)
                assert bits(q_y, dq_y, [w]) == bits(hip, angles, dhip, rates, [2.5])
            assert np.max(np.abs(model.foot_position(q, leg) - pin)) < 1e-12
            assert np.max(np.abs(model.foot_velocity(q, dq, leg))) < 1e-12
        hip, dhip = BipedModel().base_hung_from(leg - 1, pin, angles, rates)
        hip_d, dhip_d = described.base_hung_from(leg - 1, pin, angles, rates)
        assert np.max(np.abs(np.subtract(hip + dhip, hip_d + dhip_d))) < 1e-12


def test_walking_run_is_physical_and_continuous(model, walk10):
    r = walk10
    assert r.status == "completed"
    impacts = r.impacts
    assert len(impacts) >= 14
    # stance alternates 1, 2, 1, ... and events name the foot that landed
    assert [e.leg for e in impacts] == [2 - (k % 2) for k in range(len(impacts))]
    for e in impacts:
        assert e.kind == "touchdown" and e.stance_leg_after == e.leg
        J = model.foot_jacobian(e.q, e.leg)
        assert np.max(np.abs(J @ e.dq_plus)) < 1e-12              # the landing foot stops
        assert model.kinetic_energy(e.q, e.dq_plus) < model.kinetic_energy(e.q, e.dq_minus)
        assert abs(model.foot_position(e.q, e.leg)[1]) < 1e-10    # located on the ground
        assert e.warnings == []
    # physical coordinates: leg 1 stays leg 1, so positions are continuous across impacts
    # (a relabeled sample would jump by |q1 - q2|, about 0.4 rad at every impact; a step moves < 0.1)
    jumps = np.max(np.abs(np.diff(r.q, axis=0)), axis=1)
    assert np.max(jumps) < 0.25 * min(abs(e.q[2] - e.q[3]) for e in impacts)
    # two samples at each impact: before and after, same time, same q, velocities dq- and dq+
    for e in impacts:
        k = np.flatnonzero(r.t == e.time)
        assert len(k) == 2
        np.testing.assert_array_equal(r.q[k[0]], r.q[k[1]])
        np.testing.assert_allclose(r.dq[k[1]], e.dq_plus)
    # stance_leg column and ground reaction: foot on the ground pushes up
    assert set(np.unique(r.stance_leg)) == {1, 2}
    assert np.all(r.grf[:, 1] > 0)
    # figures
    s = r.stats
    assert s["max_constraint_drift_position"] < 1e-10 and s["max_constraint_drift_velocity"] < 1e-10
    assert s["max_energy_balance_residual"] < 1e-5
    assert s["energy_lost_at_impacts"] > 0 and s["steps"] > 0 and s["rhs_evaluations"] > s["steps"]
    assert s["real_time_factor"] > 0 and s["wall_time"] > 0


def test_event_times_converge_as_the_tolerance_tightens(model, walker):
    q0, dq0 = walker.initial_state()
    times = []
    for tol in (1e-5, 1e-7, 1e-9, 1e-11, 1e-13):
        r = simulate(model, q0, dq0, 1.2, controller=walker, rtol=tol, atol=tol)
        times.append(np.array([e.time for e in r.impacts[:2]]))
    errors = [np.max(np.abs(t - times[-1])) for t in times[:-1]]
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 1e-9


def test_zero_order_hold_equals_stepping_the_simulator(model, walker):
    """simulate(control_period=...) is what the node does: advance one period per held command."""
    q0, dq0 = walker.initial_state()
    period = 0.01
    r = simulate(model, q0, dq0, 1.0, controller=walker, control_period=period)
    sim = HybridSimulator(model, q0, dq0)
    for k in range(100):
        u = walker(sim.t, sim.q, sim.dq, sim.stance_leg)
        sim.advance((k + 1) * period, u=u)
    s = sim.result()
    np.testing.assert_array_equal(r.t, s.t)
    np.testing.assert_array_equal(r.q, s.q)
    assert [e.time for e in r.events] == [e.time for e in s.events]
    assert len(r.impacts) >= 1
    # the torque is held: constant inside each period
    for k in range(100):
        inside = (r.t > k * period) & (r.t < (k + 1) * period)
        if inside.sum() > 1:
            assert np.ptp(r.u[inside], axis=0).max() == 0.0


def test_a_simulator_is_not_pickled_or_copied_and_says_why(model, walker):
    """One clear refusal, before and after its first period, on either loop (its state is the compiled loop's
    memory, its mode's right-hand side a closure); its result pickles."""
    import copy
    import pickle
    sim = HybridSimulator(model, *walker.initial_state())
    for _ in range(2):
        for make_copy in (pickle.dumps, copy.deepcopy, copy.copy):
            with pytest.raises(TypeError, match="a HybridSimulator cannot be pickled or copied: .* its result"):
                make_copy(sim)
        sim.advance_period(1e-3, u=[0.0, 0.0])
    assert pickle.loads(pickle.dumps(sim.result())).t.tolist() == sim.result().t.tolist()


@pytest.mark.parametrize("bad", [[math.nan, 0.0], [1.0], [math.inf, -math.inf], "ab", [1e308, 1e308], None])
def test_a_refused_torque_loses_nothing(model, walker, bad):
    """A torque the engine refuses (ValueError) begins no period and keeps the torque held: the run goes
    on as if the call had not been made (a push after it, too)."""
    q0, dq0 = walker.initial_state()
    runs = []
    for refuse in (False, True):
        sim = HybridSimulator(model, q0, dq0, method="dopri5")
        for k in range(60):
            if refuse and k in (0, 20, 40):
                with pytest.raises(ValueError, match="two finite torques"):
                    sim.advance_period(1e-3, u=bad if bad is not None else [1.0, None])
            if k == 30:
                sim.push([1.0, 0.0])
            sim.advance_period(1e-3, u=walker(sim.t, sim.q, sim.dq, sim.stance_leg) if k % 10 else None)
        runs.append(sim)
    a, b = runs
    assert b.control_periods == a.control_periods == 60 and b.u == a.u
    np.testing.assert_array_equal(b.result().q, a.result().q)


@pytest.mark.parametrize("period", [0.0, -1e-3, math.nan, math.inf, "1e-3", True])
def test_a_bad_control_period_is_refused_and_begins_nothing(model, walker, period):
    """(a zero or negative period used to loop forever looking for the period's end)"""
    q0, dq0 = walker.initial_state()
    sim = HybridSimulator(model, q0, dq0, method="dopri5")
    for _ in range(5):      # past the first period: the compiled loop holds the state
        sim.advance_period(1e-3, u=[0.0, 0.0])
    t, k = sim.t, sim.control_periods
    for call in (lambda: sim.advance_period(period, u=[1.0, 0.0]), lambda: sim.advance_periods(period, walker, 1.0)):
        with pytest.raises(ValueError, match="period must be a number in"):
            call()
        assert (sim.t, sim.control_periods, sim.status) == (t, k, "running")


def test_guard_that_is_zero_right_after_a_reset_does_not_fire_again(model, walk10):
    times = np.array([e.time for e in walk10.impacts])
    assert np.min(np.diff(times)) > 0.2      # no re-fire of the new swing foot's guard
    # start in flight with foot 2 exactly on the ground and rising: no touchdown at t = 0
    q0 = np.array([0.0, math.cos(0.3), math.pi - 0.3, math.pi + 0.3, 0.0])
    q0[1] = -model.foot_position(np.r_[0.0, 0.0, q0[2:]], 2)[1]
    dq0 = np.array([0.0, 0.5, 0.0, 0.0, 0.0])
    r = simulate(model, q0, dq0, 0.05, stance_leg=0)
    assert not any(e.time < 1e-6 for e in r.events)


def test_a_guard_crossed_twice_inside_one_step_is_found(model):
    """Foot 2 dips below the ground and comes back within one 0.1 s step of RK4."""
    q0 = np.array([0.0, math.cos(-0.3) + 0.005, math.pi + 0.6, math.pi - 0.3, 0.0])
    dq0 = np.array([0.0, 1.0, 0.0, 6.0, 0.0])
    # the free flight, without the ground (a scene without impacts would stop at the touchdown)
    free = solve_ivp(lambda t, y: np.r_[y[5:], flight_dynamics(model, y[:5], y[5:])], (0, 0.1), np.r_[q0, dq0],
                     rtol=1e-12, atol=1e-12, dense_output=True)
    h2 = np.array([model.foot_position(free.sol(t)[:5], 2)[1] for t in np.linspace(0, 0.1, 201)])
    assert h2[0] > 0 and h2[-1] > 0 and h2.min() < 0    # both ends above, a dip in between
    ref = simulate(model, q0, dq0, 0.1, stance_leg=0, rtol=1e-12, atol=1e-12)
    big = simulate(model, q0, dq0, 0.1, stance_leg=0, method="rk4", step=0.1)
    assert ref.impacts[0].leg == big.impacts[0].leg == 2
    assert abs(ref.impacts[0].time - big.impacts[0].time) < 1e-4


def test_drop_lands_and_goes_on_in_stance(model):
    q0 = np.array([0.0, 1.3, math.pi - 0.2, math.pi + 0.3, 0.1])
    r = simulate(model, q0, np.zeros(5), 0.6, stance_leg=0)
    first = r.events[0]
    assert first.kind == "touchdown" and first.stance_leg_before == 0
    assert r.stance_leg[0] == 0 and first.leg in (1, 2)
    # free fall until the touchdown: y(t) = y0 - g t^2 / 2 for the centre of mass
    assert np.all(r.grf[r.t < first.time] == 0)
    com0 = model.com_position(q0)
    com = model.com_position(first.q)
    assert math.isclose(com[1], com0[1] - 0.5 * 9.81 * first.time ** 2, rel_tol=1e-9)


def test_both_feet_at_once_is_a_double_touchdown_and_the_limit_is_stated(model):
    q0 = np.array([0.0, 1.2, math.pi - 0.3, math.pi + 0.3, 0.0])
    r = simulate(model, q0, np.zeros(5), 1.0, stance_leg=0)
    first = r.events[0]
    assert first.kind == "double_touchdown" and first.impulse.shape == (4,)
    for leg in (1, 2):
        assert np.max(np.abs(model.foot_velocity(first.q, first.dq_plus, leg))) < 1e-12
    assert r.status == "failed" and "double support is not modelled" in r.message


def test_liftoff_goes_to_flight_or_stops_where_flight_is_not_a_phase(model):
    # a hard torque on the swing hip flings the swing leg and pulls the stance foot off the ground
    q0, dq0 = stance_state(model, [math.pi, math.pi, 0.0], [0.0, 0.0, 0.0])

    def fling(t, q, dq, leg):
        return np.array([0.0, 800.0])
    r = simulate(model, q0, dq0, 0.5, controller=fling, phases=frozenset({"stance", "impact"}))
    assert r.status == "stopped" and "add 'flight'" in r.message
    assert r.events[-1].kind == "error"
    r2 = simulate(model, q0, dq0, 0.5, controller=fling)
    kinds = [e.kind for e in r2.events]
    assert "liftoff" in kinds
    k = kinds.index("liftoff")
    assert abs(r2.grf[np.flatnonzero(r2.t == r2.events[k].time)[0], 1]) < 1e-6  # normal force reached zero
    assert np.all(r2.stance_leg[r2.t > r2.events[k].time][:3] == 0)


def test_slip_is_an_event_and_the_scene_says_whether_it_stops(model, walker):
    q0, dq0 = walker.initial_state()
    # |Ft| / Fn is 0.06 at t = 0 under the walker's torque and reaches 0.084 in the first stance
    r = simulate(model, q0, dq0, 3.0, controller=walker, mu=0.08)
    assert r.status == "stopped" and r.events[-1].kind == "slip" and "would slip" in r.message
    F = r.grf[-1]
    assert 0 < r.t[-1] < 0.47 and abs(abs(F[0]) - 0.08 * F[1]) < 1e-6 * F[1]   # located where |Ft| = mu Fn
    r0 = simulate(model, q0, dq0, 3.0, controller=walker, mu=0.05)      # outside the cone from the start
    assert r0.status == "stopped" and r0.events[-1].kind == "slip" and r0.events[-1].time == 0.0
    r2 = simulate(model, q0, dq0, 3.0, controller=walker, mu=0.08, stop_on_slip=False)
    assert r2.status == "completed" and sum(e.kind == "slip" for e in r2.events) >= 1
    r3 = simulate(model, q0, dq0, 3.0, controller=walker, mu=1.0)
    assert r3.status == "completed" and not any(e.kind == "slip" for e in r3.events)


@pytest.mark.parametrize("method", ["scipy_rk45", "scipy_dop853", "radau", "bdf"])
def test_projection_reaches_scipys_steppers(model, walker, method):
    """The projected state is where the next step starts with scipy's solvers too (the one-step methods
    from (y, f(y)), BDF from its shifted differences): the drift a step makes is then smaller than the
    drift that builds up without the projection, and the run is as correct (walking, impacts, 1 s with
    steps of at most 10 ms)."""
    q0, dq0 = walker.initial_state()
    kw = dict(controller=walker, method=method, rtol=1e-6, atol=1e-6, max_step=0.01)
    raw = simulate(model, q0, dq0, 1.0, project_constraints=False, **kw)
    proj = simulate(model, q0, dq0, 1.0, **kw)
    assert raw.status == proj.status == "completed" and len(proj.impacts) == len(raw.impacts) >= 2
    for key in ("max_constraint_drift_position", "max_constraint_drift_velocity"):
        assert proj.stats[key] < raw.stats[key] / 2, key
    assert proj.stats["max_energy_balance_residual"] < 1.5 * raw.stats["max_energy_balance_residual"] + 1e-12


def test_constraint_drift_is_measured_and_projection_removes_it(model):
    q0, dq0 = passive_state(model)
    raw = simulate(model, q0, dq0, 1.0, rtol=1e-6, atol=1e-6, project_constraints=False, **PINNED_CHAIN)
    proj = simulate(model, q0, dq0, 1.0, rtol=1e-6, atol=1e-6, **PINNED_CHAIN)

    def moved(r):
        feet = np.array([model.foot_position(q, 1) for q in r.q])
        return np.max(np.abs(feet - feet[0]))
    # without projection the foot wanders by what the run reports; with it, it stays on its pin
    assert moved(raw) > 1e-9
    assert math.isclose(moved(raw), raw.stats["max_constraint_drift_position"], rel_tol=0.5)
    assert moved(proj) < 1e-12 < proj.stats["max_constraint_drift_position"]


@pytest.mark.parametrize("method, extra", [("rk4", dict(step=1e-3)), ("semi_implicit_euler", dict(step=1e-4)),
                                           ("radau", {}), ("bdf", {}), ("scipy_dop853", {}), ("dopri5", {}),
                                           ("scipy_rk45", {})])
def test_every_integrator_walks_the_same_first_steps(model, walker, method, extra):
    q0, dq0 = walker.initial_state()
    ref = simulate(model, q0, dq0, 0.6, controller=walker, rtol=1e-10, atol=1e-10)
    r = simulate(model, q0, dq0, 0.6, controller=walker, method=method, rtol=1e-8, atol=1e-8, **extra)
    assert r.status == "completed" and len(r.impacts) == len(ref.impacts) >= 1
    tol = 5e-3 if method == "semi_implicit_euler" else 1e-5
    assert abs(r.impacts[0].time - ref.impacts[0].time) < tol


@pytest.mark.parametrize("kwargs, match", [
    (dict(q0=[0, 1, 3, 3]), "q0 must have shape"),
    (dict(dq0=[0, 0, float("nan"), 0, 0]), "dq0 has non-finite"),
    (dict(q0=[0, 1.1, math.pi, math.pi, 0]), r"stance foot \(leg 1\) is 0.1 m above the ground"),
    (dict(dq0=[0.5, 0, 0, 0, 0]), r"stance foot \(leg 1\) moves"),
    (dict(method="euler"), "unknown method 'euler'"),
    (dict(method="rk4"), "fixed-step: give step"),
    (dict(rtol=0.0), "rtol must be a number in"),
    (dict(stance_leg=3), "stance_leg must be 1, 2 or 0"),
    (dict(t_final=-1.0), "t_final must be"),
    (dict(mu=-0.5), "mu must be"),
    (dict(base="pinned"), "base must be"),
    (dict(phases=frozenset({"stance", "glide"})), "phases must be"),
    (dict(control_period=0.0), "control_period must be"),
])
def test_bad_input_is_a_clear_value_error(model, kwargs, match):
    args = dict(q0=[0, 1, math.pi, math.pi, 0], dq0=[0.0] * 5, t_final=0.1)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        simulate(model, args.pop("q0"), args.pop("dq0"), args.pop("t_final"), **args)


def test_a_bad_controller_output_stops_the_run_with_a_message(model, walker):
    q0, dq0 = walker.initial_state()
    r = simulate(model, q0, dq0, 0.5, controller=lambda t, q, dq, leg: [float("nan"), 0.0])
    assert r.status == "failed" and "two finite torques" in r.message
    r = simulate(model, q0, dq0, 0.5, controller=lambda t, q, dq, leg: [1.0], control_period=0.01)
    assert r.status == "failed" and "two finite torques" in r.message


def test_a_diverging_state_stops_with_a_message(model):
    q0, dq0 = stance_state(model, [math.pi, math.pi, 0.0], [0.0, 0.0, 0.0])
    r = simulate(model, q0, dq0, 1.0, controller=lambda t, q, dq, leg: [1e7, -1e7], max_speed=1e3,
                 **PINNED_CHAIN)
    assert r.status in ("failed", "stopped") and r.events[-1].kind == "error"
    assert r.message and np.all(np.isfinite(r.q))


def test_a_touchdown_in_a_scene_without_impacts_stops_and_names_the_phase(model):
    q0 = np.array([0.0, 1.3, math.pi - 0.2, math.pi + 0.3, 0.1])
    r = simulate(model, q0, np.zeros(5), 1.0, stance_leg=0, phases=frozenset({"flight", "stance"}))
    assert r.status == "stopped" and "add 'impact'" in r.message and r.t[-1] < 0.5
