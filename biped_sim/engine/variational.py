"""The variational equations on the engine's own accepted steps (internal differentiation), batched.

Owns ``run_jacobian``'s fast path (engine/sensitivity.py): a run in stance phases through touchdowns of one
foot, on the floating base, by DOP853, under continuous feedback of a controller or a constant torque, by
its initial state, the model's parameters and the controller's gains. Each accepted step of the
engine's run, x_{k+1} = x_k + h sum_i b_i K_i with the stages K_i = f(x_k + h sum_j a_ij K_j), is
differentiated as it stands (the derivative of the discrete step, "internal differentiation"):
S_{k+1} = Phi_k S_k with

  Phi_k = I + h sum_i b_i Psi_i,   Psi_i = A(x_ki) (I + h sum_j a_ij Psi_j)

(A = f_x + f_u u_x at the stage state x_ki), and by the inputs S_{k+1} = Phi_k S_k + Gamma_k with
Gamma_k = h sum_i b_i Gamma_i, Gamma_i = A(x_ki) h sum_j a_ij Gamma_j + f_p W_p + f_u u_theta W_theta (at
x_ki). The steps are the
engine's (its samples: every accepted step from its start, tolerances and error control), so no step is
taken for S alone, and the stages of all the steps of a phase are evaluated together: the model's terms
(engine/model_derivatives.py: the three-link's closed forms ``_gen/closed_forms.py`` and ``_gen/derivatives.py``,
or a GeneratedModel's generated functions) run on numpy arrays of every step's stage state, the
stance KKT system and its derivative columns are solved as one stack, and the law gives its torque and
its derivative for the whole stack (``jacobian_batch(t, Q, DQ, stance_leg)``) where it offers that, else
point by point (``law_jacobian``). From the last sample before an event to the event's time, one DOP853
step of that length; there the saltation matrix (``sensitivity._Integration._event``) as on the general
path.

For the three-link's closed forms under a held torque or a compiled law that offers its derivative
(``torque_hook.CompiledLaw.jacobian``), without the model's parameters or the controller's gains among the
inputs, a phase's steps run in C instead (``steps_transition_c``: engine/_variational.c on the stance KKT
system's derivative of engine/_stance_derivative.h, all 12 stages of every step without the interpreter, S
carried through their Phi there), and so does each touchdown's saltation matrix (``touchdown_c``); they agree
with ``steps_transition`` and ``_Integration._event`` to rounding (test/unit/test_variational_c.py). The rest (a
described robot, parameters, gains, a law without a compiled derivative, BIPED_SIM_PURE_PYTHON) takes the
numpy path.
"""
from __future__ import annotations

import functools

import numpy as np

#: (key, the last stack's ``stance_stack`` result): the law's ``jacobian_batch`` on its own model of the same
#: parameters and the flow ask for the same stack in turn
_STACK = [None, None]


