"""The variational terms of the three-link's steps in C (engine/_variational.c on engine/_stance_derivative.h) and
the walking laws' derivatives in C (control/_laws.c): against the numpy path (engine/variational.py
``steps_transition``) and the laws' Python derivatives, to rounding (another operation order, not the bits)."""
import ctypes

import numpy as np
import pytest

from biped_sim.analysis.gait import scene_gait
from biped_sim.control import walking
from biped_sim.control.walking import PDWalkingController, WalkingController
from biped_sim.engine import compiled, variational
from biped_sim.engine.model import BipedModel
from biped_sim.engine.model_derivatives import derivatives
from biped_sim.engine.sensitivity import LAW_EXACT, STEPS, Linearization, _Integration, run_jacobian
from biped_sim.engine.torque_hook import c_jacobian_prototype

MODEL = BipedModel()
OTHER = BipedModel(m_leg=3.7, l_leg=0.83, I_torso=1.9, g=1.62)
U_HELD = np.array([3.0, -2.0])

pytestmark = pytest.mark.skipif(compiled.IMPLEMENTATION != "C", reason="BIPED_SIM_PURE_PYTHON or no compiled twin")


def rel(a, b):
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


def test_the_variational_steps_and_the_laws_derivatives_are_built_and_chosen():
    assert variational._C is not None, variational.WHY_NOT_C
    for ctrl in (WalkingController(MODEL), PDWalkingController(MODEL)):
        law = ctrl.compiled_law(MODEL)
        assert law.jacobian != 0
        assert variational.compiled_law(derivatives(MODEL), ctrl, None)[0] == law.jacobian


def _stack(leg, rng, N=6, spread=0.05):
    """N random states near the walking start on stance ``leg``, times and step sizes."""
    q, dq = WalkingController(MODEL).initial_state(1.0)
    X0 = np.concatenate([q, dq])[None] + spread * rng.standard_normal((N, 10))
    if leg == 2:    # the relabeled state: the other leg in stance
        X0[:, [2, 3, 7, 8]] = X0[:, [3, 2, 8, 7]]
    return rng.uniform(0.0, 2.0, N), X0, rng.uniform(0.002, 0.03, N)


CONTROLLERS = {"held": lambda m: None, "walking": WalkingController, "pd": PDWalkingController,
               "walking at its limit": lambda m: WalkingController(m, torque_limit=20.0),
               "pd at its limit": lambda m: PDWalkingController(m, torque_limit=5.0)}


@pytest.mark.parametrize("model", [MODEL, OTHER], ids=["default", "other parameters"])
@pytest.mark.parametrize("leg", [1, 2])
@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_the_c_steps_give_the_numpy_steps(name, leg, model):
    rng = np.random.default_rng([leg, len(name)])
    ctrl = CONTROLLERS[name](model)
    deriv = derivatives(model)
    t0, X0, H = _stack(leg, rng)
    if "limit" in name:     # some torque of the stack is clipped
        u = [ctrl(t, x[:5], x[5:], leg) for t, x in zip(t0, X0)]
        assert np.max(np.abs(u)) == ctrl.torque_limit
    law = variational.compiled_law(deriv, ctrl, U_HELD)
    X1c, Phic = variational.steps_transition_c(deriv, law, t0, X0, H, leg)
    X1, Phi, Gamma, how, _ = variational.steps_transition(deriv, ctrl, U_HELD, t0, X0, H, leg)
    assert rel(X1c, X1) < 1e-12
    assert rel(Phic, Phi) < 1e-12
    assert np.max(np.abs(Phi - np.eye(10))) > 1e-3     # (the steps do move S)


def _c_function(address):
    return c_jacobian_prototype()(address)


def _doubles(values):
    return (ctypes.c_double * len(values))(*values)


def _c_jacobian(law, t, q, dq, leg):
    u, ux = (ctypes.c_double * 2)(), (ctypes.c_double * 20)()
    code = _c_function(law.jacobian)(t, _doubles(q), _doubles(dq), leg, _doubles(law.params), u, ux)
    assert code == 0
    return np.array(u[:]), np.array(ux[:]).reshape(2, 10)


