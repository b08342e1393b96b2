"""Phase dynamics of docs/model.md: stance (floating- and fixed-base), flight, impact map, relabeling.

Owns the equations of the section "Phases" of docs/model.md:
  * stance, floating base: [D -J^T; J 0][ddq; F] = [-C dq - G + B u; -Jdot dq]   (``stance_dynamics``)
  * stance, fixed base: the foot is a pin, the chain has 3 coordinates, F recovered
                                                                  (``stance_dynamics(base="fixed")``)
  * impact of a leg: [D -J_i^T; J_i 0][dq+; F_imp] = [D dq-; 0]                   (``impact_map``;
    one foot: the generated closed form ``impact_map_1/2``, both: ``constrained_impulse_response``)
  * a push P on the hip: the same system with D dq + J_hip^T P on the right     (``push_response``)
  * relabeling R (swap the legs, R R = I)                                            (``relabel``)
  * the notes' Delta = R o impact map (eq. 23-25)                                    (``delta``)
  * flight: D ddq + C dq + G = B u                                                  (``flight_dynamics``)

Stance on leg 2 is stance on leg 1 of the relabeled state (the legs are identical): the generator
emits leg 2's closed form from leg 1's derivation by relabeling (``stance_floating_2``), and the
other functions here relabel at run time. The ``_fast`` functions work on Python lists and are the engine's hot path;
the public functions validate their input and return numpy arrays.
"""
from __future__ import annotations

import math

import numpy as np

from biped_sim.engine.compiled import gen
from biped_sim.engine.model import BipedModel, as_state_vector, check_leg


def _swap(v):
    """R v for a list (swap entries 2 and 3: q1 <-> q2)."""
    return [v[0], v[1], v[3], v[2], v[4]]


def _inverse_sym3(a, b, c, d, e, f):
    """Upper triangle (00, 01, 02, 11, 12, 22) of the inverse of [[a b c][b d e][c e f]], a symmetric
    positive definite matrix (its adjugate over its determinant)."""
    A11 = d * f - e * e
    A12 = c * e - b * f
    A13 = b * e - c * d
    inv_det = 1.0 / (a * A11 + b * A12 + c * A13)
    return (A11 * inv_det, A12 * inv_det, A13 * inv_det, (a * f - c * c) * inv_det, (b * c - a * e) * inv_det,
            (a * d - b * b) * inv_det)


def stance_floating_fast(model, q, dq, u, stance_leg=1):
    """Floating-base stance KKT solution (ddq list, F list) for lists q, dq, u.

    The KKT system is solved by eliminating its constraint rows: J = [I2 | A], so
    ddq_base = -A ddq_r + gamma (gamma = -Jdot dq), and projecting the remaining rows on the null
    space of J removes F; then F = D_bb ddq_base + D_br ddq_r + h_base (rows x, y, where J^T = I).
    """
    if stance_leg == 2:
        return gen.stance_floating_2(q, dq, u, model.k_stance)
    return gen.stance_floating_1(q, dq, u, model.k_stance)


def stance_joint_affine_fast(model, q, dq, stance_leg=1):
    """Stance joint accelerations as an affine function of u: ddq_r = a + Bu u, r = (q1, q2, q3).

    The reduced KKT system reads Mr ddq_r = br(u) with d br / du = P^T B = [I2; 0], so one
    factorisation gives both a = Mr^-1 br(0) and Bu = the first two columns of Mr^-1 (what
    input-output linearisation needs, without solving three times). Returns (a, Bu) as lists.
    """
    if stance_leg == 2:
        a, Bu = stance_joint_affine_fast(model, _swap(q), _swap(dq), 1)
        return [a[1], a[0], a[2]], [[Bu[1][1], Bu[1][0]], [Bu[0][1], Bu[0][0]], [Bu[2][1], Bu[2][0]]]
    M00, M01, M02, M11, M12, M22, b0, b1, b2 = gen.stance_terms_1(q, dq, (0.0, 0.0), model.k["stance_terms_1"])[:9]
    i00, i01, i02, i11, i12, i22 = _inverse_sym3(M00, M01, M02, M11, M12, M22)
    a = [i00 * b0 + i01 * b1 + i02 * b2, i01 * b0 + i11 * b1 + i12 * b2, i02 * b0 + i12 * b1 + i22 * b2]
    Bu = [[i00, i01], [i01, i11], [i02, i12]]
    return a, Bu


