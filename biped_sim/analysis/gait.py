"""The periodic gait of a scene: fixed point and linearisation of the step-to-step Poincare map.

Owns the gait analysis of ``biped-sim gait`` (the engine headless, continuous feedback of the
scene's controller), for any model: the three-link ``BipedModel`` and a described robot's
``GeneratedModel`` (n coordinates q = [base_x, base_y, q[2:]], contact points 1 and 2 its feet, the
relabeling R a permutation of q's indices). The Poincare section is the set of post-impact states
Delta(S), written in stance-1 labels (after the relabeling R the new stance leg is called leg 1 again):

  z = [(R q)[2:], (R dq)[2:]]        (joint angles and rates, 2 (n - 2) numbers)

which for the three-link biped (R swaps q1 and q2) is z = [q_st, q_sw, q3, dq_st, dq_sw, dq3].

* the translation invariance in x (and the base's height) is removed by pinning the stance foot at
  the origin: the base follows from the joints (``stance_state``);
* the section constraint -- both feet on the ground: h(q[2:]) = 0, the height of contact 2 (the
  swing foot) across the slope -- leaves a section of 2 (n - 2) - 1 dimensions (5 for the
  three-link). The map is linearised on it: with U (2(n-2) x (2(n-2) - 1)) an orthonormal basis of
  the section's tangent space (velocities free, configuration tangent to h = 0), A = U^T dP/dz U,
  whose eigenvalues are the gait's Floquet multipliers. (The full Jacobian dP/dz has one more,
  zero, eigenvalue: a shift along the flow lands on the same next impact.)

dP/dz is exact by default (``StepMap.jacobian``): the state transition matrix of the step through its
touchdown (engine/sensitivity.py: the variational equations and the saltation matrix of the impact,
then the relabeling), at the cost of about one run; ``StepMap.jacobian_fd`` takes central differences
of the same map, kept as a check: Richardson-extrapolated from steps of 1e-3 and 5e-4 along each direction
of the section (4 x 5 runs for the three-link), the runs at rtol = atol no looser than 1e-12. A described
robot's exact Jacobian takes its generated derivatives (engine/model_derivatives.py) and its law's
``jacobian`` where the law has one, else central differences of the law alone (``Gait.law_derivative``
says which).

The fixed point is found by Newton's method on U^T (P(z) - z) = 0 with the exact Jacobian, each
iterate projected back onto h = 0. Its derivative by a parameter theta (a controller's gain
"controller.NAME", or a model parameter that leaves the section where it is) follows from
P(z*(theta), theta) = z*(theta): dz*/dtheta = U (I - A)^-1 U^T dP/dtheta (``Gait.derivatives``).
The step map P integrates one stance phase with the controller until the swing foot touches down (the
engine's touchdown guard and impact map).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from biped_sim.engine._gen.models.three_link import RELABELING as THREE_LINK_RELABELING
from biped_sim.engine.hybrid import HybridSimulator
from biped_sim.engine.model import B as THREE_LINK_B, BipedModel
from biped_sim.engine.options import MIN_RTOL
from biped_sim.engine.sensitivity import parameter_names, run_jacobian
from biped_sim.engine.simulate import stance_state

EXACT = "exact"
FINITE_DIFFERENCES = "central differences"


# -- the section, from the model ---------------------------------------------------------------------------
def relabeling(model) -> tuple[int, ...]:
    """R as a permutation of q's indices (R R = I): the description's mirror; the three-link's swaps q1, q2."""
    return tuple(getattr(model, "relabeling", THREE_LINK_RELABELING))


def section_size(model) -> int:
    """len(z) = 2 (n - 2): the joint angles and rates q[2:], dq[2:]."""
    return 2 * (model.n - 2)


def section_rows(model) -> list[int]:
    """The rows of the physical state (q, dq) after a touchdown of contact 2 that make the next section point
    z = [(R q)[2:], (R dq)[2:]]: contact 2's leg is the new stance leg, leg 1 in stance-1 labels."""
    R, n = relabeling(model), model.n
    return [R[i] for i in range(2, n)] + [n + R[i] for i in range(2, n)]


