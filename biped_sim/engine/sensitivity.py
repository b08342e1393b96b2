"""Exact linearisation of the hybrid dynamics: the Jacobians of the phases' flows, guards and resets, and the
state transition matrix of a run through its events.

Owns the sensitivities of a run (docs/gait.md "How the Jacobian is computed"). The state is
x = (q, dq) in physical coordinates (2n numbers, 10 for the three-link; leg 1 stays leg 1) in every mode;
w = (u, p, theta) are the inputs a run may depend on besides x: a held torque u, the model parameters p
(``PARAMETER_NAMES``) and the controller's gains theta ("controller.NAME": the law's torque depends on them,
u = law(x; theta)).

* Stance on foot i: f(x) = (dq, ddq) with the KKT system of docs/model.md, K s = r,
  K = [D -J_i^T; J_i 0], s = [ddq; F], r = [-h + B u; -Jdot_i dq] (h = C dq + G). For each variable v
  (a coordinate, a rate, a torque, a parameter) K ds/dv = dr/dv - (dK/dv) s, with
  (dK/dq_k) s = [dD/dq_k ddq - (dJ_i/dq_k)^T F; dJ_i/dq_k ddq]: one solve with K takes every
  column, and the rows of F give the derivative of the ground force (the liftoff guard's).
* Flight: D ddq = -h + B u, the same without the J rows.
* Fixed base: D_s ddq_s = B_s u - h_s on the chain (``fixed_base_jacobian``). Its motion is the floating
  base's on the pin, so a run is linearised in the floating-base coordinates whatever its ``base``.
* An event with guard g (positive while the mode holds), reset R and flows F- before and F+ after:
  the saltation matrix Xi = DR + (F+ - DR F-) g_x / (g_x F-) (Kong, Payne, Zhu, Johnson, "The saltation
  matrix", Proc. IEEE 2024; here dR/dt = 0 and dg/dt = 0: no guard or reset depends on time). With the
  sensitivity W of the inputs w: S+ = DR S + R_w W + (F+ - DR F-) (g_x S + g_w W) / (g_x F-).
  Touchdown of foot i: g = p_iy + tan(slope) p_ix, R = (q, dq+) of the impact map (solved as stance's
  KKT system, [D -J_i^T; J_i 0][dq+; L] = [D dq-; 0]); liftoff: g = F_n (the normal ground force),
  R = identity. The relabeling of the step map (swap the legs) is a permutation of the result.
* Variational equations along each phase: dS/dt = A S + f_w W, A = f_x + f_u u_x under continuous
  feedback (the controller at every evaluation), and the gains enter as f_u u_theta W_theta; under a
  zero-order hold the torque of a period is u_k = law(x(t_k); theta), so at t_k the torque's sensitivity
  becomes u_x S + u_theta W_theta and stays over the period.

The derivatives of D, h, J, Jdot dq come from a generator, through ``model_derivatives.derivatives(model)``:
a BipedModel's from the three-link closed forms' (``_gen/derivatives.py``, tools/generate_model.py), a
GeneratedModel's from the functions the generic generator wrote for its description (config/codegen.py);
a controller's from its ``jacobian(t, q, dq, stance_leg)`` (an M x 2n array, 2 x 10 for the three-link,
d u / d(q, dq)) where it has one, else from central differences of the law alone (``law_jacobian`` says
which); by its gains from its ``gain_jacobian(t, q, dq, stance_leg, names)`` (M x len(names)) where it has one,
else from central differences
of the law alone, each gain an attribute of the controller set to theta +- e and back (``law_gain_jacobian``).

The run itself is the engine's (``HybridSimulator``: it decides which events happen). S is carried along
the engine's own accepted steps, each DOP853 step differentiated (engine/variational.py), where the run
allows it (stance phases joined by touchdowns on the floating base, continuous feedback or a constant
torque); else the augmented system (x, S) is integrated again here with scipy's ``solve_ivp``
(DOP853, tight tolerances: its error control covers S as well as x, and its dense output locates each of
the engine's events on this trajectory), independently of the engine's two loops.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from biped_sim.engine import loop_rules as rules, model_derivatives, variational
from biped_sim.engine._gen import derivatives as dgen
from biped_sim.engine.hybrid import HybridSimulator

#: the model parameters a run can be differentiated by, in the order of BipedModel.p
PARAMETER_NAMES = dgen.PARAMETER_NAMES
#: a parameter "controller.NAME" is the controller's gain NAME (its attribute)
CONTROLLER_PREFIX = "controller."
LAW_EXACT = "exact"
LAW_FD = "central differences of the law"
LAW_NONE = "none (torque held constant)"
#: run_jacobian's ``integration``: the engine's own accepted steps differentiated (engine/variational.py), or
#: the augmented system integrated on its own by scipy's solve_ivp
STEPS, SOLVE_IVP = "steps", "solve_ivp"
#: the event kinds a run is linearised through (a scuff is a report, not a change of mode)
LINEARISED_EVENTS = ("touchdown", "liftoff")
#: (the last model terms (``derivatives(model).key``) and state asked, Linearization._affine's terms there): shared
#: by every Linearization, so that a law's ``jacobian`` on its own model of the same parameters and the flow share it
_AFFINE = [None, None]


def law_jacobian(controller, t, q, dq, stance_leg):
    """(u, d u / d(q, dq) as an M x 2n array (2 x 10 for the three-link), how): the law's own ``jacobian``
    (``LAW_EXACT``) where it has one, else central differences of the law alone (``LAW_FD``), steps
    1e-6 (1 + |x_k|)."""
    q, dq = np.asarray(q, float), np.asarray(dq, float)
    u = np.asarray(controller(t, q, dq, stance_leg), float)
    jac = getattr(controller, "jacobian", None)
    if jac is not None:
        return u, np.asarray(jac(t, q, dq, stance_leg), float), LAW_EXACT
    x = np.concatenate([q, dq])
    n = len(q)
    cols = []
    for k in range(2 * n):
        e = 1e-6 * (1.0 + abs(x[k]))
        xp, xm = x.copy(), x.copy()
        xp[k] += e
        xm[k] -= e
        up = np.asarray(controller(t, xp[:n], xp[n:], stance_leg), float)
        um = np.asarray(controller(t, xm[:n], xm[n:], stance_leg), float)
        cols.append((up - um) / (2 * e))
    return u, np.column_stack(cols), LAW_FD


def law_gain_jacobian(controller, t, q, dq, stance_leg, names):
    """(d u / d(gains ``names``) as an M x len(names) array, how): the law's own ``gain_jacobian`` (``LAW_EXACT``)
    where it has one, else central differences of the law alone (``LAW_FD``): each gain, an attribute of the
    controller, set to theta +- 1e-6 (1 + |theta|) and back."""
    q, dq = np.asarray(q, float), np.asarray(dq, float)
    jac = getattr(controller, "gain_jacobian", None)
    if jac is not None:
        return np.asarray(jac(t, q, dq, stance_leg, list(names)), float).reshape(-1, len(names)), LAW_EXACT
    cols = []
    for name in names:
        value = getattr(controller, name)
        e = 1e-6 * (1.0 + abs(float(value)))
        try:
            setattr(controller, name, float(value) + e)
            up = np.asarray(controller(t, q, dq, stance_leg), float)
            setattr(controller, name, float(value) - e)
            um = np.asarray(controller(t, q, dq, stance_leg), float)
        finally:
            setattr(controller, name, value)
        cols.append((up - um) / (2 * e))
    return np.column_stack(cols) if cols else np.zeros((2, 0)), LAW_FD


def parameter_names(parameters) -> tuple:
    """``run_jacobian``'s ``parameters`` as a tuple of names: one name given as a string is that name (a tuple
    of its letters would be refused letter by letter)."""
    return (parameters,) if isinstance(parameters, str) else tuple(parameters)


def _split_parameters(parameters, controller, model_parameters=PARAMETER_NAMES):
    """(the model's names, the controller's gain names) of ``run_jacobian``'s ``parameters``, checked against
    the model's ``model_parameters`` (``derivatives(model).parameter_names``)."""
    model_names, gains = [], []
    for name in parameters:
        if name.startswith(CONTROLLER_PREFIX):
            gain = name[len(CONTROLLER_PREFIX):]
            if controller is None:
                raise ValueError(f"parameter {name!r}: the run has no controller (a constant torque u)")
            known = getattr(controller, "GAINS", None)
            if getattr(controller, "gain_jacobian", None) is not None and known is not None:
                if gain not in known:
                    raise ValueError(f"parameter {name!r}: the controller's gains are "
                                     f"{[CONTROLLER_PREFIX + g for g in known]}")
            else:
                value = getattr(controller, gain, None)
                if not isinstance(value, (int, float)) or isinstance(value, bool):
                    raise ValueError(f"parameter {name!r}: the controller has no number attribute {gain!r} to "
                                     "differentiate by (and no gain_jacobian)")
            gains.append(gain)
        elif name in model_parameters:
            model_names.append(name)
        elif not model_parameters:
            raise ValueError(f"parameter {name!r}: this model's numbers are generated into its module, so a run "
                             f"has no derivative by them; a controller's gain is '{CONTROLLER_PREFIX}NAME'")
        else:
            raise ValueError(f"unknown parameter {name!r}: the model's are {list(model_parameters)}, a controller's "
                             f"gain is '{CONTROLLER_PREFIX}NAME'")
    return model_names, gains


