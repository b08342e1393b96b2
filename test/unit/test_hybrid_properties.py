"""Property-based (hypothesis): over random physically valid starts -- in stance on either foot, in
flight, landing on one foot or on both -- with held or continuous torques, slopes and friction
coefficients, every run ends "completed" with every invariant true at every sample (its scuffs
within scuff_depth), or "stopped" / "failed" with a message. None ends "completed" wrong.
"""
import math

import numpy as np
from hypothesis import HealthCheck, event, example, given, settings, strategies as st

import biped_sim as bs
from biped_sim.analysis.verify import violations

MODEL = bs.BipedModel()
L = MODEL.parameters.l_leg
angle = st.floats(-0.6, 0.6)
rate = st.floats(-2.0, 2.0)
torque = st.floats(-60.0, 60.0)
slope = st.floats(-0.2, 0.2)
friction = st.one_of(st.none(), st.floats(0.2, 1.5))


@st.composite
def stance_start(draw):
    leg = draw(st.sampled_from([1, 2]))
    a = draw(angle)                      # stance leg from the vertical
    b = draw(st.floats(-0.8, 0.8))       # swing leg from the vertical
    torso = draw(st.floats(-0.4, 0.4))
    joints = [math.pi + a - torso, math.pi + b - torso, torso] if leg == 1 else [math.pi + b - torso,
                                                                                  math.pi + a - torso, torso]
    rates = [draw(rate), draw(rate), draw(rate)]
    q, dq = bs.stance_state(MODEL, joints, rates, stance_leg=leg)
    return q, dq, leg


@st.composite
def flight_start(draw):
    a, b, torso = draw(angle), draw(angle), draw(st.floats(-0.4, 0.4))
    if draw(st.booleans()):              # a symmetric V: both feet land at once
        b = -a
    low = max(math.cos(a), math.cos(b)) * L
    height = low + draw(st.floats(0.0, 0.3))
    q = np.array([0.0, height, math.pi + a - torso, math.pi + b - torso, torso])
    dq = np.array([draw(rate), draw(st.floats(-1.0, 1.0)), draw(rate), draw(rate), draw(rate)])
    return q, dq, 0


# found by hypothesis: the swing foot straight under the hip, 31 nm below the ground, 0.25 mm in front
# of the stance foot; the start was accepted (within contact_tol) and its first sample broke ground_tol
SWING_FOOT_JUST_BELOW = (np.array([2.5e-4, 0.99999997, 3.14184265, 3.14159265, 0.0]), np.zeros(5), 1)

# found by hypothesis: foot 2 lands with the legs together at t=0.19141 s; foot 1, disarmed by that reset, was
# pushed 95 um into the ground and out again inside one step, unseen, and the run completed
LEGS_TOGETHER = (np.array([0.0, 0.96891242, 2.89159265, 2.57909265, 0.0]), np.array([0.5, 0.0, 0.0, 0.5, 1.25]), 0)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@example(start=SWING_FOOT_JUST_BELOW, u=(0.0, 1.0), ground=0.0, mu=None, held=False)
@example(start=LEGS_TOGETHER, u=(38.0, 0.0), ground=0.125, mu=None, held=False)
@given(start=st.one_of(stance_start(), flight_start()), u=st.tuples(torque, torque), ground=slope,
       mu=friction, held=st.booleans())
def test_no_run_ends_completed_with_a_violated_invariant(start, u, ground, mu, held):
    q, dq, leg = start
    if ground and leg:   # the stance foot on the sloped ground: shift the state along the slope's normal
        q = q.copy()
        foot = MODEL.foot_position(q, leg)
        q[1] -= math.tan(ground) * foot[0]
    if leg == 0:
        q = q.copy()
        q[1] += max(0.0, -min(MODEL.foot_position(q, k)[1] + math.tan(ground) * MODEL.foot_position(q, k)[0]
                                for k in (1, 2))) + 1e-6
    controller = lambda t, q, dq, stance_leg: u  # noqa: E731
    try:
        r = bs.simulate(MODEL, q, dq, 0.4, controller=controller, stance_leg=leg, mu=mu, slope=ground,
                        control_period=0.01 if held else None)
    except ValueError as exc:   # a start the model refuses (a foot below the ground, an ambiguous contact)
        assert str(exc)
        event("refused")
        return
    event(f"{r.status}, {'flight' if leg == 0 else 'stance'} start, {len(r.impacts)} impacts")
    if r.status == "completed":
        assert not violations(MODEL, r), violations(MODEL, r)
        assert r.stats["deepest_scuff"] <= r.options.scuff_depth
    else:
        assert r.status in ("stopped", "failed") and r.message, (r.status, r.message)
