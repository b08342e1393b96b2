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
