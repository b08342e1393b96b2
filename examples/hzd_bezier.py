"""An HZD walking law at compiled speed: Bezier virtual constraints held by computed torque.

The law (:func:`hzd_law`) is plain Python in the form of ``biped_sim.control.compiled_laws``; with numba
installed it runs inside the compiled loop, else as plain Python, with the same torques. Run it from
the repository's root::

    python examples/hzd_bezier.py

Outputs (Westervelt, Grizzle et al., "Feedback control of dynamic bipedal robot locomotion"): with
theta = q_s + q3 - pi the stance leg's angle from the vertical (docs/model.md's phi of the stance leg)
and s = (theta - theta_plus) / (theta_minus - theta_plus) its phase over the step (0 after an impact,
1 at the next),

    y1 = q3    - b1(s)          (the torso's pitch)
    y2 = phi_w - b2(s)          (the swing leg's angle from the vertical, phi_w = q_w + q3 - pi)

with b_i(s) = sum_k alpha_ik C(M, k) s^k (1 - s)^(M - k) Bezier polynomials of degree M. The torques
make ddy = -kp y - kd dy exactly (feedback linearisation on the stance dynamics ddq_r = a + Bu u,
``stance_joint_affine``), clipped to the torque limit. The coefficients here are the reference walking
law's (control/walking.py: the torso held at its pitch, the swing leg on the cubic f(phi_s)), exact
as Bezier coefficients of any degree M >= 3 up to roundoff, so the law starts from a gait that walks.
"""
from __future__ import annotations

import math

import numpy as np

from biped_sim.control.compiled_laws import STANCE_CONSTANTS, stance_joint_affine, torque_law

#: where each parameter is in the law's params array; the two outputs' M + 1 coefficients follow
#: ALPHA, then the model's STANCE_CONSTANTS
KP, KD, TORQUE_LIMIT, THETA_PLUS, THETA_MINUS, DEGREE, ALPHA = range(7)


def bernstein_sum(params, first, step, n, s):
    """sum_k d_k C(n, k) s^k (1 - s)^(n - k) over k = 0..n, where d_k is the step-th forward difference of
    the coefficients at params[first + k] (step 0, 1, 2: the coefficients, their differences, their second
    differences). Horner's scheme in the Bernstein basis: acc_k = acc_(k-1) (1 - s) + d_k C(n, k) s^k, with
    no power and no division by 1 - s."""
    t = 1.0 - s
    acc = 0.0
    c = 1.0                             # C(n, k), built up along k
    sk = 1.0                            # s^k, built up along k
    for k in range(n + 1):
        d = params[first + k]
        if step >= 1:
            d = params[first + k + 1] - d
        if step == 2:
            d = params[first + k + 2] - 2.0 * params[first + k + 1] + params[first + k]
        acc = acc * t + d * c * sk
        c = c * (n - k) / (k + 1)
        sk = sk * s
    return acc


def bezier(params, first, m, s):
    """A Bezier polynomial of degree m, its coefficients params[first:first + m + 1], and its first two
    derivatives in s."""
    b = bernstein_sum(params, first, 0, m, s)
    db = bernstein_sum(params, first, 1, m - 1, s)
    ddb = bernstein_sum(params, first, 2, m - 2, s)
    return b, m * db, m * (m - 1) * ddb


def hzd_law(t, q, dq, stance_leg, params, u):
    """The law (module docstring): ``law(t, q, dq, stance_leg, params, u) -> 0``."""
    kp, kd, lim = params[KP], params[KD], params[TORQUE_LIMIT]
    if stance_leg == 0:                         # flight: damp the hips (no walking law in the air)
        u[0] = -kd * dq[2]
        u[1] = -kd * dq[3]
        return 0
    m = int(params[DEGREE])
    s_i, w_i = (2, 3) if stance_leg == 1 else (3, 2)
    theta = q[s_i] + q[4] - math.pi
    dtheta = dq[s_i] + dq[4]
    ds = 1.0 / (params[THETA_MINUS] - params[THETA_PLUS])   # ds / dtheta
    s = (theta - params[THETA_PLUS]) * ds
    b1, db1, ddb1 = bezier(params, ALPHA, m, s)
    b2, db2, ddb2 = bezier(params, ALPHA + m + 1, m, s)
    db1, ddb1, db2, ddb2 = db1 * ds, ddb1 * ds * ds, db2 * ds, ddb2 * ds * ds      # in theta
    y1 = q[4] - b1
    y2 = q[w_i] + q[4] - math.pi - b2
    # dy = H dq_r over r = (q1, q2, q3); theta = q_s + q3 - pi
    h1s, h1w, h13 = -db1, 0.0, 1.0 - db1
    h2s, h2w, h23 = -db2, 1.0, 1.0 - db2
    h10, h11 = (h1s, h1w) if stance_leg == 1 else (h1w, h1s)
    h20, h21 = (h2s, h2w) if stance_leg == 1 else (h2w, h2s)
    dy1 = h10 * dq[2] + h11 * dq[3] + h13 * dq[4]
    dy2 = h20 * dq[2] + h21 * dq[3] + h23 * dq[4]
    # ddy = H ddq_r + bias, bias_i = -b_i'' dtheta^2; ddq_r = a + Bu u
    a0, a1, a2, B00, B01, B10, B11, B20, B21 = stance_joint_affine(
        q, dq, stance_leg, params[ALPHA + 2 * (m + 1):])
    r1 = -kp * y1 - kd * dy1 - (h10 * a0 + h11 * a1 + h13 * a2) + ddb1 * dtheta * dtheta
    r2 = -kp * y2 - kd * dy2 - (h20 * a0 + h21 * a1 + h23 * a2) + ddb2 * dtheta * dtheta
    m00 = h10 * B00 + h11 * B10 + h13 * B20     # (H Bu) u = r
    m01 = h10 * B01 + h11 * B11 + h13 * B21
    m10 = h20 * B00 + h21 * B10 + h23 * B20
    m11 = h20 * B01 + h21 * B11 + h23 * B21
    det = m00 * m11 - m01 * m10
    u[0] = min(lim, max(-lim, (m11 * r1 - m01 * r2) / det))
    u[1] = min(lim, max(-lim, (m00 * r2 - m10 * r1) / det))
    return 0


