/* The two walking laws of biped_sim/control/walking.py as compiled torque laws: C functions of the
 * engine's torque-law hook (biped_sim/engine/torque_hook.py),
 *
 *     int law(double t, const double *q, const double *dq, int stance_leg, const double *params, double *u)
 *
 * whose addresses this module exports (WALKING_LAW, PD_WALKING_LAW). Their parameters are
 * WalkingController._law_parameters() (torso_pitch, a2 = step_angle ** 2, ddb = -2 / a2, clearance, lag,
 * kp, kd, torque_limit), and for WalkingController its model's 9 parameters p and the constants of its
 * closed form stance_terms_1 after them. Each line follows the Python line named beside it operation for
 * operation, on the engine's generated kernels and built with -ffp-contract=off, so that a law here gives the
 * controller's own torques bit for bit (test/unit/test_compiled_loop.py).
 *
 * Their derivatives, the hook's optional law_jacobian (torque_hook.JACOBIAN_SIGNATURE: u and u_x = du/d(q, dq),
 * 2 x 10 row-major), are exported as WALKING_JACOBIAN and PD_WALKING_JACOBIAN: the twins of
 * WalkingController.jacobian_batch and of _pd_jacobian (walking.py), on the stance KKT system's derivative of
 * biped_sim/engine/_stance_derivative.h (the engine's variational steps use the same header). They agree with
 * the Python derivatives to rounding (another operation order), not bit for bit.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#include "../engine/_stance_derivative.h"

enum { TORSO_PITCH, A2, DDB, CLEARANCE, LAG, KP, KD, TORQUE_LIMIT, N_LAW_PARAMETERS };

static void
swing_target(const double *c, double phi_s, double *f, double *df, double *ddf)
{   /* WalkingController.swing_target */
    double a2 = c[A2], ddb = c[DDB], cl = c[CLEARANCE], l = c[LAG];
    double b = 1.0 - phi_s * phi_s / a2;
    double db = -2.0 * phi_s / a2;
    *f = -phi_s * (1.0 + cl * b) + l * b;
    *df = -(1.0 + cl * b) - phi_s * cl * db + l * db;
    *ddf = -2.0 * cl * db - phi_s * cl * ddb + l * ddb;
}

static double
clip(double v, double lim)
{   /* min(lim, max(-lim, v)), as Python's min and max compare (a NaN becomes -lim) */
    v = v > -lim ? v : -lim;
    return v < lim ? v : lim;
}

/* flight: the hips damped (WalkingController.__call__ with stance_leg 0) */
static int
flight(const double *dq, const double *c, double *u)
{
    u[0] = -c[KD] * dq[2];
    u[1] = -c[KD] * dq[3];
    return 0;
}

static int
pd_walking(double t, const double *q, const double *dq, int leg, const double *c, double *u)
{   /* PDWalkingController.__call__ */
    (void)t;
    if (leg == 0) return flight(dq, c, u);
    int s = leg == 1 ? 2 : 3, w = leg == 1 ? 3 : 2;
    double q3 = q[4], dq3 = dq[4], f, df, ddf;
    swing_target(c, q[s] + q3 - M_PI, &f, &df, &ddf);
    double y2 = q[w] + q3 - M_PI - f;
    double dy2 = dq[w] + dq3 - df * (dq[s] + dq3);
    double kp = c[KP], kd = c[KD], lim = c[TORQUE_LIMIT];
    double u_swing = -kp * y2 - kd * dy2;
    u_swing = u_swing > -lim ? u_swing : -lim;
    u_swing = u_swing < lim ? u_swing : lim;
    double u_stance = 2.0 * (kp * (q3 - c[TORSO_PITCH]) + kd * dq3) - u_swing;
    u_stance = u_stance > -lim ? u_stance : -lim;
    u_stance = u_stance < lim ? u_stance : lim;
    u[0] = leg == 1 ? u_stance : u_swing;
    u[1] = leg == 1 ? u_swing : u_stance;
    return 0;
}