def stance_stack(deriv, Q, DQ, leg):
    """The stance KKT system on foot ``leg`` at the points (Q, DQ) (P x n each), for the stack, from the model's
    terms ``deriv`` (``model_derivatives.derivatives(model)``, ``Linearization.derivatives``):
    (K (P,n+2,n+2), s0 (P,n+2) and s_u (P,n+2,M): s = s0 + s_u u, and ``derivative(s, parameters=False)`` ->
    (ds/dq, ds/ddq (P,n+2,n each), ds/dp (P,n+2,9) or None) at solutions s (P,n+2) of the same K:
    K ds/dq_k = dr/dq_k - (dK/dq_k) s, K ds/ddq = dr/ddq, K ds/dp = dr/dp - (dK/dp) s)."""
    key = (deriv.key, leg, Q.tobytes(), DQ.tobytes())
    if _STACK[0] == key:
        return _STACK[1]
    P, n, m = Q.shape[0], deriv.n, deriv.B.shape[1]
    D, h, dD, dh, J, dJ, jb = deriv.stack(Q, DQ, leg)      # dD [p, k, i, j], dJ [p, k, a, j]
    K = np.zeros((P, n + 2, n + 2))
    K[:, :n, :n], K[:, :n, n:], K[:, n:, :n] = D, -np.transpose(J, (0, 2, 1)), J
    rhs = np.zeros((P, n + 2, 1 + m))
    rhs[:, :n, 0], rhs[:, n:, 0] = -h, -jb[:, 0:2]
    rhs[:, :n, 1:] = deriv.B
    sol = np.linalg.solve(K, rhs)
    rq = np.concatenate([-dh[:, 0], -jb[:, 2:2 + 2 * n].reshape(P, 2, n)], axis=1)             # dr/dq (P,n+2,n)
    rv = np.concatenate([-dh[:, 1], -jb[:, 2 + 2 * n:2 + 4 * n].reshape(P, 2, n)], axis=1)     # dr/ddq

    last = [None, None, None]   # (a computed-torque law asks at its torque, the flow then at the same s)
    by_p = []                   # (dD/dp, dJ/dp, dr/dp), once asked

    def derivative(s, parameters=False):
        if last[0] is not None and last[1] == parameters and np.array_equal(last[0], s):
            return last[2]
        dKs = np.concatenate([np.einsum("pkij,pj->pik", dD, s[:, :n]) - np.einsum("pkaj,pa->pjk", dJ, s[:, n:]),
                              np.einsum("pkaj,pj->pak", dJ, s[:, :n])], axis=1)
        cols = [rq - dKs, rv]
        if parameters:
            if not by_p:
                by_p.extend(deriv.parameter_stack(Q, DQ, leg))
            dDp, dJp, rp = by_p
            dKsp = np.concatenate([np.einsum("pnij,pj->pin", dDp, s[:, :n]) - np.einsum("pnaj,pa->pjn", dJp, s[:, n:]),
                                   np.einsum("pnaj,pj->pan", dJp, s[:, :n])], axis=1)
            cols.append(rp - dKsp)
        d = np.linalg.solve(K, np.concatenate(cols, axis=2))
        last[:] = s, parameters, (d[:, :, :n], d[:, :, n:2 * n], d[:, :, 2 * n:] if parameters else None)
        return last[2]

    out = (K, sol[:, :, 0], sol[:, :, 1:], derivative)
    _STACK[:] = key, out
    return out


def torques(controller, u_held, t, Q, DQ, leg, m=2):
    """(U (P,M), d u/d x (P,M,2n) or None, how) of the law at the points: its ``jacobian_batch`` where it has
    one, else point by point (``sensitivity.law_jacobian``); a constant torque ``u_held`` without a law
    (M = ``m`` actuators)."""
    from biped_sim.engine.sensitivity import LAW_EXACT, LAW_NONE, law_jacobian
    P = Q.shape[0]
    if controller is None:
        return np.broadcast_to(np.asarray(u_held, float), (P, m)), None, LAW_NONE
    batch = getattr(controller, "jacobian_batch", None)
    if batch is not None:
        out = batch(t, Q, DQ, leg)
        if out is not None:
            return out[0], out[1], LAW_EXACT
    U, UX = np.zeros((P, m)), np.zeros((P, m, 2 * Q.shape[1]))
    how = None
    for p in range(P):
        U[p], UX[p], how = law_jacobian(controller, t[p], Q[p], DQ[p], leg)
    return U, UX, how


def gain_torques(controller, t, Q, DQ, leg, gains):
    """(d u/d(gains) (P,M,k), how) of the law at the points: its ``gain_jacobian_batch`` where it has one, else
    point by point (``sensitivity.law_gain_jacobian``)."""
    from biped_sim.engine.sensitivity import LAW_EXACT, law_gain_jacobian
    batch = getattr(controller, "gain_jacobian_batch", None)
    if batch is not None:
        out = batch(t, Q, DQ, leg, gains)
        if out is not None:
            return out, LAW_EXACT
    UG, how = None, None
    for p in range(Q.shape[0]):
        ug, how = law_gain_jacobian(controller, t[p], Q[p], DQ[p], leg, gains)
        if UG is None:
            UG = np.zeros((Q.shape[0],) + ug.shape)
        UG[p] = ug
    return UG, how


