"""The terms a model's linearisation is built from, whatever the model: ``derivatives(model)``.

Owns the adapter between a model and the linearisation of its phases (engine/sensitivity.py,
engine/variational.py): D, h = C dq + G, a contact's J_c, p_c and Jdot_c dq, and their derivatives
dD/dq_k, dh/dq, dh/d dq, dJ_c/dq_k, d(Jdot_c dq)/dq, d(Jdot_c dq)/d dq, at one state (lists in, numpy out)
or at a stack of P states (arrays (P, n) in, the same terms with a leading axis P out).

* a :class:`~biped_sim.engine.model.BipedModel`: :class:`ClosedFormDerivatives`, the three-link's closed
  forms (``_gen/closed_forms.py`` through its compiled twin, ``_gen/derivatives.py``) called as the
  linearisation always called them (the same operations, the same bits), with the derivatives by the model
  parameters (``PARAMETER_NAMES``) and the fixed base's;
* a :class:`~biped_sim.engine.generated_model.GeneratedModel`: :class:`GeneratedDerivatives`, the functions the
  generic generator wrote for its description (config/codegen.py: any N coordinates, M actuators, contacts),
  run on numbers or on numpy arrays of the stack; by the model parameters of its description ("<link>.mass",
  "<link>.inertia", "<link>.com_x", "<link>.com_z", "<link>.length", "gravity") the functions of a second
  generated module, written on the first request (config/codegen.py ``generate_parameter_source``).

A contact (``leg``) is 1-based, as ``stance_leg`` is. Layouts: dD [k, i, j] = dD_ij/dq_k; dJ [k, a, j] =
d(J_c)_aj/dq_k; ``jb`` = (Jdot_c dq (2), d(Jdot_c dq)/dq (2 x n), d(Jdot_c dq)/d dq (2 x n)) flat.
"""
from __future__ import annotations

import inspect
from pathlib import Path

import numpy as np

from biped_sim.engine import loop_rules as _rules
from biped_sim.engine._gen import closed_forms as _closed_forms, derivatives as _dgen
from biped_sim.engine.compiled import gen
from biped_sim.engine.model import B as _B


def derivatives(model):
    """The linearisation's terms of ``model``: closed forms for a BipedModel, generated ones for a
    GeneratedModel; a model that is neither is refused in one line."""
    from biped_sim.engine.generated_model import GeneratedModel
    from biped_sim.engine.model import BipedModel
    if isinstance(model, BipedModel):
        return ClosedFormDerivatives(model)
    if isinstance(model, GeneratedModel):
        return GeneratedDerivatives(model)
    raise ValueError(f"no derivatives for a model of type {type(model).__name__}: give a BipedModel or a "
                     "GeneratedModel (bs.load_model)")


def _on_arrays(source, label):
    """The functions of a generated module's source, whose scalar code (arithmetic, sin and cos) runs unchanged
    on numpy arrays of the points."""
    source = source.replace("from math import sin, cos", "from numpy import sin, cos")
    source = source.replace("from math import cos, sin", "from numpy import cos, sin")
    namespace = {}
    exec(compile(source, f"{label} (on arrays)", "exec"), namespace)
    return {key: value for key, value in namespace.items() if callable(value)}


def _stacked(values, P):
    """A generated function's list of values (arrays of the P points, or numbers) as an array (P, n)."""
    out = np.empty((len(values), P))
    for i, v in enumerate(values):
        out[i] = v
    return out.T


#: the closed forms' and their derivatives' Python code, run on numpy arrays (built on first use)
_CLOSED_ON_ARRAYS = {}


def _closed_on_arrays(name):
    if not _CLOSED_ON_ARRAYS:
        for module in (_closed_forms, _dgen):
            for key, value in _on_arrays(inspect.getsource(module), module.__file__).items():
                _CLOSED_ON_ARRAYS.setdefault(key, value)
    return _CLOSED_ON_ARRAYS[name]


