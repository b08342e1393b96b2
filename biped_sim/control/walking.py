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

from biped_sim.engine.compiled import _compiled_twin, derivatives_digest
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

    #: the gains a run can be differentiated by (``gain_jacobian``; ``run_jacobian``'s "controller.NAME")
    GAINS = ("kp", "kd", "torso_pitch", "step_angle", "clearance", "lag", "torque_limit")

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
        ``_law_parameters``, then its model's parameters p and the constants of ``stance_terms_1``; with the
        address of ``walking_jacobian``, the twin of ``jacobian_batch``, where that is its own, and of
        ``walking_stance_jacobian``, the same on the plant's stance system, where ``model`` has its model's
        parameters) when it gives
        this controller's own torques bit for bit on ``model`` (the simulator's); else None, and the loop calls
        the controller back: a subclass or an instance that replaces a method the law runs, a controller on a
        model whose closed form (``stance_terms_1``: the mass matrix and bias of ``stance_joint_affine_fast``) is not
        ``model``'s, or the compiled laws not built."""
        if _laws is None or not _runs_as(self, WalkingController,
                                         ("__call__", "outputs", "swing_target", "_law_parameters")):
            return None
        if self.model is not model and self.model.k["stance_terms_1"] != model.k["stance_terms_1"]:
            return None
        jacobian = _jacobian_address(self, WalkingController, _laws.WALKING_JACOBIAN)
        # its derivative on the plant's stance KKT system, where that system is the law's own (the same parameters)
        on_plant = _laws.WALKING_STANCE_JACOBIAN if jacobian and (self.model is model or self.model.p == model.p) else 0
        return CompiledLaw("walking", self._law_parameters() + tuple(self.model.p) + self.model.k["stance_terms_1"],
                           _laws.WALKING_LAW, jacobian, on_plant)

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

    def jacobian(self, t, q, dq, stance_leg):
        """d u / d(q, dq) (2 x 10) of this law, exact (engine/sensitivity.py's run Jacobians use it).

        The torque u* solves Phi(x, u) = H ddq_r(x, u) + bias + kp y + kd dy = 0 (ddy = -kp y - kd dy), so
        u*_x = -(H Bu)^-1 Phi_x, with ddq_r and its derivatives from the stance KKT system differentiated
        (``Linearization.accelerations``, on this law's model) at u*; a torque at its limit has derivative 0."""
        J = np.zeros((2, 10))
        if stance_leg == 0:     # flight: u = -kd (dq1, dq2)
            J[0, 7] = J[1, 8] = -self.kd
            return J
        q = [float(v) for v in q]
        dq = [float(v) for v in dq]
        s, w = (2, 3) if stance_leg == 1 else (3, 2)
        y, dy, H, HB, u_star, (acc, dsq, dsv) = self._computed_torque(q, dq, stance_leg)
        ddq_r = acc[2:5]
        phi, dphi = q[s] + q[4] - math.pi, dq[s] + dq[4]
        _f, df, ddf = self.swing_target(phi)
        d3f = 6.0 * self.clearance / self._a2      # the third derivative of f: -3 c b'' with b'' = -2 / step_angle^2
        dphi_x = np.zeros(10)
        dphi_x[s] = dphi_x[4] = 1.0
        drate_x = np.zeros(10)
        drate_x[5 + s] = drate_x[9] = 1.0
        Phi_x = H @ np.hstack([dsq[2:5], dsv[2:5]])
        # row 2: H2 depends on phi through f' (its entries s and q3 are -f'), the bias -f'' dphi^2 on phi and dphi
        Phi_x[1] += -ddf * (ddq_r[s - 2] + ddq_r[2]) * dphi_x
        Phi_x[1] += -d3f * dphi * dphi * dphi_x - 2.0 * ddf * dphi * drate_x
        # kp y + kd dy: y1 = q3 - pitch, dy1 = dq3; y2 = q_w + q3 - pi - f(phi), dy2 = dq_w + dq3 - f' dphi
        kp, kd = self.kp, self.kd
        Phi_x[0, 4] += kp
        Phi_x[0, 9] += kd
        Phi_x[1, w] += kp
        Phi_x[1, 4] += kp
        Phi_x[1] += -kp * df * dphi_x - kd * ddf * dphi * dphi_x
        Phi_x[1, 5 + w] += kd
        Phi_x[1, 9] += kd
        Phi_x[1] += -kd * df * drate_x
        J = -np.linalg.solve(HB, Phi_x)
        J[np.abs(u_star) >= self.torque_limit] = 0.0
        return J

    def jacobian_batch(self, t, Q, DQ, stance_leg):
        """(u (P, 2), d u / d(q, dq) (P, 2, 10)) at P states at once (Q, DQ: P x 5 arrays), as ``__call__`` and
        ``jacobian`` give them point by point (engine/variational.py's stacks use it), from the stance KKT
        system of the whole stack (``variational.stance_stack`` on this law's model); None in flight, or where
        a subclass or the instance replaces a method of the law or ``jacobian`` (then ``jacobian`` point by
        point)."""
        if stance_leg == 0 or not _own_law(self, "jacobian"):
            return None
        from biped_sim.engine import variational
        from biped_sim.engine.sensitivity import Linearization
        lin = getattr(self, "_linearization", None)
        if lin is None or lin.model is not self.model:
            lin = self._linearization = Linearization(self.model)
        s, w = (2, 3) if stance_leg == 1 else (3, 2)
        P = Q.shape[0]
        phi, dphi = Q[:, s] + Q[:, 4] - math.pi, DQ[:, s] + DQ[:, 4]
        f, df, ddf = self.swing_target(phi)
        H = np.zeros((P, 2, 3))
        H[:, 0, 2] = 1.0
        H[:, 1, 2] = 1.0 - df
        H[:, 1, s - 2] = -df
        H[:, 1, w - 2] = 1.0
        y = np.stack([Q[:, 4] - self.torso_pitch, Q[:, w] + Q[:, 4] - math.pi - f], axis=1)
        dy = np.einsum("pij,pj->pi", H, DQ[:, 2:5])
        bias = np.stack([np.zeros(P), -ddf * dphi * dphi], axis=1)
        _K, s0, su, derivative = variational.stance_stack(lin.derivatives, Q, DQ, stance_leg)
        HB = H @ su[:, 2:5, :]
        rhs = -self.kp * y - self.kd * dy - np.einsum("pij,pj->pi", H, s0[:, 2:5]) - bias
        u_star = np.linalg.solve(HB, rhs[:, :, None])[:, :, 0]
        acc = s0 + np.einsum("pij,pj->pi", su, u_star)
        # (for gain_jacobian_batch at the same stack, which the flow asks for next)
        self._last_batch = ((Q.tobytes(), DQ.tobytes(), stance_leg), (y, dy, HB, u_star, acc, phi, dphi))
        dsq, dsv, _ = derivative(acc)
        d3f = 6.0 * self.clearance / self._a2
        dphi_x = np.zeros(10)
        dphi_x[s] = dphi_x[4] = 1.0
        drate_x = np.zeros(10)
        drate_x[5 + s] = drate_x[9] = 1.0
        kp, kd = self.kp, self.kd
        Phi_x = H @ np.concatenate([dsq[:, 2:5], dsv[:, 2:5]], axis=2)
        Phi_x[:, 1] += np.outer(-ddf * (acc[:, s] + acc[:, 4]) - d3f * dphi * dphi - kp * df - kd * ddf * dphi,
                                dphi_x)
        Phi_x[:, 1] += np.outer(-2.0 * ddf * dphi - kd * df, drate_x)
        Phi_x[:, 0, 4] += kp
        Phi_x[:, 0, 9] += kd
        Phi_x[:, 1, w] += kp
        Phi_x[:, 1, 4] += kp
        Phi_x[:, 1, 5 + w] += kd
        Phi_x[:, 1, 9] += kd
        UX = -np.linalg.solve(HB, Phi_x)
        lim = self.torque_limit
        UX[np.abs(u_star) >= lim] = 0.0
        return np.clip(u_star, -lim, lim), UX

    def gain_jacobian_batch(self, t, Q, DQ, stance_leg, names):
        """d u / d(gains ``names``) (P, 2, len(names)) at P states at once, as ``gain_jacobian`` gives it point by
        point; None in flight, or where a subclass or the instance replaces a method of the law or
        ``gain_jacobian`` (then ``gain_jacobian`` point by point)."""
        if stance_leg == 0 or not _own_law(self, "gain_jacobian"):
            return None
        names = _checked_gains(self, names)
        key = (Q.tobytes(), DQ.tobytes(), stance_leg)
        last = getattr(self, "_last_batch", None)
        if last is None or last[0] != key:
            self.jacobian_batch(t, Q, DQ, stance_leg)
        y, dy, HB, u_star, acc, phi, dphi = self._last_batch[1]
        s = 2 if stance_leg == 1 else 3
        Phi = np.zeros((Q.shape[0], 2, len(names)))
        for j, name in enumerate(names):
            if name == "kp":
                Phi[:, :, j] = y
            elif name == "kd":
                Phi[:, :, j] = dy
            elif name == "torso_pitch":
                Phi[:, 0, j] = -self.kp
            elif name != "torque_limit":    # row 2: -f' (ddq_s + ddq3) - f'' dphi^2 + kp y2 + kd dy2
                f_t, df_t, ddf_t = self.target_derivatives(phi, name)
                Phi[:, 1, j] = (-df_t * (acc[:, s] + acc[:, 4]) - ddf_t * dphi * dphi - self.kp * f_t
                                - self.kd * df_t * dphi)
        G = -np.linalg.solve(HB, Phi)
        clipped = np.abs(u_star) >= self.torque_limit
        G[clipped] = 0.0
        if "torque_limit" in names:
            G[:, :, names.index("torque_limit")][clipped] = np.sign(u_star)[clipped]
        return G

    def _computed_torque(self, q, dq, stance_leg):
        """(y, dy, H (2 x 3), H Bu, u* unclipped, (s, ds/dq, ds/ddq) of the stance KKT system at u*) in stance:
        the terms of ``jacobian`` and ``gain_jacobian`` (``Linearization.accelerations`` on this law's model)."""
        from biped_sim.engine.sensitivity import Linearization
        lin = getattr(self, "_linearization", None)
        if lin is None or lin.model is not self.model:
            lin = self._linearization = Linearization(self.model)
        y, dy, (H1, H2), bias = self.outputs(q, dq, stance_leg)
        H = np.array([H1, H2])
        a0, _dq0, _dv0, dsu, _ = lin.accelerations(q, dq, (0.0, 0.0), stance_leg)
        HB = H @ dsu[2:5]           # H Bu: ddq_r = a + Bu u
        u_star = np.linalg.solve(HB, -self.kp * np.array(y) - self.kd * np.array(dy) - H @ a0[2:5] - np.array(bias))
        acc, dsq, dsv, _dsu, _ = lin.accelerations(q, dq, u_star, stance_leg)
        return y, dy, H, HB, u_star, (acc, dsq, dsv)

    def target_derivatives(self, phi_s, name):
        """(f_theta, f'_theta, f''_theta): ``swing_target``'s f, f', f'' at phi_s differentiated by the gain
        ``name`` (zeros for a gain f does not depend on). f = -phi + (l - c phi) b, b = 1 - phi^2 / a^2
        (a the step angle, c the clearance, l the lag): linear in b and in (c, l)."""
        a, c, l = self.step_angle, self.clearance, self.lag
        if name == "clearance":
            b, db, ddb = 1.0 - phi_s * phi_s / self._a2, -2.0 * phi_s / self._a2, self._ddb
            return -phi_s * b, -b - phi_s * db, -2.0 * db - phi_s * ddb
        if name == "lag":
            return 1.0 - phi_s * phi_s / self._a2, -2.0 * phi_s / self._a2, self._ddb
        if name == "step_angle":    # b, b', b'' by a: 2 phi^2 / a^3, 4 phi / a^3, 4 / a^3
            a3 = a * a * a
            b_a, db_a, ddb_a = 2.0 * phi_s * phi_s / a3, 4.0 * phi_s / a3, 4.0 / a3
            k = l - c * phi_s
            return k * b_a, -c * b_a + k * db_a, -2.0 * c * db_a + k * ddb_a
        return 0.0, 0.0, 0.0

    def gain_jacobian(self, t, q, dq, stance_leg, names):
        """d u / d(gains) (2 x len(names)) of this law, exact, for the gains ``names`` of ``GAINS``
        (engine/sensitivity.py's run Jacobians by "controller.NAME" use it).

        u* solves Phi(x, u, theta) = H ddq_r(x, u) + bias + kp y + kd dy = 0, so u*_theta = -(H Bu)^-1 Phi_theta
        at fixed u; a torque at its limit has derivative 0 by every gain but ``torque_limit`` (then +-1)."""
        names = _checked_gains(self, names)
        G = np.zeros((2, len(names)))
        if stance_leg == 0:     # flight: u = -kd (dq1, dq2)
            if "kd" in names:
                G[:, names.index("kd")] = [-float(dq[2]), -float(dq[3])]
            return G
        q = [float(v) for v in q]
        dq = [float(v) for v in dq]
        s = 2 if stance_leg == 1 else 3
        y, dy, _H, HB, u_star, (acc, _dsq, _dsv) = self._computed_torque(q, dq, stance_leg)
        phi, dphi = q[s] + q[4] - math.pi, dq[s] + dq[4]
        ddq_s_q3 = acc[s] + acc[4]       # ddq_s + ddq3
        Phi = np.zeros((2, len(names)))
        for j, name in enumerate(names):
            if name == "kp":
                Phi[:, j] = y
            elif name == "kd":
                Phi[:, j] = dy
            elif name == "torso_pitch":     # y1 = q3 - pitch
                Phi[0, j] = -self.kp
            elif name != "torque_limit":    # row 2: -f' (ddq_s + ddq3) - f'' dphi^2 + kp y2 + kd dy2
                f_t, df_t, ddf_t = self.target_derivatives(phi, name)
                Phi[1, j] = -df_t * ddq_s_q3 - ddf_t * dphi * dphi - self.kp * f_t - self.kd * df_t * dphi
        G = -np.linalg.solve(HB, Phi)
        return _clipped(G, u_star, self.torque_limit, names)

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
        return CompiledLaw("pd_walking", self._law_parameters(), _laws.PD_WALKING_LAW,
                           _jacobian_address(self, PDWalkingController, _laws.PD_WALKING_JACOBIAN))

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


