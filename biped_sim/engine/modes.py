"""The continuous dynamics of each mode as the integrator sees them: right-hand sides on lists.

A mode is (stance leg 1 or 2, or flight) x (floating or fixed base). For each, ``mode_functions``
returns ``rhs(t, y)`` and the maps between the integrator's state ``y`` and the physical state:

* floating base (stance and flight): ``y = q + dq + [work]``, 11 values; the stance right-hand side
  is the generated closed form of docs/model.md "Stance, floating-base";
* fixed base: ``y = (q1, q2, q3) + (dq1, dq2, dq3) + [work]``, 7 values, and the hip hangs from the
  stance foot's pin ``c`` (docs/model.md "Stance, fixed-base").

The last entry integrates the motors' power ``u1 dq1 + u2 dq2``, for the energy balance. Every
evaluation hands its torque (and, in floating-base stance, its KKT force; else None) to
``sink(F, u)``: the steppers evaluate last at the step's end, so the sample there needs neither a
second solve nor a second controller call.
"""
from __future__ import annotations

import numpy as np

from biped_sim.engine import loop_rules as rules
from biped_sim.engine.compiled import gen
from biped_sim.engine.dynamics import flight_fast, stance_fixed_accel_fast
from biped_sim.engine.model import BipedModel, hip_hung_from, real_vector, short_repr
from biped_sim.engine.results import ControllerError


def two_finite_floats(u):
    """[u0, u1] as Python floats if u is two finite real numbers with a finite sum (``model.real_vector``: a
    list, tuple or array of ints and floats; no bools, complex numbers or strings), else None. Runs at every
    evaluation: two floats in a list or tuple, and a float64 array, are taken without the general check."""
    tu = type(u)
    if tu is list or tu is tuple:
        if len(u) == 2:
            u0, u1 = u
            if type(u0) is float and type(u1) is float and rules.ev_finite_torques(u0, u1):
                return [u0, u1]
    elif tu is np.ndarray and u.shape == (2,) and u.dtype.char == "d":
        u0, u1 = u.tolist()
        if rules.ev_finite_torques(u0, u1):
            return [u0, u1]
    a, _ = real_vector(u, 2)     # anything else
    if a is None:
        return None
    u0, u1 = a.tolist()
    return [u0, u1] if rules.ev_finite_torques(u0, u1) else None


def finite_floats(u, m):
    """u as a list of m Python floats if u is m finite real numbers with a finite sum, else None
    (``two_finite_floats`` for m = 2, the three-link's two hip motors)."""
    if m == 2:
        return two_finite_floats(u)
    a, _ = real_vector(u, m)
    if a is None:
        return None
    v = a.tolist()
    return v if rules.ev_finite_sum(v, m) else None


def count_word(m):
    return "two" if m == 2 else str(m)


def checked_torques(u, t, m=2):
    """The m torques a controller returned, as finite floats, or a ControllerError."""
    out = finite_floats(u, m)
    if out is None:
        raise ControllerError(f"the controller returned {short_repr(u)} at t={t:.9g} s: it must return "
                              f"{count_word(m)} finite torques (real numbers: not bools, complex numbers or strings)")
    return out


def controller_raised(exc, t):
    """The ControllerError that ends a run whose controller raised ``exc`` at t (raise it ``from exc``: the
    cause keeps its traceback); its message names where: the file and line of the frame that raised."""
    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    where = f" ({tb.tb_frame.f_code.co_filename}:{tb.tb_lineno} in {tb.tb_frame.f_code.co_name})" if tb else ""
    return ControllerError(f"the controller raised {type(exc).__name__} at t={t:.9g} s: {exc}{where}")


def controller_failure(exc, t):
    """``raise controller_raised(exc, t) from exc`` as an object: the ControllerError, ``exc`` its cause (the
    compiled loop raises it where its direct call of the controller caught ``exc``)."""
    error = controller_raised(exc, t)
    error.__cause__ = exc
    return error