#: the three-link's ``section_rows``: z = (q2, q1, q3, dq2, dq1, dq3) after a touchdown of leg 2
RELABELED_ROWS = section_rows(BipedModel)


def section_point(model, q, dq) -> np.ndarray:
    """z of the physical post-impact state (q, dq) after a touchdown of contact 2: [(R q)[2:], (R dq)[2:]]."""
    return np.concatenate([np.asarray(q, float), np.asarray(dq, float)])[section_rows(model)]


def foot_position(model, q, leg) -> np.ndarray:
    """Contact point ``leg`` (1 or 2) of either kind of model: the three-link's feet, a description's contacts."""
    if isinstance(model, BipedModel):
        return model.foot_position(q, leg)
    return model.contact_position(q, leg)


def section_height(model, joints, slope=0.0) -> float:
    """h: the height of contact 2 (the swing foot) across the slope, y + tan(slope) x, with contact 1 (the
    stance foot) at the origin and the joints q[2:] = ``joints``; h = 0 on the section."""
    q, _ = stance_state(model, joints, np.zeros(model.n - 2), stance_leg=1)
    p = foot_position(model, q, 2)
    return float(p[1] + math.tan(slope) * p[0])


def section_basis(model, z, slope=0.0, eps=1e-7):
    """(U, grad h): U (2m x (2m - 1), m = n - 2) an orthonormal basis of the section's tangent space at z, the
    rates free and the angles tangent to h = 0; grad h by central differences of ``section_height``."""
    m = model.n - 2
    qj = np.asarray(z[0:m], float)
    grad = np.array([(section_height(model, qj + eps * e, slope) - section_height(model, qj - eps * e, slope))
                     / (2 * eps) for e in np.eye(m)])
    normal = np.concatenate([grad, np.zeros(m)])
    normal /= np.linalg.norm(normal)
    # the orthogonal complement of the normal: the last 2m - 1 left singular vectors of it
    u, _s, _vt = np.linalg.svd(normal.reshape(2 * m, 1))
    return u[:, 1:], grad


def base_angle_index(model) -> int:
    """The index in q of the floating base link's angle (the three-link's torso, q3): every other link's angle
    is relative to its parent's, so adding theta to it turns the whole robot by theta."""
    if isinstance(model, BipedModel):
        return 4
    d = model.description
    return 2 + d.links.index(d.base)


def actuated_coordinates(model) -> list[int]:
    """For each actuator (column of B, a unit column), the index in q of the joint it turns."""
    B = THREE_LINK_B if isinstance(model, BipedModel) else model.B
    return [int(np.argmax(np.abs(B[:, j]))) for j in range(B.shape[1])]


#: StepMap.jacobian_fd's defaults: the larger of its two steps along each column of U, and the loosest
#: tolerance of its runs (both measured on every shipped gait, docs/gait.md)
FD_STEP = 1e-3
FD_RTOL = 1e-12


