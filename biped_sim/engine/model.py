"""The three-link biped of docs/model.md: parameters, D(q), C(q, dq), G(q), B, feet, J, Jdot, energy.

Owns the model's parameters and the evaluation of the closed forms in ``_gen/closed_forms.py`` (which
``tools/generate_model.py`` derives from the energies; docs/model.md "Configuration and conventions").
Coordinates are ``q = [x, y, q1, q2, q3]``: hip position, leg angles relative to the torso, absolute
torso angle; angle 0 points up. Plain numpy, no ROS.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields, replace
from math import cos, sin
from typing import NamedTuple

import numpy as np

from biped_sim.engine.compiled import gen

#: Actuation matrix of docs/model.md: two hip motors acting on q1 and q2.
B = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 0.0]])
COORDINATE_NAMES = ("base_x", "base_y", "hip_1", "hip_2", "torso_pitch")


def short_repr(v, limit: int = 80) -> str:
    """repr(v), cut to ``limit`` characters: what a refused argument's message shows of it."""
    r = repr(v)
    return r if len(r) <= limit else r[:limit - 3] + "..."


def _is_real_number(x) -> bool:
    """Whether x is one real number: an int or a float (numpy's too, or a 0-d array of one); not a bool,
    a complex number or a string, which numpy and float() would convert without a word."""
    if isinstance(x, (bool, np.bool_)):
        return False
    if isinstance(x, np.ndarray):
        return x.ndim == 0 and x.dtype.kind in "iuf"
    return isinstance(x, numbers.Real)


def real_vector(v, n: int):
    """(v as a float array of shape (n,), None), or (None, why not): v must be n real numbers, a list, a
    tuple or an array of ints and floats (no bools, complex numbers, strings, None), all finite."""
    if isinstance(v, (list, tuple)):
        if any(isinstance(x, (bool, np.bool_)) for x in v):   # numpy would make them 0 and 1
            return None, "type"
    elif isinstance(v, (str, bytes, bytearray)):
        return None, "type"
    try:
        a = np.asarray(v)
    except (TypeError, ValueError):     # ragged nesting
        return None, "type"
    kind = a.dtype.kind
    if kind == "O":     # Python objects: real numbers only (a Fraction, an int beyond int64), else refused
        if not all(_is_real_number(x) for x in a.flat):
            return None, "type"
    elif kind not in "iuf":     # bools, complex numbers, strings, dates
        return None, "type"
    if a.shape != (n,):
        return None, "shape"
    try:
        a = np.asarray(a, dtype=float)
    except OverflowError:       # an int too large for a float
        return None, "non-finite"
    if not np.all(np.isfinite(a)):
        return None, "non-finite"
    return a, None


def _is_finite(x) -> bool:
    try:
        return math.isfinite(x)
    except OverflowError:       # an int too large for a float
        return False


def as_state_vector(v, name: str, n: int = 5) -> np.ndarray:
    """A float vector of length n with finite entries, or a ValueError that names the problem."""
    a, why = real_vector(v, n)
    if why is None:
        return a
    if why == "type":
        raise ValueError(f"{name} must be {n} real numbers (ints or floats; not bools, complex numbers or "
                         f"strings), got {short_repr(v)}")
    if why == "shape":
        raise ValueError(f"{name} must have shape ({n},), got shape {np.shape(v)}")
    values = np.asarray(v, dtype=object).tolist()
    bad = [i for i, x in enumerate(values) if not _is_finite(x)]
    raise ValueError(f"{name} has non-finite entries at index {bad}: {short_repr(values)}")


class StickFigure(NamedTuple):
    """The points that draw the robot, (x, y) in the model's plane (m): hip, feet, torso tip."""
    hip: np.ndarray
    foot_1: np.ndarray
    foot_2: np.ndarray
    torso_tip: np.ndarray


