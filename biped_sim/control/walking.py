"""Reference walking controller: virtual constraints enforced by input-output linearisation.

Owns the walking feedback law (not an equation of docs/model.md; it uses ``stance_dynamics``, which is
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

from biped_sim.engine.compiled import _compiled_twin
from biped_sim.engine.dynamics import stance_joint_affine_fast
from biped_sim.engine.model import BipedModel
from biped_sim.engine.torque_hook import CompiledLaw


def _compiled_laws():
    """The compiled laws (control/_laws.c: the C functions of the torque-law hook), or None: not built, built
    on other generated kernels than the engine's, or BIPED_SIM_PURE_PYTHON set (then the controller is
    called back, and the Python loop calls it anyway)."""
    twin, _ = _compiled_twin()
    if twin is None:
        return None
    try:
        from biped_sim.control import _laws
    except ImportError:
        return None
    return _laws if _laws.KERNELS_SHA256 == twin.SOURCE_SHA256 else None


_laws = _compiled_laws()


class WalkingController:
    """``controller(t, q, dq, stance_leg) -> u`` for ``simulate`` and the ``walk_controller`` node.

    q and dq may be numpy arrays or lists (the engine gives lists).
    """

    def __init__(self, model: BipedModel, torso_pitch=0.15, step_angle=0.2, clearance=0.5, lag=-0.04,
                 kp=200.0, kd=30.0, torque_limit=500.0):
        if step_angle <= 0:
            raise ValueError(f"step_angle must be positive, got {step_angle}")
        self.model = model
        self.torso_pitch, self.step_angle = float(torso_pitch), float(step_angle)
        self.clearance, self.lag = float(clearance), float(lag)
        self.kp, self.kd, self.torque_limit = float(kp), float(kd), float(torque_limit)

    @property
    def step_angle(self):
        return self._step_angle

    @step_angle.setter
    def step_angle(self, value):
        # the parameter-only terms of swing_target, once (it runs at every right-hand-side evaluation)
        self._step_angle = value
        self._a2 = value ** 2
        self._ddb = -2.0 / self._a2

    def _law_parameters(self):
        return (self.torso_pitch, self._a2, self._ddb, self.clearance, self.lag, self.kp, self.kd, self.torque_limit)

    def compiled_law(self, model):
        """This law as the engine's torque-law hook takes it (a
        :class:`~biped_sim.engine.torque_hook.CompiledLaw`: control/_laws.c's ``walking``, the parameters of
        ``_law_parameters`` and then the constants of ``stance_terms_1``) when it gives this controller's
        own torques bit for bit on ``model`` (the simulator's); else None, and the loop calls the controller
        back: a subclass or an instance that replaces a method the law runs, a controller on a model whose
        closed form (``stance_terms_1``: the mass matrix and bias of ``stance_joint_affine_fast``) is not
        ``model``'s, or the compiled laws not built."""
        if _laws is None or not _runs_as(self, WalkingController,
                                         ("__call__", "outputs", "swing_target", "_law_parameters")):
            return None
        if self.model is not model and self.model.k["stance_terms_1"] != model.k["stance_terms_1"]:
            return None
        return CompiledLaw("walking", self._law_parameters() + self.model.k["stance_terms_1"], _laws.WALKING_LAW)

    def swing_target(self, phi_s):
        """f(phi_s) and its first two derivatives."""
        a2 = self._a2
        b = 1.0 - phi_s * phi_s / a2
        db = -2.0 * phi_s / a2
        ddb = self._ddb
        c, l = self.clearance, self.lag
        f = -phi_s * (1.0 + c * b) + l * b
        df = -(1.0 + c * b) - phi_s * c * db + l * db
        ddf = -2.0 * c * db - phi_s * c * ddb + l * ddb
        return f, df, ddf

    def outputs(self, q, dq, stance_leg):
        """(y, dy, H, ddy_bias) on the joints r = (q1, q2, q3): y = h(q), dy = H dq_r,
        ddy = H ddq_r + ddy_bias. Scalar code: this runs at every right-hand-side evaluation."""
        s, w = (2, 3) if stance_leg == 1 else (3, 2)
        phi_s = q[s] + q[4] - math.pi
        dphi_s = dq[s] + dq[4]
        f, df, ddf = self.swing_target(phi_s)
        y = (q[4] - self.torso_pitch, q[w] + q[4] - math.pi - f)
        # H rows over (q1, q2, q3): y1 = q3; y2 = q_w + q3 - f(q_s + q3)
        H2 = [0.0, 0.0, 1.0 - df]
        H2[s - 2] = -df
        H2[w - 2] = 1.0
        dy = (dq[4], H2[0] * dq[2] + H2[1] * dq[3] + H2[2] * dq[4])
        return y, dy, ((0.0, 0.0, 1.0), tuple(H2)), (0.0, -ddf * dphi_s * dphi_s)

    def __call__(self, t, q, dq, stance_leg):
        if stance_leg == 0:  # flight: damp the hips (no walking law in the air)
            return np.array([-self.kd * float(dq[2]), -self.kd * float(dq[3])])
        if type(q) is not list:     # (the engine gives lists: no copy)
            q = q.tolist() if type(q) is np.ndarray else [float(v) for v in q]
        if type(dq) is not list:
            dq = dq.tolist() if type(dq) is np.ndarray else [float(v) for v in dq]
        y, dy, (H1, H2), bias = self.outputs(q, dq, stance_leg)
        a, Bu = stance_joint_affine_fast(self.model, q, dq, stance_leg)  # ddq_r = a + Bu u
        kp, kd = self.kp, self.kd
        # H ddq_r + bias = v  =>  (H Bu) u = v - H a - bias, a 2x2 solve
        r0 = -kp * y[0] - kd * dy[0] - a[2] - bias[0]
        r1 = -kp * y[1] - kd * dy[1] - (H2[0] * a[0] + H2[1] * a[1] + H2[2] * a[2]) - bias[1]
        m00, m01 = Bu[2][0], Bu[2][1]
        m10 = H2[0] * Bu[0][0] + H2[1] * Bu[1][0] + H2[2] * Bu[2][0]
        m11 = H2[0] * Bu[0][1] + H2[1] * Bu[1][1] + H2[2] * Bu[2][1]
        det = m00 * m11 - m01 * m10
        lim = self.torque_limit
        u0 = min(lim, max(-lim, (m11 * r0 - m01 * r1) / det))
        u1 = min(lim, max(-lim, (m00 * r1 - m10 * r0) / det))
        return np.array([u0, u1])

    def initial_state(self, speed=1.0):
        """A state on the virtual constraints at the start of a step (stance leg 1 in front).

        ``speed`` is the stance leg's angular rate (rad/s); returns physical (q, dq).
        """
        from biped_sim.engine.simulate import stance_state
        a, pitch = self.step_angle, self.torso_pitch
        f, df, _ = self.swing_target(-a)
        return stance_state(self.model, [math.pi - a - pitch, math.pi + f - pitch, pitch], [speed, df * speed, 0.0])


class PDWalkingController(WalkingController):
    """The same virtual constraints held by a PD law, without inverting the model.

    The swing hip drives y2; both hips together hold the torso (the torso feels the reaction of
    both hip torques). Cheaper per call than the computed torque of :class:`WalkingController`
    (docs/scenes.md), so a run's cost is the integrator's; it converges to a periodic gait too, more
    slowly.
    """

    def compiled_law(self, model):
        """control/_laws.c's ``pd_walking`` on the parameters of ``_law_parameters``, as
        :meth:`WalkingController.compiled_law`; the PD law uses no model constant, so it runs compiled on
        any ``model``."""
        if _laws is None or not _runs_as(self, PDWalkingController, ("__call__", "swing_target", "_law_parameters")):
            return None
        return CompiledLaw("pd_walking", self._law_parameters(), _laws.PD_WALKING_LAW)

    def __call__(self, t, q, dq, stance_leg):
        """(u1, u2), a tuple: this runs at every right-hand-side evaluation, so only y and dy of
        :meth:`outputs` are computed (the PD law needs neither H nor the bias)."""
        if stance_leg == 0:
            return super().__call__(t, q, dq, stance_leg)
        if type(q) is not list:
            q = q.tolist() if type(q) is np.ndarray else [float(v) for v in q]
        if type(dq) is not list:
            dq = dq.tolist() if type(dq) is np.ndarray else [float(v) for v in dq]
        s, w = (2, 3) if stance_leg == 1 else (3, 2)
        q3, dq3 = q[4], dq[4]
        f, df, _ = self.swing_target(q[s] + q3 - math.pi)
        y2 = q[w] + q3 - math.pi - f                    # y2 and dy2 = H2 dq_r as in outputs()
        dy2 = dq[w] + dq3 - df * (dq[s] + dq3)
        kp, kd, lim = self.kp, self.kd, self.torque_limit
        # clipped to [-lim, lim] as min(lim, max(-lim, v)) does (a NaN becomes -lim), without the calls
        u_swing = -kp * y2 - kd * dy2
        u_swing = u_swing if u_swing > -lim else -lim
        u_swing = u_swing if u_swing < lim else lim
        u_stance = 2.0 * (kp * (q3 - self.torso_pitch) + kd * dq3) - u_swing
        u_stance = u_stance if u_stance > -lim else -lim
        u_stance = u_stance if u_stance < lim else lim
        return (u_stance, u_swing) if stance_leg == 1 else (u_swing, u_stance)


def _runs_as(controller, cls, methods):
    """Whether ``controller`` runs ``cls``'s own ``methods`` (none replaced by a subclass or on the instance)
    on parameters that are Python numbers (an attribute set after ``__init__`` to a float32, say, would
    compute in another precision than C's doubles)."""
    own = vars(controller)
    return (all(getattr(type(controller), name) is getattr(cls, name) and name not in own for name in methods)
            and all(isinstance(v, (float, int)) for v in controller._law_parameters()))