@dataclass
class Gait:
    z: np.ndarray                 # fixed point: post-impact [(R q)[2:], (R dq)[2:]] (section_point), 2(n - 2)
    step_length: float            # m, between the feet at touchdown (along the ground)
    step_period: float            # s
    speed: float                  # m/s, step_length / step_period
    cost_of_transport: float      # sum over the hips of |u dq| integrated over a step / (m g step_length)
    motor_work: float             # J per step, signed (u . dq integrated)
    eigenvalues: np.ndarray       # of the linearised Poincare map (2(n-2) - 1 of them), largest modulus first
    residual: float               # |P(z) - z| at the fixed point
    newton_iterations: int
    max_torque: float             # N m, largest |u| over the step
    slope: float
    jacobian: np.ndarray | None = None    # A = U^T dP/dz U (2(n-2) - 1 square) at the fixed point
    jacobian_method: str = EXACT          # EXACT or FINITE_DIFFERENCES
    law_derivative: str = ""              # the controller's derivative in the exact Jacobian (sensitivity.LAW_*)
    step_map: "StepMap | None" = field(default=None, repr=False, compare=False)

    @property
    def stable(self) -> bool:
        return bool(np.all(np.abs(self.eigenvalues) < 1.0))

    @property
    def period(self) -> float:
        """The step period (s)."""
        return self.step_period

    @property
    def fixed_point(self) -> np.ndarray:
        """z*, the post-impact state of the gait on the section."""
        return self.z

    @property
    def multipliers(self) -> np.ndarray:
        """The Floquet multipliers: the eigenvalues of ``jacobian``, largest modulus first."""
        return self.eigenvalues

    def jacobian_fd(self, eps=FD_STEP, rtol=None, extrapolate=True) -> np.ndarray:
        """A by central differences of the same step map (a check of ``jacobian``): ``StepMap.jacobian_fd``,
        Richardson-extrapolated from steps of eps and eps / 2, its runs at rtol = atol = the gait's but no
        looser than FD_RTOL (by default)."""
        U, _ = self.step_map.basis(self.z)
        return self.step_map.jacobian_fd(self.z, U, eps, rtol, extrapolate)

    def derivatives(self, parameters) -> "GaitDerivatives":
        """How the gait moves with ``parameters`` (``run_jacobian``'s names: a controller's gain
        "controller.NAME", or a model parameter but ``l_leg``, which moves the section itself), exact: the
        fixed point's dz*/dtheta = U (I - A)^-1 U^T dP/dtheta and the period's dT/dtheta = T_z dz*/dtheta + T_theta,
        from one run of the step's variational equations at z*."""
        parameters = parameter_names(parameters)
        smap = self.step_map
        if "l_leg" in parameters:
            raise ValueError("Gait.derivatives: l_leg moves the section (both feet on the ground) itself; the "
                             "other model parameters and the controller's gains are at hand")
        U, _ = smap.basis(self.z)
        r = smap.sensitivity(self.z, parameters)
        J, k, nz = r.jacobian[smap.rows], len(parameters), section_size(smap.model)
        A = U.T @ J[:, :nz] @ U
        I_A, b = np.eye(U.shape[1]) - A, U.T @ J[:, nz:]
        s = np.linalg.svd(I_A, compute_uv=False)
        neutral = int(np.sum(s < NEUTRAL_RCOND * s[0]))
        if neutral:
            # a multiplier at 1 (the compass gait's free torso rotor): the gaits form a family along the null
            # space of I - A, and the least-squares solution of least norm is the one without a component there
            dz_section = np.linalg.lstsq(I_A, b, rcond=NEUTRAL_RCOND)[0]
        else:
            dz_section = np.linalg.solve(I_A, b)
        dz = U @ dz_section
        dT = r.time_derivative[:nz] @ dz + r.time_derivative[nz:]
        return GaitDerivatives(parameters=parameters, fixed_point=dz.reshape(nz, k), period=np.asarray(dT).reshape(k),
                               law_derivative=r.law_derivative, gain_derivative=r.gain_derivative, neutral=neutral)


@dataclass
class GaitDerivatives:
    """``Gait.derivatives``: the gait's fixed point and period differentiated by ``parameters``."""
    parameters: tuple
    fixed_point: np.ndarray       # dz*/dtheta, len(z) x len(parameters)
    period: np.ndarray            # dT/dtheta (s per unit), len(parameters)
    law_derivative: str           # the law's derivative by the state (sensitivity.LAW_*)
    gain_derivative: str          # by its gains (sensitivity.LAW_*; "" without gains)
    neutral: int = 0              # directions of the section along which the gait is a family (multipliers at
    #                               1, singular values of I - A below NEUTRAL_RCOND of the largest): fixed_point
    #                               has no component along them, the period's derivative does not depend on them


#: Gait.derivatives: a singular value of I - A below this fraction of the largest is a neutral direction (the
#: compass gait's rotor angle is one to rounding; a gait whose multipliers all stay 1e-5 from 1 has none)
NEUTRAL_RCOND = 1e-5


