# The generated formulas as the compiled rules (loop_rules.py) call them: the kernels of _gen/_kernels.h behind
# the names and arguments of loop_kernels.py, their Python twins: the state S (a pointer to its first entry) and
# offsets into it. Wiring only: every operation is a generated kernel's (or a copy). The model's kernels dispatch
# on S[MODEL_KERNELS] as the twins do: 0 the three-link's closed forms, k > 0 a described robot's table.
from libc.string cimport memcpy
from libc.math cimport fabs, isinf, nextafter, INFINITY, NAN

cdef extern from "_loop_state.h":
    # the right-hand side f(ctx, t, y, dy) the generated steps take (the compiled loop's, with its torque law)
    ctypedef int (*rhs_t)(void *ctx, double t, const double *y, double *dy) noexcept nogil
    # a guard's value at time t (the root finder's and the dip search's function)
    ctypedef double (*guard_t)(double *S, void *ctx, double t) noexcept nogil
    # the feet (x, height, dx, dheight, a row a foot) at time t into S[FEET] (the scuff's tracking)
    ctypedef void (*feet_t)(double *S, void *ctx, double t) noexcept nogil

cdef extern from "_gen/_kernels.h" nogil:
    int k_dop853_step_9(rhs_t fun, void *ctx, double t, const double *ys, const double *k0, double h, double rtol,
                         double atol, double *out)
    int k_dopri5_step_9(rhs_t fun, void *ctx, double t, const double *ys, const double *k0, double h, double rtol,
                         double atol, double *out)
    int k_dop853_dense_9(rhs_t fun, void *ctx, double t, double h, const double *ys, const double *y_new,
                          const double *k0, const double *k5, const double *k6, const double *k7, const double *k8,
                          const double *k9, const double *k10, const double *k11, const double *k12, double *out)
    int k_dopri5_dense_9(const double *ys, const double *k0, const double *k1, const double *k2, const double *k3,
                          const double *k4, const double *k5, const double *k6, double *out)
    int k_dop853_step_11(rhs_t fun, void *ctx, double t, const double *ys, const double *k0, double h, double rtol,
                         double atol, double *out)
    int k_dopri5_step_11(rhs_t fun, void *ctx, double t, const double *ys, const double *k0, double h, double rtol,
                         double atol, double *out)
    int k_dop853_dense_11(rhs_t fun, void *ctx, double t, double h, const double *ys, const double *y_new,
                          const double *k0, const double *k5, const double *k6, const double *k7, const double *k8,
                          const double *k9, const double *k10, const double *k11, const double *k12, double *out)
    int k_dopri5_dense_11(const double *ys, const double *k0, const double *k1, const double *k2, const double *k3,
                          const double *k4, const double *k5, const double *k6, double *out)
    int k_dop853_step_15(rhs_t fun, void *ctx, double t, const double *ys, const double *k0, double h, double rtol,
                         double atol, double *out)
    int k_dopri5_step_15(rhs_t fun, void *ctx, double t, const double *ys, const double *k0, double h, double rtol,
                         double atol, double *out)
    int k_dop853_dense_15(rhs_t fun, void *ctx, double t, double h, const double *ys, const double *y_new,
                          const double *k0, const double *k5, const double *k6, const double *k7, const double *k8,
                          const double *k9, const double *k10, const double *k11, const double *k12, double *out)
    int k_dopri5_dense_15(const double *ys, const double *k0, const double *k1, const double *k2, const double *k3,
                          const double *k4, const double *k5, const double *k6, double *out)
    int c_foot_positions "k_foot_positions"(const double *q, const double *k, double *out)
    int c_impact_map_1 "k_impact_map_1"(const double *q, const double *dqm, const double *k, double *out)
    int c_impact_map_2 "k_impact_map_2"(const double *q, const double *dqm, const double *k, double *out)
    int c_energy "k_energy"(const double *q, const double *dq, const double *k, double *out)
    int c_foot_kinematics "k_foot_kinematics"(const double *q, const double *dq, const double *k, double *out)