def checked_command(controller, m=2, stance_leg=None):
    """``controller(t, q, dq, stance_leg)`` with its m torques checked: ``command(t, q, dq, stance_leg)``, a control
    period's command; given ``stance_leg``, ``command(t, q, dq)`` calls it with that leg (``bind_controller``). A
    controller that raises, or returns anything but m finite real numbers, is a ControllerError. (The compiled
    loop calls a controller directly and checks it the same way: ``_core.c`` call_controller.)"""
    def command(t, q, dq, stance_leg=stance_leg):   # at every right-hand-side evaluation: the message only on failure
        try:
            u = controller(t, q, dq, stance_leg)
        except Exception as exc:   # a fault of the user's code ends the run "failed", with its message
            raise controller_raised(exc, t) from exc
        v = two_finite_floats(u) if m == 2 else finite_floats(u, m)
        return v if v is not None else checked_torques(u, t, m)
    return command


def bind_controller(controller, stance_leg, m=2):
    """``controller(t, q, dq, stance_leg)`` as ``f(t, q, dq)``, with its m torques checked (``checked_command`` with
    the stance leg given); None for no controller. q and dq are lists of floats (the controller's own: the engine
    does not use them after the call)."""
    return None if controller is None else checked_command(controller, m, stance_leg)


def floating_to_phys(y):
    """(q, dq, work) of the floating base's integrated state y = q + dq + [work] (N coordinates: 2 N + 1 entries)."""
    yl = y if type(y) is list else y.tolist()
    n = len(yl) >> 1
    return yl[0:n], yl[n:2 * n], yl[2 * n]


def floating_from_phys(q, dq, w):   # lists
    return q + dq + [w]


def mode_functions(model, stance_leg, base, pin, u_hold, control, sink):
    """(rhs, to_physical, from_physical) of a mode. ``control(t, q, dq) -> u`` (lists) or None to hold
    ``u_hold``; ``sink(F, u)`` receives each evaluation's force (or None) and torque."""
    if not isinstance(model, BipedModel):
        return _generated_functions(model, stance_leg, base, pin, u_hold, control, sink)
    if stance_leg and base == "fixed":
        return _fixed_base_functions(model, stance_leg, pin, u_hold, control, sink)

    to_phys, from_phys = floating_to_phys, floating_from_phys

    if stance_leg:   # the generated closed form itself, one per stance leg
        k_stance = model.k_stance
        stance = gen.stance_floating_1 if stance_leg == 1 else gen.stance_floating_2

        def rhs(t, y):
            q, dq = y[0:5], y[5:10]
            u = u_hold if control is None else control(t, y[0:5], y[5:10])   # (lists of its own)
            ddq, F = stance(q, dq, u, k_stance)
            sink(F, u)
            return dq + ddq + [rules.ev_motor_power(u, dq[2], dq[3])]
    else:
        def rhs(t, y):
            q, dq = y[0:5], y[5:10]
            u = u_hold if control is None else control(t, y[0:5], y[5:10])
            ddq = flight_fast(model, q, dq, u)
            sink(None, u)
            return dq + ddq + [rules.ev_motor_power(u, dq[2], dq[3])]
    return rhs, to_phys, from_phys


def _generated_functions(model, stance_leg, base, pin, u_hold, control, sink):
    """A described robot's mode (a GeneratedModel's kernels): floating-base stance on contact point stance_leg
    (the KKT solve, k_stance) or flight (k_flight), y = q + dq + [work], or fixed-base stance; the motors' power
    u . (B^T dq)."""
    n, m, joints = model.n, model.m, model.actuated_indices
    if stance_leg and base == "fixed":
        return _generated_fixed_base_functions(model, stance_leg, pin, u_hold, control, sink)

    if stance_leg:
        k_stance, c = model.k_stance, stance_leg - 1

        def rhs(t, y):
            q, dq = y[0:n], y[n:2 * n]
            u = u_hold if control is None else control(t, y[0:n], y[n:2 * n])
            ddq, F = k_stance(q, dq, u, c)
            sink(F, u)
            return dq + ddq + [rules.ev_actuated_power(u, dq, joints, m)]
    else:
        k_flight = model.k_flight

        def rhs(t, y):
            q, dq = y[0:n], y[n:2 * n]
            u = u_hold if control is None else control(t, y[0:n], y[n:2 * n])
            ddq = k_flight(q, dq, u)
            sink(None, u)
            return dq + ddq + [rules.ev_actuated_power(u, dq, joints, m)]
    return rhs, floating_to_phys, floating_from_phys