def _pd_jacobian(self, t, q, dq, stance_leg):
    """d u / d(q, dq) (2 x 10) of PDWalkingController's law, exact; a torque at its limit has derivative 0."""
    if stance_leg == 0:
        return WalkingController.jacobian(self, t, q, dq, 0)
    q = [float(v) for v in q]
    dq = [float(v) for v in dq]
    s, w = (2, 3) if stance_leg == 1 else (3, 2)
    phi, dphi = q[s] + q[4] - math.pi, dq[s] + dq[4]
    _f, df, ddf = self.swing_target(phi)
    kp, kd, lim = self.kp, self.kd, self.torque_limit
    y2_x = np.zeros(10)     # y2 = q_w + q3 - pi - f(phi)
    y2_x[w], y2_x[4], y2_x[s] = 1.0, 1.0 - df, -df
    dy2_x = np.zeros(10)    # dy2 = dq_w + dq3 - f'(phi) dphi
    dy2_x[s] = dy2_x[4] = -ddf * dphi
    dy2_x[5 + w], dy2_x[9], dy2_x[5 + s] = 1.0, 1.0 - df, -df
    u = self(t, q, dq, stance_leg)
    u_stance, u_swing = (u[0], u[1]) if stance_leg == 1 else (u[1], u[0])
    swing_x = np.zeros(10) if abs(u_swing) >= lim else -kp * y2_x - kd * dy2_x
    stance_x = -swing_x
    stance_x[4] += 2.0 * kp
    stance_x[9] += 2.0 * kd
    if abs(u_stance) >= lim:
        stance_x[:] = 0.0
    return np.array([stance_x, swing_x] if stance_leg == 1 else [swing_x, stance_x])


