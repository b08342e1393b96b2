"""Torque laws written in Python that run in the compiled loop (the engine's torque-law hook).

A law is a Python function of the hook's signature (:data:`biped_sim.engine.torque_hook.SIGNATURE`) on
float64 arrays::

    def law(t, q, dq, stance_leg, params, u):
        u[0] = ...          # N m on hip 1
        u[1] = ...          # N m on hip 2
        return 0            # 0: success; any other int ends the run "failed" with that code

with ``q``, ``dq`` the 5 coordinates and rates, ``stance_leg`` 1, 2 or 0 (flight), ``params`` the law's
parameter array (read-only) and ``u`` the two torques to write. :func:`torque_law` wraps one with its
parameters into a controller (:class:`TorqueLaw`) that every tool takes. Its ``compiled_law(model)``
compiles the function with numba (``@cfunc``, the optional extra ``biped_sim[numba]``) and hands its
address to the hook, so the law runs inside the compiled loop without the interpreter; its
``__call__(t, q, dq, stance_leg)`` runs the same function as plain Python (the pure-Python loop, and any
run without numba). Both give the same torques bit for bit: numba compiles without fast-math and
without contracting a * b + c into a fused multiply-add, and calls the libm of Python's ``math``.

The form numba compiles: scalar arithmetic, ``math`` functions, indexing of the arrays, loops, tuples
and calls of other module-level Python functions in that form (compiled with the law: the generated
closed forms of the model, :func:`stance_joint_affine`, your own helpers). Write ``x * x`` for a square
(``x ** 2`` is ``pow`` in Python, a multiplication in numba: the last bit may differ).
"""
from __future__ import annotations

import math
import types
import warnings

import numpy as np

from biped_sim.engine._gen.closed_forms import stance_terms_1
from biped_sim.engine.dynamics import _inverse_sym3
from biped_sim.engine.torque_hook import MAX_PARAMETERS, CompiledLaw

__all__ = ["TorqueLaw", "TorqueLawError", "torque_law", "stance_joint_affine", "stance_terms_1",
           "STANCE_CONSTANTS", "NOT_FINITE", "numba_available"]

#: the code a compiled law returns when the torques it wrote are not both finite (the plain Python
#: call raises :class:`TorqueLawError` naming them)
NOT_FINITE = -1000000
#: the name, in ``BipedModel.k``, of the constants that :func:`stance_joint_affine` takes as ``k``
STANCE_CONSTANTS = "stance_terms_1"


class TorqueLawError(Exception):
    """A torque law returned a nonzero code or wrote torques that are not finite (plain Python call)."""


def numba_available():
    """(True, "") when numba imports, else (False, the one line that says how to get it)."""
    try:
        import numba  # noqa: F401
    except ImportError as exc:
        return False, (f"numba is not installed ({exc}): torque laws run as plain Python; "
                       "pip install 'biped_sim[numba]' runs them compiled")
    return True, ""


def stance_joint_affine(q, dq, stance_leg, k):
    """Stance joint accelerations as an affine function of u, for a law: ddq_r = a + Bu u, r = (q1, q2,
    q3), in stance on ``stance_leg`` (1 or 2), from the closed form ``stance_terms_1`` with ``k`` =
    ``model.k[STANCE_CONSTANTS]`` (22 numbers; in a compiled law, a slice of ``params``).

    Returns (a0, a1, a2, B00, B01, B10, B11, B20, B21): the operations of
    ``dynamics.stance_joint_affine_fast``, so the same bits, as a flat tuple (numba's form)."""
    s, w = (2, 3) if stance_leg == 1 else (3, 2)
    M00, M01, M02, M11, M12, M22, b0, b1, b2 = stance_terms_1(
        (q[0], q[1], q[s], q[w], q[4]), (dq[0], dq[1], dq[s], dq[w], dq[4]), (0.0, 0.0), k)[:9]
    i00, i01, i02, i11, i12, i22 = _inverse_sym3(M00, M01, M02, M11, M12, M22)
    a0 = i00 * b0 + i01 * b1 + i02 * b2
    a1 = i01 * b0 + i11 * b1 + i12 * b2
    a2 = i02 * b0 + i12 * b1 + i22 * b2
    if stance_leg == 1:
        return a0, a1, a2, i00, i01, i01, i11, i02, i12
    # leg 2: the leg-1 solution of the swapped state, swapped back (as stance_joint_affine_fast)
    return a1, a0, a2, i11, i01, i01, i00, i12, i02