class NoGait(ValueError):
    """A step of the map that does not end in the swing foot's touchdown (the controller does not walk from
    there): there is no step-to-step map to iterate."""


class StepMap:
    """The step-to-step map of a controller on the engine (stance leg called leg 1), for any model: z's size,
    the section constraint and the relabeling come from the model (``section_point``)."""

    def __init__(self, model, controller, rtol=1e-10, atol=1e-10, slope=0.0, method="dop853", **options):
        self.model, self.controller = model, controller
        self.rows = section_rows(model)     # the next section point's rows of the physical state
        self.slope = float(slope)
        self.kw = dict(rtol=rtol, atol=atol, method=method, slope=self.slope, max_events=1,
                       phases=frozenset({"stance", "impact"}), **options)

    def state(self, z):
        """Physical (q, dq) of a section point, stance leg 1 with its foot at the origin."""
        m = self.model.n - 2
        return stance_state(self.model, z[0:m], z[m:2 * m], stance_leg=1)

    def height(self, qj):
        """Height of the swing foot above the ground with the stance foot at the origin (h = 0 on S)."""
        return section_height(self.model, qj, self.slope)

    def run(self, z, max_time=5.0, **extra):
        """Integrate one step from z; returns (z_next, simulator)."""
        q, dq = self.state(np.asarray(z, float))
        sim = HybridSimulator(self.model, q, dq, stance_leg=1, **dict(self.kw, **extra))
        sim.advance(max_time, controller=self.controller)
        ev = sim.events[-1] if sim.events else None
        if ev is None or ev.kind != "touchdown" or ev.leg != 2:
            why = sim.message or (ev.message if ev else f"no touchdown within {max_time} s")
            raise NoGait(f"the step from z={np.round(z, 6).tolist()} does not end in a touchdown: {why}")
        qe, dqp = ev.q, ev.dq_plus          # leg 2 is the new stance leg: relabel
        if np.linalg.norm(foot_position(self.model, qe, 2) - foot_position(self.model, qe, 1)) < 1e-6:
            # both legs as one (q_st = q_sw): the swing foot is on the ground where the stance foot is, at once
            raise NoGait(f"the step from z={np.round(z, 6).tolist()} touches down where the stance foot is, "
                         f"at t={ev.time:.3g} s (the legs together): not a step")
        return section_point(self.model, qe, dqp), sim

    def __call__(self, z):
        return self.run(z)[0]

    def basis(self, z, eps=1e-7):
        """(U, grad h): the orthonormal basis (6 x 5 for the three-link) of the section's tangent space at z
        (``section_basis``)."""
        return section_basis(self.model, z, self.slope, eps)

    def project(self, z, grad=None):
        """z moved along the configuration gradient of h until h = 0 (Newton)."""
        z, m = np.array(z, float), self.model.n - 2
        for _ in range(20):
            h = self.height(z[0:m])
            if abs(h) < 1e-14:
                break
            if grad is None or _ > 0:
                _U, grad = self.basis(z)
            z[0:m] -= h * grad / (grad @ grad)
        return z

    def sensitivity(self, z, parameters=(), max_time=5.0):
        """The step's ``RunSensitivity`` (``engine.sensitivity.run_jacobian`` to the touchdown and through its
        impact map; the initial perturbations are z's own coordinates, the stance foot held at the origin, then
        ``parameters``); its rows are physical: ``section_rows`` picks the next section point's."""
        q, dq = self.state(np.asarray(z, float))
        r = run_jacobian(self.model, q, dq, max_time, controller=self.controller, stance_leg=1, end_at_event=True,
                         parameters=parameters, **self.kw)
        kind, leg = r.events[-1][1:] if r.events else (None, None)
        if kind != "touchdown" or leg != 2:
            raise NoGait(f"the step from z={np.round(z, 6).tolist()} does not end in a touchdown of leg 2 "
                               f"(events {r.events})")
        return r

    def full_jacobian(self, z, max_time=5.0):
        """(dP/dz (len(z) square), the law's derivative): exact (``sensitivity``)."""
        r = self.sensitivity(z, max_time=max_time)
        return r.jacobian[self.rows], r.law_derivative

    def jacobian(self, z, U):
        """A = U^T dP/dz U, exact (``full_jacobian``)."""
        return U.T @ self.full_jacobian(z)[0] @ U

    def jacobian_fd(self, z, U, eps=FD_STEP, rtol=None, extrapolate=True):
        """A = U^T dP/dz U by central differences of the map along U's columns u_i (a check of ``jacobian``).

        D(h) = (P(z + h u_i) - P(z - h u_i)) / (2 h) errs by c h^2 (the map's third derivative) plus the map's
        own error over h (the integrator's tolerance, and a step more or less of its error control between the
        two runs): a single h small enough for one gait's c is too small for another's noise. With
        ``extrapolate`` (default), Richardson's (4 D(eps / 2) - D(eps)) / 3 removes the h^2 term, so eps can be
        large (4 runs a column); without it, D(eps) (2 runs a column). The runs are at rtol = ``rtol`` and
        atol = ``rtol``; by default the map's own, but no looser than FD_RTOL. docs/gait.md has the
        measurements behind FD_STEP and FD_RTOL."""
        if isinstance(eps, bool) or not isinstance(eps, (int, float)) or not 0 < eps < math.inf:
            raise ValueError(f"jacobian_fd: eps must be a positive number (the step along each column of U), "
                             f"got {eps!r}")
        if rtol is None:
            tol = dict(rtol=min(self.kw["rtol"], FD_RTOL), atol=min(self.kw["atol"], FD_RTOL))
        elif isinstance(rtol, bool) or not isinstance(rtol, (int, float)) or not MIN_RTOL <= rtol < 1:
            raise ValueError(f"jacobian_fd: rtol must be a number in [{MIN_RTOL:.3g}, 1) (the rtol and atol of its "
                             f"runs), got {rtol!r}")
        else:
            tol = dict(rtol=rtol, atol=rtol)

        def central(h):
            return np.column_stack([(self.run(z + h * u, **tol)[0] - self.run(z - h * u, **tol)[0]) / (2 * h)
                                    for u in U.T])
        dP = (4 * central(eps / 2) - central(eps)) / 3 if extrapolate else central(eps)
        return U.T @ dP


