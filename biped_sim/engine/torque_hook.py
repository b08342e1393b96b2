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
"""
from __future__ import annotations

from typing import NamedTuple

#: the C signature of a compiled law: u (2 values) from t, q (5), dq (5), the stance leg (1, 2; 0 in
#: flight) and the parameters; nonzero return: the law failed
SIGNATURE = ("int law(double t, const double *q, const double *dq, int stance_leg, const double *params, "
             "double *u)")
#: the most parameters a compiled law takes
MAX_PARAMETERS = 128


class CompiledLaw(NamedTuple):
    """A compiled torque law: its name (in messages only), its parameters (a tuple of Python numbers,
    copied into the loop as doubles) and the address of its C function (:data:`SIGNATURE`)."""
    name: str
    params: tuple
    address: int


def c_prototype():
    """The ctypes function type of :data:`SIGNATURE` (``c_prototype()(python_function)`` makes a C
    function of a Python one, whose address ``ctypes.cast(f, ctypes.c_void_p).value`` is a law's)."""
    import ctypes
    p = ctypes.POINTER(ctypes.c_double)
    return ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_double, p, p, ctypes.c_int, p, p)
