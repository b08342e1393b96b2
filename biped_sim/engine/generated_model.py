"""The dynamics of any described robot, from its generated module: D, C, G, B, contact points, J, Jdot, R.

Owns :class:`GeneratedModel`, which evaluates a module written by :mod:`biped_sim.config.codegen` for a
:class:`~biped_sim.engine.description.RobotDescription` and solves the phases of docs/model.md for N
coordinates with numpy: stance on contact c, ``[D -J_c^T; J_c 0] [ddq; F] = [-C dq - G + B u; -Jdot_c dq]``;
the impact of contact c, ``[D -J_c^T; J_c 0] [dq+; F_imp] = [D dq-; 0]``; the relabeling R (a permutation
from the description's mirror, R R = I); and the exact derivatives of these phases from the generated
derivative terms, each KKT system differentiated as it stands, ``K ds = dr - (dK) s`` (docs/gait.md
"Derivatives for any robot"). The hybrid engine runs the three-link chain only (BipedModel):
a GeneratedModel given to it is refused with one line (:data:`ENGINE_REFUSAL`).
"""
from __future__ import annotations

import numpy as np

from biped_sim.engine.description import RobotDescription
from biped_sim.engine.model import as_state_vector

ENGINE_REFUSAL = ("model {name!r} ({n} coordinates) cannot be simulated yet: the hybrid engine runs the "
                  "three-link chain only (BipedModel; bs.load_model gives one for three_link, compass_gait and "
                  "three_link_hip_mass) until the generic engine lands; its dynamics are available: "
                  "mass_matrix, bias_forces, contact_jacobian, stance_dynamics, impact_map (docs/models.md)")


class EngineCannotRun(ValueError):
    """A model the hybrid engine cannot simulate yet."""