def stance_fixed_accel_fast(model, qs, dqs, u, stance_leg=1):
    """Fixed-base stance accelerations ddq_s of the chain qs = [q1, q2, q3] pinned at the stance foot:
    D_s ddq_s = B_s u - C_s dq_s - G_s (the engine's right-hand side; no force)."""
    if stance_leg == 2:
        dd = stance_fixed_accel_fast(model, [qs[1], qs[0], qs[2]], [dqs[1], dqs[0], dqs[2]], (u[1], u[0]), 1)
        return [dd[1], dd[0], dd[2]]
    return gen.fixed_base_dynamics_1(qs, dqs, u, model.k_fixed)


def stance_fixed_fast(model, qs, dqs, u, stance_leg=1):
    """Fixed-base stance with everything recovered: (ddqs, F, hip_minus_foot, hip_velocity,
    hip_acceleration); F = m_total (ddp_com + [0, g]) is Newton's law for the whole body."""
    if stance_leg == 2:
        sq, sdq = [qs[1], qs[0], qs[2]], [dqs[1], dqs[0], dqs[2]]
        dd, F, r, v, a = stance_fixed_fast(model, sq, sdq, (u[1], u[0]), 1)
        return [dd[1], dd[0], dd[2]], F, r, v, a
    a1, a2, a3 = stance_fixed_accel_fast(model, qs, dqs, u, 1)
    Jc00, Jc01, Jc02, Jc10, Jc11, Jc12, jd0, jd1, rx, ry, vx, vy = gen.fixed_base_kinematics_1(
        qs, dqs, model.k_fixed_kin)
    m = model.total_mass
    F = [m * (Jc00 * a1 + Jc01 * a2 + Jc02 * a3 + jd0),
         m * (Jc10 * a1 + Jc11 * a2 + Jc12 * a3 + jd1 + model.parameters.g)]
    # hip = foot + r(theta), theta = q1 + q3, r = -l (sin, cos): second derivative of r
    w, dw = dqs[0] + dqs[2], a1 + a3
    acc = [ry * dw - rx * w * w, -rx * dw - ry * w * w]
    return [a1, a2, a3], F, [rx, ry], [vx, vy], acc


def _check_stance_inputs(q, dq, u, stance_leg):
    q = as_state_vector(q, "q")
    dq = as_state_vector(dq, "dq")
    u = np.zeros(2) if u is None else as_state_vector(u, "u", 2)
    return q.tolist(), dq.tolist(), u.tolist(), check_leg(stance_leg)


def stance_dynamics(model: BipedModel, q, dq, u=None, stance_leg=1, base="floating"):
    """Stance phase of docs/model.md: (ddq, F) with the foot of ``stance_leg`` on the ground.

    ``base="floating"`` solves the KKT system of docs/model.md with the given (q, dq), whatever the
    foot's velocity. ``base="fixed"`` uses the three-coordinate pinned chain: the base velocity is
    taken as the one the pin implies (so it agrees with the floating base when J dq = 0).
    F is the force of the ground on the stance foot (N), in world axes.
    """
    if base == "floating" and type(stance_leg) is int and (stance_leg == 1 or stance_leg == 2):
        # fast path: the generated closed form straight on float arrays' lists; anything else (lists,
        # wrong sizes, nested arrays; bool or complex arrays, whose lists it would take as numbers) goes
        # through the checks below
        try:
            if not (q.dtype.kind == "f" and dq.dtype.kind == "f" and (u is None or u.dtype.kind == "f")):
                raise TypeError
            ql, dql, ul = q.tolist(), dq.tolist(), [0.0, 0.0] if u is None else u.tolist()
            ddq, F = stance_floating_fast(model, ql, dql, ul, stance_leg)
        except (AttributeError, TypeError, ValueError):
            pass
        else:
            # x and y do not enter the dynamics: check the inputs too, not only the outputs
            if math.isfinite(ddq[0] + ddq[1] + ddq[2] + ddq[3] + ddq[4] + F[0] + F[1] + sum(ql) + sum(dql)):
                return np.array(ddq), np.array(F)
    if base not in ("floating", "fixed"):
        raise ValueError(f"base must be 'floating' or 'fixed', got {base!r}")
    ql, dql, ul, leg = _check_stance_inputs(q, dq, u, stance_leg)
    ddq, F = _stance(model, ql, dql, ul, leg, base)
    if not math.isfinite(sum(ddq) + sum(F)):
        raise ValueError(f"stance dynamics produced non-finite values at q={ql}, dq={dql}, u={ul} "
                         "(singular configuration or overflow)")
    return np.array(ddq), np.array(F)