class Linearization:
    """The Jacobians of one model's phases, guards and resets (``model``: a BipedModel or a GeneratedModel;
    ``slope``: the ground's, rad; ``derivatives``: the model's terms, ``model_derivatives.derivatives(model)``
    unless given: another description of the same robot's, to check one derivation against the other)."""

    def __init__(self, model, slope=0.0, derivatives=None):
        self.model = model
        self.derivatives = derivatives if derivatives is not None else model_derivatives.derivatives(model)
        self.n, self.B = self.derivatives.n, self.derivatives.B
        self.k = self.derivatives.k     # (the closed forms' derivative constants; None for generated terms)
        self.slope = float(slope)
        self.sin, self.cos, self.tan = math.sin(self.slope), math.cos(self.slope), math.tan(self.slope)

    # -- the terms of the equations and their partial derivatives --------------------------------
    def _mass_and_bias(self, q, dq):
        """D, h, dD/dq_k ([k, i, j]), dh/dq, dh/ddq."""
        return self.derivatives.mass_and_bias(q, dq)

    def _foot(self, q, dq, leg):
        """J_i (2xn), dJ_i/dq_k ([k, a, j]), Jdot_i dq (2), d(Jdot_i dq)/dq (2xn), d(Jdot_i dq)/ddq (2xn)."""
        return self.derivatives.foot(q, dq, leg)

    def _parameters(self, q, dq):
        """d/dp of D ([j, i, l]), h (5x9), J_1, J_2 ([j, a, l]), Jdot_1 dq, Jdot_2 dq (2x9), (p_1, p_2) (4x9)."""
        return self.derivatives.parameters(q, dq)

    # -- the phases ----------------------------------------------------------------------------
    def accelerations(self, q, dq, u, stance_leg, parameters=False):
        """The phase's solution s and its derivatives: (s, ds/dq, ds/ddq, ds/du, ds/dp or None).

        In stance on ``stance_leg`` (1, 2) s = [ddq (n); F (2)] of the KKT system (F the force of the ground
        on the foot, world axes); in flight (``stance_leg`` 0) s = ddq. q, dq, u: sequences.

        s is affine in u, s = s0 + s_u u, and so is ds/dq: K ds/dq_k = dr/dq_k - (dK/dq_k) s with r - B u and K
        free of u. The part at u = 0 (``_affine``) is kept for the last state asked, which a controller's
        ``jacobian`` and the flow ask for in turn; the part of u costs one more solve."""
        q, dq = [float(v) for v in q], [float(v) for v in dq]
        u = np.asarray(u, float)
        M, s0, su, dsq0, dsv, dsp0, dKs, dKsp = self._affine(q, dq, stance_leg, parameters)
        delta = su @ u
        s = s0 + delta
        if not delta.any():
            return s, dsq0, dsv, su, dsp0
        cols = [dKs(delta)] + ([dKsp(delta)] if parameters else [])
        corr = -np.linalg.solve(M, np.hstack(cols))
        n = self.n
        dsq = dsq0 + corr[:, :n]
        return s, dsq, dsv, su, (dsp0 + corr[:, n:] if parameters else None)

    def _affine(self, q, dq, stance_leg, parameters):
        """(K or D, s0, s_u, ds0/dq, ds/ddq, ds0/dp, v -> (dK/dq) v, v -> (dK/dp) v) at u = 0."""
        key = (self.derivatives.key, tuple(q), tuple(dq), stance_leg, parameters)
        if _AFFINE[0] == key:
            return _AFFINE[1]
        n, B = self.n, self.B
        D, h, dD, dhq, dhv = self._mass_and_bias(q, dq)
        pj = self._parameters(q, dq) if parameters else None
        if stance_leg:
            J, dJ, jb, djbq, djbv = self._foot(q, dq, stance_leg)
            M = np.zeros((n + 2, n + 2))
            M[:n, :n], M[:n, n:], M[n:, :n] = D, -J.T, J
            rhs0, Bw = np.concatenate([-h, -jb]), np.vstack([B, np.zeros((2, B.shape[1]))])
            rq, rv = np.vstack([-dhq, -djbq]), np.vstack([-dhv, -djbv])

            def dKs(s):     # column k: (dK/dq_k) s = [dD/dq_k ddq - (dJ/dq_k)^T F; dJ/dq_k ddq]
                return np.vstack([np.einsum("kij,j->ik", dD, s[:n]) - np.einsum("kaj,a->jk", dJ, s[n:]),
                                  np.einsum("kaj,j->ak", dJ, s[:n])])
            dKsp = rp = None
            if parameters:
                dDp, dhp, dJ1p, dJ2p, djb1p, djb2p, _feet = pj
                dJp, djbp = (dJ1p, djb1p) if stance_leg == 1 else (dJ2p, djb2p)
                rp = np.vstack([-dhp, -djbp])

                def dKsp(s):
                    return np.vstack([np.einsum("pij,j->ip", dDp, s[:n]) - np.einsum("paj,a->jp", dJp, s[n:]),
                                      np.einsum("paj,j->ap", dJp, s[:n])])
        else:
            M, rhs0, Bw, rq, rv = D, -h, B, -dhq, -dhv

            def dKs(s):
                return np.einsum("kij,j->ik", dD, s)
            dKsp = rp = None
            if parameters:
                dDp, dhp = pj[:2]
                rp = -dhp

                def dKsp(s):
                    return np.einsum("pij,j->ip", dDp, s)
        s0 = np.linalg.solve(M, rhs0)
        cols = [rq - dKs(s0), rv, Bw] + ([rp - dKsp(s0)] if parameters else [])
        sol = np.linalg.solve(M, np.hstack(cols))
        m = B.shape[1]
        data = (M, s0, sol[:, 2 * n:2 * n + m], sol[:, 0:n], sol[:, n:2 * n],
                sol[:, 2 * n + m:] if parameters else None, dKs, dKsp)
        _AFFINE[:] = key, data
        return data

    def flow(self, q, dq, u, stance_leg, u_x=None, parameters=False):
        """f = (dq, ddq) of the mode, A = df/dx (2n x 2n; with the law's u_x (M x 2n) the torque's dependence
        on the state is in it), f_u (2n x M), f_p (2n x 9 or None), and the ground force F with dF/dx, dF/du,
        dF/dp (stance; None in flight)."""
        s, dsq, dsv, dsu, dsp = self.accelerations(q, dq, u, stance_leg, parameters)
        dsx = np.hstack([dsq, dsv])
        if u_x is not None:
            dsx = dsx + dsu @ u_x
        n = self.n
        A = np.zeros((2 * n, 2 * n))
        A[:n, n:] = np.eye(n)
        A[n:] = dsx[:n]
        f = np.concatenate([np.asarray(dq, float), s[:n]])
        fu = np.vstack([np.zeros((n, dsu.shape[1])), dsu[:n]])
        fp = None if dsp is None else np.vstack([np.zeros((n, dsp.shape[1])), dsp[:n]])
        force = None
        if stance_leg:
            force = (s[n:], dsx[n:], dsu[n:], None if dsp is None else dsp[n:])
        return f, A, fu, fp, force

    def fixed_base_jacobian(self, qs, dqs, u, stance_leg=1):
        """The fixed-base chain (q_s = (q1, q2, q3) pinned at the stance foot): (ddq_s, d ddq_s/dq_s,
        d ddq_s/ddq_s, d ddq_s/du), from D_s ddq_s = B_s u - h_s differentiated."""
        if stance_leg == 2:     # the chain of leg 2 is leg 1's of the relabeled state
            P = np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, 1]])
            a, aq, av, au = self.fixed_base_jacobian(P @ qs, P @ dqs, np.asarray(u)[::-1], 1)
            return P @ a, P @ aq @ P, P @ av @ P, P @ au[:, ::-1]
        Ds, hs, dDs, dhq, dhv = self.derivatives.fixed_base(qs, dqs)
        Bs = np.array([[1.0, 0], [0, 1], [0, 0]])
        a = np.linalg.solve(Ds, Bs @ np.asarray(u, float) - hs)
        d = np.linalg.solve(Ds, np.hstack([-dhq - np.einsum("kij,j->ik", dDs, a), -dhv, Bs]))
        return a, d[:, 0:3], d[:, 3:6], d[:, 6:8]

    # -- the guards and the resets ---------------------------------------------------------------
    def touchdown_guard(self, q, leg, parameters=False):
        """(g, g_x (2n), g_p (9 or None)): foot ``leg``'s height above the ground, g = p_y + tan(slope) p_x."""
        ql = list(map(float, q))
        px, py = self.derivatives.foot_position(ql, leg)
        J = self.derivatives.foot_jacobian(ql, leg)
        # (the witness's value and its derivatives: the one rule of a height across the ground, on rows too)
        g = rules.ev_across(self.tan, px, py)
        gx = np.concatenate([rules.ev_across(self.tan, J[0], J[1]), np.zeros(self.n)])
        gp = None
        if parameters:
            feet = self._parameters(ql, [0.0] * self.n)[6]
            gp = rules.ev_across(self.tan, feet[2 * leg - 2], feet[2 * leg - 1])
        return g, gx, gp

    def normal_force(self, force):
        """(F_n, dF_n/dx, dF_n/du, dF_n/dp) of ``flow``'s ground force: the liftoff guard."""
        F, Fx, Fu, Fp = force
        n = np.array([self.sin, self.cos])
        return float(n @ F), n @ Fx, n @ Fu, None if Fp is None else n @ Fp

    def impact(self, q, dq_minus, leg, parameters=False):
        """(dq+, impulse, d dq+/dq (nxn), d dq+/d dq- (nxn), d dq+/dp (nx9 or None)) of the rigid impact of foot
        ``leg``: [D -J^T; J 0][dq+; L] = [D dq-; 0] differentiated as the stance system is."""
        q, dqm = list(map(float, q)), np.asarray(dq_minus, float)
        D, _h, dD, _a, _b = self._mass_and_bias(q, dqm.tolist())
        J, dJ = self._foot(q, dqm.tolist(), leg)[:2]
        n = self.n
        K = np.zeros((n + 2, n + 2))
        K[:n, :n], K[:n, n:], K[n:, :n] = D, -J.T, J
        s = np.linalg.solve(K, np.concatenate([D @ dqm, np.zeros(2)]))
        dqp, L = s[:n], s[n:]
        cols = [np.vstack([np.einsum("kij,j->ik", dD, dqm - dqp) + np.einsum("kaj,a->jk", dJ, L),
                           -np.einsum("kaj,j->ak", dJ, dqp)]),
                np.vstack([D, np.zeros((2, n))])]
        if parameters:
            dDp, _hp, dJ1p, dJ2p = self._parameters(q, dqm.tolist())[:4]
            dJp = dJ1p if leg == 1 else dJ2p
            cols.append(np.vstack([np.einsum("pij,j->ip", dDp, dqm - dqp) + np.einsum("paj,a->jp", dJp, L),
                                   -np.einsum("paj,j->ap", dJp, dqp)]))
        d = np.linalg.solve(K, np.hstack(cols))
        return dqp, L, d[:n, 0:n], d[:n, n:2 * n], (d[:n, 2 * n:] if parameters else None)

    def stance_tangent(self, q, dq, stance_leg):
        """The 2n x 2(n - 2) derivative of the stance state (``stance_state``: the base placed so that the stance
        foot stays where it is, at rest) by the joint coordinates q_r = q[2:] and their rates (10 x 6 for the
        three-link: (q1, q2, q3, dq1, dq2, dq3)): with J = [I2 | A] the base moves as -A dq_r, so
        d(x, y)/dq_r = -A and d(dx, dy)/dq_r,k = -(dA/dq_k) dq_r."""
        q, dq = list(map(float, q)), np.asarray(dq, float)
        J, dJ = self._foot(q, dq.tolist(), stance_leg)[:2]
        n = self.n
        r = n - 2
        T = np.zeros((2 * n, 2 * r))
        T[0:2, 0:r] = T[n:n + 2, r:2 * r] = -J[:, 2:]      # -A
        k = np.arange(r)
        T[2 + k, k] = T[n + 2 + k, r + k] = 1.0
        T[n:n + 2, 0:r] = -(dJ[2:, :, 2:] @ dq[2:]).T      # column k: -(dA/dq_k) dq_r
        return T