def reference_coefficients(degree=5, step_angle=0.2, torso_pitch=0.15, clearance=0.5, lag=-0.04):
    """(alpha_torso, alpha_swing) of degree ``degree``: the reference walking law's constraints (the torso
    at ``torso_pitch``; the swing leg on control/walking.py's f(phi_s)), fitted at Chebyshev nodes
    (exact for degree >= 3: f is a cubic)."""
    s = 0.5 - 0.5 * np.cos(np.pi * (np.arange(degree + 1) + 0.5) / (degree + 1))
    theta = -step_angle + 2.0 * step_angle * s
    b = 1.0 - (theta / step_angle) ** 2
    f = -theta * (1.0 + clearance * b) + lag * b
    basis = np.array([[math.comb(degree, k) * sk ** k * (1.0 - sk) ** (degree - k) for k in range(degree + 1)]
                      for sk in s])
    return [torso_pitch] * (degree + 1), np.linalg.solve(basis, f).tolist()


def hzd_controller(model, kp=200.0, kd=30.0, torque_limit=500.0, step_angle=0.2, degree=5, alpha_torso=None,
                   alpha_swing=None):
    """The HZD law with its parameters on ``model``: a controller for every tool (``--controller
    examples.hzd_bezier:hzd_controller``; ``controller.kp`` etc. in a sweep). The coefficients default to
    :func:`reference_coefficients`."""
    degree = int(degree)
    ref_torso, ref_swing = reference_coefficients(degree, step_angle)
    alpha_torso = ref_torso if alpha_torso is None else list(alpha_torso)
    alpha_swing = ref_swing if alpha_swing is None else list(alpha_swing)
    if len(alpha_torso) != degree + 1 or len(alpha_swing) != degree + 1:
        raise ValueError(f"a Bezier polynomial of degree {degree} has {degree + 1} coefficients")
    params = [kp, kd, torque_limit, -step_angle, step_angle, degree, *alpha_torso, *alpha_swing,
              *model.k[STANCE_CONSTANTS]]
    return torque_law(hzd_law, params, name="hzd_bezier")


def initial_state(model, controller, speed=1.0):
    """(q, dq): a state on the constraints at a step's start (s = 0, stance leg 1, its foot at the
    origin), the stance leg turning at ``speed`` rad/s."""
    from biped_sim.engine.simulate import stance_state
    p = controller.params
    m, ds = int(p[DEGREE]), 1.0 / (p[THETA_MINUS] - p[THETA_PLUS])
    b1, db1, _ = bezier(p, ALPHA, m, 0.0)
    b2, db2, _ = bezier(p, ALPHA + m + 1, m, 0.0)
    q3, dq3 = b1, db1 * ds * speed
    theta = p[THETA_PLUS]
    return stance_state(model, [theta + math.pi - q3, b2 + math.pi - q3, q3],
                        [speed - dq3, db2 * ds * speed - dq3, dq3])


def main():
    import time

    import biped_sim as bs
    from biped_sim.analysis.gait import find_gait, format_gait

    scene = bs.load_scene("walk")
    model = scene.engine_arguments()["model"]
    ctrl = hzd_controller(model)
    t0 = time.perf_counter()
    compiled = ctrl.compiled_law(model) is not None
    print(f"compiled: {compiled} ({time.perf_counter() - t0:.2f} s to compile)")
    r = scene.simulate(controller=ctrl)     # the walk scene: 10 s, torques held 1 ms
    print(f"walk scene {r.t[-1]:g} s: {r.status}, {len(r.impacts)} impacts, hip x {r.q[-1, 0]:.4f} m, "
          f"wall {r.stats['wall_time']:.3f} s, real-time factor {r.stats['real_time_factor']:.0f}")
    q0, dq0 = initial_state(model, ctrl)
    gait = find_gait(model, ctrl, z0=np.concatenate([q0[2:], dq0[2:]]))
    print(format_gait(gait))


if __name__ == "__main__":
    main()
