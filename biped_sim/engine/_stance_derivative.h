/* The stance KKT system of the three-link biped and its derivative at one point: the C twin of
 * biped_sim/engine/variational.py's stance_stack and flows, on the generated closed forms (_gen/_kernels.h)
 * and their derivatives (_gen/_derivatives.h). Static inline, for the variational steps
 * (biped_sim/engine/_variational.c) and the derivatives of compiled torque laws (biped_sim/control/_laws.c):
 * one source.
 *
 * Stance on foot `leg` (1, 2) at (q, dq), n = 5 coordinates, the foot's 2 constraint forces F:
 *
 *     K s = r0 + r_u u,   K = [D  -J_c^T; J_c  0],   s = (ddq, F),   r0 = (-h, -Jdot_c dq),   r_u = (B, 0)
 *
 * so s = s0 + s_u u. At a solution s of the same K, the derivative columns (MODEL.md's symbols, x = (q, dq)):
 *
 *     K ds/dq_k = dr/dq_k - (dK/dq_k) s,     K ds/ddq_k = dr/ddq_k
 *
 * and the flow x' = f(x) = (dq, ddq) has A = df/dx = [[0, I], [ds/dq, ds/ddq] + s_u u_x] (the lower rows: the
 * first n rows of s) and f_u = (0, s_u). K is factored once (LU, partial pivoting) and reused for every
 * column, and by a compiled law's derivative on the same system (stance_flow_on after the law's stance_jacobian,
 * biped_sim/engine/torque_hook.py STANCE_JACOBIAN_SIGNATURE). Built with -ffp-contract=off as the other extensions; the operation order is not numpy's, so the
 * results agree with the numpy path to rounding, not bit for bit.
 */
#ifndef BIPED_SIM_STANCE_DERIVATIVE_H
#define BIPED_SIM_STANCE_DERIVATIVE_H

#include <math.h>

#include "_gen/_kernels.h"
#include "_gen/_derivatives.h"

enum { SD_N = 5, SD_NK = 7, SD_NX = 10, SD_M = 2, SD_N_PARAMETERS = 9, SD_MAX_CONSTANTS = 32 };

/* the model's constants of the closed forms used here (each f's f_constants(p)), from its 9 parameters p */
typedef struct {
    double mass_matrix[SD_MAX_CONSTANTS], bias_forces[SD_MAX_CONSTANTS], foot_jacobian[2][SD_MAX_CONSTANTS];
    double mass_matrix_jacobian[SD_MAX_CONSTANTS], bias_forces_jacobian[SD_MAX_CONSTANTS];
    double foot_jacobian_jacobian[2][SD_MAX_CONSTANTS], foot_bias_jacobian[2][SD_MAX_CONSTANTS];
} StanceConstants;

static inline void
stance_constants(const double *p, StanceConstants *c)
{
    k_mass_matrix_constants(p, c->mass_matrix);
    k_bias_forces_constants(p, c->bias_forces);
    k_foot_jacobian_1_constants(p, c->foot_jacobian[0]);
    k_foot_jacobian_2_constants(p, c->foot_jacobian[1]);
    k_mass_matrix_jacobian_constants(p, c->mass_matrix_jacobian);
    k_bias_forces_jacobian_constants(p, c->bias_forces_jacobian);
    k_foot_jacobian_jacobian_1_constants(p, c->foot_jacobian_jacobian[0]);
    k_foot_jacobian_jacobian_2_constants(p, c->foot_jacobian_jacobian[1]);
    k_foot_bias_jacobian_1_constants(p, c->foot_bias_jacobian[0]);
    k_foot_bias_jacobian_2_constants(p, c->foot_bias_jacobian[1]);
}

/* the KKT system at one point: K's LU factors, s0, s_u, and the terms of its derivative */
typedef struct {
    double LU[SD_NK][SD_NK];    /* P K = L U: L below the diagonal (unit diagonal), U on and above */
    int piv[SD_NK];             /* row i of P K is row piv[i] of K */
    double inv_diag[SD_NK];     /* 1 / U_ii (a multiplication in the substitutions rather than a division) */
    double s0[SD_NK], su[SD_NK][SD_M];
    double dD[SD_N * SD_N * SD_N];      /* dD_ij/dq_k at [k][i][j] */
    double dh[2 * SD_N * SD_N];         /* dh_i/dq_k at [i][k], then dh_i/ddq_k at 25 + [i][k] */
    double dJ[SD_N * 2 * SD_N];         /* d(J_c)_aj/dq_k at [k][a][j] */
    double jb[2 + 4 * SD_N];            /* Jdot_c dq (2), d(Jdot_c dq)_a/dq_k at 2 + [a][k], /ddq_k at 12 + [a][k] */
} StanceSystem;

/* K X = B solved in place by the factors for `ncols` right-hand sides at once (B: SD_NK rows of `ncols` values,
 * row-major; ncols <= SD_NX): the columns innermost, so that their substitutions run side by side rather than
 * one dependent chain after another */
