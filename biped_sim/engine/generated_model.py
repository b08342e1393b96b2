"""The dynamics of any described robot, from its generated module: D, C, G, B, contact points, J, Jdot, R.

Owns :class:`GeneratedModel`, which evaluates a module written by :mod:`biped_sim.config.codegen` for a
:class:`~biped_sim.engine.description.RobotDescription` and solves the phases of docs/model.md for N
coordinates with numpy: stance on contact c, ``[D -J_c^T; J_c 0] [ddq; F] = [-C dq - G + B u; -Jdot_c dq]``;
the impact of contact c, ``[D -J_c^T; J_c 0] [dq+; F_imp] = [D dq-; 0]``; the relabeling R (a permutation
from the description's mirror, R R = I); and the exact derivatives of these phases from the generated
derivative terms, each KKT system differentiated as it stands, ``K ds = dr - (dK) s`` (docs/gait.md
"Derivatives for any robot"). The hybrid engine runs it, on both loops, through the kernels
``k_stance``, ``k_flight``, ``k_impact``, ``k_foot_positions``, ``k_foot_kinematics`` and ``k_energy`` (lists in,
lists out, in the three-link kernels' layouts: ``loop_kernels``; their compiled twin, ``model_kernels``, where it
is built); a biped with two contact points, at most
``loop_state.NQ_MAX`` coordinates (:meth:`GeneratedModel.engine_refusal` says why not otherwise). The
three-link biped's closed forms (``p``, ``k``) it has not: what needs them refuses it in one line
(:class:`EngineCannotRun`).
"""
from __future__ import annotations

import numpy as np

from biped_sim.engine.description import RobotDescription
from biped_sim.engine.model import as_state_vector
from biped_sim.engine.model_kernels import KERNELS, compiled_kernels

NO_CLOSED_FORMS = ("model {name!r} ({n} coordinates) has no three-link closed forms (p, k): the hybrid engine runs "
                   "it, but this needs the three-link biped (BipedModel; bs.load_model gives one "
                   "for three_link, compass_gait and three_link_hip_mass)")


def contact_chains(desc: RobotDescription) -> tuple:
    """Per contact point, its chain from the floating base's point (grazing.contact_chains' form): the links from
    the base to the point's link, each as (l_k, terms): l_k the distance from the link's joint to the next joint
    on the way (or to the point), terms the entries of y whose sum (the signs of the joints' axes) is the link's
    absolute angle, +-(entry + 1), the link's own first. A link that carries the way no distance is left out."""
    by_name = {link.name: link for link in desc.links}
    index = {link.name: 2 + i for i, link in enumerate(desc.links)}

    def terms(name):
        link = by_name[name]
        own = index[name] + 1
        if link.parent is None:
            return (own,)
        return (own if link.sign > 0 else -own,) + terms(link.parent)

    out = []
    for contact in desc.contacts:
        path = [contact.link]
        while by_name[path[-1]].parent is not None:
            path.append(by_name[path[-1]].parent)
        path.reverse()
        chain = []
        for k, name in enumerate(path):
            to = by_name[path[k + 1]].origin if k + 1 < len(path) else contact.point
            length = float(np.hypot(*to))
            if length > 0.0:
                chain.append((length, terms(name)))
        out.append(tuple(chain))
    return tuple(out)


def at_tip(link, point) -> bool:
    """Whether a point of ``link``'s frame is its tip (on its z axis at ``length``): what ``<link>.length`` moves."""
    return link.length > 0.0 and float(point[0]) == 0.0 and float(point[1]) == float(link.length)


def parameter_names(desc: RobotDescription) -> tuple:
    """The names of ``desc``'s model parameters, in the order of the parameters' module: per link
    ``<link>.mass``, ``<link>.inertia``, ``<link>.com_x``, ``<link>.com_z`` and, when a contact point or a child's
    joint is at the link's tip, ``<link>.length`` (which moves them along the link's z axis), then ``gravity``."""
    names = []
    for link in desc.links:
        names += [f"{link.name}.{k}" for k in ("mass", "inertia", "com_x", "com_z")]
        tips = [c.point for c in desc.contacts if c.link == link.name]
        tips += [child.origin for child in desc.links if child.parent == link.name]
        if any(at_tip(link, p) for p in tips):
            names.append(f"{link.name}.length")
    return tuple(names) + ("gravity",)


class EngineCannotRun(ValueError):
    """A described robot given where the three-link biped's closed forms are needed."""


