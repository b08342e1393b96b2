"""The MJCF of benchmarks/bench_mujoco.py is the model of docs/model.md: MuJoCo's mass matrix and bias
forces equal D(q) and C(q, dq) dq + G(q) at random states, and its feet are the model's feet. Skipped
where mujoco is not installed (a benchmark-only dependency: ``make bench`` installs it)."""
import numpy as np
import pytest

from biped_sim.engine.model import BipedModel

mujoco = pytest.importorskip("mujoco")
bench_mujoco = pytest.importorskip("benchmarks.bench_mujoco")


@pytest.mark.parametrize("overrides", [{}, {"m_leg": 4.0, "c_leg": 0.3, "I_torso": 1.7, "g": 3.7}])
def test_the_mjcf_has_the_model_mass_matrix_and_bias_forces(overrides):
    model = BipedModel(**overrides)
    err_D, err_bias = bench_mujoco.model_check(model, bench_mujoco.mujoco_model(model), states=5, seed=1)
    assert err_D < 1e-12 and err_bias < 1e-12, (err_D, err_bias)


def test_the_mjcf_feet_are_the_model_feet_and_the_motors_its_B():
    model = BipedModel()
    mj = bench_mujoco.mujoco_model(model)
    data = mujoco.MjData(mj)
    rng = np.random.default_rng(2)
    q, dq = rng.uniform(-3, 3, 5), rng.uniform(-3, 3, 5)
    bench_mujoco.set_state(mj, data, q, dq)
    for leg in (1, 2):
        centre = data.geom_xpos[mj.geom(f"foot_{leg}").id]
        assert np.allclose(centre[[0, 2]], model.foot_position(q, leg), rtol=0, atol=1e-12)
    data.ctrl[:] = [3.0, -5.0]
    mujoco.mj_forward(mj, data)
    assert np.allclose(data.qfrc_actuator[list(bench_mujoco.Q_FROM_QPOS)], model.B @ [3.0, -5.0], rtol=0, atol=1e-12)