static inline void
stance_solve(const StanceSystem *S, double *B, int ncols)
{
    double y[SD_NK][SD_NX];
    for (int i = 0; i < SD_NK; i++) {
        const double *row = B + S->piv[i] * ncols;
        for (int c = 0; c < ncols; c++) y[i][c] = row[c];
        for (int j = 0; j < i; j++) {
            const double l = S->LU[i][j];
            for (int c = 0; c < ncols; c++) y[i][c] -= l * y[j][c];
        }
    }
    for (int i = SD_NK - 1; i >= 0; i--) {
        for (int j = i + 1; j < SD_NK; j++) {
            const double u = S->LU[i][j];
            for (int c = 0; c < ncols; c++) y[i][c] -= u * y[j][c];
        }
        const double d = S->inv_diag[i];
        for (int c = 0; c < ncols; c++) y[i][c] *= d;
    }
    for (int i = 0; i < SD_NK; i++)
        for (int c = 0; c < ncols; c++) B[i * ncols + c] = y[i][c];
}

/* K, its factors, s0 and s_u at (q, dq) on foot `leg`, and the derivative terms; -1 where K is singular */
static inline int
stance_system(const StanceConstants *c, const double *q, const double *dq, int leg, StanceSystem *S)
{
    double D[SD_N * SD_N], h[SD_N], J[2 * SD_N];
    const int f = leg == 1 ? 0 : 1;
    k_mass_matrix(q, c->mass_matrix, D);
    k_bias_forces(q, dq, c->bias_forces, h);
    k_mass_matrix_jacobian(q, c->mass_matrix_jacobian, S->dD);
    k_bias_forces_jacobian(q, dq, c->bias_forces_jacobian, S->dh);
    if (f == 0) {
        k_foot_jacobian_1(q, c->foot_jacobian[0], J);
        k_foot_jacobian_jacobian_1(q, c->foot_jacobian_jacobian[0], S->dJ);
        k_foot_bias_jacobian_1(q, dq, c->foot_bias_jacobian[0], S->jb);
    } else {
        k_foot_jacobian_2(q, c->foot_jacobian[1], J);
        k_foot_jacobian_jacobian_2(q, c->foot_jacobian_jacobian[1], S->dJ);
        k_foot_bias_jacobian_2(q, dq, c->foot_bias_jacobian[1], S->jb);
    }
    double (*A)[SD_NK] = S->LU;
    for (int i = 0; i < SD_N; i++) {
        for (int j = 0; j < SD_N; j++) A[i][j] = D[i * SD_N + j];
        for (int a = 0; a < 2; a++) {
            A[i][SD_N + a] = -J[a * SD_N + i];
            A[SD_N + a][i] = J[a * SD_N + i];
        }
    }
    for (int a = 0; a < 2; a++)
        for (int b = 0; b < 2; b++) A[SD_N + a][SD_N + b] = 0.0;
    /* the right-hand sides r0, r_u (B = [0 0; 0 0; 1 0; 0 1; 0 0], zero on the constraint rows) */
    double r[SD_NK][1 + SD_M];
    for (int i = 0; i < SD_N; i++) {
        r[i][0] = -h[i];
        r[i][1] = i == 2 ? 1.0 : 0.0;
        r[i][2] = i == 3 ? 1.0 : 0.0;
    }
    for (int a = 0; a < 2; a++) {
        r[SD_N + a][0] = -S->jb[a];
        r[SD_N + a][1] = r[SD_N + a][2] = 0.0;
    }
    /* LU with partial pivoting (the first row of the largest magnitude, as LAPACK's getrf) */
    int perm[SD_NK];
    for (int i = 0; i < SD_NK; i++) perm[i] = i;
    for (int k = 0; k < SD_NK; k++) {
        int p = k;
        double best = fabs(A[k][k]);
        for (int i = k + 1; i < SD_NK; i++)
            if (fabs(A[i][k]) > best) { best = fabs(A[i][k]); p = i; }
        if (!(best > 0.0)) return -1;
        if (p != k) {
            for (int j = 0; j < SD_NK; j++) { double t = A[k][j]; A[k][j] = A[p][j]; A[p][j] = t; }
            int t = perm[k]; perm[k] = perm[p]; perm[p] = t;
        }
        double inv = 1.0 / A[k][k];
        S->inv_diag[k] = inv;
        for (int i = k + 1; i < SD_NK; i++) {
            double l = A[i][k] * inv;
            A[i][k] = l;
            for (int j = k + 1; j < SD_NK; j++) A[i][j] -= l * A[k][j];
        }
    }
    for (int i = 0; i < SD_NK; i++) S->piv[i] = perm[i];
    stance_solve(S, &r[0][0], 1 + SD_M);
    for (int i = 0; i < SD_NK; i++) {
        S->s0[i] = r[i][0];
        S->su[i][0] = r[i][1];
        S->su[i][1] = r[i][2];
    }
    return 0;
}

/* w = K^-T g (K^T = U^T L^T P): for a few combinations g^T ds/dx of the derivative's rows, one solve each
 * instead of one per column (g^T K^-1 C = (K^-T g)^T C) */
