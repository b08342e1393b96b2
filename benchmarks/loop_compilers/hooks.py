"""The torque-law hook as each candidate would make it: the loop calls a law n times, either a compiled
kernel given by its address (a ``double *`` signature: ``law(p, y, u)``, as glue_so.c's ``so_pd_law``) or a
Python callable ``law(y) -> (u1, u2)``. Written once like rules.py; measure.py times it and checks that an
exception raised by the Python law reaches the caller."""
from __future__ import annotations

import cython

if cython.compiled:
    from cython.cimports.benchmarks.loop_compilers.hooks_c import call_address
else:
    def call_address(address, p, y, u):
        raise NotImplementedError("a law by address needs a compiler: run as Python the hook takes a callable")


@cython.ccall
@cython.boundscheck(False)
@cython.wraparound(False)
def run_compiled_law(address: cython.Py_ssize_t, p: cython.double[::1], y: cython.double[::1], u: cython.double[::1],
                     n: cython.int) -> cython.double:
    """n calls of the law at ``address``; the sum of its first torque (so that no call is left out)."""
    total: cython.double = 0.0
    _k: cython.int
    for _k in range(n):
        call_address(address, p, y, u)
        total += u[0]
    return total


@cython.ccall
def run_python_law(law, y: cython.double[::1], u: cython.double[::1], n: cython.int) -> cython.double:
    """n calls of the Python callable ``law(y) -> (u1, u2)``; the sum of its first torque."""
    total: cython.double = 0.0
    _k: cython.int
    for _k in range(n):
        u[0], u[1] = law(y)
        total += u[0]
    return total