def find_gait(scene, controller=None, z0=None, slope=0.0, warmup_steps=2, tol=1e-9, max_iter=12,
              jacobian=EXACT, **options) -> Gait:
    """The periodic gait: the fixed point of the step map, its figures and the Floquet multipliers.

    ``scene``: a scene name or a Scene (``load_scene``; its model, controller, slope, touchdown and scuff rules;
    with ``controller``, yours instead: an object, a class or factory, or ``"MODULE:ATTR"``), or a model (a
    BipedModel, or a described robot's GeneratedModel) with ``controller`` (and ``z0``, the initial guess on the
    section, 2 (n - 2) numbers; by default the controller's ``initial_state``, and ``slope``). ``jacobian``:
    ``EXACT`` (default) or ``FINITE_DIFFERENCES``, the one Newton's method and the multipliers use (for any
    model; ``Gait.law_derivative`` says how the law was differentiated); ``Gait.jacobian_fd()`` is always at
    hand as a check."""
    if isinstance(scene, str) or hasattr(scene, "engine_arguments"):
        return scene_gait(scene, jacobian=jacobian, controller=controller, z0=z0, warmup_steps=warmup_steps,
                          tol=tol, max_iter=max_iter, **options)
    if controller is None:
        raise ValueError("find_gait(model, controller, z0): a model needs a controller")
    if jacobian not in (EXACT, FINITE_DIFFERENCES):
        raise ValueError(f"jacobian must be {EXACT!r} or {FINITE_DIFFERENCES!r}, got {jacobian!r}")
    model = scene
    smap = StepMap(model, controller, slope=slope, **options)
    nz = section_size(model)
    if z0 is None:
        if not hasattr(controller, "initial_state"):
            raise ValueError(f"find_gait(model, controller): give z0, the post-impact state {_z_names(model)} to "
                             "start Newton's method from (this controller has no initial_state()), "
                             "or a scene: find_gait('walk', controller=...) starts from the scene's state")
        q, dq = controller.initial_state()
        z0 = np.concatenate([q[2:], dq[2:]])
        if slope:   # rotate the flat-ground start onto the slope
            z0[base_angle_index(model) - 2] += slope
    z = np.asarray(z0, float)
    if z.shape != (nz,) or not np.all(np.isfinite(z)):
        raise ValueError(f"z0 must be {nz} finite numbers, the post-impact state {_z_names(model)}, "
                         f"got {np.round(z, 6).tolist() if z.size <= 2 * nz else f'shape {z.shape}'}")
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not tol > 0 \
            or isinstance(max_iter, bool) or not isinstance(max_iter, int) or max_iter < 1:
        raise ValueError(f"tol must be a positive number and max_iter a positive integer, got tol={tol!r}, "
                         f"max_iter={max_iter!r}")
    for _ in range(warmup_steps):
        z = smap(z)

    def linearised(z, U):
        if jacobian == EXACT:
            J6, how = smap.full_jacobian(z)
            return U.T @ J6 @ U, how
        return smap.jacobian_fd(z, U), ""

    it, A = 0, None
    for it in range(1, max_iter + 1):
        U, grad = smap.basis(z)
        Pz = smap(z)
        r = Pz - z
        if np.linalg.norm(r) < tol:
            break
        if A is None or jacobian == EXACT or it % 4 == 0:   # (chord Newton for the costlier differences)
            A = linearised(z, U)[0]
        delta = _newton_step(A - np.eye(U.shape[1]), -(U.T @ r))
        z = smap.project(z + U @ delta, grad)
    U, _ = smap.basis(z)
    z_next, _sim = smap.run(z)
    residual = float(np.linalg.norm(z_next - z))
    if not residual < tol:
        raise NoGait(f"Newton's method did not converge in {max_iter} iterations: |P(z) - z| = {residual:.2e} at "
                     f"z={np.round(z, 6).tolist()}, above tol={tol:g} (a looser tol, a start nearer the gait, or "
                     "no gait there)")
    A, how = linearised(z, U)
    eig = np.linalg.eigvals(A)
    eig = eig[np.argsort(-np.abs(eig))]
    g = _figures(smap, z, eig, residual, it)
    g.jacobian, g.jacobian_method, g.law_derivative, g.step_map = A, jacobian, how, smap
    return g