def _pd_gain_jacobian(self, t, q, dq, stance_leg, names):
    """d u / d(gains) (2 x len(names)) of PDWalkingController's law, exact: u_sw = -kp y2 - kd dy2,
    u_st = 2 (kp (q3 - pitch) + kd dq3) - u_sw; a torque at its limit has derivative 0 by every gain but
    ``torque_limit`` (then +-1)."""
    if stance_leg == 0:
        return WalkingController.gain_jacobian(self, t, q, dq, 0, names)
    names = _checked_gains(self, names)
    q = [float(v) for v in q]
    dq = [float(v) for v in dq]
    s, w = (2, 3) if stance_leg == 1 else (3, 2)
    phi, dphi = q[s] + q[4] - math.pi, dq[s] + dq[4]
    f, df, _ = self.swing_target(phi)
    y1, dy1 = q[4] - self.torso_pitch, dq[4]
    y2, dy2 = q[w] + q[4] - math.pi - f, dq[w] + dq[4] - df * dphi
    swing, stance = np.zeros(len(names)), np.zeros(len(names))
    for j, name in enumerate(names):
        if name == "kp":
            swing[j], stance[j] = -y2, 2.0 * y1 + y2
        elif name == "kd":
            swing[j], stance[j] = -dy2, 2.0 * dy1 + dy2
        elif name == "torso_pitch":
            stance[j] = -2.0 * self.kp
        elif name != "torque_limit":    # y2 = ... - f, dy2 = ... - f' dphi
            f_t, df_t, _ = self.target_derivatives(phi, name)
            swing[j] = self.kp * f_t + self.kd * df_t * dphi
            stance[j] = -swing[j]
    u = self(t, q, dq, stance_leg)
    G = np.array([stance, swing] if stance_leg == 1 else [swing, stance])
    return _clipped(G, np.asarray(u, float), self.torque_limit, names)