def _stance(model, q, dq, u, leg, base):
    if base == "floating":
        return stance_floating_fast(model, q, dq, u, leg)
    dds, F, _r, _v, acc = stance_fixed_fast(model, q[2:], dq[2:], u, leg)
    return acc + dds, F


def flight_dynamics(model: BipedModel, q, dq, u=None) -> np.ndarray:
    """Flight: the free floating-base dynamics D ddq + C dq + G = B u (the notes' section 3)."""
    q = as_state_vector(q, "q")
    dq = as_state_vector(dq, "dq")
    u = np.zeros(2) if u is None else as_state_vector(u, "u", 2)
    return np.array(flight_fast(model, q.tolist(), dq.tolist(), u.tolist()))


def flight_fast(model, q, dq, u):
    D = np.array(gen.mass_matrix(q, model.k["mass_matrix"])).reshape(5, 5)
    rhs = -np.array(gen.bias_forces(q, dq, model.k["bias_forces"]))
    rhs[2] += u[0]
    rhs[3] += u[1]
    return np.linalg.solve(D, rhs).tolist()


def _impact_legs(impact_leg):
    """The landing feet of ``impact_leg``: (1,) or (2,), or (1, 2) for both (given as (1, 2), "both" or 0)."""
    if isinstance(impact_leg, bool):     # (False == 0 would mean both feet)
        raise ValueError(f"impact_leg must be 1, 2, or (1, 2), 'both' or 0 for both feet, got {impact_leg!r}")
    return (1, 2) if impact_leg in ((1, 2), "both", 0) else (check_leg(impact_leg),)


def _impact_jacobian(model, q, impact_leg):
    legs = _impact_legs(impact_leg)
    return np.vstack([model.foot_jacobian(q, leg) for leg in legs])


#: above this condition number of J D^-1 J^T a double impact's impulses are not determined by the
#: data (the feet nearly at one point): the post-impact velocity still is, and is what is computed
IMPACT_CONDITION_LIMIT = 1e8


def impact_condition(model: BipedModel, q, impact_leg) -> float:
    """Condition number of J D^-1 J^T of an impact (1 ... inf; large only for both feet at once with
    the feet nearly at one point)."""
    J = _impact_jacobian(model, as_state_vector(q, "q", model.n), impact_leg)
    return float(np.linalg.cond(J @ np.linalg.solve(model.mass_matrix(q), J.T)))


def impact_map(model: BipedModel, q, dq_minus, impact_leg=2):
    """Rigid plastic impact of ``impact_leg`` (docs/model.md "Impact"), before relabeling.

    Solves [D -J^T; J 0][dq+; F_imp] = [D dq-; 0]. ``impact_leg`` is 1, 2, or (1, 2) for both feet
    at once (then the impulse has 4 entries, foot 1 first). Returns (dq_plus, impulse) with the
    impulse of the ground on the foot in N s. Where that system is ill-conditioned (both feet at
    nearly one point: ``impact_condition`` above ``IMPACT_CONDITION_LIMIT``), the post-impact velocity
    is the unique one with J dq+ = 0 and the impulses are the smallest that give it (their split
    between the feet is not determined), never impulses blown up by the near-singular solve.
    """
    q = as_state_vector(q, "q", model.n)
    dq_minus = as_state_vector(dq_minus, "dq_minus", model.n)
    return impact_map_fast(model, q, dq_minus, impact_leg)


def impact_map_fast(model, q, dq_minus, impact_leg):
    """``impact_map`` for checked arrays (the engine's resets): one foot by its generated closed form (the
    KKT system reduced on the null space of J, as stance's), both feet by the KKT solve with D and J
    straight from the closed forms."""
    ql = q.tolist()
    legs = _impact_legs(impact_leg)
    if type(model) is not BipedModel and not isinstance(model, BipedModel):   # a described robot's KKT solves
        if len(legs) == 1:
            dq_plus, impulse = model.k_impact(ql, dq_minus.tolist(), legs[0] - 1)
            return np.array(dq_plus), np.array(impulse)
        J = np.vstack([model.contact_jacobian(q, leg) for leg in legs])
        return constrained_impulse_response(model.mass_matrix(q), J, dq_minus)
    if len(legs) == 1:
        impact = gen.impact_map_2 if legs[0] == 2 else gen.impact_map_1
        dq_plus, impulse = impact(ql, dq_minus.tolist(), model.k["impact_map_1"])   # the same constants
        return np.array(dq_plus), np.array(impulse)
    D = np.array(gen.mass_matrix(ql, model.k["mass_matrix"])).reshape(5, 5)
    J = gen.foot_jacobian_1(ql, model.k["foot_jacobian_1"]) + gen.foot_jacobian_2(ql, model.k["foot_jacobian_2"])
    return constrained_impulse_response(D, np.array(J).reshape(4, 5), dq_minus)