static inline void
stance_solve_transposed(const StanceSystem *S, const double *g, double *w)
{
    double z[SD_NK];
    for (int i = 0; i < SD_NK; i++) {       /* U^T z = g */
        double v = g[i];
        for (int j = 0; j < i; j++) v -= S->LU[j][i] * z[j];
        z[i] = v * S->inv_diag[i];
    }
    for (int i = SD_NK - 1; i >= 0; i--) {  /* L^T v = z, then w = P^T v */
        double v = z[i];
        for (int j = i + 1; j < SD_NK; j++) v -= S->LU[j][i] * z[j];
        z[i] = v;
    }
    for (int i = 0; i < SD_NK; i++) w[S->piv[i]] = z[i];
}

/* the right-hand sides of the derivative columns at a solution s of the system's K, C (SD_NK x 2 SD_N):
 * C[:, k] = dr/dq_k - (dK/dq_k) s, C[:, SD_N + k] = dr/ddq_k, so [ds/dq, ds/ddq] = K^-1 C */
static inline void
stance_derivative_rhs(const StanceSystem *S, const double *s, double col[SD_NK][2 * SD_N])
{
    for (int k = 0; k < SD_N; k++) {
        const double *dD = S->dD + k * SD_N * SD_N, *dJ = S->dJ + k * 2 * SD_N;
        for (int i = 0; i < SD_N; i++) {     /* -dh_i/dq_k - dD_i. ddq + dJ_.i^T F */
            double v = 0.0;
            for (int j = 0; j < SD_N; j++) v += dD[i * SD_N + j] * s[j];
            v -= dJ[i] * s[SD_N] + dJ[SD_N + i] * s[SD_N + 1];
            col[i][k] = -S->dh[i * SD_N + k] - v;
            col[i][SD_N + k] = -S->dh[SD_N * SD_N + i * SD_N + k];
        }
        for (int a = 0; a < 2; a++) {       /* -d(Jdot_c dq)_a/dq_k - dJ_a. ddq */
            double v = 0.0;
            for (int j = 0; j < SD_N; j++) v += dJ[a * SD_N + j] * s[j];
            col[SD_N + a][k] = -S->jb[2 + a * SD_N + k] - v;
            col[SD_N + a][SD_N + k] = -S->jb[2 + 2 * SD_N + a * SD_N + k];
        }
    }
}

/* ds/dq (dsq [i][k]) and ds/ddq (dsv [i][k]), all SD_NK rows (accelerations, then forces), at a solution s of
 * the system's K: the 10 columns solved with the one factorisation */
static inline void
stance_derivative(const StanceSystem *S, const double *s, double dsq[SD_NK][SD_N], double dsv[SD_NK][SD_N])
{
    double col[SD_NK][2 * SD_N];
    stance_derivative_rhs(S, s, col);
    stance_solve(S, &col[0][0], 2 * SD_N);
    for (int i = 0; i < SD_NK; i++)
        for (int k = 0; k < SD_N; k++) {
            dsq[i][k] = col[i][k];
            dsv[i][k] = col[i][SD_N + k];
        }
}

/* stance_flow on a system already factored at x (stance_system's), and stance_flow: the stance flow at x = (q, dq) under u with u_x (SD_M x SD_NX row-major; NULL: a held torque, u_x = 0):
 * f (SD_NX), the lower rows of A (A_low [SD_N][SD_NX]: [ds/dq, ds/ddq] + s_u u_x, the accelerations' rows) and
 * f_u's lower rows (fu [SD_N][SD_M] = s_u); -1 where K is singular */
static inline void
stance_flow_on(const StanceSystem *S, const double *x, const double *u, const double *u_x, double *f,
               double A_low[SD_N][SD_NX], double fu[SD_N][SD_M])
{
    double s[SD_NK], dsq[SD_NK][SD_N], dsv[SD_NK][SD_N];
    for (int i = 0; i < SD_NK; i++) s[i] = S->s0[i] + (S->su[i][0] * u[0] + S->su[i][1] * u[1]);
    stance_derivative(S, s, dsq, dsv);
    for (int i = 0; i < SD_N; i++) {
        f[i] = x[SD_N + i];
        f[SD_N + i] = s[i];
        for (int k = 0; k < SD_N; k++) {
            A_low[i][k] = dsq[i][k];
            A_low[i][SD_N + k] = dsv[i][k];
        }
        if (u_x != NULL)
            for (int k = 0; k < SD_NX; k++) A_low[i][k] += S->su[i][0] * u_x[k] + S->su[i][1] * u_x[SD_NX + k];
        fu[i][0] = S->su[i][0];
        fu[i][1] = S->su[i][1];
    }
}

static inline int
stance_flow(const StanceConstants *c, const double *x, int leg, const double *u, const double *u_x,
            double *f, double A_low[SD_N][SD_NX], double fu[SD_N][SD_M])
{
    StanceSystem S;
    if (stance_system(c, x, x + SD_N, leg, &S) < 0) return -1;
    stance_flow_on(&S, x, u, u_x, f, A_low, fu);
    return 0;
}

#endif