@pytest.mark.parametrize("cls", [WalkingController, PDWalkingController])
def test_the_laws_derivatives_in_c_give_the_python_ones(cls):
    rng = np.random.default_rng(7)
    for model in (MODEL, OTHER):
        for kw in ({}, {"torque_limit": 20.0}):
            ctrl = cls(model, **kw)
            law = ctrl.compiled_law(model)
            q0, dq0 = ctrl.initial_state(1.0)
            clipped = 0
            for k in range(40):
                leg = (0, 1, 2, 1, 2)[k % 5]
                q = q0 + 0.1 * rng.standard_normal(5)
                dq = dq0 + 0.5 * rng.standard_normal(5)
                u, ux = _c_jacobian(law, 0.3, q, dq, leg)
                expected = ctrl.jacobian(0.3, q, dq, leg)
                assert rel(ux, expected) < 1e-12, (leg, ux, expected)
                assert rel(u, np.asarray(ctrl(0.3, q, dq, leg), float)) < 1e-12
                clipped += bool(np.any(np.abs(u) == ctrl.torque_limit)) and leg != 0
            assert clipped > 0 if kw else clipped == 0


def test_the_walk_gaits_multipliers_through_c_are_the_numpy_paths(monkeypatch):
    gait = scene_gait("walk")
    smap, z = gait.step_map, gait.fixed_point
    U, _ = smap.basis(z)
    q, dq = smap.state(z)
    r = run_jacobian(smap.model, q, dq, 5.0, controller=smap.controller, end_at_event=True, **smap.kw)
    assert (r.integration, r.law_derivative) == (STEPS, LAW_EXACT)
    exact = np.sort_complex(np.linalg.eigvals(smap.jacobian(z, U)))
    monkeypatch.setattr(variational, "_C", None)      # the numpy path
    numpy_path = np.sort_complex(np.linalg.eigvals(smap.jacobian(z, U)))
    assert np.max(np.abs(exact - numpy_path)) < 1e-10
    assert np.max(np.abs(exact - np.sort_complex(gait.multipliers))) < 1e-10


class FailingDerivative(PDWalkingController):
    """The PD law compiled as the loop's, with a derivative (made by ctypes) that fails from ``t_fail`` on."""

    def __init__(self, model, t_fail):
        super().__init__(model)

        def jacobian(t, q, dq, stance_leg, params, u, u_x):
            if t >= t_fail:
                return 5
            u[0] = u[1] = 0.0
            for k in range(20):
                u_x[k] = 0.0
            return 0
        self._c_jacobian = c_jacobian_prototype()(jacobian)

    def compiled_law(self, model):
        law = super().compiled_law(model)
        return law._replace(jacobian=ctypes.cast(self._c_jacobian, ctypes.c_void_p).value)


def test_a_failing_derivative_is_one_line_naming_the_law_and_the_time():
    ctrl = FailingDerivative(MODEL, t_fail=0.1)
    q, dq = ctrl.initial_state(1.0)
    with pytest.raises(ValueError, match=r"^the torque law pd_walking's derivative returned 5 at t=0\.1\d* s$"):
        run_jacobian(MODEL, q, dq, 0.3, controller=ctrl)


def test_without_a_compiled_derivative_the_numpy_path_runs():
    ctrl = PDWalkingController(MODEL)
    ctrl.jacobian = lambda *a: walking._pd_jacobian(ctrl, *a)       # (its own, but replaced on the instance)
    assert ctrl.compiled_law(MODEL).jacobian == 0
    assert variational.compiled_law(derivatives(MODEL), ctrl, None) is None
    q, dq = ctrl.initial_state(1.0)
    r = run_jacobian(MODEL, q, dq, 0.05, controller=ctrl)
    assert (r.integration, r.law_derivative) == (STEPS, LAW_EXACT)


@pytest.mark.parametrize("leg", [1, 2])
@pytest.mark.parametrize("name", ["held", "walking", "pd at its limit"])
def test_the_c_steps_carry_s_through_their_phis(name, leg):
    rng = np.random.default_rng([leg, len(name), 3])
    ctrl = CONTROLLERS[name](MODEL)
    deriv = derivatives(MODEL)
    t0, X0, H = _stack(leg, rng)
    law = variational.compiled_law(deriv, ctrl, U_HELD)
    S0 = rng.standard_normal((10, 7))
    S = S0.copy()
    _X1, Phi = variational.steps_transition_c(deriv, law, t0, X0, H, leg, S)
    expected = S0
    for phi in Phi:
        expected = phi @ expected
    assert rel(S, expected) < 1e-12
    assert rel(S, S0) > 1e-3


