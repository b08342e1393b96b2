"""The list-based Runge-Kutta steppers against scipy's solvers, and the node's choice of method."""
import numpy as np
import pytest
from scipy.integrate import DOP853, RK45, solve_ivp

from biped_sim.config.parameters import resolve_method, validate
from biped_sim.engine._gen import rk_steps as _rk_steps
from biped_sim.engine.integrators import DOP853Stepper, DOPRI5Stepper


def oscillator_list(t, y):
    # a damped oscillator and a driven one: 11 entries, like the engine's floating-base state
    return [y[1], -y[0] - 0.1 * y[1], y[3], -4.0 * y[2] + np.cos(t).item()] + [0.5 * v for v in y[4:]]


def oscillator_array(t, y):
    return np.array(oscillator_list(t, y.tolist()))


@pytest.mark.parametrize("ours, theirs, n", [(DOP853Stepper, DOP853, 11), (DOPRI5Stepper, RK45, 11),
                                             (DOP853Stepper, DOP853, 7), (DOPRI5Stepper, RK45, 7),
                                             (DOP853Stepper, DOP853, 5), (DOPRI5Stepper, RK45, 5)])
def test_list_steppers_take_scipys_steps(ours, theirs, n):
    """Same tableau, error norm and step control as scipy's solver (sizes 7 and 11 run the unrolled
    code, 5 the generic one): the same first step, the same number of steps to the end, the same
    end state to the tolerance, and a dense output as accurate as the steps. (Step for step the
    sizes drift apart by ~1e-7 relative: the error estimate is a difference of stages, where
    summation order changes the rounding.)"""
    y0 = [1.0, 0.0, 0.5, 0.2] + [0.1 * (i + 1) for i in range(n - 4)]

    def f_list(t, y):
        return oscillator_list(t, y + [0.0] * (11 - n))[:n]

    def f_array(t, y):
        return np.array(f_list(t, y.tolist()))
    a = ours(f_list, 0.0, y0, 5.0, rtol=1e-8, atol=1e-8)
    b = theirs(f_array, 0.0, np.array(y0), 5.0, rtol=1e-8, atol=1e-8)
    assert a.h_abs == b.h_abs                       # the same initial step selection
    ref = solve_ivp(f_array, (0.0, 5.0), y0, method="DOP853", rtol=1e-13, atol=1e-13, dense_output=True).sol
    steps_a = 0
    while a.t < 5.0:
        a.step()
        steps_a += 1
        tm = 0.5 * (a.t_old + a.t)
        np.testing.assert_allclose(a.dense_output()(tm), ref(tm), rtol=0, atol=1e-6)
    steps_b = 0
    while b.status == "running":
        b.step()
        steps_b += 1
    assert steps_a > 10 and abs(steps_a - steps_b) <= 1
    np.testing.assert_allclose(a.y, b.y, rtol=0, atol=1e-7)
    np.testing.assert_allclose(a.y, ref(5.0), rtol=0, atol=1e-7)


def test_unrolled_and_generic_steps_agree():
    f = oscillator_list
    y = [1.0 + i for i in range(11)]
    for name in ("dop853", "dopri5"):
        g = getattr(_rk_steps, f"{name}_step")(f, 0.3, y, f(0.3, y), 1e-2, 1e-9, 1e-9)
        u = getattr(_rk_steps, f"{name}_step_11")(f, 0.3, y, f(0.3, y), 1e-2, 1e-9, 1e-9)
        assert g[0] == u[0] and g[1] == u[1] and g[2] == pytest.approx(u[2], rel=1e-13)


def test_method_auto_picks_dopri5_for_short_control_periods():
    assert resolve_method(validate({"control_period": 0.001})) == "dopri5"
    assert resolve_method(validate({"control_period": 0.005})) == "dopri5"
    assert resolve_method(validate({"control_period": 0.01})) == "dop853"
    assert resolve_method(validate({"control_period": 0.001, "method": "dop853"})) == "dop853"
    with pytest.raises(ValueError, match="method"):
        validate({"method": "rk45"})


@pytest.mark.parametrize("cls", [DOP853Stepper, DOPRI5Stepper])
def test_a_stepper_on_a_given_state_takes_the_steps_of_one_on_its_own(cls):
    """A stepper given a hybrid state (the pure-Python simulator's: make_stepper(S=...)) runs on it, and
    what an earlier stepper left there (counters, step sizes, another method's options) changes no bit."""
    from biped_sim.engine.loop_state import new_state
    y0 = [1.0, 0.0, 0.5, 0.2] + [0.1 * (i + 1) for i in range(7)]
    S = new_state()
    old = DOP853Stepper(oscillator_list, 0.0, [v + 1.0 for v in y0], 3.0, rtol=1e-6, atol=1e-6, max_step=0.01, S=S)
    for _ in range(5):
        old.step()
    old.dense_at(old.t - 0.001)
    own = cls(oscillator_list, 0.5, y0, 2.0, rtol=1e-8, atol=1e-8)
    shared = cls(oscillator_list, 0.5, y0, 2.0, rtol=1e-8, atol=1e-8, S=S)
    assert shared.S is S and own.S is not S
    while own.t < 2.0:
        own.step()
        shared.step()
        assert (shared.t, shared.y, shared.h_abs) == (own.t, own.y, own.h_abs)
        assert shared.dense_at(shared.t - 0.3 * shared.h) == own.dense_at(own.t - 0.3 * own.h)
    assert (shared.nfev, shared.naccepted, shared.nrejected) == (own.nfev, own.naccepted, own.nrejected)