def _z_names(model) -> str:
    """z's entries in words: [q_st, q_sw, q3, dq_st, dq_sw, dq3] for the three-link, else the coordinates'."""
    if isinstance(model, BipedModel):
        return "[q_st, q_sw, q3, dq_st, dq_sw, dq3]"
    joints = model.coordinates[2:]
    return "[" + ", ".join([*joints, *(f"d{c}" for c in joints)]) + "] (leg 1 the new stance leg)"


def _newton_step(A_I, rhs):
    """Newton's step on the section: (A - I) delta = rhs; where A has a multiplier at 1 (the compass gait's
    rotor angle: the gaits are a family), the least-squares step of least norm, which does not move along
    the family (solve() would, by rounding over a singular value of 1e-14)."""
    s = np.linalg.svd(A_I, compute_uv=False)
    if s[-1] < NEUTRAL_RCOND * s[0]:
        return np.linalg.lstsq(A_I, rhs, rcond=NEUTRAL_RCOND)[0]
    return np.linalg.solve(A_I, rhs)


def _figures(smap, z, eig, residual, iterations) -> Gait:
    model, ctrl = smap.model, smap.controller
    # one step again with short steps, to integrate |u dq| by the trapezoidal rule
    _z, sim = smap.run(z, max_step=1e-3)
    res = sim.result()
    ev = sim.events[-1]
    T = ev.time
    p1, p2 = foot_position(model, ev.q, 1), foot_position(model, ev.q, 2)
    L = float(np.linalg.norm(p2 - p1))
    keep = res.t <= T
    t, q, dq = res.t[keep], res.q[keep], res.dq[keep]
    u = np.array([ctrl(ti, qi, dqi, 1) for ti, qi, dqi in zip(t, q, dq)]).reshape(len(t), -1)
    # |u_j dq_k| summed over the actuators j, k the joint each turns (B's unit columns)
    pw_abs = sum(np.abs(u[:, j] * dq[:, k]) for j, k in enumerate(actuated_coordinates(model)))
    work_abs = float(np.trapezoid(pw_abs, t))
    mass, g = model.total_mass, _gravity(model)
    return Gait(z=z, step_length=L, step_period=T, speed=L / T, cost_of_transport=work_abs / (mass * g * L),
                motor_work=float(sim.work), eigenvalues=eig, residual=residual, newton_iterations=iterations,
                max_torque=float(np.max(np.abs(u))), slope=smap.slope)


