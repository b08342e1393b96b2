"""RABBIT's walking law: four virtual constraints held by computed torque through the stance KKT system.

Owns the walking feedback law of a five-link biped with knees (docs/models.md, "RABBIT walking"); it is not
an equation of docs/model.md. The robot's coordinates are q = [base_x, base_y, hip_1, hip_2, knee_1,
knee_2, torso_pitch] (a femur hanging straight down has hip = pi, a straight knee is 0, knee > 0 swings
the foot back), with motors on the hips and the knees. For leg i the line from the hip to the foot, the
*virtual leg*, has the absolute angle from straight down

  phi_i = torso_pitch + hip_i + knee_i / 2 - pi        (phi > 0: foot behind the hip)

(exact for a femur and a tibia of equal length, as RABBIT's: the hip, the knee and the foot make an isosceles
triangle), and the length 2 l cos(knee_i / 2). The phase variable is the stance leg's, theta = phi_s: it grows
from -step_angle at the start of a step to +step_angle at the touchdown while the hip passes over the
stance foot. The four outputs (hybrid-zero-dynamics style, Westervelt and Grizzle) are

  y1 = torso_pitch - pitch                       (hold the torso at a lean)
  y2 = knee_s - stance_knee                      (a stance knee bent by a constant angle)
  y3 = phi_w + theta                             (the swing leg mirrors the stance leg)
  y4 = knee_w - g(theta),  g = stance_knee + (swing_knee - stance_knee) b,  b = 1 - (theta / step_angle)^2

so at both ends of a step the legs are equal and symmetric (both feet on flat ground), and in between the
swing knee bends up to ``swing_knee`` at mid-step, which shortens the swing leg and lifts its foot. After
a touchdown the same outputs, the legs' roles swapped, are zero again: the law needs no coordinate swap.

The impact blend: the rigid impact changes the rates, so just after a touchdown on the gait the outputs'
rates would not be zero (the new swing leg still swings back, its knee hardly moves) and the law would
spend large torques to take that error out at every step. Each target therefore adds, over the first
``impact_blend`` of the step,

  delta_i e w^3,  e = theta - theta+,  w = 1 - e / (2 step_angle impact_blend)     (0 beyond)

with theta+ = -step_angle: zero at theta+ with slope delta_i, and zero with its slope and curvature where
it ends, so the end of the step, and the state at the touchdown, are the nominal targets'. The slopes
delta are computed once, from the state on the gait at the touchdown and the model's ``impact_map``, so
that the outputs' rates right after that impact are zero: the gait's impact lands on the outputs (the
hybrid zero dynamics' invariance), and a step on the gait needs no correction.

The torques make ddy = -kp y - kd dy exactly (feedback linearisation): with the stance foot pinned,
``[D -J_c^T; J_c 0] [ddq; F] = [B u - C dq - G; -Jdot_c dq]`` gives ddq = a + A u, and y'' = H ddq + bias, so
(H A) u = -kp y - kd dy - H a - bias, a 4 x 4 solve, clipped to ``torque_limit``. Where H A is singular the
PD term below holds the outputs instead; in flight the joints are damped (no walking law in the air).
"""
from __future__ import annotations

import math

import numpy as np

#: the coordinates the law reads, by name (their positions come from the model)
COORDINATES = ("hip_1", "hip_2", "knee_1", "knee_2", "torso_pitch")
#: the joints it drives, by name (the model's actuated joints, in any order)
ACTUATED = ("hip_1", "hip_2", "knee_1", "knee_2")


def _check_model(model):
    coordinates = tuple(getattr(model, "coordinates", ()))
    actuated = tuple(getattr(getattr(model, "description", None), "actuated", ()))
    missing = [c for c in COORDINATES if c not in coordinates]
    if missing or sorted(actuated) != sorted(ACTUATED) or not hasattr(model, "stance_dynamics"):
        what = (f"{model.name!r} with coordinates {list(coordinates)} and motors {list(actuated)}" if coordinates
                else f"a {type(model).__name__}")
        raise ValueError(f"RabbitWalkingController needs a five-link biped with knees (bs.load_model('rabbit')): "
                         f"coordinates {', '.join(COORDINATES)} and motors on {', '.join(ACTUATED)}; got {what}")
    return coordinates, actuated