def flows(deriv, controller, u_held, t, X, leg, parameters=False):
    """(f (P,2n), A (P,2n,2n), f_p (P,2n,9) or None, f_u (P,2n,M), how) of stance on ``leg`` at the points X
    (P,2n) at times t (P), from the model's terms ``deriv``."""
    n, m = deriv.n, deriv.B.shape[1]
    Q, DQ = np.ascontiguousarray(X[:, :n]), np.ascontiguousarray(X[:, n:])
    U, UX, how = torques(controller, u_held, t, Q, DQ, leg, m)
    _K, s0, su, derivative = stance_stack(deriv, Q, DQ, leg)
    s = s0 + np.einsum("pij,pj->pi", su, U)
    dsq, dsv, dsp = derivative(s, parameters)
    P = X.shape[0]
    f = np.concatenate([DQ, s[:, :n]], axis=1)
    A = np.zeros((P, 2 * n, 2 * n))
    A[:, :n, n:] = np.eye(n)
    A[:, n:, :n], A[:, n:, n:] = dsq[:, :n], dsv[:, :n]
    if UX is not None:
        A[:, n:] += np.einsum("pik,pkj->pij", su[:, :n], UX)
    fp = None
    if parameters:
        fp = np.zeros((P, 2 * n, dsp.shape[2]))
        fp[:, n:] = dsp[:, :n]
    fu = np.zeros((P, 2 * n, m))
    fu[:, n:] = su[:, :n]
    return f, A, fp, fu, how


@functools.lru_cache(maxsize=1)
def _tableau():
    from scipy.integrate._ivp import dop853_coefficients as c
    return tuple(np.ascontiguousarray(v, float) for v in (c.A[:12, :12], c.B, c.C[:12]))