static void
joint_affine(const double *k_terms, const double *q, const double *dq, int leg, double *a, double Bu[3][2])
{   /* dynamics.stance_joint_affine_fast (leg 2 through the relabeling R, as there) */
    if (leg == 2) {
        double qs[5] = {q[0], q[1], q[3], q[2], q[4]}, dqs[5] = {dq[0], dq[1], dq[3], dq[2], dq[4]};
        double a1[3], B1[3][2];
        joint_affine(k_terms, qs, dqs, 1, a1, B1);
        a[0] = a1[1]; a[1] = a1[0]; a[2] = a1[2];
        Bu[0][0] = B1[1][1]; Bu[0][1] = B1[1][0];
        Bu[1][0] = B1[0][1]; Bu[1][1] = B1[0][0];
        Bu[2][0] = B1[2][1]; Bu[2][1] = B1[2][0];
        return;
    }
    double out[26];
    const double zero[2] = {0.0, 0.0};
    k_stance_terms_1(q, dq, zero, k_terms, out);
    double M00 = out[0], M01 = out[1], M02 = out[2], M11 = out[3], M12 = out[4], M22 = out[5];
    double b0 = out[6], b1 = out[7], b2 = out[8];
    /* _inverse_sym3 */
    double A11 = M11 * M22 - M12 * M12, A12 = M02 * M12 - M01 * M22, A13 = M01 * M12 - M02 * M11;
    double inv_det = 1.0 / (M00 * A11 + M01 * A12 + M02 * A13);
    double i00 = A11 * inv_det, i01 = A12 * inv_det, i02 = A13 * inv_det;
    double i11 = (M00 * M22 - M02 * M02) * inv_det, i12 = (M01 * M02 - M00 * M12) * inv_det;
    double i22 = (M00 * M11 - M01 * M01) * inv_det;
    a[0] = i00 * b0 + i01 * b1 + i02 * b2;
    a[1] = i01 * b0 + i11 * b1 + i12 * b2;
    a[2] = i02 * b0 + i12 * b1 + i22 * b2;
    Bu[0][0] = i00; Bu[0][1] = i01;
    Bu[1][0] = i01; Bu[1][1] = i11;
    Bu[2][0] = i02; Bu[2][1] = i12;
}

static int
walking(double t, const double *q, const double *dq, int leg, const double *c, double *u)
{   /* WalkingController.__call__: outputs(), then the computed torque on the model's stance_terms_1 */
    (void)t;
    if (leg == 0) return flight(dq, c, u);
    int s = leg == 1 ? 2 : 3, w = leg == 1 ? 3 : 2;
    double phi_s = q[s] + q[4] - M_PI, dphi_s = dq[s] + dq[4], f, df, ddf;
    swing_target(c, phi_s, &f, &df, &ddf);
    double y0 = q[4] - c[TORSO_PITCH], y1 = q[w] + q[4] - M_PI - f;
    double H2[3] = {0.0, 0.0, 1.0 - df};
    H2[s - 2] = -df;
    H2[w - 2] = 1.0;
    double dy0 = dq[4], dy1 = H2[0] * dq[2] + H2[1] * dq[3] + H2[2] * dq[4];
    double bias1 = -ddf * dphi_s * dphi_s;
    double a[3], Bu[3][2];
    joint_affine(c + N_LAW_PARAMETERS + SD_N_PARAMETERS, q, dq, leg, a, Bu);
    double kp = c[KP], kd = c[KD], lim = c[TORQUE_LIMIT];
    double r0 = -kp * y0 - kd * dy0 - a[2] - 0.0;
    double r1 = -kp * y1 - kd * dy1 - (H2[0] * a[0] + H2[1] * a[1] + H2[2] * a[2]) - bias1;
    double m00 = Bu[2][0], m01 = Bu[2][1];
    double m10 = H2[0] * Bu[0][0] + H2[1] * Bu[1][0] + H2[2] * Bu[2][0];
    double m11 = H2[0] * Bu[0][1] + H2[1] * Bu[1][1] + H2[2] * Bu[2][1];
    double det = m00 * m11 - m01 * m10;
    u[0] = clip((m11 * r0 - m01 * r1) / det, lim);
    u[1] = clip((m00 * r1 - m10 * r0) / det, lim);
    return 0;
}

/* flight: u = -kd (dq1, dq2), u_x = -kd on dq1, dq2 (WalkingController.jacobian with stance_leg 0) */
static int
flight_jacobian(const double *dq, const double *c, double *u, double *u_x)
{
    for (int k = 0; k < 2 * SD_NX; k++) u_x[k] = 0.0;
    u_x[7] = u_x[SD_NX + 8] = -c[KD];
    return flight(dq, c, u);
}