class ClosedFormDerivatives:
    """A BipedModel's terms: the three-link closed forms and ``_gen/derivatives.py``."""

    parameter_names = _dgen.PARAMETER_NAMES

    def __init__(self, model):
        self.model = model
        self.name = "closed forms"
        self.n = 5
        self.B = _B
        #: the derivatives' constants (``_gen/derivatives.py``'s ``*_constants(p)``)
        self.k = {name: constants(model.p) for name, constants in _dgen.CONSTANTS.items()}
        #: what the linearisation's caches of a state are keyed by: the same terms give the same key
        self.key = ("closed forms", model.p)

    def mass_and_bias(self, q, dq):
        """D, h, dD [k, i, j], dh/dq, dh/d dq."""
        m = self.model
        D = np.array(gen.mass_matrix(q, m.k["mass_matrix"])).reshape(5, 5)
        h = np.array(gen.bias_forces(q, dq, m.k["bias_forces"]))
        dD = np.array(_dgen.mass_matrix_jacobian(q, self.k["mass_matrix_jacobian"])).reshape(5, 5, 5)
        dh = np.array(_dgen.bias_forces_jacobian(q, dq, self.k["bias_forces_jacobian"])).reshape(2, 5, 5)
        return D, h, dD, dh[0], dh[1]

    def foot(self, q, dq, leg):
        """J (2 x 5), dJ [k, a, j], Jdot dq (2), d(Jdot dq)/dq (2 x 5), d(Jdot dq)/d dq (2 x 5) of foot ``leg``."""
        m = self.model
        J = np.array((gen.foot_jacobian_1 if leg == 1 else gen.foot_jacobian_2)(q, m.k[f"foot_jacobian_{leg}"]))
        dJf = _dgen.foot_jacobian_jacobian_1 if leg == 1 else _dgen.foot_jacobian_jacobian_2
        dJ = np.array(dJf(q, self.k[f"foot_jacobian_jacobian_{leg}"])).reshape(5, 2, 5)
        jbf = _dgen.foot_bias_jacobian_1 if leg == 1 else _dgen.foot_bias_jacobian_2
        jb = np.array(jbf(q, dq, self.k[f"foot_bias_jacobian_{leg}"]))
        return J.reshape(2, 5), dJ, jb[0:2], jb[2:12].reshape(2, 5), jb[12:22].reshape(2, 5)

    def foot_position(self, q, leg):
        """(x, y) of foot ``leg``."""
        point = [0.0, 0.0]
        _rules.ev_foot_point(gen.foot_positions(q, self.model.k["foot_positions"]), leg, point)
        return point[0], point[1]

    def foot_jacobian(self, q, leg):
        """J of foot ``leg`` (2 x 5)."""
        m = self.model
        return np.array((gen.foot_jacobian_1 if leg == 1 else gen.foot_jacobian_2)(
            q, m.k[f"foot_jacobian_{leg}"])).reshape(2, 5)

    def stance_force(self, q, dq, u, leg):
        """F of stance on foot ``leg`` (the liftoff guard's)."""
        from biped_sim.engine.dynamics import stance_floating_fast
        return stance_floating_fast(self.model, q, dq, u, leg)[1]

    def parameters(self, q, dq):
        """d/dp of D ([j, i, l]), h (5 x 9), J_1, J_2 ([j, a, l]), Jdot_1 dq, Jdot_2 dq (2 x 9), (p_1, p_2)
        (4 x 9)."""
        v = np.array(_dgen.parameter_jacobian(q, dq, self.k["parameter_jacobian"]))
        n = len(self.parameter_names)
        o = 0
        out = []
        for shape in ((n, 5, 5), (5, n), (n, 2, 5), (n, 2, 5), (2, n), (2, n), (4, n)):
            size = int(np.prod(shape))
            out.append(v[o:o + size].reshape(shape))
            o += size
        return out

    def fixed_base(self, qs, dqs):
        """(D_s, h_s, dD_s [k, i, j], dh_s/dq_s, dh_s/d dq_s) of the chain pinned at foot 1."""
        v = np.array(_dgen.fixed_base_jacobian_1(list(map(float, qs)), list(map(float, dqs)),
                                                 self.k["fixed_base_jacobian_1"]))
        return v[0:9].reshape(3, 3), v[9:12], v[12:39].reshape(3, 3, 3), v[39:48].reshape(3, 3), v[48:57].reshape(3, 3)

    # -- on a stack of P states ---------------------------------------------------------------------
    def stack(self, Q, DQ, leg):
        """D (P,5,5), h (P,5), dD (P,5,5,5) [p, k, i, j], dh (P,2,5,5) (by q, by dq), J (P,2,5), dJ (P,5,2,5)
        [p, k, a, j], jb (P,22) at the points (Q, DQ) (P x 5 each), stance on foot ``leg``."""
        m, k = self.model, self.k
        P = Q.shape[0]
        q, dq = list(Q.T), list(DQ.T)
        f = _closed_on_arrays
        D = _stacked(f("mass_matrix")(q, m.k["mass_matrix"]), P).reshape(P, 5, 5)
        h = _stacked(f("bias_forces")(q, dq, m.k["bias_forces"]), P)
        dD = _stacked(f("mass_matrix_jacobian")(q, k["mass_matrix_jacobian"]), P).reshape(P, 5, 5, 5)
        dh = _stacked(f("bias_forces_jacobian")(q, dq, k["bias_forces_jacobian"]), P).reshape(P, 2, 5, 5)
        J = _stacked(f(f"foot_jacobian_{leg}")(q, m.k[f"foot_jacobian_{leg}"]), P).reshape(P, 2, 5)
        dJ = _stacked(f(f"foot_jacobian_jacobian_{leg}")(q, k[f"foot_jacobian_jacobian_{leg}"]), P).reshape(
            P, 5, 2, 5)
        jb = _stacked(f(f"foot_bias_jacobian_{leg}")(q, dq, k[f"foot_bias_jacobian_{leg}"]), P)
        return D, h, dD, dh, J, dJ, jb

    def parameter_stack(self, Q, DQ, leg):
        """(dD/dp (P,n,5,5), dJ_leg/dp (P,n,2,5), dr/dp (P,7,n)) at the points (``parameters``' layout)."""
        n = len(self.parameter_names)
        P = Q.shape[0]
        v = _stacked(_closed_on_arrays("parameter_jacobian")(list(Q.T), list(DQ.T), self.k["parameter_jacobian"]), P)
        out, o = [], 0
        for shape in ((n, 5, 5), (5, n), (n, 2, 5), (n, 2, 5), (2, n), (2, n)):
            size = int(np.prod(shape))
            out.append(v[:, o:o + size].reshape((P,) + shape))
            o += size
        dDp, dhp, dJ1p, dJ2p, djb1p, djb2p = out
        dJp, djbp = (dJ1p, djb1p) if leg == 1 else (dJ2p, djb2p)
        return dDp, dJp, np.concatenate([-dhp, -djbp], axis=1)


