/* glue.h as a shared library with external symbols, for numba (ctypes): see numba_binding.py. */
#include "glue.h"

void so_rhs(const double *P, double t, const double *y, double *dy) { g_rhs(P, t, y, dy); }
void so_dop853_step(const double *P, double t, const double *y, const double *f, double h, double rtol, double atol,
                    double *out) { g_dop853_step(P, t, y, f, h, rtol, atol, out); }
void so_dop853_dense(const double *P, double t_old, double h, const double *y_old, const double *y, const double *k,
                     double *dense) { g_dop853_dense(P, t_old, h, y_old, y, k, dense); }
void so_foot_positions(const double *P, const double *q, double *p) { g_foot_positions(P, q, p); }
double so_ulp(double x) { return g_ulp(x); }

/* a torque law as the loop's hook would take it (a compiled kernel on a parameter array): a PD on the two hip
 * angles, u = -kp q_i - kd dq_i, with p = (kp, kd) and the state y = (q, dq) */
void so_pd_law(const double *p, const double *y, double *u)
{
    u[0] = -p[0] * y[2] - p[1] * y[7];
    u[1] = -p[0] * y[3] - p[1] * y[8];
}