# a described robot's kernels (model_kernels = k > 0): the C entry points of its twin's table (_kernel_table.h), the
# table of the Loop whose state S is (_core.c's loop_table; the Python twins call the same entry points)
cdef extern from "_kernel_table.h" nogil:
    ctypedef struct KernelTable:
        int (*impact)(const double *q, const double *dq_minus, int contact, double *dq_plus, double *F) noexcept nogil
        int (*foot_positions)(const double *q, double *p) noexcept nogil
        int (*foot_kinematics)(const double *q, const double *dq, double *pv) noexcept nogil
        int (*energy)(const double *q, const double *dq, double *tv) noexcept nogil

cdef extern from "_loop_table.h" nogil:
    const KernelTable *loop_table(double *S)

cdef extern from "_loop_state.h":
    enum:
        LS_MODEL_KERNELS
        LS_NQ_MAX
        LS_N_Y
        LS_METHOD
        LS_K_POS
        LS_K_IMPACT
        LS_K_ENERGY
        LS_K_FEET


cdef inline void k_rhs(double *S, rhs_t fun, void *ctx, double t, Py_ssize_t y, Py_ssize_t dy) noexcept nogil:
    fun(ctx, t, &S[y], &S[dy])


cdef inline void k_step(double *S, rhs_t fun, void *ctx, double t, Py_ssize_t y, Py_ssize_t f, double h,
                        double rtol, double atol, Py_ssize_t out) noexcept nogil:
    # S[out:] = y_new, f_new, err, stages k0..k12, rows S[N_Y] apart: the generated kernel of y's size (the
    # three-link's floating base 11 entries, a described robot's 2 N + 1: 9 or 15; Loop.begin refuses others)
    cdef Py_ssize_t n = <Py_ssize_t>S[LS_N_Y]
    if S[LS_METHOD] == 0.0:
        if n == 11:
            k_dop853_step_11(fun, ctx, t, &S[y], &S[f], h, rtol, atol, &S[out])
        elif n == 15:
            k_dop853_step_15(fun, ctx, t, &S[y], &S[f], h, rtol, atol, &S[out])
        else:
            k_dop853_step_9(fun, ctx, t, &S[y], &S[f], h, rtol, atol, &S[out])
    else:
        if n == 11:
            k_dopri5_step_11(fun, ctx, t, &S[y], &S[f], h, rtol, atol, &S[out])
        elif n == 15:
            k_dopri5_step_15(fun, ctx, t, &S[y], &S[f], h, rtol, atol, &S[out])
        else:
            k_dopri5_step_9(fun, ctx, t, &S[y], &S[f], h, rtol, atol, &S[out])