static int
walking_stance_jacobian(const void *system, double t, const double *q, const double *dq, int leg, const double *c,
                        double *u, double *u_x)
{   /* WalkingController.jacobian_batch at one point: u* solves Phi(x, u) = H ddq_r(x, u) + bias + kp y + kd dy = 0
     * on the stance KKT system (ddq_r = s0_r + s_u,r u), so u*_x = -(H B_u)^-1 Phi_x with ds/dx at u*; a torque
     * at its limit has derivative 0. `system`: that system at (q, dq) on `leg`, factored (stance_system, on the
     * model parameters of c + N_LAW_PARAMETERS: the law's own, or a plant's of the same parameters) */
    (void)t;
    if (leg == 0) return flight_jacobian(dq, c, u, u_x);
    const StanceSystem *S = system;
    int s = leg == 1 ? 2 : 3, w = leg == 1 ? 3 : 2;
    double phi = q[s] + q[4] - M_PI, dphi = dq[s] + dq[4], f, df, ddf;
    swing_target(c, phi, &f, &df, &ddf);
    double H[2][3] = {{0.0, 0.0, 1.0}, {0.0, 0.0, 1.0 - df}};
    H[1][s - 2] = -df;
    H[1][w - 2] = 1.0;
    double y[2] = {q[4] - c[TORSO_PITCH], q[w] + q[4] - M_PI - f};
    double dy[2] = {dq[4], H[1][0] * dq[2] + H[1][1] * dq[3] + H[1][2] * dq[4]};
    double bias[2] = {0.0, -ddf * dphi * dphi};
    double kp = c[KP], kd = c[KD], lim = c[TORQUE_LIMIT];
    double HB[2][2], rhs[2];
    for (int i = 0; i < 2; i++) {
        for (int m = 0; m < 2; m++) HB[i][m] = H[i][0] * S->su[2][m] + H[i][1] * S->su[3][m] + H[i][2] * S->su[4][m];
        rhs[i] = -kp * y[i] - kd * dy[i] - (H[i][0] * S->s0[2] + H[i][1] * S->s0[3] + H[i][2] * S->s0[4]) - bias[i];
    }
    double det = HB[0][0] * HB[1][1] - HB[0][1] * HB[1][0];
    double inv[2][2] = {{HB[1][1] / det, -HB[0][1] / det}, {-HB[1][0] / det, HB[0][0] / det}};
    double u_star[2] = {inv[0][0] * rhs[0] + inv[0][1] * rhs[1], inv[1][0] * rhs[0] + inv[1][1] * rhs[1]};
    double acc[SD_NK], C[SD_NK][SD_NX];
    for (int i = 0; i < SD_NK; i++) acc[i] = S->s0[i] + (S->su[i][0] * u_star[0] + S->su[i][1] * u_star[1]);
    stance_derivative_rhs(S, acc, C);
    double d3f = 6.0 * c[CLEARANCE] / c[A2];   /* the third derivative of the swing target */
    double Phi_x[2][SD_NX];
    for (int i = 0; i < 2; i++) {   /* H ds_r/dx = (K^-T g)^T C with g = H on the joint rows (2 solves, not 10) */
        double g[SD_NK] = {0.0, 0.0, H[i][0], H[i][1], H[i][2], 0.0, 0.0}, wt[SD_NK];
        stance_solve_transposed(S, g, wt);
        for (int k2 = 0; k2 < SD_NX; k2++) {
            double v = 0.0;
            for (int r = 0; r < SD_NK; r++) v += wt[r] * C[r][k2];
            Phi_x[i][k2] = v;
        }
    }
    /* row 2: H2 depends on phi through f', the bias -f'' dphi^2 on phi and dphi; kp y + kd dy (y2 through f) */
    double by_phi = -ddf * (acc[s] + acc[4]) - d3f * dphi * dphi - kp * df - kd * ddf * dphi;
    double by_rate = -2.0 * ddf * dphi - kd * df;
    Phi_x[1][s] += by_phi;
    Phi_x[1][4] += by_phi;
    Phi_x[1][SD_N + s] += by_rate;
    Phi_x[1][9] += by_rate;
    Phi_x[0][4] += kp;
    Phi_x[0][9] += kd;
    Phi_x[1][w] += kp;
    Phi_x[1][4] += kp;
    Phi_x[1][SD_N + w] += kd;
    Phi_x[1][9] += kd;
    for (int i = 0; i < 2; i++) {
        int at_limit = fabs(u_star[i]) >= lim;
        for (int k2 = 0; k2 < SD_NX; k2++)
            u_x[i * SD_NX + k2] = at_limit ? 0.0 : -(inv[i][0] * Phi_x[0][k2] + inv[i][1] * Phi_x[1][k2]);
        u[i] = clip(u_star[i], lim);
    }
    return 0;
}