class GeneratedModel:
    """A described robot's dynamics. ``contact`` arguments are a contact point's name or its 1-based index."""

    def __init__(self, description: RobotDescription, module, parameters=None):
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
        self.contact_mirror = tuple(module.CONTACT_MIRROR)
        self.m = self.B.shape[1]        # the actuators M
        # the entry of q each actuator turns (B is a selection: a 1 a column), for the motors' power u . (B^T dq)
        self.actuated_indices = tuple(int(np.flatnonzero(self.B[:, j])[0]) for j in range(self.m))
        self.contact_chains = contact_chains(description)
        self.total_mass = module.TOTAL_MASS
        # the module of the derivatives by the model parameters: a callable that gives it (generated on the first
        # request; config.models passes one), asked for by a run Jacobian by model parameters only
        self._parameters_source = parameters
        self._parameters_module = None
        # the six kernels the hybrid loop calls (model_kernels.KERNELS): the compiled twin where it is built, whose
        # functions then stand for the numpy methods of the same names on this model; None: the numpy path runs
        self.kernels = compiled_kernels(self)
        if self.kernels is not None:
            for name in KERNELS:
                setattr(self, name, getattr(self.kernels, name))

    def __repr__(self):
        return f"GeneratedModel({self.name!r}, n={self.n}, contacts={self.contacts})"

    @property
    def engine_refusal(self) -> str | None:
        """Why the hybrid engine cannot run this model (one line), or None: it runs bipeds, two contact points,
        at most NQ_MAX coordinates and NU_MAX actuators, and chains the grazing bound has room for."""
        from biped_sim.engine.loop_state import CHAIN_MAX, NQ_MAX, NU_MAX, TERMS_MAX
        why = None
        if len(self.contacts) != 2:
            why = (f"it has {len(self.contacts)} contact points ({', '.join(self.contacts)}); the engine runs bipeds, "
                   "two contact points (a foot each)")
        elif self.n > NQ_MAX or self.m > NU_MAX:
            why = f"it has {self.n} coordinates and {self.m} actuators; the engine has room for {NQ_MAX} and {NU_MAX}"
        elif any(len(chain) > CHAIN_MAX or any(len(t) > TERMS_MAX for _, t in chain) for chain in self.contact_chains):
            why = (f"a foot's chain from the floating base has more than {CHAIN_MAX} links, or a link's angle more "
                   f"than {TERMS_MAX} joints: the grazing bound has no room for it")
        return None if why is None else f"the hybrid engine cannot run robot {self.name!r}: {why}"

    def parameters_module(self):
        """The generated module of the derivatives by the model parameters (``PARAMETER_NAMES``,
        ``parameter_jacobian``), of this model's description; ValueError in one line if the model was built
        without a way to it."""
        if self._parameters_module is None:
            if self._parameters_source is None:
                raise ValueError(f"model {self.name!r} was built without its parameters' module: load it with "
                                 "bs.load_model (or pass GeneratedModel(..., parameters=callable giving the module))")
            module = self._parameters_source()
            if module.DIGEST != self.description.digest():
                raise ValueError(f"the parameters' module of {self.name!r} is of another description "
                                 f"({module.DIGEST} != {self.description.digest()}): regenerate it")
            self._parameters_module = module
        return self._parameters_module

    # the three-link biped's closed forms: what reads them (the sensitivity, a compiled torque law) refuses in one line
    @property
    def p(self):
        raise EngineCannotRun(NO_CLOSED_FORMS.format(name=self.name, n=self.n))

    k = p

    # the names the engine's resets and pushes call (BipedModel's)
    def foot_position(self, q, leg) -> np.ndarray:
        return self.contact_position(q, leg)

    def foot_jacobian(self, q, leg) -> np.ndarray:
        return self.contact_jacobian(q, leg)

    def energy_fast(self, q, dq) -> float:
        """``energy`` for lists of checked numbers."""
        T, V = self.module.energy(q, dq)
        return T + V

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

    def base_hung_from(self, contact_index0, pin, angles, rates):
        """(base, base velocity) as lists: the floating base (x, y) hung from contact ``contact_index0`` (0-based)
        pinned at ``pin`` = c and at rest, the joint angles q[2:] = ``angles`` and rates dq[2:] = ``rates`` (lists).
        The base enters the contact point as a translation, p_c(q) = (x, y) + p_c(0, 0, q[2:]), so J_c[:, :2] = I:
        (x, y) = c - p_c(0, 0, q[2:]) and, from J_c dq = 0, (dx, dy) = -J_c[:, 2:] dq[2:] (J_c does not depend on
        the base)."""
        n, a, w = self.n, self.n - 2, 2 * self.n
        q0 = [0.0, 0.0] + angles
        p = self.module.contact_positions(q0)
        J = self.module.contact_jacobians(q0)[w * contact_index0:w * contact_index0 + w]
        vx = -sum(J[2 + i] * rates[i] for i in range(a))
        vy = -sum(J[n + 2 + i] * rates[i] for i in range(a))
        return [pin[0] - p[2 * contact_index0], pin[1] - p[2 * contact_index0 + 1]], [vx, vy]

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

    # -- the engine's kernels: lists in, lists out, in the three-link kernels' layouts (loop_kernels) ------
    def _kkt_matrix(self, q, c):
        """D, J_c and the KKT matrix [D -J_c^T; J_c 0] of contact index c (0-based) at q (lists)."""
        n, m = self.n, self.module
        D = np.array(m.mass_matrix(q)).reshape(n, n)
        w = 2 * n
        J = np.array(m.contact_jacobians(q)[w * c:w * c + w]).reshape(2, n)
        K = np.zeros((n + 2, n + 2))
        K[:n, :n], K[:n, n:], K[n:, :n] = D, -J.T, J
        return D, K

    def k_stance(self, q, dq, u, contact_index0):
        """(ddq, F) of floating-base stance on contact ``contact_index0`` (0-based): the KKT solve
        [D -J_c^T; J_c 0] [ddq; F] = [B u - C dq - G; -Jdot_c dq], F the ground's force on the contact point."""
        n, w, c = self.n, 2 * self.n, contact_index0
        _, K = self._kkt_matrix(q, c)
        Jd = np.array(self.module.contact_jacobian_dots(q, dq)[w * c:w * c + w]).reshape(2, n)
        dqa = np.array(dq)
        rhs = np.concatenate([self.B @ np.array(u) - np.array(self.module.bias_forces(q, dq)), -Jd @ dqa])
        x = np.linalg.solve(K, rhs).tolist()
        return x[:n], x[n:]

    def k_flight(self, q, dq, u):
        """ddq of flight, D ddq = B u - C dq - G."""
        n = self.n
        D = np.array(self.module.mass_matrix(q)).reshape(n, n)
        return np.linalg.solve(D, self.B @ np.array(u) - np.array(self.module.bias_forces(q, dq))).tolist()

    def k_impact(self, q, dq_minus, contact_index0):
        """(dq+, impulse) of the rigid plastic impact of contact ``contact_index0`` (0-based):
        [D -J_c^T; J_c 0] [dq+; Lambda] = [D dq-; 0]."""
        n = self.n
        D, K = self._kkt_matrix(q, contact_index0)
        x = np.linalg.solve(K, np.concatenate([D @ np.array(dq_minus), np.zeros(2)])).tolist()
        return x[:n], x[n:]

    def k_foot_positions(self, q):
        """[x_1, y_1, x_2, y_2, ...]: the contact points' positions."""
        return list(self.module.contact_positions(q))

    def k_foot_kinematics(self, q, dq):
        """[p_1 (2), p_2 (2), ..., v_1 (2), v_2 (2), ...]: the contact points' positions, then their velocities."""
        return list(self.module.contact_positions(q)) + list(self.module.contact_velocities(q, dq))

    def k_energy(self, q, dq):
        """[T, V]."""
        return list(self.module.energy(q, dq))

    # -- phases --------------------------------------------------------------------------------------
    def relabel(self, q, dq):
        """R q, R dq: the mirror's links swapped (R R = I)."""
        q, dq = self._qdq(q, dq)
        r = self.relabeling
        return np.array([q[i] for i in r]), np.array([dq[i] for i in r])

    def flight_dynamics(self, q, dq, u) -> np.ndarray:
        """ddq of ``D ddq + C dq + G = B u``."""
        q, dq = self._qdq(q, dq)
        return np.array(self.k_flight(q, dq, as_state_vector(u, "u", self.m).tolist()))

    def stance_dynamics(self, q, dq, u, contact=1):
        """(ddq, F): the KKT system of stance on ``contact`` (its point pinned)."""
        c = self.contact_index(contact)
        q, dq = self._qdq(q, dq)
        ddq, F = self.k_stance(q, dq, as_state_vector(u, "u", self.m).tolist(), c)
        return np.array(ddq), np.array(F)

    def impact_map(self, q, dq, contact=2):
        """(dq+, F_imp): the rigid plastic impact of ``contact`` (before relabeling)."""
        c = self.contact_index(contact)
        q, dq = self._qdq(q, dq)
        dq_plus, impulse = self.k_impact(q, dq, c)
        return np.array(dq_plus), np.array(impulse)

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
        """K = [D -J_c^T; J_c 0] (:meth:`_kkt_matrix`), D, dD/dq_k [k, i, j], dJ_c/dq_k [k, a, j]."""
        D, K = self._kkt_matrix(self._q(q), self.contact_index(contact))
        return K, D, self.mass_matrix_jacobian(q), self.contact_jacobian_jacobian(q, contact)

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
        K, _D, dD, dJ = self._kkt(q, contact)
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
        K, D, dD, dJ = self._kkt(q, contact)
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
