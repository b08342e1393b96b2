"""The torque-law hook: how a torque law enters the compiled loop.

The engine names no controller. In a mode the compiled loop runs, the torque at each evaluation
comes from one of three laws:

* held: no controller, the torque ``u`` set for the control period;
* a compiled law: a C function with the signature of :data:`SIGNATURE`, given by its address, and the
  parameter array it reads (:class:`CompiledLaw`); it runs in the loop without the interpreter. A
  controller offers one by a method ``compiled_law(model) -> CompiledLaw or None`` (None: call me);
* any other controller, called back from C and checked as the Python loop checks it
  (``modes.bind_controller``; ``_core.c`` call_controller).

The signature is plain scalars and ``double`` pointers, so a function made by ctypes
(:func:`c_prototype`) or by numba's ``@cfunc`` (its ``.address``) plugs in as a C extension's does. A
nonzero return means the law failed: the run ends "failed" with a message naming the law, the code
and the time.

A compiled law may offer its derivative too (:data:`JACOBIAN_SIGNATURE`, ``CompiledLaw.jacobian``): the
loop never calls it; the exact Jacobians of a run on the engine's steps (engine/variational.py) take u and
u_x from it in C, and differentiate a law without it in Python.
"""
from __future__ import annotations

from typing import NamedTuple

#: the C signature of a compiled law: u (2 values) from t, q (5), dq (5), the stance leg (1, 2; 0 in
#: flight) and the parameters; nonzero return: the law failed
SIGNATURE = ("int law(double t, const double *q, const double *dq, int stance_leg, const double *params, "
             "double *u)")
#: the C signature of a compiled law's optional derivative (:attr:`CompiledLaw.jacobian`): the law's u (to
#: rounding) and u_x = du/d(q, dq) (2 x 10, row-major: u_x[i * 10 + k] = du_i/dx_k with x = (q, dq)) at the
#: same arguments; a torque at its limit has derivative 0 there. Nonzero return: the derivative failed (the
#: Jacobian's run raises ValueError naming the law, the code and the time)
JACOBIAN_SIGNATURE = ("int law_jacobian(double t, const double *q, const double *dq, int stance_leg, "
                      "const double *params, double *u, double *u_x)")
#: the C signature of a compiled law's optional derivative on a stance KKT system already factored
#: (:attr:`CompiledLaw.stance_jacobian`): :data:`JACOBIAN_SIGNATURE`'s, with ``system`` the StanceSystem of
#: engine/_stance_derivative.h at (q, dq) on ``stance_leg`` (stance_system's) of the plant, whose model parameters
#: are the law's own; the exact Jacobians' steps in C factor that system once for the law and the flow. Unused in
#: flight (stance_leg 0)
STANCE_JACOBIAN_SIGNATURE = ("int law_stance_jacobian(const void *system, double t, const double *q, const double *dq, "
                             "int stance_leg, const double *params, double *u, double *u_x)")
#: the most parameters a compiled law takes
MAX_PARAMETERS = 128


class CompiledLaw(NamedTuple):
    """A compiled torque law: its name (in messages only), its parameters (a tuple of Python numbers,
    copied into the loop as doubles), the address of its C function (:data:`SIGNATURE`) and, optionally, the
    address of its derivative (:data:`JACOBIAN_SIGNATURE`, on the same parameters; 0: none) and of that same
    derivative on the plant's stance KKT system (:data:`STANCE_JACOBIAN_SIGNATURE`; 0: none, or the law's model
    parameters are not the plant's; a law that replaces ``jacobian`` replaces this too, or sets it to 0)."""
    name: str
    params: tuple
    address: int
    jacobian: int = 0
    stance_jacobian: int = 0


def c_prototype():
    """The ctypes function type of :data:`SIGNATURE` (``c_prototype()(python_function)`` makes a C
    function of a Python one, whose address ``ctypes.cast(f, ctypes.c_void_p).value`` is a law's)."""
    import ctypes
    p = ctypes.POINTER(ctypes.c_double)
    return ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_double, p, p, ctypes.c_int, p, p)


def c_jacobian_prototype():
    """The ctypes function type of :data:`JACOBIAN_SIGNATURE` (a law's derivative, as :func:`c_prototype`)."""
    import ctypes
    p = ctypes.POINTER(ctypes.c_double)
    return ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_double, p, p, ctypes.c_int, p, p, p)


def offered_law(controller, model):
    """The law a mode's torque comes from on the compiled loop: ``("held", None)`` for no controller, the
    :class:`CompiledLaw` a controller offers on ``model`` (the simulator's: ``controller.compiled_law(model)``),
    else None (the controller is called back)."""
    if controller is None:
        return "held", None
    law = getattr(controller, "compiled_law", None)
    return law(model) if callable(law) else None


def reference_law(controller, model):
    """The :class:`CompiledLaw` a controller offers on ``model``, else None (no controller: a held torque; or
    one called back)."""
    law = offered_law(controller, model)
    return law if law is not None and law[0] != "held" else None


def law_in_mode(controller, model):
    """The torque law of a mode on the compiled loop: held, compiled, or ``("callback", controller)``."""
    law = offered_law(controller, model)
    return law if law is not None else ("callback", controller)


def hook_argument(law):
    """What the C loop takes for a law (``Loop.begin``, ``Loop.law_torque``, ``Loop.periods``): None (held), the
    Python callable (called back), or a compiled law's (address, parameters, name)."""
    if law[0] == "held":
        return None
    if law[0] == "callback":
        return law[1]
    return law.address, law.params, law.name