def _gravity(model) -> float:
    return model.parameters.g if isinstance(model, BipedModel) else model.description.gravity


def scene_gait(scene, jacobian=EXACT, controller=None, **newton) -> Gait:
    """The periodic gait of a scene (a Scene of ``load_scene(...)``, or its name) under a controller: the
    scene's (u = 0 for a scene without a walk_controller section: the passive gait), or ``controller``
    (an object, a class or factory made on the scene's model, or ``"MODULE:ATTR"``). Newton starts from the
    controller's ``initial_state()`` if it has one, else from the scene's initial state."""
    if isinstance(scene, str):
        from biped_sim.config.scenes import load_scene
        scene = load_scene(scene)
    if controller is None:
        # a scene without a walk_controller section runs with u = 0: its gait is the passive one
        from biped_sim.config.controllers import no_torque
        ctrl = scene.controller() or no_torque
    else:
        from biped_sim.config.controllers import make_controller
        ctrl = make_controller(controller, scene.engine_arguments()["model"])
    if newton.get("z0") is None and not hasattr(ctrl, "initial_state"):
        newton["z0"] = np.array(scene.params["initial_q"][2:] + scene.params["initial_dq"][2:], float)
    if scene.params["base"] != "floating" or "impact" not in scene.phases:
        raise ValueError(f"scene {scene.name!r} has no impacts (phases {sorted(scene.phases)}): a gait needs "
                         "the 'impact' phase")
    kw = scene.engine_arguments()
    # the scene's rules for a swing foot under the ground decide whether a step is a step, as in its runs
    return find_gait(kw["model"], ctrl, slope=kw["slope"], touchdown_rule=kw["touchdown_rule"],
                     scuff_rule=kw["scuff_rule"], scuff_depth=kw["scuff_depth"], jacobian=jacobian, **newton)


def format_gait(g: Gait, coordinates=None) -> str:
    """The gait's figures, a line each. ``coordinates``: the robot's names of q (``config.joints.joint_layout``),
    which name z*'s entries; by default a described robot's own, and q_st, q_sw, q3 for a BipedModel."""
    rows = [
        ("fixed point z*", "[" + ", ".join(f"{v:.6f}" for v in g.z) + f"]  ({_section_label(g, coordinates)})"),
        ("|P(z*) - z*|", f"{g.residual:.2e}  ({g.newton_iterations} Newton iterations)"),
        ("step length", f"{g.step_length:.4f} m"),
        ("step period", f"{g.step_period:.4f} s"),
        ("speed", f"{g.speed:.4f} m/s"),
        ("cost of transport", f"{g.cost_of_transport:.4f}  (sum |u dq| dt / (m g L))"),
        ("motor work per step", f"{g.motor_work:.3f} J (signed)"),
        ("max |u|", f"{g.max_torque:.1f} N m"),
        ("eigenvalues", ", ".join(_c(e) for e in g.eigenvalues)),
        ("|eigenvalues|", ", ".join(f"{abs(e):.4g}" for e in g.eigenvalues)),
        ("Jacobian", _method(g)),
        ("stable", _stability_line(g)),
    ]
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:>{w}}  {v}" for k, v in rows)