class GeneratedModel:
    """A described robot's dynamics. ``contact`` arguments are a contact point's name or its 1-based index."""

    def __init__(self, description: RobotDescription, module):
        if module.DIGEST != description.digest():
            raise ValueError(f"the generated module of {description.name!r} is of another description "
                             f"({module.DIGEST} != {description.digest()}): regenerate it")
        self.description = description
        self.module = module
        self.name = description.name
        self.n = description.n
        self.coordinates = description.coordinates
        self.contacts = tuple(module.CONTACTS)
        self.B = np.array(module.B, dtype=float).reshape(self.n, len(module.ACTUATED))
        self.relabeling = tuple(module.RELABELING)
        self.total_mass = module.TOTAL_MASS

    def __repr__(self):
        return f"GeneratedModel({self.name!r}, n={self.n}, contacts={self.contacts})"

    @property
    def engine_refusal(self) -> str:
        """Why the hybrid engine cannot run this model (``simulate`` raises it)."""
        return ENGINE_REFUSAL.format(name=self.name, n=self.n)

    # what the engine reads of a model first: refuse there too, in one line, instead of deep inside a step
    @property
    def p(self):
        raise EngineCannotRun(self.engine_refusal)

    k = p

    def _q(self, q):
        return as_state_vector(q, "q", self.n).tolist()

    def _qdq(self, q, dq):
        return as_state_vector(q, "q", self.n).tolist(), as_state_vector(dq, "dq", self.n).tolist()

    def contact_index(self, contact) -> int:
        if isinstance(contact, str):
            if contact not in self.contacts:
                raise ValueError(f"{self.name} has no contact point {contact!r}; it has {', '.join(self.contacts)}")
            return self.contacts.index(contact)
        if isinstance(contact, bool) or contact not in range(1, len(self.contacts) + 1):
            raise ValueError(f"contact must be a name ({', '.join(self.contacts)}) or 1..{len(self.contacts)}, "
                             f"got {contact!r}")
        return int(contact) - 1

    # -- dynamics terms ------------------------------------------------------------------------------
    def mass_matrix(self, q) -> np.ndarray:
        return np.array(self.module.mass_matrix(self._q(q))).reshape(self.n, self.n)

    def coriolis(self, q, dq) -> np.ndarray:
        return np.array(self.module.coriolis_matrix(*self._qdq(q, dq))).reshape(self.n, self.n)

    def gravity(self, q) -> np.ndarray:
        return np.array(self.module.gravity_vector(self._q(q)))

    def bias_forces(self, q, dq) -> np.ndarray:
        return np.array(self.module.bias_forces(*self._qdq(q, dq)))

    def contact_position(self, q, contact) -> np.ndarray:
        i = self.contact_index(contact)
        return np.array(self.module.contact_positions(self._q(q))[2 * i: 2 * i + 2])

    def contact_jacobian(self, q, contact) -> np.ndarray:
        i, w = self.contact_index(contact), 2 * self.n
        return np.array(self.module.contact_jacobians(self._q(q))[w * i: w * i + w]).reshape(2, self.n)

    def contact_jacobian_dot(self, q, dq, contact) -> np.ndarray:
        i, w = self.contact_index(contact), 2 * self.n
        return np.array(self.module.contact_jacobian_dots(*self._qdq(q, dq))[w * i: w * i + w]).reshape(2, self.n)

    def contact_velocity(self, q, dq, contact) -> np.ndarray:
        i = self.contact_index(contact)
        return np.array(self.module.contact_velocities(*self._qdq(q, dq))[2 * i: 2 * i + 2])

    def energy(self, q, dq) -> float:
        T, V = self.module.energy(*self._qdq(q, dq))
        return T + V

    def kinetic_energy(self, q, dq) -> float:
        return self.module.energy(*self._qdq(q, dq))[0]

    def potential_energy(self, q) -> float:
        return self.module.energy(self._q(q), [0.0] * self.n)[1]

    def com_position(self, q) -> np.ndarray:
        return np.array(self.module.com_position(self._q(q)))

    def segments(self, q) -> np.ndarray:
        """Each link's joint and tip: an array (links, 2 points, xy), the drawing of any chain."""
        return np.array(self.module.segments(self._q(q))).reshape(-1, 2, 2)

    # -- phases --------------------------------------------------------------------------------------
    def relabel(self, q, dq):
        """R q, R dq: the mirror's links swapped (R R = I)."""
        q, dq = self._qdq(q, dq)
        r = self.relabeling
        return np.array([q[i] for i in r]), np.array([dq[i] for i in r])

    def flight_dynamics(self, q, dq, u) -> np.ndarray:
        """ddq of ``D ddq + C dq + G = B u``."""
        u = as_state_vector(u, "u", self.B.shape[1])
        return np.linalg.solve(self.mass_matrix(q), self.B @ u - self.bias_forces(q, dq))

    def stance_dynamics(self, q, dq, u, contact=1):
        """(ddq, F): the KKT system of stance on ``contact`` (its point pinned)."""
        u = as_state_vector(u, "u", self.B.shape[1])
        n = self.n
        J = self.contact_jacobian(q, contact)
        K = np.zeros((n + 2, n + 2))
        K[:n, :n], K[:n, n:], K[n:, :n] = self.mass_matrix(q), -J.T, J
        rhs = np.concatenate([self.B @ u - self.bias_forces(q, dq),
                              -self.contact_jacobian_dot(q, dq, contact) @ np.asarray(dq, dtype=float)])
        x = np.linalg.solve(K, rhs)
        return x[:n], x[n:]

    def impact_map(self, q, dq, contact=2):
        """(dq+, F_imp): the rigid plastic impact of ``contact`` (before relabeling)."""
        n = self.n
        D = self.mass_matrix(q)
        J = self.contact_jacobian(q, contact)
        K = np.zeros((n + 2, n + 2))
        K[:n, :n], K[:n, n:], K[n:, :n] = D, -J.T, J
        x = np.linalg.solve(K, np.concatenate([D @ as_state_vector(dq, "dq", n), np.zeros(2)]))
        return x[:n], x[n:]

    # -- derivatives (docs/gait.md "Derivatives for any robot") -----------------------------------------
    def mass_matrix_jacobian(self, q) -> np.ndarray:
        """dD/dq_k as an array [k, i, j] (n x n x n)."""
        n = self.n
        return np.array(self.module.mass_matrix_jacobian(self._q(q)), dtype=float).reshape(n, n, n)

    def bias_forces_jacobian(self, q, dq):
        """(dh/dq, dh/d dq), n x n each, h = C dq + G."""
        n = self.n
        v = np.array(self.module.bias_forces_jacobian(*self._qdq(q, dq)), dtype=float)
        return v[:n * n].reshape(n, n), v[n * n:].reshape(n, n)

    def contact_jacobian_jacobian(self, q, contact) -> np.ndarray:
        """dJ_c/dq_k of ``contact`` as an array [k, a, j] (n x 2 x n)."""
        i, n = self.contact_index(contact), self.n
        w = 2 * n * n
        return np.array(self.module.contact_jacobian_jacobians(self._q(q))[w * i: w * i + w],
                        dtype=float).reshape(n, 2, n)

    def contact_bias_jacobian(self, q, dq, contact):
        """(Jdot_c dq (2), d(Jdot_c dq)/dq (2 x n), d(Jdot_c dq)/d dq (2 x n)) of ``contact``."""
        i, n = self.contact_index(contact), self.n
        w = 2 + 4 * n
        v = np.array(self.module.contact_bias_jacobians(*self._qdq(q, dq))[w * i: w * i + w], dtype=float)
        return v[:2], v[2:2 + 2 * n].reshape(2, n), v[2 + 2 * n:].reshape(2, n)

    def _kkt(self, q, contact):
        """K = [D -J_c^T; J_c 0], D, J_c, dD/dq_k [k, i, j], dJ_c/dq_k [k, a, j]."""
        n = self.n
        D, J = self.mass_matrix(q), self.contact_jacobian(q, contact)
        K = np.zeros((n + 2, n + 2))
        K[:n, :n], K[:n, n:], K[n:, :n] = D, -J.T, J
        return K, D, J, self.mass_matrix_jacobian(q), self.contact_jacobian_jacobian(q, contact)

    def flight_dynamics_jacobian(self, q, dq, u):
        """(A_q, A_dq, A_u): d ddq/dq (n x n), d ddq/d dq (n x n), d ddq/du (n x M) of D ddq = B u - (C dq + G),
        differentiated: D d ddq/dq_k = -dh/dq_k - (dD/dq_k) ddq, D d ddq/d dq = -dh/d dq, D d ddq/du = B."""
        n = self.n
        ddq = self.flight_dynamics(q, dq, u)
        D, dD = self.mass_matrix(q), self.mass_matrix_jacobian(q)
        dhq, dhv = self.bias_forces_jacobian(q, dq)
        d = np.linalg.solve(D, np.hstack([-dhq - np.einsum("kij,j->ik", dD, ddq), -dhv, self.B]))
        return d[:, :n], d[:, n:2 * n], d[:, 2 * n:]

    def stance_dynamics_jacobian(self, q, dq, u, contact=1):
        """(A_q, A_dq, A_u, F_q, F_dq, F_u): the derivatives of ddq (n x ...) and of the contact force F
        (2 x ...) of ``stance_dynamics`` by q, dq and u. With K s = r, K = [D -J_c^T; J_c 0], s = [ddq; F],
        r = [B u - h; -Jdot_c dq]: K ds/dv = dr/dv - (dK/dv) s for each variable v, where
        (dK/dq_k) s = [dD/dq_k ddq - (dJ_c/dq_k)^T F; dJ_c/dq_k ddq]; one solve with K takes every column."""
        n = self.n
        ddq, F = self.stance_dynamics(q, dq, u, contact)
        K, _D, _J, dD, dJ = self._kkt(q, contact)
        dhq, dhv = self.bias_forces_jacobian(q, dq)
        _jb, djbq, djbv = self.contact_bias_jacobian(q, dq, contact)
        dKs = np.vstack([np.einsum("kij,j->ik", dD, ddq) - np.einsum("kaj,a->jk", dJ, F),
                         np.einsum("kaj,j->ak", dJ, ddq)])
        cols = [np.vstack([-dhq, -djbq]) - dKs, np.vstack([-dhv, -djbv]),
                np.vstack([self.B, np.zeros((2, self.B.shape[1]))])]
        d = np.linalg.solve(K, np.hstack(cols))
        q_, v_, u_ = d[:, :n], d[:, n:2 * n], d[:, 2 * n:]
        return q_[:n], v_[:n], u_[:n], q_[n:], v_[n:], u_[n:]

    def impact_map_jacobian(self, q, dq_minus, contact=2):
        """(P_q, P_dq, I_q, I_dq): the derivatives of dq+ (n x n) and of the impulse (2 x n) of ``impact_map``
        by q and dq-. With K [dq+; I] = [D dq-; 0]: K d[dq+; I]/dq_k = [dD/dq_k (dq- - dq+) + (dJ_c/dq_k)^T I;
        -dJ_c/dq_k dq+] and K d[dq+; I]/d dq- = [D; 0]."""
        n = self.n
        dqm = as_state_vector(dq_minus, "dq", n)
        dqp, imp = self.impact_map(q, dqm, contact)
        K, D, _J, dD, dJ = self._kkt(q, contact)
        cols = [np.vstack([np.einsum("kij,j->ik", dD, dqm - dqp) + np.einsum("kaj,a->jk", dJ, imp),
                           -np.einsum("kaj,j->ak", dJ, dqp)]),
                np.vstack([D, np.zeros((2, n))])]
        d = np.linalg.solve(K, np.hstack(cols))
        return d[:n, :n], d[:n, n:], d[n:, :n], d[n:, n:]

    def contact_velocity_jacobian(self, q, dq, contact):
        """(dv_c/dq, dv_c/d dq), 2 x n each, of the contact point's velocity v_c = J_c dq: column k of the
        first is (dJ_c/dq_k) dq, the second is J_c (the touchdown guard's rate dg/dt = n . v_c, differentiated)."""
        dq = as_state_vector(dq, "dq", self.n)
        return (np.einsum("kaj,j->ak", self.contact_jacobian_jacobian(q, contact), dq),
                self.contact_jacobian(q, contact))

    def check_positive_definite(self, q) -> None:
        """ValueError unless D(q) is positive definite (a link with no mass or inertia where it needs one)."""
        w = np.linalg.eigvalsh(self.mass_matrix(q))
        if not w[0] > 1e-12 * max(w[-1], 1.0):
            raise ValueError(f"robot description {self.name}: D is not positive definite (smallest eigenvalue "
                             f"{w[0]:.3g}): a link's angle moves no mass and no inertia; give it an inertia or "
                             "move its centre of mass off its joint")