cdef inline void k_dense(double *S, rhs_t fun, void *ctx, double t_old, double h, Py_ssize_t y_old, Py_ssize_t y,
                         Py_ssize_t k, Py_ssize_t dense) noexcept nogil:
    # S[dense:] = the dense output's rows of the step from the stages at S[k:], S[N_Y] apart (dop853: 8 an entry,
    # dopri5: 5)
    cdef Py_ssize_t n = <Py_ssize_t>S[LS_N_Y]
    if S[LS_METHOD] == 0.0:
        if n == 11:
            k_dop853_dense_11(fun, ctx, t_old, h, &S[y_old], &S[y], &S[k], &S[k + 5 * n], &S[k + 6 * n],
                              &S[k + 7 * n], &S[k + 8 * n], &S[k + 9 * n], &S[k + 10 * n], &S[k + 11 * n],
                              &S[k + 12 * n], &S[dense])
        elif n == 15:
            k_dop853_dense_15(fun, ctx, t_old, h, &S[y_old], &S[y], &S[k], &S[k + 5 * n], &S[k + 6 * n],
                              &S[k + 7 * n], &S[k + 8 * n], &S[k + 9 * n], &S[k + 10 * n], &S[k + 11 * n],
                              &S[k + 12 * n], &S[dense])
        else:
            k_dop853_dense_9(fun, ctx, t_old, h, &S[y_old], &S[y], &S[k], &S[k + 5 * n], &S[k + 6 * n],
                              &S[k + 7 * n], &S[k + 8 * n], &S[k + 9 * n], &S[k + 10 * n], &S[k + 11 * n],
                              &S[k + 12 * n], &S[dense])
    else:
        if n == 11:
            k_dopri5_dense_11(&S[y_old], &S[k], &S[k + n], &S[k + 2 * n], &S[k + 3 * n], &S[k + 4 * n],
                              &S[k + 5 * n], &S[k + 6 * n], &S[dense])
        elif n == 15:
            k_dopri5_dense_15(&S[y_old], &S[k], &S[k + n], &S[k + 2 * n], &S[k + 3 * n], &S[k + 4 * n],
                              &S[k + 5 * n], &S[k + 6 * n], &S[dense])
        else:
            k_dopri5_dense_9(&S[y_old], &S[k], &S[k + n], &S[k + 2 * n], &S[k + 3 * n], &S[k + 4 * n],
                              &S[k + 5 * n], &S[k + 6 * n], &S[dense])


cdef inline void k_foot_positions(double *S, Py_ssize_t q, Py_ssize_t p) noexcept nogil:
    if S[LS_MODEL_KERNELS] != 0.0:
        loop_table(S).foot_positions(&S[q], &S[p])
        return
    c_foot_positions(&S[q], &S[LS_K_POS], &S[p])


cdef inline void k_impact_map(double *S, int leg, Py_ssize_t q, Py_ssize_t dqm, Py_ssize_t out) noexcept nogil:
    # S[out:out + 5] = dq+ and S[out + NQ_MAX:] the impulse (2) of foot leg's impact (the kernel writes them in
    # one row of 7)
    cdef double r[7]
    if S[LS_MODEL_KERNELS] != 0.0:
        if loop_table(S).impact(&S[q], &S[dqm], leg - 1, &S[out], &S[out + LS_NQ_MAX]) != 0:
            S[out] = NAN     # (no impact: the contact's Jacobian lost rank; a non-finite state stops the run)
        return
    if leg == 2:
        c_impact_map_2(&S[q], &S[dqm], &S[LS_K_IMPACT], r)
    else:
        c_impact_map_1(&S[q], &S[dqm], &S[LS_K_IMPACT], r)
    memcpy(&S[out], r, 5 * sizeof(double))
    S[out + LS_NQ_MAX] = r[5]
    S[out + LS_NQ_MAX + 1] = r[6]


cdef inline void k_energy(double *S, Py_ssize_t q, Py_ssize_t dq, Py_ssize_t out) noexcept nogil:
    if S[LS_MODEL_KERNELS] != 0.0:
        loop_table(S).energy(&S[q], &S[dq], &S[out])
        return
    c_energy(&S[q], &S[dq], &S[LS_K_ENERGY], &S[out])


cdef inline void k_foot_kinematics(double *S, Py_ssize_t q, Py_ssize_t dq, Py_ssize_t out) noexcept nogil:
    if S[LS_MODEL_KERNELS] != 0.0:
        loop_table(S).foot_kinematics(&S[q], &S[dq], &S[out])
        return
    c_foot_kinematics(&S[q], &S[dq], &S[LS_K_FEET], &S[out])


cdef inline void k_copy(double *S, Py_ssize_t dst, Py_ssize_t src, Py_ssize_t n) noexcept nogil:
    memcpy(&S[dst], &S[src], n * sizeof(double))


cdef inline double k_ulp(double x) noexcept nogil:
    # math.ulp
    x = fabs(x)
    if isinf(x):
        return x
    cdef double x2 = nextafter(x, INFINITY)
    if isinf(x2):
        return x - nextafter(x, -INFINITY)
    return x2 - x