def _own_law(controller, derivative):
    """Whether ``controller`` runs WalkingController's own computed-torque law and ``derivative`` (none of the
    methods replaced by a subclass or on the instance), which the stacked derivatives reproduce."""
    return all(getattr(type(controller), name) is getattr(WalkingController, name) and name not in vars(controller)
               for name in ("__call__", "outputs", "swing_target", "target_derivatives", derivative))


def _checked_gains(controller, names):
    names = list(names)
    bad = [n for n in names if n not in controller.GAINS]
    if bad:
        raise ValueError(f"{type(controller).__name__} has no gains {bad}: its gains are {list(controller.GAINS)}")
    return names


def _clipped(G, u, limit, names):
    """G with the rows of the torques at their limit (|u| >= limit) replaced by their derivative there: 0 by
    every gain, sign(u) by ``torque_limit``."""
    for i in range(2):
        if abs(u[i]) >= limit:
            G[i] = 0.0
            if "torque_limit" in names:
                G[i, names.index("torque_limit")] = math.copysign(1.0, u[i])
    return G


#: (set here, not in the class body: compiled_law's _runs_as lists the methods the C law replaces)
PDWalkingController.jacobian = _pd_jacobian
PDWalkingController.gain_jacobian = _pd_gain_jacobian
PDWalkingController.jacobian_batch = None     # (not the computed torque's: point by point, ``jacobian``)
PDWalkingController.gain_jacobian_batch = None


def _jacobian_address(controller, cls, address):
    """The address of the compiled law's derivative (control/_laws.c) where ``controller`` runs ``cls``'s own
    ``jacobian`` and the laws were built on the current derivative closed forms (_gen/_derivatives.h); else 0
    (engine/variational.py then differentiates the law in Python)."""
    own = _runs_as(controller, cls, ("jacobian", "jacobian_batch"))
    return address if own and _laws.DERIVATIVES_SHA256 == derivatives_digest() else 0


def _runs_as(controller, cls, methods):
    """Whether ``controller`` runs ``cls``'s own ``methods`` (none replaced by a subclass or on the instance)
    on parameters that are Python numbers (an attribute set after ``__init__`` to a float32, say, would
    compute in another precision than C's doubles)."""
    own = vars(controller)
    return (all(getattr(type(controller), name) is getattr(cls, name) and name not in own for name in methods)
            and all(isinstance(v, (float, int)) for v in controller._law_parameters()))