def constrained_impulse_response(D, J, dq, generalized_impulse=None):
    """The velocity jump of an impulse with the contacts J held: the KKT system of docs/model.md
    "Impact", [D -J^T; J 0][dq+; Lambda] = [D dq + tau; 0], with ``tau`` the generalized impulse
    (N s; none for an impact, J_hip^T P for a push). Returns (dq+, Lambda): Lambda is the impulse
    of the ground on the feet (N s). With four constraint rows (both feet) an ill-conditioned
    J D^-1 J^T gives the smallest impulses (see :func:`impact_map`)."""
    rhs = D @ dq if generalized_impulse is None else D @ dq + generalized_impulse
    k = J.shape[0]
    if k == 4:
        Dinv_JT = np.linalg.solve(D, J.T)
        A = J @ Dinv_JT
        if np.linalg.cond(A) > IMPACT_CONDITION_LIMIT:
            dq_free = dq if generalized_impulse is None else dq + np.linalg.solve(D, generalized_impulse)
            impulse = -np.linalg.pinv(A, rcond=1.0 / IMPACT_CONDITION_LIMIT, hermitian=True) @ (J @ dq_free)
            return dq_free + Dinv_JT @ impulse, impulse
    n = D.shape[0]
    K = np.zeros((n + k, n + k))
    K[:n, :n] = D
    K[:n, n:] = -J.T
    K[n:, :n] = J
    sol = np.linalg.solve(K, np.concatenate([rhs, np.zeros(k)]))
    return sol[:n], sol[n:]


#: J_hip = d(hip)/dq: the hip is the base point (x, y) of q, so J_hip = [I2 | 0] (2 x 5; a described robot's
#: base point alike, 2 x N)
J_HIP = np.hstack([np.eye(2), np.zeros((2, 3))])


def push_response(model: BipedModel, q, dq, impulse, stance_leg):
    """A push: the impulse P (N s, world axes: x forward, y up) on the hip, as an instantaneous
    velocity change (docs/engine.md "Pushes").

    In stance the stance foot stays pinned: [D -J_st^T; J_st 0][dq+; Lambda] = [D dq + J_hip^T P; 0]
    (:func:`constrained_impulse_response`, the impact's system), Lambda the ground's impulse on the
    stance foot; in flight (``stance_leg`` 0) dq+ = dq + D^-1 J_hip^T P and Lambda = 0. The fixed
    base gives the same dq+ (its chain's hip Jacobian is J_hip restricted to the pinned motions).
    Returns (dq+, Lambda) as arrays. Whether the ground can give Lambda (it can only push) is the
    simulator's question."""
    q = as_state_vector(q, "q", model.n)
    dq = as_state_vector(dq, "dq", model.n)
    P = as_state_vector(impulse, "impulse", 2)
    in_flight = stance_leg == 0 and not isinstance(stance_leg, bool)   # (False == 0)
    leg = 0 if in_flight else check_leg(stance_leg)
    if not P.any():     # no push: exactly the state it was given (no rounding of a solve)
        return dq.copy(), np.zeros(2)
    D = model.mass_matrix(q)
    tau = (J_HIP if model.n == 5 else np.hstack([np.eye(2), np.zeros((2, model.n - 2))])).T @ P
    if not leg:
        return dq + np.linalg.solve(D, tau), np.zeros(2)
    return constrained_impulse_response(D, model.foot_jacobian(q, leg), dq, tau)


R = np.array([[1, 0, 0, 0, 0], [0, 1, 0, 0, 0], [0, 0, 0, 1, 0], [0, 0, 1, 0, 0], [0, 0, 0, 0, 1]],
             dtype=float)


def relabel(q, dq):
    """Relabeling R of docs/model.md: swap stance and swing leg (q1 <-> q2); R R = I."""
    q = as_state_vector(q, "q")
    dq = as_state_vector(dq, "dq")
    return R @ q, R @ dq


def delta(model: BipedModel, q_minus, dq_minus):
    """The notes' impact map x+ = Delta(x-) (eq. 23-25): impact of leg 2, then relabeling R.

    In stance/swing coordinates: the swing leg (2) lands and becomes the new stance leg (1).
    """
    dq_plus, _ = impact_map(model, q_minus, dq_minus, impact_leg=2)
    return relabel(q_minus, dq_plus)