@dataclass(frozen=True)
class BipedParameters:
    """Physical constants (SI units); defaults are the table of docs/model.md.

    ``c_torso`` and ``c_leg`` are the distances of the links' centres of mass from the hip; by
    default half the link length (uniform links, as in docs/model.md).
    """
    m_torso: float = 10.0
    I_torso: float = 1.0
    l_torso: float = 0.5
    c_torso: float | None = None
    m_leg: float = 5.0
    I_leg: float = 0.5
    l_leg: float = 1.0
    c_leg: float | None = None
    g: float = 9.81

    def __post_init__(self):
        if self.c_torso is None:
            object.__setattr__(self, "c_torso", 0.5 * self.l_torso)
        if self.c_leg is None:
            object.__setattr__(self, "c_leg", 0.5 * self.l_leg)
        for f in fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise ValueError(f"parameter {f.name} must be a finite number, got {v!r}")
            if f.name == "g":
                if v < 0:
                    raise ValueError(f"parameter g must be >= 0, got {v}")
            elif f.name in ("c_torso", "c_leg", "I_torso", "I_leg", "l_torso"):
                if v < 0:
                    raise ValueError(f"parameter {f.name} must be >= 0, got {v}")
            elif v <= 0:
                raise ValueError(f"parameter {f.name} must be positive, got {v}")
        # a point-mass link (I = 0) is fine while its angle still moves mass: D stays positive definite
        # exactly when every link has I + m c^2 > 0 (the legs' and the torso's absolute angles each carry it)
        for link in ("torso", "leg"):
            if getattr(self, f"I_{link}") + getattr(self, f"m_{link}") * getattr(self, f"c_{link}") ** 2 <= 0:
                raise ValueError(f"parameters I_{link} = 0 and c_{link} = 0: the {link}'s angle would move no mass "
                                 f"and D would be singular; give I_{link} > 0 or c_{link} > 0")

    def as_tuple(self) -> tuple:
        return tuple(float(getattr(self, n)) for n in gen.PARAMETER_NAMES)


class BipedModel:
    """The planar three-link biped (torso and two legs, point feet, two hip motors).

    ``BipedModel(m_leg=4.0)`` overrides any constant of :class:`BipedParameters`. All methods take
    and return numpy arrays; ``leg`` is 1 or 2.
    """

    B = B
    n = 5

    def __init__(self, parameters: BipedParameters | None = None, **overrides):
        params = parameters or BipedParameters()
        if overrides:
            unknown = set(overrides) - {f.name for f in fields(BipedParameters)}
            if unknown:
                allowed = ", ".join(f.name for f in fields(BipedParameters))
                raise ValueError(f"unknown model parameter(s) {sorted(unknown)}; allowed: {allowed}")
            params = replace(params, **overrides)
            if "l_torso" in overrides and "c_torso" not in overrides:
                params = replace(params, c_torso=0.5 * params.l_torso)
            if "l_leg" in overrides and "c_leg" not in overrides:
                params = replace(params, c_leg=0.5 * params.l_leg)
        self.parameters = params
        self.p = params.as_tuple()
        self.total_mass = params.m_torso + 2.0 * params.m_leg
        # parameter-only subexpressions of every closed form, computed once
        self.k = {name: constants(self.p) for name, constants in gen.CONSTANTS.items()}
        self.k_stance = self.k["stance_floating_1"]
        self.k_fixed = self.k["fixed_base_dynamics_1"]
        self.k_fixed_kin = self.k["fixed_base_kinematics_1"]

    def __repr__(self):
        return f"BipedModel({self.parameters})"

    # -- dynamics terms (docs/model.md: D = d^2T/d dq^2, C from Christoffel symbols, G = dV/dq) ----------
    def mass_matrix(self, q) -> np.ndarray:
        """D(q), 5x5 symmetric positive definite."""
        q = as_state_vector(q, "q")
        return np.array(gen.mass_matrix(q.tolist(), self.k["mass_matrix"])).reshape(5, 5)

    def coriolis(self, q, dq) -> np.ndarray:
        """The matrix C(q, dq) (so that C dq are the Coriolis and centrifugal forces)."""
        q, dq = as_state_vector(q, "q"), as_state_vector(dq, "dq")
        return np.array(gen.coriolis_matrix(q.tolist(), dq.tolist(), self.k["coriolis_matrix"])).reshape(5, 5)

    def gravity(self, q) -> np.ndarray:
        """G(q) = dV/dq (depends on q only; docs/model.md notes the homework's slip G(dq))."""
        q = as_state_vector(q, "q")
        return np.array(gen.gravity_vector(q.tolist(), self.k["gravity_vector"]))

    def bias_forces(self, q, dq) -> np.ndarray:
        """C(q, dq) dq + G(q)."""
        q, dq = as_state_vector(q, "q"), as_state_vector(dq, "dq")
        return np.array(gen.bias_forces(q.tolist(), dq.tolist(), self.k["bias_forces"]))

    # -- feet (docs/model.md: p_i = (x + l_leg sin(qi + q3), y + l_leg cos(qi + q3))) ---------------------
    def foot_position(self, q, leg: int) -> np.ndarray:
        leg = check_leg(leg)
        q = as_state_vector(q, "q")
        return np.array(gen.foot_positions(q.tolist(), self.k["foot_positions"])[2 * leg - 2: 2 * leg])

    def stick_figure(self, q) -> StickFigure:
        """Hip (x, y), both feet (``foot_position``) and the torso's tip, hip + l_torso (sin q3, cos q3):
        the one geometry of the markers and the animation."""
        q = as_state_vector(q, "q")
        p = gen.foot_positions(q.tolist(), self.k["foot_positions"])
        l_torso = self.parameters.l_torso
        return StickFigure(q[:2].copy(), np.array(p[0:2]), np.array(p[2:4]),
                           np.array([q[0] + l_torso * math.sin(q[4]), q[1] + l_torso * math.cos(q[4])]))

    def base_hung_from(self, contact_index0, pin, angles, rates):
        """(hip, hip velocity) as lists: the hip (x, y) hung from foot ``contact_index0 + 1`` pinned at ``pin`` and at
        rest, the joint angles q[2:] = ``angles`` and rates dq[2:] = ``rates`` (lists of floats;
        ``GeneratedModel.base_hung_from``'s meaning): ``hip_hung_from`` with this model's l_leg."""
        return hip_hung_from(self.parameters.l_leg, contact_index0, pin, angles, rates)

    def foot_jacobian(self, q, leg: int) -> np.ndarray:
        """J_i = d p_i / dq (2 x 5)."""
        leg = check_leg(leg)
        q = as_state_vector(q, "q")
        name = f"foot_jacobian_{leg}"
        return np.array(getattr(gen, name)(q.tolist(), self.k[name])).reshape(2, 5)

    def foot_jacobian_dot(self, q, dq, leg: int) -> np.ndarray:
        """dJ_i/dt (2 x 5)."""
        leg = check_leg(leg)
        q, dq = as_state_vector(q, "q"), as_state_vector(dq, "dq")
        name = f"foot_jacobian_dot_{leg}"
        return np.array(getattr(gen, name)(q.tolist(), dq.tolist(), self.k[name])).reshape(2, 5)

    def foot_velocity(self, q, dq, leg: int) -> np.ndarray:
        leg = check_leg(leg)
        q, dq = as_state_vector(q, "q"), as_state_vector(dq, "dq")
        v = gen.foot_kinematics(q.tolist(), dq.tolist(), self.k["foot_kinematics"])
        return np.array(v[2 * leg + 2: 2 * leg + 4])

    # -- energy (kept so that tests and run statistics can check conservation) ---------------------
    def kinetic_energy(self, q, dq) -> float:
        q, dq = as_state_vector(q, "q"), as_state_vector(dq, "dq")
        return gen.energy(q.tolist(), dq.tolist(), self.k["energy"])[0]

    def potential_energy(self, q) -> float:
        q = as_state_vector(q, "q")
        return gen.energy(q.tolist(), [0.0] * 5, self.k["energy"])[1]

    def energy(self, q, dq) -> float:
        """Total mechanical energy T + V (J), with V = 0 at hip height 0 (y_centre measured from 0)."""
        q, dq = as_state_vector(q, "q"), as_state_vector(dq, "dq")
        return self.energy_fast(q.tolist(), dq.tolist())

    def energy_fast(self, q, dq) -> float:
        """``energy`` for lists of checked numbers (the engine's resets)."""
        T, V = gen.energy(q, dq, self.k["energy"])
        return T + V

    def com_position(self, q) -> np.ndarray:
        q = as_state_vector(q, "q")
        return np.array(gen.com_position(q.tolist(), self.k["com_position"]))