#: a multiplier within this of 1 is neutral: the gaits form a family along it (the compass gait's free torso rotor,
#: its angle and rate), and a perturbation there neither grows nor decays but drifts
NEUTRAL_MULTIPLIER = 1e-6


def _stability_line(g):
    """The verdict on the multipliers, naming the neutral ones (at 1) apart from the others."""
    moduli = np.abs(g.eigenvalues)
    line = (f"{'yes (all' if g.stable else 'NO (not all'} inside the unit circle: max |lambda| = "
            f"{np.max(moduli):.4f})")
    at_one = np.abs(g.eigenvalues - 1.0) < NEUTRAL_MULTIPLIER
    if at_one.any() and not at_one.all():
        rest = moduli[~at_one]
        line += (f"; {int(at_one.sum())} at 1 (neutral: the gaits form a family along them, e.g. a free torso "
                 f"rotor), the other {rest.size} {'inside' if np.all(rest < 1.0) else 'NOT all inside'}: "
                 f"max |lambda| = {np.max(rest):.4f}")
    return line


def _section_label(g, coordinates):
    model = g.step_map.model if g.step_map is not None else None
    if coordinates is None and not isinstance(model, BipedModel) and model is not None:
        coordinates = model.coordinates
    if coordinates is None:
        return "q_st, q_sw, q3, dq_st, dq_sw, dq3 after impact"
    return f"{', '.join(coordinates[2:])} and their rates after impact, leg 1 the new stance leg"


def _method(g):
    if g.jacobian_method == EXACT:
        return f"exact (variational equations and saltation matrix; law derivative: {g.law_derivative})"
    return "central differences of the step map"


def _c(e):
    return f"{e.real:.4g}" if abs(e.imag) < 1e-12 else f"{e.real:.4g}{e.imag:+.4g}j"


def gaits_along(scene, parameter, values, jacobian=EXACT):
    """The gait of a scene (a name or a path) as one of its parameters (``load_scene``'s override names: the
    node's, e.g. ``slope``, or the controller's, e.g. ``kp``) takes ``values`` in turn: a list of
    (value, Gait or None, why not). Continuation: each Newton's method starts from the last fixed point
    found (after its warm-up steps from there)."""
    from biped_sim.config.scenes import load_scene
    out, z = [], None
    for v in values:
        s = load_scene(scene, {parameter: v})
        try:
            g = scene_gait(s, jacobian=jacobian, z0=z)
        except (ValueError, np.linalg.LinAlgError) as exc:     # NoGait among them
            out.append((v, None, str(exc).splitlines()[0]))
            continue
        if g.residual > 1e-8:
            out.append((v, None, f"Newton's method did not converge (|P(z) - z| = {g.residual:.1e})"))
            continue
        z = g.fixed_point
        out.append((v, g, ""))
    return out


def compass_gait(**newton) -> Gait:
    """The passive compass gait (Drake's CompassGait defaults: hip mass 10 kg, legs of 1 m with 5 kg point
    masses at 0.5 m, slope 0.0525 rad) on ``load_model("compass_gait")``, this model's special case: the
    torso a 10 kg mass at the hip (c_torso = 0; its inertia, 1 kg m^2, a free rotor there, since no torque
    acts on it with u = 0), point-mass legs, no torque. The swing foot passes under the ground behind the
    stance foot (scuff_rule "behind"), as the compass gait's does. Its five multipliers are the compass
    gait's three and the torso rotor's two, at 1 (its angle and rate are neutral)."""
    from biped_sim.config.models import load_model
    model = load_model("compass_gait")

    def no_torque(t, q, dq, stance_leg):
        return (0.0, 0.0)

    z0 = np.array([2.92075575, 3.46742955, 0.0, 1.09644226, 0.37368084, 0.0])   # near the limit cycle
    return find_gait(model, no_torque, z0=z0, slope=0.0525, scuff_rule="behind", warmup_steps=0, **newton)