@pytest.mark.parametrize("slope", [0.0, 0.04])
@pytest.mark.parametrize("legs", [(1, 2), (2, 1)])
@pytest.mark.parametrize("name", ["held", "walking", "pd", "walking at its limit"])
def test_the_c_touchdown_gives_the_saltation_matrix_of_the_numpy_path(name, legs, slope):
    """variational.touchdown_c against sensitivity._Integration._event (the law's own Python derivative, the impact
    map's, the guard's and the flows in numpy), the last event of a step map and one a run goes on from."""
    leg, gleg = legs
    rng = np.random.default_rng([leg, len(name), int(slope * 100)])
    ctrl = CONTROLLERS[name](OTHER)
    deriv = derivatives(OTHER)
    law = variational.compiled_law(deriv, ctrl, U_HELD)
    lin = Linearization(OTHER, slope, deriv)
    integ = _Integration(lin, ctrl, None if ctrl is not None else U_HELD, None, False, [], 1e-10, 1e-10)
    _t0, X0, _H = _stack(leg, rng, N=4)
    for x in X0:
        S = rng.standard_normal((10, 6))
        for last in (True, False):
            xc, Sc, dtc = variational.touchdown_c(deriv, law, 0.4, x, S, leg, gleg, lin.tan, last)
            xp, Sp, new_leg, dtp = integ._event(0.4, x, S, np.zeros((2, 6)), np.zeros((9, 6)), leg, "touchdown", gleg,
                                                last)
            assert new_leg == gleg
            assert rel(xc, xp) < 1e-12
            assert rel(Sc, Sp) < 1e-12, (last, rel(Sc, Sp))
            if last:
                assert rel(dtc, dtp) < 1e-12
            else:
                assert dtc is None and dtp is None
            assert rel(Sc, S) > 1e-3       # (the saltation matrix moves S)


def test_a_singular_stance_system_at_a_touchdown_in_c_is_one_line():
    deriv = derivatives(MODEL)
    x = np.zeros(10)
    x[2] = x[3] = np.nan
    with pytest.raises(ValueError, match=r"^the stance KKT system on foot 1 is singular at t=0\.25 s$"):
        variational.touchdown_c(deriv, ("held", U_HELD), 0.25, x, np.eye(10)[:, :6], 1, 2, 0.0, True)


@pytest.mark.parametrize("leg", [1, 2])
@pytest.mark.parametrize("name", ["walking", "walking at its limit"])
def test_the_law_on_the_flows_stance_system_gives_the_same_bits(name, leg):
    """The walking law's derivative on the flow's own factored stance system (one factorisation a stage) against
    the law factoring its own: the same system, so the same bits."""
    rng = np.random.default_rng([leg, len(name), 5])
    ctrl = CONTROLLERS[name](BipedModel())       # (a model of the plant's parameters, not the plant itself)
    deriv = derivatives(MODEL)
    t0, X0, H = _stack(leg, rng)
    law = variational.compiled_law(deriv, ctrl, None)
    assert law[3] != 0
    X1, Phi = variational.steps_transition_c(deriv, law, t0, X0, H, leg)
    X1_own, Phi_own = variational.steps_transition_c(deriv, law[:3], t0, X0, H, leg)
    assert np.array_equal(X1, X1_own) and np.array_equal(Phi, Phi_own)


def test_only_a_law_on_the_plants_parameters_offers_its_derivative_on_the_plants_system():
    assert WalkingController(BipedModel()).compiled_law(MODEL).stance_jacobian != 0
    assert WalkingController(OTHER).compiled_law(OTHER).stance_jacobian != 0
    assert PDWalkingController(MODEL).compiled_law(MODEL).stance_jacobian == 0      # (the PD law needs no model)
    heavier = BipedModel(m_torso=11.0)
    assert WalkingController(heavier).compiled_law(MODEL) is None     # (its own system is not the plant's)
