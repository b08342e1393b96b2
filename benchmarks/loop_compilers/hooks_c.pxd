# The torque-law hook's C side for hooks.py under Cython: a law is a C function at an address.
cimport cython

ctypedef void (*law_t)(const double *p, const double *y, double *u) noexcept nogil

@cython.boundscheck(False)
@cython.wraparound(False)
cdef inline void call_address(Py_ssize_t address, double[::1] p, double[::1] y, double[::1] u) noexcept nogil:
    (<law_t>address)(&p[0], &y[0], &u[0])