def hip_hung_from(l_leg, leg_index0, pin, angles, rates):
    """(hip, hip velocity) as lists: the hip (x, y) hung from foot i = ``leg_index0 + 1`` pinned at ``pin`` = c and at
    rest, q[2:] = ``angles`` = (q1, q2, q3), dq[2:] = ``rates`` (lists of floats). From p_i(q) = c, with
    p_i(q) = (x + l_leg sin(qi + q3), y + l_leg cos(qi + q3)): (x, y) = c - l_leg (sin(qi + q3), cos(qi + q3)), and
    from J_i dq = 0: (dx, dy) = -l_leg (cos(qi + q3), -sin(qi + q3)) (dqi + dq3). The fixed-base mode's ``to_phys``
    calls it at every evaluation: floats, no checks, l_leg given (``BipedModel.base_hung_from`` gives the model's)."""
    th, dth = angles[leg_index0] + angles[2], rates[leg_index0] + rates[2]
    sn, cs = sin(th), cos(th)
    return [pin[0] - l_leg * sn, pin[1] - l_leg * cs], [-l_leg * cs * dth, l_leg * sn * dth]


def check_leg(leg) -> int:
    if leg not in (1, 2) or isinstance(leg, bool):
        raise ValueError(f"leg must be 1 or 2, got {leg!r}")
    return int(leg)