def _generated_fixed_base_functions(model, stance_leg, pin, u_hold, control, sink):
    """A described robot's fixed-base stance on contact point stance_leg: y = q[2:] + dq[2:] + [work], the joint
    angles and their rates; the base hangs from the pin c (``GeneratedModel.base_hung_from``); the accelerations
    are the KKT solve's (k_stance) at that state."""
    n, m, joints = model.n, model.m, model.actuated_indices
    a = n - 2                   # the angles
    c = stance_leg - 1
    hung, k_stance = model.base_hung_from, model.k_stance

    def to_phys(y):
        yl = y if type(y) is list else y.tolist()
        angles, rates = yl[0:a], yl[a:2 * a]
        base, dbase = hung(c, pin, angles, rates)
        return base + angles, dbase + rates, yl[2 * a]

    def from_phys(q, dq, w):   # lists
        return q[2:] + dq[2:] + [w]

    def rhs(t, y):
        q, dq, _ = to_phys(y)
        u = u_hold if control is None else control(t, q, dq)
        ddq, F = k_stance(q, dq, u, c)
        sink(None, u)           # (as the three-link's fixed base: the guards ask for the force)
        return dq[2:] + ddq[2:] + [rules.ev_actuated_power(u, dq, joints, m)]
    return rhs, to_phys, from_phys


def _fixed_base_functions(model, stance_leg, pin, u_hold, control, sink):
    """The three-link's fixed-base stance on leg stance_leg: y = (q1, q2, q3) + (dq1, dq2, dq3) + [work]; the hip
    hangs from the pin c (``engine.model.hip_hung_from``); the accelerations are the pinned chain's."""
    l_leg, i = model.parameters.l_leg, stance_leg - 1

    def to_phys(y):
        yl = y if type(y) is list else y.tolist()
        angles, rates = yl[0:3], yl[3:6]
        hip, dhip = hip_hung_from(l_leg, i, pin, angles, rates)
        hip += angles       # (in place, one list fewer: the two lists are this call's own)
        dhip += rates
        return hip, dhip, yl[6]

    def from_phys(q, dq, w):   # lists
        return q[2:] + dq[2:] + [w]

    def rhs(t, y):
        qs, dqs = y[0:3], y[3:6]
        if control is None:
            u = u_hold
        else:
            q, dq, _ = to_phys(y)
            u = control(t, q, dq)
        dds = stance_fixed_accel_fast(model, qs, dqs, u, stance_leg)   # no force: guards ask for it
        sink(None, u)
        return dqs + dds + [rules.ev_motor_power(u, dqs[0], dqs[1])]
    return rhs, to_phys, from_phys


def project_onto_pin(q, dq, foot, pin, tan_slope, project=True):
    """(q, dq, drift, drift rate) of a floating-base stance state whose stance foot (``foot``, its
    FootState) has drifted from its pin: the drift |p - c| and |J dq| before the projection, and the
    state projected back (the hip moved by the drift, the base velocity set so that J dq = 0) where
    ``project``, else unchanged (the rules ``loop_rules.ev_pin_drift``, ``ev_pin_drift_rate`` and
    ``ev_project_onto_pin``). Lists in, lists out."""
    drift, rate = rules.ev_pin_drift(foot, pin, tan_slope), rules.ev_pin_drift_rate(foot)
    if not project:
        return q, dq, drift, rate
    q, dq = list(q), list(dq)
    rules.ev_project_onto_pin(q, dq, foot, pin, tan_slope)
    return q, dq, drift, rate
