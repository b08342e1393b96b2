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