@dataclass
class RunSensitivity:
    """A run's final state and its derivatives (``run_jacobian``)."""
    t: float                    # s, where the run ends (t_final, or its last event's time with ``end_at_event``)
    q: np.ndarray               # the end state of the integration of (x, S) (physical; after the last event's reset)
    dq: np.ndarray
    jacobian: np.ndarray        # d(q, dq)(t) / d(inputs): 2n x (directions + parameters), 10 x ... for the three-link
    time_derivative: np.ndarray | None   # d(end time)/d(inputs) with ``end_at_event``, else None
    events: list                # (t, kind, leg) of the engine's run, each linearised through
    law_derivative: str         # LAW_EXACT, LAW_FD or LAW_NONE
    parameters: tuple           # the names of the parameter columns (the last columns of ``jacobian``)
    gain_derivative: str = ""   # by the controller's gains: LAW_EXACT or LAW_FD ("" without gains)
    integration: str = ""       # STEPS (the engine's own steps differentiated) or SOLVE_IVP
    simulator: object = field(repr=False, default=None)   # the engine's run (HybridSimulator)


def run_jacobian(model, q0, dq0, t_final, controller=None, u=None, stance_leg=1, control_period=None,
                 directions=None, parameters=(), rtol=1e-12, atol=1e-12, end_at_event=False, method="dop853",
                 integration=STEPS, derivatives=None, **options) -> RunSensitivity:
    """The state transition matrix of a run: d(q, dq)(t_final) / d(initial state, parameters).

    The run is the engine's (``HybridSimulator`` with ``options``, the same arguments as ``simulate``): under
    ``controller`` at every evaluation (continuous feedback), or once per ``control_period`` and held, or under
    the constant torque ``u``. ``directions`` (2n x m, 10 x m for the three-link) are the initial perturbations;
    by default the joint
    coordinates of the stance state (``Linearization.stance_tangent``: the stance foot stays where it is), or
    the identity in flight. ``parameters``: names of ``PARAMETER_NAMES`` (the plant's; the controller keeps its
    own model) and "controller.NAME", the controller's gain NAME (its ``gain_jacobian``, else central differences of
the law alone by its attribute NAME; ``gain_derivative`` says which). ``end_at_event``: the run ends at its last
event, after the reset (a step map): the
    Jacobian is of the state just after it, and ``time_derivative`` that of its time. Events other than
    touchdowns of one foot and liftoffs (slips, both feet at once, pushes) have no linearisation here: a
    ValueError says so. ``integration``: ``STEPS`` (default) differentiates the engine's own accepted steps
    where the run allows it (engine/variational.py: DOP853 on the floating base, stance phases joined by
    touchdowns, continuous feedback or a constant torque), else and with ``SOLVE_IVP`` the
    augmented system is integrated on its own by scipy's DOP853 (so too under a law whose ``jacobian_jumps``
    is true: its u_x jumps across a surface of the state, which an engine step may straddle). ``derivatives``:
    the model's terms (``model_derivatives.derivatives(model)`` by default: the closed forms of a BipedModel,
    the generated terms of a GeneratedModel); those of another description of the same robot check one
    derivation against the other."""
    parameters = parameter_names(parameters)
    if isinstance(t_final, bool) or not isinstance(t_final, (int, float, np.floating)) or not np.isfinite(t_final):
        raise ValueError(f"t_final must be a finite number of seconds, got {t_final!r}")
    own = model_derivatives.derivatives(model)
    if derivatives is None:
        derivatives = own
    elif (getattr(derivatives, "n", None), np.shape(getattr(derivatives, "B", None))) != (own.n, own.B.shape):
        raise ValueError(f"derivatives: of a robot with {getattr(derivatives, 'n', '?')} coordinates and B of shape "
                         f"{np.shape(getattr(derivatives, 'B', None))}, but the model has {own.n} and {own.B.shape}: "
                         "give the terms of the same robot (model_derivatives.derivatives(model))")
    n = derivatives.n
    model_names, gains = _split_parameters(parameters, controller, derivatives.parameter_names)
    if "l_leg" in model_names and stance_leg:
        # the stance foot's place and rate follow from (q, dq) and l_leg: another l_leg makes the initial state
        # one the engine refuses (or re-places), so the run from the same (q, dq) has no derivative by it
        raise ValueError("parameter 'l_leg': a run that starts in stance cannot be differentiated by l_leg (it moves "
                         "the stance foot of the initial state); start in flight (stance_leg=0), or give the other "
                         "parameters")
    if stance_leg and model_names and "l_leg" not in derivatives.parameter_names:
        # likewise a described robot's parameter that moves the stance contact point ("<link>.length" on its chain)
        feet = derivatives.parameters(list(map(float, q0)), list(map(float, dq0)))[-1]
        feet = feet[2 * stance_leg - 2:2 * stance_leg]
        moving = [name for name in model_names if np.any(feet[:, derivatives.parameter_names.index(name)])]
        if moving:
            raise ValueError(f"parameters {moving}: a run that starts in stance cannot be differentiated by what moves "
                             "the stance contact point of the initial state; start in flight (stance_leg=0), or give "
                             "the other parameters")
    if controller is None and u is None:
        u = (0.0,) * derivatives.B.shape[1]
    q0, dq0 = np.asarray(q0, float), np.asarray(dq0, float)
    sim = HybridSimulator(model, q0, dq0, stance_leg=stance_leg, rtol=rtol, atol=atol, method=method, **options)
    if not t_final > sim.t:
        raise ValueError(f"t_final must be after the run's start (t = {sim.t:g} s), got {t_final!r}")
    if control_period is not None:
        sim.advance_periods(control_period, controller, t_final)
    elif controller is not None:
        sim.advance(t_final, controller=controller)
    else:
        sim.advance(t_final, u=u)
    events = [(e.time, e.kind, e.leg) for e in sim.events if e.kind != "scuff"]
    for t, kind, _leg in events:
        if kind not in LINEARISED_EVENTS:
            raise ValueError(f"the run has a {kind} event at t={t:.9g} s ({sim.message or 'no message'}): "
                             "a run is linearised through touchdowns of one foot and liftoffs only")
    if sim.status == "failed":
        raise ValueError(f"the run failed: {sim.message}")
    if end_at_event and not events:
        raise ValueError(f"end_at_event: the run has no event before t={t_final} s")
    t_end = events[-1][0] if end_at_event else sim.t
    lin = Linearization(model, options.get("slope", 0.0), derivatives)
    integ = _Integration(lin, controller, u, control_period, bool(model_names), gains, rtol, atol)
    x = np.concatenate([q0, dq0])
    if directions is None:
        directions = lin.stance_tangent(q0, dq0, stance_leg) if stance_leg else np.eye(2 * n)
    directions = np.asarray(directions, float)
    if directions.ndim != 2 or directions.shape[0] != 2 * n:
        raise ValueError(f"directions must be a {2 * n} x m array (one column per initial perturbation of (q, dq)), "
                         f"got shape {directions.shape}")
    m0 = directions.shape[1]
    m = m0 + len(parameters)
    S = np.zeros((2 * n, m))
    S[:, :m0] = directions
    Sp = np.zeros((len(derivatives.parameter_names), m))
    integ.Sg = np.zeros((len(gains), m))
    for j, name in enumerate(parameters):
        if name.startswith(CONTROLLER_PREFIX):
            integ.Sg[gains.index(name[len(CONTROLLER_PREFIX):]), m0 + j] = 1.0
        else:
            Sp[derivatives.parameter_names.index(name), m0 + j] = 1.0
    if integration not in (STEPS, SOLVE_IVP):
        raise ValueError(f"integration must be {STEPS!r} or {SOLVE_IVP!r}, got {integration!r}")
    if integration == STEPS and getattr(controller, "jacobian_jumps", False):
        # the law's u_x jumps across a surface of the state: an engine step that straddles it is differentiated
        # with an error its error control (on x alone) does not see, so S is integrated with its own
        integration = SOLVE_IVP
    if integration == STEPS and variational.eligible(sim, method, control_period, stance_leg, events, options):
        x, S, dtau = variational.run(integ, sim, S, Sp, events, t_end, end_at_event)
    else:
        integration = SOLVE_IVP
        x, S, dtau = integ.run(sim.t0, x, S, Sp, stance_leg, events, t_end, end_at_event)
    return RunSensitivity(t=t_end, q=x[:n], dq=x[n:], jacobian=S, time_derivative=dtau, events=events,
                          law_derivative=integ.law_derivative, parameters=parameters,
                          gain_derivative=integ.gain_derivative, integration=integration, simulator=sim)


