# The generated formulas as the probe's rules call them under Cython: glue.h's C entry points behind the
# names and signatures of kernels.py (its Python twin): the state S (a pointer to its first entry) and offsets
# into it; ptr(S) gives that pointer from the entry points' typed memoryview.
cdef extern from "glue.h" nogil:
    void g_rhs(const double *P, double t, const double *y, double *dy)
    void g_dop853_step(const double *P, double t, const double *y, const double *f, double h, double rtol,
                       double atol, double *out)
    void g_dop853_dense(const double *P, double t_old, double h, const double *y_old, const double *y,
                        const double *k, double *dense)
    void g_foot_positions(const double *P, const double *q, double *p)
    double g_ulp(double x)

cdef inline void k_rhs(double *S, double t, Py_ssize_t y, Py_ssize_t dy) noexcept nogil:
    g_rhs(S, t, &S[y], &S[dy])

cdef inline void k_step(double *S, double t, Py_ssize_t y, Py_ssize_t f, double h, double rtol, double atol,
                        Py_ssize_t out) noexcept nogil:
    g_dop853_step(S, t, &S[y], &S[f], h, rtol, atol, &S[out])

cdef inline void k_dense(double *S, double t_old, double h, Py_ssize_t y_old, Py_ssize_t y, Py_ssize_t k,
                         Py_ssize_t dense) noexcept nogil:
    g_dop853_dense(S, t_old, h, &S[y_old], &S[y], &S[k], &S[dense])

cdef inline void k_foot_positions(double *S, Py_ssize_t q, Py_ssize_t p) noexcept nogil:
    g_foot_positions(S, &S[q], &S[p])

cdef inline double k_ulp(double x) noexcept nogil:
    return g_ulp(x)

cdef inline double *ptr(double[::1] S) noexcept nogil:
    return &S[0]