def steps_transition(deriv, controller, u_held, t0, X0, H, leg, Wp=None, gains=(), Wg=None):
    """The DOP853 steps of sizes H (N) from the states X0 (N,2n) at times t0 (N), all on stance ``leg``, of the
    model whose terms are ``deriv``: (their end states (N,2n), Phi (N,2n,2n) the derivative of each step's end
    state by its start, Gamma (N,2n,m) its derivative by the parameters' directions ``Wp`` (9 x m) and the
    controller's ``gains``' ``Wg`` (k x m) (None without either), how, the gains' how)."""
    a, b, c = _tableau()
    N, nx = X0.shape
    Kf = np.zeros((12, N, nx))
    Psi = np.zeros((12, N, nx, nx))
    m = Wp.shape[1] if Wp is not None else (Wg.shape[1] if gains else 0)
    Gam = np.zeros((12, N, nx, m)) if m else None
    eye = np.eye(nx)
    how = gain_how = None
    for i in range(12):
        ti = t0 + c[i] * H
        Xi = X0 + H[:, None] * np.einsum("j,jpn->pn", a[i, :i], Kf[:i])
        Mi = eye + H[:, None, None] * np.einsum("j,jpmn->pmn", a[i, :i], Psi[:i])
        f, A, fp, fu, how = flows(deriv, controller, u_held, ti, Xi, leg, Wp is not None)
        Kf[i] = f
        Psi[i] = A @ Mi
        if Gam is not None:
            Gam[i] = A @ (H[:, None, None] * np.einsum("j,jpmn->pmn", a[i, :i], Gam[:i]))
            if Wp is not None:
                Gam[i] += fp @ Wp
            if gains:
                Q, DQ = np.ascontiguousarray(Xi[:, :nx // 2]), np.ascontiguousarray(Xi[:, nx // 2:])
                UG, gain_how = gain_torques(controller, ti, Q, DQ, leg, gains)
                Gam[i] += fu @ (UG @ Wg)
    X1 = X0 + H[:, None] * np.einsum("j,jpn->pn", b, Kf)
    Phi = eye + H[:, None, None] * np.einsum("j,jpmn->pmn", b, Psi)
    Gamma = None if Gam is None else H[:, None, None] * np.einsum("j,jpmn->pmn", b, Gam)
    return X1, Phi, Gamma, how, gain_how


def _compiled_steps():
    """(the _variational module or None, why not): the C twin of ``steps_transition`` (engine/_variational.c),
    built on the current generated kernels and derivative closed forms, unless BIPED_SIM_PURE_PYTHON is set."""
    from biped_sim.engine.compiled import _compiled_twin, derivatives_digest
    twin, why = _compiled_twin()
    if twin is None:
        return None, why
    try:
        from biped_sim.engine import _variational
    except ImportError:
        return None, ("the variational steps biped_sim/engine/_variational were not built: install gcc and the "
                      "Python headers, then make venv")
    if _variational.KERNELS_SHA256 != twin.SOURCE_SHA256 or _variational.DERIVATIVES_SHA256 != derivatives_digest():
        return None, "the variational steps are older than the generated code; rebuild them: make venv"
    return _variational, ""


_C, WHY_NOT_C = _compiled_steps()


def compiled_law(deriv, controller, u_held, parameters=False, gains=()):
    """What ``steps_transition_c`` runs the stance flow of a stack under: ``("held", u)`` for no controller, the
    law's ``(jacobian address, parameters, name, stance_jacobian address or 0)`` for a compiled law that offers its
    derivative (``torque_hook.CompiledLaw.jacobian``, ``stance_jacobian``); None where the numpy path runs: the
    C not built (``WHY_NOT_C``), terms other than the three-link's closed forms (a described robot), the model's
    parameters or the controller's gains among the inputs, or a controller without such a law."""
    from biped_sim.engine.model_derivatives import ClosedFormDerivatives
    from biped_sim.engine.torque_hook import reference_law
    if _C is None or type(deriv) is not ClosedFormDerivatives or parameters or gains:
        return None
    if controller is None:
        return "held", np.ascontiguousarray(np.broadcast_to(np.asarray(u_held, float), (2,)))
    law = reference_law(controller, deriv.model)
    if law is None or not law.jacobian:
        return None
    return law.jacobian, law.params, law.name, law.stance_jacobian


def steps_transition_c(deriv, law, t0, X0, H, leg, S=None):
    """``steps_transition`` in C (engine/_variational.c) for the three-link's closed forms ``deriv`` under ``law``
    (``compiled_law``): (X1 (N,10), Phi (N,10,10)). ``S`` (10 x m, C-contiguous float64): carried through the
    steps in place, S <- Phi_k S for each step k in turn."""
    a, b, c = _tableau()
    N = X0.shape[0]
    X1, Phi = np.empty((N, 10)), np.empty((N, 10, 10))
    held = law[0] == "held"
    _C.steps_transition(leg, np.asarray(deriv.model.p, float), a, b, c, np.ascontiguousarray(t0, float),
                        np.ascontiguousarray(X0, float), np.ascontiguousarray(H, float), None if held else law,
                        law[1] if held else _NO_TORQUE, X1, Phi, S)
    return X1, Phi


#: steps_transition_c's and touchdown_c's u_held under a compiled law (unused there)
_NO_TORQUE = np.zeros(2)


def touchdown_c(deriv, law, t, x, S, leg, gleg, tan_s, last):
    """The touchdown of foot ``gleg`` ending stance on ``leg`` at (t, x) in C (engine/_variational.c), the twin of
    ``sensitivity._Integration._event`` for the three-link's closed forms ``deriv`` under ``law``
    (``compiled_law``) on a ground of slope tangent ``tan_s``: (x+ (10), S+ (10 x m), dtau (m) with ``last``,
    else None), S+ = DR S - (F+ - DR F-) dtau, or with ``last`` the state just after the event, DR (S + F- dtau)."""
    S = np.ascontiguousarray(S, float)
    x_plus, S_plus, dtau = np.empty(10), np.empty_like(S), np.empty(S.shape[1])
    held = law[0] == "held"
    _C.touchdown(leg, gleg, np.asarray(deriv.model.p, float), tan_s, float(t), np.ascontiguousarray(x, float), S,
                 None if held else law, law[1] if held else _NO_TORQUE, bool(last), x_plus, S_plus, dtau)
    return x_plus, S_plus, (dtau if last else None)


def eligible(sim, method, control_period, stance_leg, events, options):
    """Whether ``run_jacobian``'s run takes this path: DOP853 on the floating base, stance phases (no flight)
    joined by touchdowns, continuous feedback or a constant torque."""
    return (method == "dop853" and control_period is None and stance_leg in (1, 2)
            and options.get("base", "floating") == "floating" and sim.opt.keep_samples
            and all(kind == "touchdown" for _t, kind, _leg in events))


def phase_steps(t, legs, leg, t_start, t_stop):
    """(idx, H): the engine's accepted steps in stance on ``leg`` from ``t_start`` to ``t_stop``, from its samples
    (times ``t``, stance legs ``legs``): the indices of the samples each starts from, and their lengths, the last
    one to ``t_stop``. A sample repeated at the same time (an event's, before and after its reset) starts none, so
    every length is positive."""
    idx = np.flatnonzero((legs == leg) & (t >= t_start) & (t < t_stop))
    if idx.size:
        idx = idx[np.append(t[idx[1:]] > t[idx[:-1]], True)]
    t_idx = t[idx]
    return idx, np.append(t_idx[1:], t_stop) - t_idx


def run(integ, sim, S, Sp, events, t_end, end_at_event):
    """(the end state, S there, dtau or None): S carried through the engine's run, step by step (each
    phase's steps as one stack) and through each event's saltation matrix (``integ._event``); ``Sp``: the
    parameters' directions (9 x m)."""
    lin = integ.lin
    # the engine's samples as they stand (its rows: t, q, dq side by side, the stance leg; no SimulationResult)
    samples = sim._samples
    rows, at, n_q = samples.rows(), samples.layout, samples.n_q
    t, legs = rows[:, at["ROW_T"]], rows[:, at["ROW_LEG"]]
    X = rows[:, at["ROW_Q"]:at["ROW_Q"] + 2 * n_q]
    if np.any(legs == 0):
        raise ValueError("the run has a flight phase, which the engine's steps are not differentiated through: "
                         "run_jacobian(..., integration='solve_ivp')")
    from biped_sim.engine.sensitivity import LAW_EXACT, LAW_NONE
    Su = np.zeros((lin.derivatives.B.shape[1], S.shape[1]))
    Wp = Sp if integ.parameters else None
    law = compiled_law(lin.derivatives, integ.controller, integ.u_held, integ.parameters, integ.gains)
    if law is not None:
        S = np.array(S, float, order="C")     # (carried in place through the steps in C)
    leg, t_start = int(legs[0]), float(t[0])
    stops = [(te, kind, lg) for te, kind, lg in events] + ([] if end_at_event else [(t_end, None, None)])
    x = X[0].copy()
    for n, (t_stop, kind, gleg) in enumerate(stops):
        idx, H = phase_steps(t, legs, leg, t_start, t_stop)
        if idx.size:
            t0, X0 = t[idx], X[idx]
            if law is not None:     # (S carried through the steps in C)
                X1, _Phi = steps_transition_c(lin.derivatives, law, t0, X0, H, leg, S)
                how, gain_how = (LAW_NONE if law[0] == "held" else LAW_EXACT), None
            else:
                X1, Phi, Gamma, how, gain_how = steps_transition(
                    lin.derivatives, integ.controller, integ.u_held, t0, X0, H, leg, Wp, integ.gains, integ.Sg)
                for k in range(Phi.shape[0]):
                    S = Phi[k] @ S if Gamma is None else Phi[k] @ S + Gamma[k]
            if how is not None:
                integ.law_derivative = how
            if gain_how is not None:
                integ.gain_derivative = gain_how
            x = X1[-1]
        if kind is None:
            return x, S, None
        last = end_at_event and n == len(stops) - 1
        if law is not None and kind == "touchdown":     # (its saltation matrix in C)
            x, S, dtau = touchdown_c(lin.derivatives, law, t_stop, x, S, leg, gleg, lin.tan, last)
            leg = gleg
            if law[0] != "held":
                integ.law_derivative = LAW_EXACT
        else:
            x, S, leg, dtau = integ._event(t_stop, x, S, Su, Sp, leg, kind, gleg, last)
        if last:
            return x, S, dtau
        t_start = t_stop
    return x, S, None