class _Integration:
    """The augmented system (x, S) along the engine's sequence of modes (``run_jacobian``)."""

    def __init__(self, lin, controller, u, control_period, parameters, gains, rtol, atol):
        self.lin, self.controller, self.period = lin, controller, control_period
        self.parameters = bool(parameters)      # (model parameters among the inputs)
        self.gains = list(gains)                # the controller's gains among the inputs, their W_theta in Sg
        self.Sg = np.zeros((len(self.gains), 0))
        self.rtol, self.atol = rtol, atol
        self.u_held = None if u is None else np.asarray(u, float)
        self.law_derivative = LAW_NONE
        self.gain_derivative = ""

    def _gain_sensitivity(self, t, x, leg):
        """u_theta W_theta (M x m): the torque's sensitivity through the gains, at fixed x."""
        n = self.lin.n
        ug, self.gain_derivative = law_gain_jacobian(self.controller, t, x[:n], x[n:], leg, self.gains)
        return ug @ self.Sg

    def _torque(self, t, x, leg, Su):
        """(u, u_x or None, the torque's sensitivity W_u (M x m)): the law's at every evaluation (continuous
        feedback: u_x folded into A, W_u = u_theta W_theta, None without gains), or the held one with its
        sensitivity."""
        if self.controller is not None and self.period is None:
            n = self.lin.n
            u, ux, how = law_jacobian(self.controller, t, x[:n], x[n:], leg)
            self.law_derivative = how
            return u, ux, (self._gain_sensitivity(t, x, leg) if self.gains else None)
        return self.u_held, None, Su

    def _flow(self, t, x, leg, S, Su, Sp):
        u, ux, Wu = self._torque(t, x, leg, Su)
        n = self.lin.n
        f, A, fu, fp, force = self.lin.flow(x[:n], x[n:], u, leg, ux, self.parameters)
        dS = A @ S
        if Wu is not None:
            dS += fu @ Wu
        if fp is not None:
            dS += fp @ Sp
        return f, dS, (u, ux, Wu, fu, fp, force)

    def _piece(self, t0, t1, x, S, Su, Sp, leg, guard=None):
        """Integrate (x, S) from t0 to t1 in one mode; with ``guard`` (kind, leg), on to its crossing nearest
        to t1 (the engine's event time) and return that time too."""
        from scipy.integrate import solve_ivp  # (here: its import costs ~1.5 s, which no command pays unused)

        n, m = 2 * self.lin.n, S.shape[1]

        def rhs(t, y):
            f, dS, _ = self._flow(t, y[:n], leg, y[n:].reshape(n, m), Su, Sp)
            return np.concatenate([f, dS.ravel()])

        y0 = np.concatenate([x, S.ravel()])
        if guard is None:
            if t1 <= t0:
                return t0, x, S
            sol = solve_ivp(rhs, (t0, t1), y0, method="DOP853", rtol=self.rtol, atol=self.atol)
            if not sol.success:
                raise ValueError(f"the variational equations failed between t={t0} and {t1} s: {sol.message}")
            y = sol.y[:, -1]
            return t1, y[:n], y[n:].reshape(n, m)
        kind, gleg = guard

        def g(t, y):
            if kind == "touchdown":
                return self.lin.touchdown_guard(y[:self.lin.n], gleg)[0]
            u = self._torque(t, y[:n], leg, Su)[0]
            return self.lin.sin * self._force(y[:n], u, leg)[0] + self.lin.cos * self._force(y[:n], u, leg)[1]

        g.direction = -1
        margin = max(1e-6, 1e-3 * (t1 - t0))
        sol = solve_ivp(rhs, (t0, t1 + margin), y0, method="DOP853", rtol=self.rtol, atol=self.atol,
                        events=g, dense_output=True)
        roots = sol.t_events[0]
        if not sol.success or len(roots) == 0:
            raise ValueError(f"the {kind} of leg {gleg} near t={t1:.9g} s is not found on the variational "
                             f"equations' trajectory ({sol.message})")
        te = roots[np.argmin(np.abs(roots - t1))]
        y = sol.sol(te)
        return te, y[:n], y[n:].reshape(n, m)

    def _force(self, x, u, leg):
        n = self.lin.n
        return self.lin.derivatives.stance_force(x[:n].tolist(), x[n:].tolist(), list(map(float, u)), leg)

    def _hold(self, t, x, leg, S):
        """A control period starts: u_k = law(x(t_k); theta), its sensitivity u_x S + u_theta W_theta."""
        n = self.lin.n
        u, ux, how = law_jacobian(self.controller, t, x[:n], x[n:], leg)
        self.law_derivative = how
        self.u_held = u
        return ux @ S + (self._gain_sensitivity(t, x, leg) if self.gains else 0.0)

    def run(self, t, x, S, Sp, leg, events, t_end, end_at_event):
        m = S.shape[1]
        Su = np.zeros((self.lin.B.shape[1], m))
        breaks = []
        if self.period is not None:
            k = 0
            while k * self.period < t_end - 1e-9 * self.period:
                breaks.append((k * self.period, "period", None))
                k += 1
        breaks += list(events)
        breaks.sort(key=lambda b: (b[0], b[1] != "period"))
        i = 0
        while i < len(breaks):
            tb, kind, lg = breaks[i]
            i += 1
            if kind == "period":
                t, x, S = self._piece(t, tb, x, S, Su, Sp, leg)
                Su = self._hold(tb, x, leg, S)
                continue
            if kind == "liftoff" and tb - t <= 1e-12 * max(1.0, abs(t)):
                # the stance starts with the ground pulling (the engine's _check_stance_start): flight from
                # this instant, a time fixed by the last event, so the state and S go on unchanged
                leg = 0
                continue
            # a liftoff at the same instant as this touchdown (the new stance cannot hold): the mode after the
            # event is flight, and F+ is flight's
            leg_after = None
            while i < len(breaks) and breaks[i][1] == "liftoff" and breaks[i][0] - tb <= 1e-12 * max(1.0, abs(tb)):
                leg_after = 0
                i += 1
            last = end_at_event and i == len(breaks)
            t, x, S = self._piece(t, tb, x, S, Su, Sp, leg, guard=(kind, lg))
            x, S, leg, dtau = self._event(t, x, S, Su, Sp, leg, kind, lg, last, leg_after)
            if last:
                return x, S, dtau
        t, x, S = self._piece(t, t_end, x, S, Su, Sp, leg)
        return x, S, None

    def _event(self, t, x, S, Su, Sp, leg, kind, gleg, last, leg_after=None):
        """The saltation matrix at an event: S+ = DR S + R_w W + (F+ - DR F-) (g_x S + g_w W) / (g_x F-); for the
        last event of an ``end_at_event`` run the state just after it, DR (S + F- dtau) + R_w W, and dtau."""
        lin = self.lin
        f_minus, _dS, (u, ux, Wu, _fu, _fp, force) = self._flow(t, x, leg, S, Su, Sp)
        n_par, n = Sp.shape[0], lin.n
        if kind == "touchdown":
            g, gx, gp = lin.touchdown_guard(x[:n], gleg, self.parameters)
            gu = np.zeros(lin.B.shape[1])
            dqp, _L, Rq, Rv, Rp = lin.impact(x[:n], x[n:], gleg, self.parameters)
            DR = np.eye(2 * n)
            DR[n:, :n], DR[n:, n:] = Rq, Rv
            Rw = np.zeros((2 * n, n_par)) if Rp is None else np.vstack([np.zeros((n, n_par)), Rp])
            x_plus = np.concatenate([x[:n], dqp])
            new_leg = gleg
        else:   # liftoff: the normal force reaches zero; the state goes on unchanged, in flight
            g, gx, gu, gp = lin.normal_force(force)   # (gx has u_x folded in under continuous feedback)
            DR, Rw, x_plus, new_leg = np.eye(2 * n), np.zeros((2 * n, n_par)), x.copy(), 0
        dg = gx @ S
        if Wu is not None:
            dg = dg + gu @ Wu
        if gp is not None:
            dg = dg + gp @ Sp
        rate = gx @ f_minus
        dtau = -dg / rate
        if leg_after is not None:
            new_leg = leg_after
        if last:
            return x_plus, DR @ (S + np.outer(f_minus, dtau)) + Rw @ Sp, new_leg, dtau
        f_plus = self._flow(t, x_plus, new_leg, S, Su, Sp)[0]
        S_plus = DR @ S + Rw @ Sp - np.outer(f_plus - DR @ f_minus, dtau)
        return x_plus, S_plus, new_leg, None