class GeneratedDerivatives:
    """A GeneratedModel's terms: its generated module's functions (config/codegen.py), and by its model parameters
    (``parameter_names``: "<link>.mass", ... "gravity") those of its parameters' module, generated on the first
    request (``GeneratedModel.parameters_module``)."""

    k = None

    def __init__(self, model):
        from biped_sim.engine.generated_model import parameter_names
        self.model = model
        self.module = model.module
        self.name = f"generated ({model.name})"
        self.n = model.n
        self.B = model.B
        self.parameter_names = parameter_names(model.description)
        self.key = ("generated", model.name, model.module.DIGEST, model.module.GENERATOR_VERSION)
        self._arrays = None
        self._parameter_arrays = None

    def _index(self, leg):
        return self.model.contact_index(leg)

    def mass_and_bias(self, q, dq):
        m = self.model
        dhq, dhv = m.bias_forces_jacobian(q, dq)
        return m.mass_matrix(q), m.bias_forces(q, dq), m.mass_matrix_jacobian(q), dhq, dhv

    def foot(self, q, dq, leg):
        m = self.model
        jb, jbq, jbv = m.contact_bias_jacobian(q, dq, leg)
        return m.contact_jacobian(q, leg), m.contact_jacobian_jacobian(q, leg), jb, jbq, jbv

    def foot_position(self, q, leg):
        x, y = self.model.contact_position(q, leg)
        return float(x), float(y)

    def foot_jacobian(self, q, leg):
        return self.model.contact_jacobian(q, leg)

    def stance_force(self, q, dq, u, leg):
        return self.model.stance_dynamics(q, dq, u, leg)[1]

    def _split_parameters(self, v, lead=()):
        """The parameters' module's flat values (last axis) as (dD/dp [p, i, j], dh/dp [i, p], dJ_c/dp [p, a, j]
        per contact..., d(Jdot_c dq)/dp [a, p] per contact..., dp_c/dp (2C x P))."""
        n, P, C = self.n, len(self.parameter_names), len(self.model.contacts)
        shapes = [(P, n, n), (n, P)] + [(P, 2, n)] * C + [(2, P)] * C + [(2 * C, P)]
        out, o = [], 0
        for shape in shapes:
            size = int(np.prod(shape))
            out.append(v[..., o:o + size].reshape(lead + shape))
            o += size
        return out

    def parameters(self, q, dq):
        """d/dp of D ([p, i, j]), h (n x P), J_c ([p, a, j]) of each contact, Jdot_c dq (2 x P) of each contact, and
        the contact points (2C x P): :meth:`ClosedFormDerivatives.parameters`' layout for a biped's two contacts."""
        module = self.model.parameters_module()
        q, dq = self.model._qdq(q, dq)
        return self._split_parameters(np.array(module.parameter_jacobian(q, dq), dtype=float))

    def parameter_stack(self, Q, DQ, leg):
        """(dD/dp (P,np,n,n), dJ_leg/dp (P,np,2,n), dr/dp (P,n+2,np)) at the points (``parameters``' layout)."""
        if self._parameter_arrays is None:
            module = self.model.parameters_module()
            path = getattr(module, "__file__", None)
            source = Path(path).read_text() if path else inspect.getsource(module)
            self._parameter_arrays = _on_arrays(source, path or f"{self.model.name} parameters")
        P, C, i = Q.shape[0], len(self.model.contacts), self._index(leg)
        v = _stacked(self._parameter_arrays["parameter_jacobian"](list(Q.T), list(DQ.T)), P)
        parts = self._split_parameters(v, (P,))
        dDp, dhp, dJp, djbp = parts[0], parts[1], parts[2 + i], parts[2 + C + i]
        return dDp, dJp, np.concatenate([-dhp, -djbp], axis=1)

    def fixed_base(self, qs, dqs):
        raise ValueError(f"model {self.model.name!r}: the fixed base's derivatives are the three-link's only; "
                         "linearise the floating base (a run on the fixed base is linearised in floating-base "
                         "coordinates)")

    def stack(self, Q, DQ, leg):
        """As :meth:`ClosedFormDerivatives.stack`, n coordinates: D (P,n,n), h (P,n), dD (P,n,n,n), dh (P,2,n,n),
        J (P,2,n), dJ (P,n,2,n), jb (P, 2 + 4n)."""
        if self._arrays is None:
            path = getattr(self.module, "__file__", None)
            source = Path(path).read_text() if path else inspect.getsource(self.module)
            self._arrays = _on_arrays(source, path or self.model.name)
        f, n, P = self._arrays, self.n, Q.shape[0]
        i = self._index(leg)
        q, dq = list(Q.T), list(DQ.T)
        D = _stacked(f["mass_matrix"](q), P).reshape(P, n, n)
        h = _stacked(f["bias_forces"](q, dq), P)
        dD = _stacked(f["mass_matrix_jacobian"](q), P).reshape(P, n, n, n)
        dh = _stacked(f["bias_forces_jacobian"](q, dq), P).reshape(P, 2, n, n)
        w = 2 * n
        J = _stacked(f["contact_jacobians"](q)[w * i: w * i + w], P).reshape(P, 2, n)
        w = 2 * n * n
        dJ = _stacked(f["contact_jacobian_jacobians"](q)[w * i: w * i + w], P).reshape(P, n, 2, n)
        w = 2 + 4 * n
        jb = _stacked(f["contact_bias_jacobians"](q, dq)[w * i: w * i + w], P)
        return D, h, dD, dh, J, dJ, jb
