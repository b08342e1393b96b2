"""Reference walking controller: virtual constraints enforced by input-output linearisation.

Owns the walking feedback law (not an equation of MODEL.md; it uses ``stance_dynamics``, which is
affine in u). With phi_i = q_i + q3 - pi the absolute angle of leg i from straight down (phi > 0:
foot behind the hip), the two outputs (hybrid-zero-dynamics style, Westervelt and Grizzle) are

  y1 = q3 - torso_pitch                                     (hold the torso at a lean)
  y2 = phi_w - f(phi_s),  f(s) = -s (1 + clearance b) + lag b,  b = 1 - (s / step_angle)^2

so the swing leg mirrors the stance leg, reaches -step_angle when the stance leg reaches
+step_angle (the touchdown), and clears the ground in between: straight legs must graze the ground
near mid-stance, and ``lag < 0`` puts that graze behind the stance foot, where the touchdown guard
ignores it. The torques make ddy = -kp y - kd dy exactly (computed torque), clipped to
``torque_limit``.
"""
from __future__ import annotations

import math

import numpy as np

from .dynamics import stance_floating_fast
from .model import BipedModel


class WalkingController:
    """``controller(t, q, dq, stance_leg) -> u`` for ``simulate`` and the ``walk_controller`` node."""

    def __init__(self, model: BipedModel, torso_pitch=0.15, step_angle=0.2, clearance=0.5, lag=-0.04,
                 kp=200.0, kd=30.0, torque_limit=500.0):
        if step_angle <= 0:
            raise ValueError(f"step_angle must be positive, got {step_angle}")
        self.model = model
        self.torso_pitch, self.step_angle = float(torso_pitch), float(step_angle)
        self.clearance, self.lag = float(clearance), float(lag)
        self.kp, self.kd, self.torque_limit = float(kp), float(kd), float(torque_limit)

    def swing_target(self, phi_s):
        """f(phi_s) and its first two derivatives."""
        a2 = self.step_angle ** 2
        b = 1.0 - phi_s * phi_s / a2
        db = -2.0 * phi_s / a2
        ddb = -2.0 / a2
        c, l = self.clearance, self.lag
        f = -phi_s * (1.0 + c * b) + l * b
        df = -(1.0 + c * b) - phi_s * c * db + l * db
        ddf = -2.0 * c * db - phi_s * c * ddb + l * ddb
        return f, df, ddf

    def outputs(self, q, dq, stance_leg):
        """(y, dy, H, ddy_bias): y = h(q), dy = H dq, ddy = H ddq + ddy_bias."""
        s, w = (2, 3) if stance_leg == 1 else (3, 2)
        phi_s = q[s] + q[4] - math.pi
        phi_w = q[w] + q[4] - math.pi
        dphi_s = dq[s] + dq[4]
        f, df, ddf = self.swing_target(phi_s)
        y = [q[4] - self.torso_pitch, phi_w - f]
        H = np.zeros((2, 5))
        H[0, 4] = 1.0
        H[1, w] += 1.0
        H[1, 4] += 1.0 - df
        H[1, s] -= df
        dy = H @ np.asarray(dq, float)
        return np.array(y), dy, H, np.array([0.0, -ddf * dphi_s * dphi_s])

    def __call__(self, t, q, dq, stance_leg):
        if stance_leg == 0:  # flight: hold the legs where they are (no walking law in the air)
            return np.array([-self.kd * dq[2], -self.kd * dq[3]])
        q, dq = list(map(float, q)), list(map(float, dq))
        y, dy, H, bias = self.outputs(q, dq, stance_leg)
        # stance dynamics are affine in u: ddq = a + Bu u, from three evaluations
        a, _ = stance_floating_fast(self.model, q, dq, (0.0, 0.0), stance_leg)
        a1, _ = stance_floating_fast(self.model, q, dq, (1.0, 0.0), stance_leg)
        a2, _ = stance_floating_fast(self.model, q, dq, (0.0, 1.0), stance_leg)
        a = np.array(a)
        Bu = np.column_stack([np.array(a1) - a, np.array(a2) - a])
        v = -self.kp * y - self.kd * dy
        u = np.linalg.solve(H @ Bu, v - H @ a - bias)
        return np.clip(u, -self.torque_limit, self.torque_limit)

    def initial_state(self, speed=1.0):
        """A state on the virtual constraints at the start of a step (stance leg 1 in front).

        ``speed`` is the stance leg's angular rate (rad/s); returns physical (q, dq).
        """
        from .hybrid import stance_state
        a, pitch = self.step_angle, self.torso_pitch
        f, df, _ = self.swing_target(-a)
        return stance_state(self.model, [math.pi - a - pitch, math.pi + f - pitch, pitch], [speed, df * speed, 0.0])