static int
walking_jacobian(double t, const double *q, const double *dq, int leg, const double *c, double *u, double *u_x)
{   /* walking_stance_jacobian on the law's own stance KKT system */
    if (leg == 0) return flight_jacobian(dq, c, u, u_x);
    StanceConstants k;
    stance_constants(c + N_LAW_PARAMETERS, &k);
    StanceSystem S;
    if (stance_system(&k, q, dq, leg, &S) < 0) return 1;
    return walking_stance_jacobian(&S, t, q, dq, leg, c, u, u_x);
}

static int
pd_walking_jacobian(double t, const double *q, const double *dq, int leg, const double *c, double *u, double *u_x)
{   /* _pd_jacobian (walking.py): u_sw = -kp y2 - kd dy2, u_st = 2 (kp (q3 - pitch) + kd dq3) - u_sw; a torque at
     * its limit has derivative 0 */
    if (leg == 0) return flight_jacobian(dq, c, u, u_x);
    int s = leg == 1 ? 2 : 3, w = leg == 1 ? 3 : 2;
    double phi = q[s] + q[4] - M_PI, dphi = dq[s] + dq[4], f, df, ddf;
    swing_target(c, phi, &f, &df, &ddf);
    double kp = c[KP], kd = c[KD], lim = c[TORQUE_LIMIT];
    double y2_x[SD_NX] = {0.0}, dy2_x[SD_NX] = {0.0};     /* y2 = q_w + q3 - pi - f(phi), dy2 = dq_w + dq3 - f' dphi */
    y2_x[w] = 1.0;
    y2_x[4] = 1.0 - df;
    y2_x[s] = -df;
    dy2_x[s] = dy2_x[4] = -ddf * dphi;
    dy2_x[SD_N + w] = 1.0;
    dy2_x[9] = 1.0 - df;
    dy2_x[SD_N + s] = -df;
    pd_walking(t, q, dq, leg, c, u);
    double u_stance = leg == 1 ? u[0] : u[1], u_swing = leg == 1 ? u[1] : u[0];
    double *stance_x = u_x + (leg == 1 ? 0 : SD_NX), *swing_x = u_x + (leg == 1 ? SD_NX : 0);
    for (int k2 = 0; k2 < SD_NX; k2++) {
        swing_x[k2] = fabs(u_swing) >= lim ? 0.0 : -kp * y2_x[k2] - kd * dy2_x[k2];
        stance_x[k2] = -swing_x[k2];
    }
    stance_x[4] += 2.0 * kp;
    stance_x[9] += 2.0 * kd;
    if (fabs(u_stance) >= lim)
        for (int k2 = 0; k2 < SD_NX; k2++) stance_x[k2] = 0.0;
    return 0;
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_laws",
    "The walking laws as compiled torque laws (biped_sim/control/_laws.c; see biped_sim/control/walking.py).",
    -1, NULL, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC
PyInit__laws(void)
{
    PyObject *m = PyModule_Create(&module);
    if (m == NULL) return NULL;
    if (PyModule_AddObject(m, "WALKING_LAW", PyLong_FromVoidPtr((void *)walking)) < 0
        || PyModule_AddObject(m, "PD_WALKING_LAW", PyLong_FromVoidPtr((void *)pd_walking)) < 0
        || PyModule_AddObject(m, "WALKING_JACOBIAN", PyLong_FromVoidPtr((void *)walking_jacobian)) < 0
        || PyModule_AddObject(m, "WALKING_STANCE_JACOBIAN", PyLong_FromVoidPtr((void *)walking_stance_jacobian)) < 0
        || PyModule_AddObject(m, "PD_WALKING_JACOBIAN", PyLong_FromVoidPtr((void *)pd_walking_jacobian)) < 0
        || PyModule_AddIntConstant(m, "N_MODEL_PARAMETERS", SD_N_PARAMETERS) < 0
        || PyModule_AddStringConstant(m, "DERIVATIVES_SHA256", BIPED_SIM_DERIVATIVES_SHA256) < 0
        || PyModule_AddIntConstant(m, "N_LAW_PARAMETERS", N_LAW_PARAMETERS) < 0
        || PyModule_AddStringConstant(m, "KERNELS_SHA256", BIPED_SIM_KERNELS_SHA256) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
