"""The hybrid engine on any described planar biped (a GeneratedModel): its kernels, the rules that dispatch to
them, and runs of RABBIT and of the three-link robots as generated models (docs/models.md)."""
from __future__ import annotations

import numpy as np
import pytest

import biped_sim as bs
from biped_sim.config import models
from biped_sim.engine import guards as G, resets
from biped_sim.engine.model import BipedModel

RNG = np.random.default_rng(31)


def _random_state(n):
    q = RNG.uniform(-0.5, 0.5, n)
    q[2:4] += np.pi
    return q.tolist(), RNG.uniform(-1.0, 1.0, n).tolist()


def test_generated_kernels_agree_with_the_three_link_closed_forms():
    """The three-link description's generated kernels (lists in, lists out) give the closed forms' stance,
    impact, feet and energy to roundoff."""
    g, m = models.generated_model("three_link"), BipedModel()
    for _ in range(5):
        q, dq = _random_state(5)
        u = RNG.uniform(-5, 5, 2).tolist()
        for c in (0, 1):
            ddq, F = g.k_stance(q, dq, u, c)
            ddq_m, F_m = bs.stance_dynamics(m, np.array(q), np.array(dq), np.array(u), c + 1)
            np.testing.assert_allclose(ddq, ddq_m, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(F, F_m, rtol=1e-9, atol=1e-9)
            dq_plus, impulse = g.k_impact(q, dq, c)
            dq_plus_m, impulse_m = bs.impact_map(m, np.array(q), np.array(dq), c + 1)
            np.testing.assert_allclose(dq_plus, dq_plus_m, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(impulse, impulse_m, rtol=1e-9, atol=1e-9)
        feet = G.foot_states(m, q, dq)
        kin = g.k_foot_kinematics(q, dq)
        np.testing.assert_allclose(kin, [feet[0].x, kin[1], feet[1].x, kin[3], feet[0].dx, kin[5], feet[1].dx, kin[7]],
                                   atol=1e-12)
        np.testing.assert_allclose(g.k_foot_positions(q), kin[:4], atol=1e-12)
        np.testing.assert_allclose(sum(g.k_energy(q, dq)), m.energy(q, dq), rtol=1e-12)
        np.testing.assert_allclose(g.k_flight(q, dq, u), bs.flight_dynamics(m, np.array(q), np.array(dq),
                                                                           np.array(u)), rtol=1e-9, atol=1e-9)


def test_the_impact_rule_runs_on_a_generated_models_kernels():
    """loop_rules.ev_impact (the touchdown's rule, through loop_kernels' dispatch) on RABBIT gives its impact
    map's dq+ and impulse, and the energy the impact took."""
    rabbit = bs.load_model("rabbit")
    q = np.array([0.0, 0.78, 3.3, 2.9, 0.2, 0.1, 0.1])
    dq = np.array([0.3, -0.2, 0.1, 0.5, -0.3, 0.2, 0.05])
    ev = resets.touchdown_reset(rabbit, 1.0, q, dq, [2], 1, G.Ground.of(0.0))
    dq_plus, impulse = rabbit.impact_map(q, dq, 2)
    assert ev.dq_plus.tolist() == dq_plus.tolist() and ev.impulse.tolist() == impulse.tolist()
    assert ev.energy_loss == pytest.approx(rabbit.energy(q, dq) - rabbit.energy(q, dq_plus), abs=1e-12)
    assert ev.energy_loss > 0


@pytest.mark.parametrize("method", ["dop853", "dopri5", "rk4"])
def test_the_dip_search_finds_every_dip_of_a_rabbit_step(method):
    """The grazing bound summed over a foot's chain (femur and tibia): on steps of RABBIT in flight with leg 2
    swinging through its lowest point, a ground line placed so that the foot dips 1.5 graze_tol (and more) below
    it inside the step, both ends above it, is always found (a bracket around a crossing); one below the
    sampled lowest point gives none."""
    from biped_sim.engine.grazing import chain_fields, dip_bracket
    from biped_sim.engine.integrators import make_stepper
    from biped_sim.engine.loop_state import COEF, COEF_LENGTH, COEF_LINKS, COEF_WIDTH
    rabbit = bs.load_model("rabbit")
    chains, graze_tol, found = chain_fields(rabbit), 1e-6, 0
    for swing in (-6.0, -8.0, 7.0):
        q = [0.0, 1.0, np.pi - 0.15 * np.sign(swing), np.pi - 0.3 * np.sign(swing), 0.05, 0.0, 0.1]
        dq = [0.4, 0.25 * 9.81 / abs(swing), 0.5, swing, 1.0, -0.5, 0.0]   # the hip's top where leg 2 is lowest

        def rhs(t, y):
            return y[7:14] + rabbit.k_flight(y[:7], y[7:14], [0.0] * 4) + [0.0]
        st = make_stepper(method, rhs, 0.0, q + dq + [0.0], 0.3, 1e-9, 1e-9, step=0.02, n_positions=7)
        while st.t < 0.3:
            st.step()
            dense = st.dense_output()

            def height(t):
                return rabbit.k_foot_positions(list(np.asarray(dense(t))[:7]))[3]
            ts = np.linspace(st.t_old, st.t, 801)
            hs = np.array([height(t) for t in ts])
            lowest, ends = hs.min(), min(hs[0], hs[-1])
            if not ends - lowest > 2 * graze_tol:
                continue
            for c in np.linspace(lowest + 1.5 * graze_tol, ends - 0.25 * (ends - lowest), 4):
                def guard(t, c=c):
                    return height(t) - c
                bracket = dip_bracket(st, None, guard, 2, 0, False, chains, 0.0, hs[0] - c, hs[-1] - c, graze_tol)
                assert bracket is not None, (method, swing, st.t, c)
                assert guard(bracket[0]) > 0 >= guard(bracket[1])
                found += 1
            if method != "rk4":     # the bound over the whole step dominates the sampled |h''| (in s)
                S = st.dense_state()
                coef = np.array(S[COEF:COEF + 8 * COEF_WIDTH]).reshape(8, COEF_WIDTH)
                k = np.arange(8.0)
                d1, d2 = k @ coef, (k * (k - 1)) @ coef
                links = int(S[COEF_LINKS])
                bound = d2[1] + sum(S[COEF_LENGTH + j] * (d2[2 + j] + d1[2 + j] ** 2) for j in range(links))
                second = np.abs(np.diff(hs, 2)) * 800.0 ** 2
                assert links == 2 and second.max() <= bound, (second.max(), bound)
            c = lowest - 1e-3
            assert dip_bracket(st, None, lambda t: height(t) - c, 2, 0, False, chains, 0.0, hs[0] - c, hs[-1] - c,
                               graze_tol) is None
    assert found >= 8


# -- RABBIT through the hybrid loop ---------------------------------------------------------------------------
def _rabbit_on_foot_1(lift=0.0):
    """RABBIT standing-ish on foot 1 at the origin (leg 2 bent, its foot 2 cm up), at rest; ``lift`` raises it."""
    rabbit = bs.load_model("rabbit")
    q = np.array([0.0, 0.0, np.pi + 0.1, np.pi - 0.2, -0.05, 0.5, 0.05])
    q[:2] -= rabbit.contact_position(q, 1)
    q[1] += lift
    return rabbit, q, np.zeros(7)


def _check_impacts(rabbit, r):
    """Each touchdown of the run is RABBIT's impact map (dq+ and impulse), takes energy out, and the energy
    balance holds."""
    assert r.impacts
    for e in r.impacts:
        dq_plus, impulse = rabbit.impact_map(e.q, e.dq_minus, e.leg)
        np.testing.assert_allclose(e.dq_plus, dq_plus, rtol=0, atol=1e-12)
        np.testing.assert_allclose(e.impulse, impulse, rtol=0, atol=1e-12)
        assert e.energy_loss >= 0
    assert r.stats["max_energy_balance_residual"] < 1e-6
    assert r.q.shape[1] == r.dq.shape[1] == 7 and r.u.shape[1] == 4


def _posture_law(reference):
    """A PD law holding the hips and knees at ``reference`` (4 torques), too weak to hold RABBIT up."""
    def law(t, q, dq, stance_leg):
        return [-20.0 * (q[2 + i] - reference[i]) - 2.0 * dq[2 + i] for i in range(4)]
    return law


@pytest.mark.parametrize("law", ["held zero", "posture PD", "posture PD, 10 ms periods"])
def test_rabbit_falls_and_its_swing_foot_lands(law):
    """RABBIT on foot 1 falls over under zero torque, or a weak PD posture law (continuous or held a period):
    foot 2 lands (a touchdown, RABBIT's impact map), and the run ends 'completed' with no invariant failed."""
    rabbit, q0, dq0 = _rabbit_on_foot_1()
    controller = None if law == "held zero" else _posture_law(q0[2:6].copy())
    t_final = 0.2 if law == "held zero" else 0.35
    r = bs.simulate(rabbit, q0, dq0, t_final, controller=controller,
                    control_period=0.01 if "periods" in law else None, stance_leg=1)
    assert r.status == "completed", r.message
    assert [(e.kind, e.leg) for e in r.events] == [("touchdown", 2)]
    assert r.events[0].stance_leg_before == 1 and r.stance_leg[-1] == 2
    _check_impacts(rabbit, r)
    if controller is not None:
        assert np.abs(r.u).max() > 0.1


def test_rabbit_dropped_onto_foot_1_lands_from_flight():
    """RABBIT dropped from 5 cm in flight: flight samples, then foot 1 lands (RABBIT's impact map)."""
    rabbit, q0, dq0 = _rabbit_on_foot_1(lift=0.05)
    r = bs.simulate(rabbit, q0, dq0, 0.15, stance_leg=0)
    assert r.status == "completed", r.message
    assert [(e.kind, e.leg) for e in r.events] == [("touchdown", 1)]
    assert r.stance_leg[0] == 0 and r.stance_leg[-1] == 1
    _check_impacts(rabbit, r)


@pytest.mark.parametrize("name, t_final", [("compass_gait", 3.0), ("three_link", 2.0)])
def test_a_three_link_description_runs_as_its_biped_model_does(name, t_final):
    """The compass gait (passive, down its slope: touchdowns and scuffs) and the three-link biped (falling, its
    impacts) as GeneratedModels give the BipedModel's run: the same events, impact times to 1e-9 s, states to
    1e-8 (the closed forms and the generated forms differ in roundoff)."""
    q0, dq0 = np.array([0.0, 1.0, np.pi, np.pi, 0.0]), np.array([0.4, 0.0, 0.4, -2.0, 0.0])
    kw = dict(rtol=1e-10, atol=1e-10, slope=0.0525, phases=frozenset({"stance", "impact"}))
    a = bs.simulate(bs.load_model(name), q0, dq0, t_final, **kw)
    b = bs.simulate(models.generated_model(name), q0, dq0, t_final, **kw)
    assert a.status == b.status == "completed" and len(a.impacts) >= 3
    assert [(e.kind, e.leg) for e in a.events] == [(e.kind, e.leg) for e in b.events]
    for ea, eb in zip(a.events, b.events):
        assert abs(ea.time - eb.time) < 1e-9
        if ea.kind == "touchdown":
            np.testing.assert_allclose(eb.dq_plus, ea.dq_plus, rtol=0, atol=1e-8)
    np.testing.assert_allclose(b.q[-1], a.q[-1], rtol=0, atol=1e-8)
    np.testing.assert_allclose(b.dq[-1], a.dq[-1], rtol=0, atol=1e-8)


def test_bad_input_to_a_rabbit_run_is_one_line():
    """A torque of the wrong length, a state of the wrong length, a controller's wrong torques, a described
    robot with three contact points, base='fixed': each refused in one line that says what to give."""
    import copy

    from biped_sim.engine.hybrid import HybridSimulator
    rabbit, q0, dq0 = _rabbit_on_foot_1()
    sim = HybridSimulator(rabbit, q0, dq0, stance_leg=1)
    with pytest.raises(ValueError, match=r"^u must be 4 finite torques") as e:
        sim.advance(0.01, u=[0.0, 0.0])
    assert "\n" not in str(e.value) and sim.u == [0.0] * 4
    for name, q, dq in (("q0", q0[:5], dq0), ("dq0", q0, np.zeros(5))):
        with pytest.raises(ValueError, match=rf"^{name} must have shape \(7,\), got shape \(5,\)$"):
            HybridSimulator(rabbit, q, dq, stance_leg=1)
    r = bs.simulate(rabbit, q0, dq0, 0.05, controller=lambda t, q, dq, leg: [0.0, 0.0])
    assert r.status == "failed" and "it must return 4 finite torques" in r.message
    three = copy.copy(rabbit)
    three.contacts = rabbit.contacts + ("hand",)
    with pytest.raises(ValueError, match=r"^the hybrid engine cannot run robot 'rabbit': it has 3 contact points "
                                         r"\(foot_1, foot_2, hand\); the engine runs bipeds") as e:
        bs.simulate(three, q0, dq0, 0.1)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("law", ["held zero", "posture PD"])
def test_rabbits_fixed_base_gives_the_floating_bases_run(law):
    """base='fixed' on RABBIT (its joint angles integrated, the base hung from the pin) gives the floating base's
    fall: the same touchdown to 1e-10 s, dq+ to 1e-8, the end state to 1e-9 and the stance force to 1e-6 N."""
    rabbit, q0, dq0 = _rabbit_on_foot_1()
    controller = None if law == "held zero" else _posture_law(q0[2:6].copy())
    kw = dict(controller=controller, stance_leg=1, phases=frozenset({"stance", "impact"}), rtol=1e-10, atol=1e-10)
    t_final = 0.2 if law == "held zero" else 0.35
    a = bs.simulate(rabbit, q0, dq0, t_final, base="floating", **kw)
    b = bs.simulate(rabbit, q0, dq0, t_final, base="fixed", **kw)
    assert a.status == b.status == "completed" and [(e.kind, e.leg) for e in b.events] == [("touchdown", 2)]
    assert abs(a.events[0].time - b.events[0].time) < 1e-10
    np.testing.assert_allclose(b.events[0].dq_plus, a.events[0].dq_plus, rtol=0, atol=1e-8)
    np.testing.assert_allclose(b.q[-1], a.q[-1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.grf[-1], a.grf[-1], rtol=0, atol=1e-6)
    _check_impacts(rabbit, b)


def test_a_push_throws_rabbit_into_flight_and_it_lands():
    """A push (40 N s up on the base's point) on RABBIT standing on foot 1: the ground cannot hold the foot, it lifts
    off into flight, foot 2 lands; the push's work enters the energy balance, which holds."""
    from biped_sim.engine.hybrid import HybridSimulator
    rabbit, q0, dq0 = _rabbit_on_foot_1()
    sim = HybridSimulator(rabbit, q0, dq0, stance_leg=1)
    sim.advance(0.05)
    assert [(e.kind, e.stance_leg_after) for e in sim.push([0.0, 40.0])] == [("push", 0), ("liftoff", 0)]
    sim.advance(0.3)
    r = sim.result()
    assert r.status == "completed", r.message
    assert [(e.kind, e.leg) for e in r.events] == [("push", 1), ("liftoff", 1), ("touchdown", 2)]
    assert 0 in r.stance_leg and r.stats["push_work"] > 20.0
    _check_impacts(rabbit, r)