class RabbitWalkingController:
    """``controller(t, q, dq, stance_leg) -> u`` (4 torques, in the model's actuated order) for RABBIT.

    ``stance_leg`` 1 or 2 is the pinned contact point (foot_1, foot_2), 0 flight. q and dq may be lists or
    arrays.
    """

    #: u_x jumps where the impact blend ends (theta = theta+ + 2 step_angle impact_blend: the blend is C2 there,
    #: h_d''' jumps): run_jacobian integrates the variational equations with their own error control
    #: (solve_ivp) rather than differentiating the engine's steps, one of which straddles that surface
    jacobian_jumps = True

    #: the law's named parameters (a scene's walk_controller section sets them)
    GAINS = ("torso_pitch", "step_angle", "stance_knee", "swing_knee", "impact_blend", "kp", "kd", "torque_limit")

    def __init__(self, model, torso_pitch=0.1, step_angle=0.25, stance_knee=0.3, swing_knee=1.0,
                 impact_blend=0.9, kp=400.0, kd=40.0, torque_limit=150.0):
        coordinates, actuated = _check_model(model)
        values = dict(torso_pitch=torso_pitch, step_angle=step_angle, stance_knee=stance_knee,
                      swing_knee=swing_knee, impact_blend=impact_blend, kp=kp, kd=kd, torque_limit=torque_limit)
        for name, value in values.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"RabbitWalkingController: {name} must be a finite number, got {value!r}")
        for name in ("step_angle", "torque_limit"):
            if values[name] <= 0:
                raise ValueError(f"RabbitWalkingController: {name} must be positive, got {values[name]!r}")
        for name in ("kp", "kd"):
            if values[name] < 0:
                raise ValueError(f"RabbitWalkingController: {name} must be >= 0, got {values[name]!r}")
        if not 0.0 <= stance_knee < math.pi or not 0.0 <= swing_knee < math.pi:
            raise ValueError(f"RabbitWalkingController: stance_knee and swing_knee must be in [0, pi) (a knee "
                             f"bent forward; pi folds the leg), got {stance_knee!r} and {swing_knee!r}")
        if not 0.0 < impact_blend < 1.0:
            raise ValueError(f"RabbitWalkingController: impact_blend must be in (0, 1) (a fraction of the step), got "
                             f"{impact_blend!r}")
        self.model = model
        for name, value in values.items():
            setattr(self, name, float(value))
        index = {c: coordinates.index(c) for c in COORDINATES}
        self._torso = index["torso_pitch"]
        #: per stance leg 1, 2: (stance hip, swing hip, stance knee, swing knee) as indices of q
        self._legs = {1: (index["hip_1"], index["hip_2"], index["knee_1"], index["knee_2"]),
                      2: (index["hip_2"], index["hip_1"], index["knee_2"], index["knee_1"])}
        self._column = {name: actuated.index(name) for name in ACTUATED}   # u's entry of each joint
        self._B = np.asarray(model.B, dtype=float)
        self._slopes = self._impact_slopes()

    # -- the outputs --------------------------------------------------------------------------------
    def knee_target(self, theta):
        """g(theta) of the swing knee and its first two derivatives."""
        a2 = self.step_angle * self.step_angle
        lift = self.swing_knee - self.stance_knee
        return (self.stance_knee + lift * (1.0 - theta * theta / a2), -2.0 * lift * theta / a2, -2.0 * lift / a2)

    def targets(self, theta):
        """(h_d, h_d', h_d''): the four outputs' targets at the phase theta and their derivatives in theta:
        the nominal targets plus the impact blend."""
        g, dg, ddg = self.knee_target(theta)
        hd = np.array([self.torso_pitch, self.stance_knee, -theta, g])
        dhd = np.array([0.0, 0.0, -1.0, dg])
        ddhd = np.array([0.0, 0.0, 0.0, ddg])
        e = theta + self.step_angle                 # theta - theta+, theta+ = -step_angle
        span = 2.0 * self.step_angle * self.impact_blend
        if e < span and self._slopes is not None:
            # delta e w^3, w = 1 - e / span: value 0 and slope delta at theta+, and value, slope and
            # curvature 0 at e = span (C2 there)
            w = 1.0 - e / span
            d = self._slopes
            hd = hd + d * (e * w ** 3)
            dhd = dhd + d * (w * w * (w - 3.0 * e / span))
            ddhd = ddhd - d * (6.0 * w * (w - e / span) / span)
        return hd, dhd, ddhd

    def target_third_derivative(self, theta):
        """h_d'''(theta): the knee target's is 0 (a parabola); the impact blend's delta f'''(e), f = e w^3, is
        delta 6 (3 w - e / span) / span^2 (0 beyond the blend)."""
        e = theta + self.step_angle
        span = 2.0 * self.step_angle * self.impact_blend
        if e < span and self._slopes is not None:
            w = 1.0 - e / span
            return self._slopes * (6.0 * (3.0 * w - e / span) / (span * span))
        return np.zeros(4)

    def phase(self, q, stance_leg):
        """theta = phi_s, the stance leg's virtual-leg angle from straight down (rad)."""
        hs, _hw, ks, _kw = self._legs[stance_leg]
        return q[self._torso] + q[hs] + 0.5 * q[ks] - math.pi

    def phase_rate(self, dq, stance_leg):
        """theta' (rad/s)."""
        hs, _hw, ks, _kw = self._legs[stance_leg]
        return dq[self._torso] + dq[hs] + 0.5 * dq[ks]

    def outputs(self, q, dq, stance_leg):
        """(y, dy, H, bias): y = h(q) - h_d(theta) (4), dy = H dq, y'' = H ddq + bias (H: 4 x n)."""
        q = np.asarray(q, dtype=float)
        dq = np.asarray(dq, dtype=float)
        hs, hw, ks, kw = self._legs[stance_leg]
        t = self._torso
        c = np.zeros(q.size)        # theta = c . q - pi
        c[t], c[hs], c[ks] = 1.0, 1.0, 0.5
        theta = float(c @ q) - math.pi
        dtheta = float(c @ dq)
        hd, dhd, ddhd = self.targets(theta)
        H = -np.outer(dhd, c)       # dh/dq - h_d'(theta) c
        H[0, t] += 1.0
        H[1, ks] += 1.0
        H[2, t] += 1.0
        H[2, hw] += 1.0
        H[2, kw] += 0.5
        H[3, kw] += 1.0
        h = np.array([q[t], q[ks], q[t] + q[hw] + 0.5 * q[kw] - math.pi, q[kw]])
        return h - hd, H @ dq, H, -ddhd * dtheta * dtheta

    def _impact_slopes(self):
        """The slopes delta of the impact blend that make the impact of the gait land on the outputs: at the
        touchdown (theta = step_angle) the state on the gait (y = 0, dy = 0) meets the rigid impact, and the
        new stance leg's outputs then have dy = h_d'-error * theta'+; delta cancels it (dy+ = 0)."""
        self._slopes = None
        q, dq = self.state_on_gait(1.0, stance_leg=1, theta=self.step_angle)
        dq_plus, _impulse = self.model.impact_map(q, dq, 2)
        _y, dy, _H, _bias = self.outputs(q, dq_plus, 2)
        return dy / self.phase_rate(dq_plus, 2)

    # -- the law ------------------------------------------------------------------------------------
    def stance_affine(self, q, dq, stance_leg):
        """(a, A): the stance dynamics on contact ``stance_leg`` as ddq = a + A u (the KKT system solved for
        the drift and for each motor's column of B at once)."""
        m = self.model
        n = len(q)
        J = m.contact_jacobian(q, stance_leg)
        K = np.zeros((n + 2, n + 2))
        K[:n, :n], K[:n, n:], K[n:, :n] = m.mass_matrix(q), -J.T, J
        rhs = np.zeros((n + 2, 1 + self._B.shape[1]))
        rhs[:n, 0] = -m.bias_forces(q, dq)
        rhs[n:, 0] = -m.contact_jacobian_dot(q, dq, stance_leg) @ np.asarray(dq, dtype=float)
        rhs[:n, 1:] = self._B
        x = np.linalg.solve(K, rhs)
        return x[:n, 0], x[:n, 1:]

    def pd_torques(self, y, dy, stance_leg):
        """The PD term: each output held by the motor that moves it most directly (the swing hip y3, the knees
        y2 and y4, the stance hip the torso against its reaction), as the three-link's PD law does."""
        kp, kd = self.kp, self.kd
        v = -kp * y - kd * dy
        swing_hip = v[2]
        u = {}
        s_hip, w_hip, s_knee, w_knee = (("hip_1", "hip_2", "knee_1", "knee_2") if stance_leg == 1
                                        else ("hip_2", "hip_1", "knee_2", "knee_1"))
        u[w_hip] = swing_hip
        u[s_hip] = -v[0] - swing_hip          # the hips' reactions turn the torso: both hold it
        u[s_knee] = v[1]
        u[w_knee] = v[3]
        return self._ordered(u)

    def _ordered(self, by_joint):
        out = np.zeros(len(ACTUATED))
        for name, value in by_joint.items():
            out[self._column[name]] = value
        return out

    def __call__(self, t, q, dq, stance_leg):
        lim = self.torque_limit
        if stance_leg == 0:     # flight: damp the joints (no walking law in the air)
            rates = {name: float(dq[self.model.coordinates.index(name)]) for name in ACTUATED}
            return np.clip(self._ordered({k: -self.kd * v for k, v in rates.items()}), -lim, lim)
        u, y, dy, _H, _a, _A, _HA = self._computed_torque(np.asarray(q, dtype=float), np.asarray(dq, dtype=float),
                                                           stance_leg)
        if u is None:       # the outputs cannot all be decoupled here: the PD term holds them
            u = self.pd_torques(y, dy, stance_leg)
        return np.clip(u, -lim, lim)

    def _computed_torque(self, q, dq, stance_leg):
        """(u, y, dy, H, a, A, H A): the torque that gives y'' = -kp y - kd y' through the stance dynamics
        ddq = a + A u, H (a + A u) + bias = -kp y - kd dy; u None where H A is singular (the outputs cannot all
        be decoupled: the PD term holds them)."""
        y, dy, H, bias = self.outputs(q, dq, stance_leg)
        a, A = self.stance_affine(q, dq, stance_leg)
        HA = H @ A
        rhs = -self.kp * y - self.kd * dy - H @ a - bias
        try:
            if np.linalg.cond(HA) > 1e10:
                raise np.linalg.LinAlgError
            u = np.linalg.solve(HA, rhs)
        except np.linalg.LinAlgError:
            u = None
        return u, y, dy, H, a, A, HA

    def jacobian(self, t, q, dq, stance_leg):
        """d u / d(q, dq) (4 x 2n) of this law, exact (engine/sensitivity.py's run Jacobians use it).

        The computed torque u* solves Phi(x, u) = H ddq(x, u) + bias + kp y + kd dy = 0, so
        u*_x = -(H A)^-1 Phi_x with ddq and its derivatives from the model's stance KKT system differentiated
        (``stance_dynamics_jacobian``) at u*. H depends on q through the phase theta = c . q - pi
        (H = dh/dq - h_d'(theta) c^T), so (dH/dq_k) v = -h_d'' (c . v) c_k, and bias = -h_d'' theta'^2 brings
        h_d'''. Where the PD term holds the outputs (H A singular), its derivative, and in flight the damping's; a
        torque at its limit has derivative 0."""
        n = len(q)
        lim = self.torque_limit
        J = np.zeros((len(ACTUATED), 2 * n))
        if stance_leg == 0:     # flight: u = -kd (the actuated joints' rates)
            for name in ACTUATED:
                J[self._column[name], n + self.model.coordinates.index(name)] = -self.kd
            J[np.abs(self(t, q, dq, 0)) >= lim] = 0.0
            return J
        q = np.asarray(q, dtype=float)
        dq = np.asarray(dq, dtype=float)
        hs, _hw, ks, _kw = self._legs[stance_leg]
        c = np.zeros(n)
        c[self._torso], c[hs], c[ks] = 1.0, 1.0, 0.5
        theta, dtheta = float(c @ q) - math.pi, float(c @ dq)
        _hd, _dhd, ddhd = self.targets(theta)
        u, y, dy, H, a, A, HA = self._computed_torque(q, dq, stance_leg)
        # y_x = [H, 0]; dy = H dq, so dy_x = [-theta' h_d'' c^T, H]
        y_x = np.hstack([H, np.zeros((4, n))])
        dy_x = np.hstack([-dtheta * np.outer(ddhd, c), H])
        if u is None:       # the PD term (linear in y, dy): its columns are the law's columns
            u = self.pd_torques(y, dy, stance_leg)
            J = np.column_stack([self.pd_torques(y_x[:, k], dy_x[:, k], stance_leg) for k in range(2 * n)])
            J[np.abs(u) >= lim] = 0.0
            return J
        ddq = a + A @ u
        A_q, A_dq, _A_u, _F_q, _F_dq, _F_u = self.model.stance_dynamics_jacobian(q, dq, u, stance_leg)
        Phi_x = H @ np.hstack([A_q, A_dq])
        Phi_x[:, :n] -= float(c @ ddq) * np.outer(ddhd, c)                                  # (dH/dq) ddq
        Phi_x[:, :n] -= dtheta * dtheta * np.outer(self.target_third_derivative(theta), c)   # bias by theta
        Phi_x[:, n:] -= 2.0 * dtheta * np.outer(ddhd, c)                                     # bias by theta'
        Phi_x += self.kp * y_x + self.kd * dy_x
        J = -np.linalg.solve(HA, Phi_x)
        J[np.abs(u) >= lim] = 0.0
        return J

    def state_on_gait(self, speed, stance_leg=1, theta=None):
        """A state on the virtual constraints (y = 0, dy = 0) with the stance foot at the origin and at rest:
        ``theta`` (default -step_angle: the start of a step) and the phase rate ``speed`` (rad/s). Returns
        (q, dq)."""
        m = self.model
        theta = -self.step_angle if theta is None else float(theta)
        hs, hw, ks, kw = self._legs[stance_leg]
        t = self._torso
        n = len(m.coordinates)
        hd, _dhd, _ddhd = self.targets(theta)
        q = np.zeros(n)
        q[t], q[ks], q[kw] = hd[0], hd[1], hd[3]
        q[hs] = theta + math.pi - q[t] - 0.5 * q[ks]
        q[hw] = hd[2] + math.pi - q[t] - 0.5 * q[kw]
        foot = m.contact_position(q, stance_leg)
        q[0] -= foot[0]
        q[1] -= foot[1]
        _y, _dy, H, _bias = self.outputs(q, np.zeros(n), stance_leg)
        c = np.zeros(n)
        c[t], c[hs], c[ks] = 1.0, 1.0, 0.5
        system = np.vstack([H, m.contact_jacobian(q, stance_leg), c])
        dq = np.linalg.solve(system, np.concatenate([np.zeros(6), [float(speed)]]))
        return q, dq
