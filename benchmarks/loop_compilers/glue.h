/* The C glue of the loop-compiler probe (benchmarks/loop_compilers): the generated kernels of
 * biped_sim/engine/_gen/_kernels.h behind four flat entry points that take the probe's parameter block
 * P (see kernels.py for its layout), so that the rules in rules.py reach the same formulas from Cython
 * (kernels.pxd), from numba (a shared library called through ctypes) and, as their Python twins, from
 * the interpreter. Only wiring here: every operation is a generated kernel's. */
#ifndef LOOP_COMPILERS_GLUE_H
#define LOOP_COMPILERS_GLUE_H
#include <math.h>
#include "_gen/_kernels.h"

#define G_N 11
#define G_LEG 0
#define G_U 1
#define G_K_STANCE 3
#define G_K_POS 25

/* the floating-base stance right-hand side under a held torque (_core.c rhs with controller HELD) */
static int
g_rhs_ctx(void *ctx, double t, const double *y, double *dy)
{
    const double *P = ctx;
    double out[7];
    (void)t;
    if (P[G_LEG] == 1.0) k_stance_floating_1(y, y + 5, P + G_U, P + G_K_STANCE, out);
    else k_stance_floating_2(y, y + 5, P + G_U, P + G_K_STANCE, out);
    for (int i = 0; i < 5; i++) dy[i] = y[5 + i];
    for (int i = 0; i < 5; i++) dy[5 + i] = out[i];
    dy[10] = P[G_U] * y[7] + P[G_U + 1] * y[8];
    return 0;
}

static inline void
g_rhs(const double *P, double t, const double *y, double *dy)
{
    g_rhs_ctx((void *)P, t, y, dy);
}

/* one unrolled dop853 step: out = y_new (N), f_new (N), err, stages k0..k12 (13 N) */
static inline void
g_dop853_step(const double *P, double t, const double *y, const double *f, double h, double rtol, double atol,
              double *out)
{
    k_dop853_step_11(g_rhs_ctx, (void *)P, t, y, f, h, rtol, atol, out);
}

/* dop853's dense output rows (N x 8) of the step (t_old, t_old + h) from its stages k0..k12 (13 N) */
static inline void
g_dop853_dense(const double *P, double t_old, double h, const double *y_old, const double *y, const double *k,
               double *dense)
{
    k_dop853_dense_11(g_rhs_ctx, (void *)P, t_old, h, y_old, y, k, k + 5 * G_N, k + 6 * G_N, k + 7 * G_N,
                      k + 8 * G_N, k + 9 * G_N, k + 10 * G_N, k + 11 * G_N, k + 12 * G_N, dense);
}

/* the feet's positions (p_1, p_2) at q (5) */
static inline void
g_foot_positions(const double *P, const double *q, double *p)
{
    k_foot_positions(q, P + G_K_POS, p);
}

/* math.ulp */
static inline double
g_ulp(double x)
{
    x = fabs(x);
    if (isinf(x)) return x;
    double x2 = nextafter(x, INFINITY);
    if (isinf(x2)) return x - nextafter(x, -INFINITY);
    return x2 - x;
}
#endif