class TorqueLaw:
    """A controller made of a law function (module docstring) and its parameters; see :func:`torque_law`.

    ``controller(t, q, dq, stance_leg) -> [u1, u2]`` runs the function as plain Python;
    ``compiled_law(model)`` gives the hook the compiled function (None without numba: the loop then calls
    the controller back). Picklable (a sweep's workers compile it again, once per process)."""
    accepts_lists = True

    def __init__(self, fn, params=(), name=None):
        fn = getattr(fn, "py_func", fn)         # a function already under numba's @njit: its Python function
        if not callable(fn) or not isinstance(getattr(fn, "__code__", None), types.CodeType):
            raise ValueError(f"a torque law must be a Python function, got {fn!r}")
        if fn.__code__.co_argcount != 6:
            raise ValueError(f"the torque law {fn.__qualname__} takes {fn.__code__.co_argcount} arguments; a law "
                             "is law(t, q, dq, stance_leg, params, u) -> 0")
        p = np.array(params, dtype=object).ravel() if not isinstance(params, np.ndarray) else params.ravel()
        if len(p) > MAX_PARAMETERS or any(isinstance(v, (bool, np.bool_)) or not _is_real(v) for v in p):
            raise ValueError(f"the torque law's params must be at most {MAX_PARAMETERS} finite real numbers, "
                             f"got {params!r}")
        self.fn, self.name = fn, name or fn.__name__
        self.params = np.array([float(v) for v in p], dtype=np.float64)
        self.params.flags.writeable = False     # the law reads its parameters (the compiled law gets a copy)

    def __call__(self, t, q, dq, stance_leg):
        u = np.zeros(2)
        code = self.fn(float(t), np.array(q, dtype=np.float64), np.array(dq, dtype=np.float64), int(stance_leg),
                       self.params, u)
        if code != 0:
            raise TorqueLawError(f"the torque law {self.name} returned {code!r}")
        u0, u1 = float(u[0]), float(u[1])
        if not (math.isfinite(u0) and math.isfinite(u1)):
            raise TorqueLawError(f"the torque law {self.name} wrote u = [{u0!r}, {u1!r}]: not finite")
        return [u0, u1]

    def compiled_law(self, model):
        """The hook's :class:`~biped_sim.engine.torque_hook.CompiledLaw` (the law's C function and its
        parameters; ``model`` is not used: a law that needs the model's constants has them in ``params``),
        or None without numba."""
        address = compiled_address(self.fn, len(self.params))
        if address is None:
            return None
        return CompiledLaw(self.name, tuple(self.params.tolist()), address)

    def __getstate__(self):
        return {"fn": self.fn, "params": self.params.tolist(), "name": self.name}

    def __setstate__(self, state):
        self.__init__(state["fn"], state["params"], state["name"])

    def __repr__(self):
        return f"TorqueLaw({self.fn.__qualname__}, {len(self.params)} params)"


def torque_law(fn, params=(), name=None):
    """The controller that runs ``fn`` (``law(t, q, dq, stance_leg, params, u) -> 0``) with ``params``:
    compiled in the loop when numba is installed, as plain Python otherwise (one warning says so)."""
    law = TorqueLaw(fn, params, name)
    ok, why = numba_available()
    if not ok:
        _warn_once(why)
    return law


_WARNED = set()


def _warn_once(line):
    if line not in _WARNED:
        _WARNED.add(line)
        warnings.warn(line, stacklevel=3)


def _is_real(v):
    try:
        return math.isfinite(float(v)) and not isinstance(v, (complex, str, bytes))
    except (TypeError, ValueError, OverflowError):
        return False


# -- compilation ---------------------------------------------------------------------------------------

#: (law function, number of parameters) -> the numba cfunc (one compilation per law and size a process)
_COMPILED = {}


def compiled_address(fn, n_params):
    """The address of ``fn`` compiled as a C function of the hook's signature for ``n_params`` parameters,
    or None without numba. A function numba cannot compile raises ValueError (one line; the cause chained)."""
    key = (fn, n_params)
    if key not in _COMPILED:
        ok, why = numba_available()
        if not ok:
            _warn_once(why)
            return None
        _COMPILED[key] = _compile(fn, n_params)
    return _COMPILED[key].address


def _compile(fn, n_params):
    import numba
    from numba import carray, cfunc, types as nt

    law = _jitted(fn, {})
    p = nt.CPointer(nt.float64)
    signature = nt.int32(nt.float64, p, p, nt.int32, p, p)

    def c_law(t, q_ptr, dq_ptr, stance_leg, params_ptr, u_ptr):
        # copies of q and dq: the law may write into its arrays, as into the plain call's copies, and
        # never into the loop's state
        q = carray(q_ptr, 5).copy()
        dq = carray(dq_ptr, 5).copy()
        params = carray(params_ptr, n_params)
        u = carray(u_ptr, 2)
        code = law(t, q, dq, stance_leg, params, u)
        if code != 0:
            return code
        if not (math.isfinite(u[0]) and math.isfinite(u[1])):
            return NOT_FINITE
        return 0
    try:
        compiled = cfunc(signature, error_model="numpy")(c_law)
    except numba.core.errors.NumbaError as exc:
        first = next((line.strip() for line in str(exc).splitlines() if line.strip()), type(exc).__name__)
        raise ValueError(f"the torque law {fn.__qualname__} does not compile with numba: {first} "
                         "(a law is scalar code on its arrays: see biped_sim.control.compiled_laws)") from exc
    return compiled


def _jitted(fn, done):
    """numba's njit of ``fn`` with every module-level Python function it names compiled the same way (so
    a law calls the closed forms and its own helpers as plain functions)."""
    import numba
    if fn in done:
        return done[fn]
    glb = dict(fn.__globals__)
    copy = types.FunctionType(fn.__code__, glb, fn.__name__, fn.__defaults__, fn.__closure__)
    # cache=True: the machine code is kept beside the function's module (numba's __pycache__), so the next
    # process compiles only the small C wrapper (the compile times: docs/controllers.md). numba names the
    # entry by the file and the qualified name, and the entry imports the module that wrote it: the module's
    # name in the qualified name keeps a file imported as ``pkg.law`` and run as ``python pkg/law.py``
    # (module __main__) from finding each other's entries
    copy.__qualname__ = f"{fn.__module__}.{fn.__qualname__}"
    try:
        jitted = numba.njit(error_model="numpy", cache=True)(copy)
    except RuntimeError:        # no file to keep it beside (a function of `python -c`): compiled each process
        jitted = numba.njit(error_model="numpy")(copy)
    done[fn] = jitted
    for name in fn.__code__.co_names:
        value = glb.get(name)
        if isinstance(value, types.FunctionType):
            glb[name] = _jitted(value, done)
    return jitted
