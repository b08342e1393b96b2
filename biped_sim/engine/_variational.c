/* The variational terms of the three-link's DOP853 steps in stance, in C: the twin of
 * biped_sim/engine/variational.py's steps_transition (without parameters or gains) for the closed forms, under
 * a held torque or a compiled law that offers its derivative (biped_sim/engine/torque_hook.py
 * JACOBIAN_SIGNATURE). For each step of sizes h from x0 at t0, with the stages K_i = f(x_i),
 * x_i = x0 + h sum_j a_ij K_j, the step's end x1 = x0 + h sum_i b_i K_i and its derivative by x0
 *
 *     Phi = I + h sum_i b_i Psi_i,   Psi_i = A(x_i) (I + h sum_j a_ij Psi_j)
 *
 * (A = f_x + f_u u_x at the stage state, biped_sim/engine/_stance_derivative.h), and a state transition matrix S
 * carried through them (S <- Phi S). No allocation: the stages of one step live on the stack; the tableau comes
 * from the caller (scipy's DOP853 coefficients, as the numpy path's). And the touchdown's saltation matrix, the
 * twin of biped_sim/engine/sensitivity.py's _Integration._event for the same runs (touchdown below).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdio.h>

#include "_py_doubles.h"
#include "_stance_derivative.h"

enum { STAGES = 12, MAX_PARAMETERS = 128 };

typedef int (*LawJacobian)(double t, const double *q, const double *dq, int stance_leg, const double *params,
                           double *u, double *u_x);
/* the same on the stance KKT system already factored at (q, dq) (torque_hook.STANCE_JACOBIAN_SIGNATURE) */
typedef int (*LawStanceJacobian)(const void *system, double t, const double *q, const double *dq, int stance_leg,
                                 const double *params, double *u, double *u_x);

/* S <- Phi S in place (Phi 10 x 10, S 10 x m, row-major): the state transition matrix carried through a step */
static void
chain(const double *phi, double *S, Py_ssize_t m)
{
    double row[SD_NX];
    for (Py_ssize_t col = 0; col < m; col++) {
        for (int r = 0; r < SD_NX; r++) {
            double v = 0.0;
            for (int l = 0; l < SD_NX; l++) v += phi[r * SD_NX + l] * S[l * m + col];
            row[r] = v;
        }
        for (int r = 0; r < SD_NX; r++) S[r * m + col] = row[r];
    }
}

/* a law's derivative failed (its return code) at t: -1 with the exception set */
static int
law_failed(const char *name, int code, double t)
{
    char when[32];
    snprintf(when, sizeof when, "%.17g", t);
    PyErr_Format(PyExc_ValueError, "the torque law %s's derivative returned %d at t=%s s", name, code, when);
    return -1;
}

/* the stance KKT system singular at t: -1 with the exception set */
static int
singular_at(int leg, double t)
{
    char when[32];
    snprintf(when, sizeof when, "%.17g", t);
    PyErr_Format(PyExc_ValueError, "the stance KKT system on foot %d is singular at t=%s s", leg, when);
    return -1;
}

/* one stage's flow (f, the lower rows of A, f_u) under a law's derivative on the stance system the flow factors:
 * one factorisation for both */
static __attribute__((flatten)) int
stage_on_system(const StanceConstants *k, LawStanceJacobian on_system, double t, const double *x, int leg,
                const double *params, const char *name, double *f, double A[SD_N][SD_NX], double fu[SD_N][SD_M])
{
    StanceSystem kkt;
    double u[SD_M], u_x[SD_M * SD_NX];
    if (stance_system(k, x, x + SD_N, leg, &kkt) < 0) return singular_at(leg, t);
    int code = on_system(&kkt, t, x, x + SD_N, leg, params, u, u_x);
    if (code != 0) return law_failed(name, code, t);
    stance_flow_on(&kkt, x, u, u_x, f, A, fu);
    return 0;
}

/* the steps of one stack: X1 (N x 10) and Phi (N x 10 x 10); -1 with an exception set. (flatten: the stance
 * system inlined in the stages' loop whatever else calls it, 0.61 -> 0.54 us a held stage) */
static __attribute__((flatten)) int
steps(const StanceConstants *k, int leg, const double *a, const double *b, const double *c, Py_ssize_t N,
      const double *t0, const double *X0, const double *H, LawJacobian law, LawStanceJacobian on_system,
      const double *params, const char *name, const double *u_held, double *X1, double *Phi, double *S, Py_ssize_t m)
{
    double Kf[STAGES][SD_NX], Psi[STAGES][SD_NX][SD_NX];
    for (Py_ssize_t p = 0; p < N; p++) {
        const double *x0 = X0 + p * SD_NX;
        const double h = H[p];
        for (int i = 0; i < STAGES; i++) {
            double xi[SD_NX], sx[SD_NX] = {0.0}, Mi[SD_NX][SD_NX] = {{0.0}};
            for (int j = 0; j < i; j++) {
                const double aij = a[i * STAGES + j];
                if (aij == 0.0) continue;
                for (int r = 0; r < SD_NX; r++) {
                    sx[r] += aij * Kf[j][r];
                    for (int col = 0; col < SD_NX; col++) Mi[r][col] += aij * Psi[j][r][col];
                }
            }
            for (int r = 0; r < SD_NX; r++) {
                xi[r] = x0[r] + h * sx[r];
                for (int col = 0; col < SD_NX; col++) Mi[r][col] = (r == col ? 1.0 : 0.0) + h * Mi[r][col];
            }
            double u[SD_M], u_x[SD_M * SD_NX], A[SD_N][SD_NX], fu[SD_N][SD_M];
            const double ti = t0[p] + c[i] * h;
            if (on_system != NULL) {
                if (stage_on_system(k, on_system, ti, xi, leg, params, name, Kf[i], A, fu) < 0) return -1;
            } else {
                if (law != NULL) {
                    int code = law(ti, xi, xi + SD_N, leg, params, u, u_x);
                    if (code != 0) return law_failed(name, code, ti);
                } else {
                    u[0] = u_held[0];
                    u[1] = u_held[1];
                }
                if (stance_flow(k, xi, leg, u, law != NULL ? u_x : NULL, Kf[i], A, fu) < 0)
                    return singular_at(leg, ti);
            }
            /* Psi_i = A M_i: the upper rows of A are [0 I], so its upper rows are M_i's lower ones */
            for (int r = 0; r < SD_N; r++)
                for (int col = 0; col < SD_NX; col++) Psi[i][r][col] = Mi[SD_N + r][col];
            for (int r = 0; r < SD_N; r++) {
                double *out = Psi[i][SD_N + r];
                for (int col = 0; col < SD_NX; col++) out[col] = 0.0;
                for (int l = 0; l < SD_NX; l++) {
                    const double arl = A[r][l];
                    for (int col = 0; col < SD_NX; col++) out[col] += arl * Mi[l][col];
                }
            }
        }
        double *x1 = X1 + p * SD_NX, *phi = Phi + p * SD_NX * SD_NX;
        double sx[SD_NX] = {0.0}, sp[SD_NX][SD_NX] = {{0.0}};
        for (int i = 0; i < STAGES; i++) {
            if (b[i] == 0.0) continue;
            for (int r = 0; r < SD_NX; r++) {
                sx[r] += b[i] * Kf[i][r];
                for (int col = 0; col < SD_NX; col++) sp[r][col] += b[i] * Psi[i][r][col];
            }
        }
        for (int r = 0; r < SD_NX; r++) {
            x1[r] = x0[r] + h * sx[r];
            for (int col = 0; col < SD_NX; col++) phi[r * SD_NX + col] = (r == col ? 1.0 : 0.0) + h * sp[r][col];
        }
        if (S != NULL) chain(phi, S, m);
    }
    return 0;
}

/* the torque at (t, x) on stance `leg`: the compiled law's (its derivative's u) or the held one; -1 with an
 * exception set */
static int
torque_at(LawJacobian law, const double *params, const char *name, const double *u_held, double t, const double *x,
          int leg, double *u)
{
    double u_x[SD_M * SD_NX];
    if (law == NULL) {
        u[0] = u_held[0];
        u[1] = u_held[1];
        return 0;
    }
    int code = law(t, x, x + SD_N, leg, params, u, u_x);
    return code != 0 ? law_failed(name, code, t) : 0;
}

/* the stance flow's value f = (dq, ddq) at x under u on foot `leg` (stance_flow's f, without its derivative) */
static int
stance_rate(const StanceConstants *c, const double *x, int leg, const double *u, double *f)
{
    StanceSystem S;
    if (stance_system(c, x, x + SD_N, leg, &S) < 0) return -1;
    for (int i = 0; i < SD_N; i++) {
        f[i] = x[SD_N + i];
        f[SD_N + i] = S.s0[i] + (S.su[i][0] * u[0] + S.su[i][1] * u[1]);
    }
    return 0;
}

/* The rigid impact of foot `leg` at q, the rates dq- before it: K [dq+; L] = [D dq-; 0] with K = [D -J^T; J 0] of
 * that foot, and its derivative as the stance system's (sensitivity.Linearization.impact's twin):
 *
 *     K d[dq+; L]/dq_k = [dD/dq_k (dq- - dq+) + (dJ/dq_k)^T L; -dJ/dq_k dq+],   K d[dq+; L]/d dq- = [D; 0]
 *
 * dq+ into dqp, d dq+/dq into Rq [i][k], d dq+/d dq- into Rv [i][k]; -1 where K is singular */
static int
impact(const StanceConstants *c, const double *q, const double *dqm, int leg, double *dqp, double Rq[SD_N][SD_N],
       double Rv[SD_N][SD_N])
{
    StanceSystem S;
    if (stance_system(c, q, dqm, leg, &S) < 0) return -1;
    double D[SD_N * SD_N], r[SD_NK], col[SD_NK][2 * SD_N];
    k_mass_matrix(q, c->mass_matrix, D);
    for (int i = 0; i < SD_N; i++) {
        double v = 0.0;
        for (int j = 0; j < SD_N; j++) v += D[i * SD_N + j] * dqm[j];
        r[i] = v;
    }
    r[SD_N] = r[SD_N + 1] = 0.0;
    stance_solve(&S, r, 1);
    const double *L = r + SD_N;
    for (int k = 0; k < SD_N; k++) {
        const double *dD = S.dD + k * SD_N * SD_N, *dJ = S.dJ + k * 2 * SD_N;
        for (int i = 0; i < SD_N; i++) {
            double v = 0.0;
            for (int j = 0; j < SD_N; j++) v += dD[i * SD_N + j] * (dqm[j] - r[j]);
            col[i][k] = v + (dJ[i] * L[0] + dJ[SD_N + i] * L[1]);
            col[i][SD_N + k] = D[i * SD_N + k];
        }
        for (int a = 0; a < 2; a++) {
            double v = 0.0;
            for (int j = 0; j < SD_N; j++) v += dJ[a * SD_N + j] * r[j];
            col[SD_N + a][k] = -v;
            col[SD_N + a][SD_N + k] = 0.0;
        }
    }
    stance_solve(&S, &col[0][0], 2 * SD_N);
    for (int i = 0; i < SD_N; i++) {
        dqp[i] = r[i];
        for (int k = 0; k < SD_N; k++) {
            Rq[i][k] = col[i][k];
            Rv[i][k] = col[i][SD_N + k];
        }
    }
    return 0;
}

/* (DR y) of the touchdown's reset R(q, dq) = (q, dq+): y's configuration rows, then Rq y_q + Rv y_dq */
static void
reset_times(double Rq[SD_N][SD_N], double Rv[SD_N][SD_N], const double *y, double *out)
{
    for (int i = 0; i < SD_N; i++) {
        double v = 0.0;
        for (int k = 0; k < SD_N; k++) v += Rq[i][k] * y[k] + Rv[i][k] * y[SD_N + k];
        out[i] = y[i];
        out[SD_N + i] = v;
    }
}

/* The touchdown of foot `gleg` ending stance on `leg` at (t, x), S (10 x m) just before it: the saltation matrix
 * (sensitivity._Integration._event's twin for a held torque or a compiled law, without parameters or gains)
 *
 *     dtau = -(g_x S) / (g_x F-),   S+ = DR S - (F+ - DR F-) dtau,   or with `last`: S+ = DR (S + F- dtau)
 *
 * g = p_y + tan(slope) p_x the foot's height across the ground (loop_rules.ev_across), g_x = (J_y + tan J_x, 0),
 * F- the stance flow on `leg`, F+ on `gleg` after the reset. x+ into x_plus, S+ into S_plus, dtau (m) into dtau;
 * -1 with an exception set */
static int
touchdown(const StanceConstants *c, int leg, int gleg, double tan_s, double t, const double *x, const double *S,
          Py_ssize_t m, LawJacobian law, const double *params, const char *name, const double *u_held, int last,
          double *x_plus, double *S_plus, double *dtau)
{
    double u[SD_M], f_minus[SD_NX], J[2 * SD_N], gx[SD_N], dqp[SD_N], Rq[SD_N][SD_N], Rv[SD_N][SD_N];
    if (torque_at(law, params, name, u_held, t, x, leg, u) < 0) return -1;
    if (stance_rate(c, x, leg, u, f_minus) < 0) return singular_at(leg, t);
    if (gleg == 1) k_foot_jacobian_1(x, c->foot_jacobian[0], J);
    else k_foot_jacobian_2(x, c->foot_jacobian[1], J);
    for (int j = 0; j < SD_N; j++) gx[j] = J[SD_N + j] + tan_s * J[j];
    if (impact(c, x, x + SD_N, gleg, dqp, Rq, Rv) < 0) return singular_at(gleg, t);
    for (int i = 0; i < SD_N; i++) {
        x_plus[i] = x[i];
        x_plus[SD_N + i] = dqp[i];
    }
    double rate = 0.0;
    for (int j = 0; j < SD_N; j++) rate += gx[j] * f_minus[j];
    for (Py_ssize_t col = 0; col < m; col++) {
        double dg = 0.0;
        for (int j = 0; j < SD_N; j++) dg += gx[j] * S[j * m + col];
        dtau[col] = -dg / rate;
    }
    double w[SD_NX], y[SD_NX], out[SD_NX];
    if (!last) {    /* w = F+ - DR F- */
        double u_plus[SD_M], f_plus[SD_NX], Rf[SD_NX];
        if (torque_at(law, params, name, u_held, t, x_plus, gleg, u_plus) < 0) return -1;
        if (stance_rate(c, x_plus, gleg, u_plus, f_plus) < 0) return singular_at(gleg, t);
        reset_times(Rq, Rv, f_minus, Rf);
        for (int r = 0; r < SD_NX; r++) w[r] = f_plus[r] - Rf[r];
    }
    for (Py_ssize_t col = 0; col < m; col++) {
        for (int r = 0; r < SD_NX; r++) y[r] = S[r * m + col] + (last ? f_minus[r] * dtau[col] : 0.0);
        reset_times(Rq, Rv, y, out);
        for (int r = 0; r < SD_NX; r++) S_plus[r * m + col] = last ? out[r] : out[r] - w[r] * dtau[col];
    }
    return 0;
}

/* a law's derivative from (address of its law_jacobian, its parameters, its name[, address of its
 * law_stance_jacobian or 0]); on_system (NULL: not asked) gets the last, NULL where 0 or not given */
static int
law_from(PyObject *spec, LawJacobian *law, LawStanceJacobian *on_system, double *params, Py_ssize_t *n_params,
         const char **name)
{
    PyObject *address, *values, *label, *stance_address = NULL;
    if (!PyArg_ParseTuple(spec, "OOO|O:a law (address of its jacobian, parameters, name, address on the system)",
                          &address, &values, &label, &stance_address))
        return -1;
    if (on_system != NULL) {
        *on_system = NULL;
        if (stance_address != NULL) {
            void *fs = PyLong_AsVoidPtr(stance_address);
            if (fs == NULL && PyErr_Occurred()) return -1;
            *on_system = (LawStanceJacobian)fs;
        }
    }
    void *fn = PyLong_AsVoidPtr(address);
    if (fn == NULL) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "a law's jacobian address must not be 0");
        return -1;
    }
    if (doubles(values, params, 0, MAX_PARAMETERS, "a compiled law's parameters", n_params) < 0) return -1;
    *name = PyUnicode_AsUTF8(label);
    if (*name == NULL) return -1;
    *law = (LawJacobian)fn;
    return 0;
}

static int
check(const Py_buffer *buf, Py_ssize_t n, const char *what)
{
    if (buf->len != n * (Py_ssize_t)sizeof(double)) {
        PyErr_Format(PyExc_ValueError, "%s must hold %zd float64 values, got %zd bytes", what, n, buf->len);
        return -1;
    }
    return 0;
}

PyDoc_STRVAR(steps_transition_doc,
"steps_transition(leg, p, a, b, c, t0, X0, H, law, u_held, X1, Phi, S=None)\n\n"
"The DOP853 steps of sizes H (N) from the states X0 (N x 10) at times t0 (N) in stance on foot leg, of the\n"
"three-link of parameters p (9): their end states into X1 (N x 10) and their derivatives by their start into\n"
"Phi (N x 10 x 10). a (12 x 12), b, c (12): the tableau. law: None (the torque u_held, 2 values, held) or\n"
"(address of a law_jacobian, its parameters, its name). S (10 x m): carried through the steps in place,\n"
"S <- Phi S for each step in turn. Arrays: C-contiguous float64.");

static PyObject *
steps_transition(PyObject *self, PyObject *args)
{
    (void)self;
    int leg;
    PyObject *law_spec, *s_arg = Py_None;
    Py_buffer bp = {0}, ba = {0}, bb = {0}, bc = {0}, bt = {0}, bx = {0}, bh = {0}, bu = {0}, bx1 = {0}, bphi = {0};
    Py_buffer bs = {0};
    if (!PyArg_ParseTuple(args, "iy*y*y*y*y*y*y*Oy*w*w*|O:steps_transition", &leg, &bp, &ba, &bb, &bc, &bt, &bx, &bh,
                          &law_spec, &bu, &bx1, &bphi, &s_arg))
        return NULL;
    PyObject *result = NULL;
    Py_ssize_t N = bt.len / (Py_ssize_t)sizeof(double);
    double params[MAX_PARAMETERS];
    Py_ssize_t n_params = 0;
    LawJacobian law = NULL;
    const char *name = "";
    if (leg != 1 && leg != 2) {
        PyErr_Format(PyExc_ValueError, "steps_transition(): leg must be 1 or 2, got %d", leg);
        goto done;
    }
    if (check(&bp, SD_N_PARAMETERS, "p") || check(&ba, STAGES * STAGES, "a") || check(&bb, STAGES, "b")
        || check(&bc, STAGES, "c") || check(&bx, N * SD_NX, "X0") || check(&bh, N, "H") || check(&bu, SD_M, "u_held")
        || check(&bx1, N * SD_NX, "X1") || check(&bphi, N * SD_NX * SD_NX, "Phi"))
        goto done;
    Py_ssize_t m = 0;
    if (s_arg != Py_None) {
        if (PyObject_GetBuffer(s_arg, &bs, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) goto done;
        m = bs.len / (Py_ssize_t)(SD_NX * sizeof(double));
        if (check(&bs, SD_NX * m, "S")) goto done;
    }
    LawStanceJacobian on_system = NULL;
    if (law_spec != Py_None && law_from(law_spec, &law, &on_system, params, &n_params, &name) < 0) goto done;
    StanceConstants k;
    stance_constants((const double *)bp.buf, &k);
    if (steps(&k, leg, (const double *)ba.buf, (const double *)bb.buf, (const double *)bc.buf, N,
              (const double *)bt.buf, (const double *)bx.buf, (const double *)bh.buf, law, on_system, params, name,
              (const double *)bu.buf, (double *)bx1.buf, (double *)bphi.buf, bs.buf != NULL ? (double *)bs.buf : NULL, m) < 0)
        goto done;
    result = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&bp); PyBuffer_Release(&ba); PyBuffer_Release(&bb); PyBuffer_Release(&bc);
    PyBuffer_Release(&bt); PyBuffer_Release(&bx); PyBuffer_Release(&bh); PyBuffer_Release(&bu);
    PyBuffer_Release(&bx1); PyBuffer_Release(&bphi);
    if (bs.obj != NULL) PyBuffer_Release(&bs);
    return result;
}

PyDoc_STRVAR(touchdown_doc,
"touchdown(leg, gleg, p, tan_s, t, x, S, law, u_held, last, x_plus, S_plus, dtau)\n\n"
"The touchdown of foot gleg ending stance on foot leg at time t and state x (10) of the three-link of\n"
"parameters p (9) on the ground of slope tan_s (its tangent), S (10 x m) just before it: the state after the\n"
"impact into x_plus (10), S after the saltation matrix into S_plus (10 x m; with last, the state just after\n"
"the event: DR (S + F- dtau)) and the event time's derivative into dtau (m). law, u_held: as steps_transition's.\n"
"Arrays: C-contiguous float64.");

static PyObject *
touchdown_event(PyObject *self, PyObject *args)
{
    (void)self;
    int leg, gleg, last;
    double tan_s, t, params[MAX_PARAMETERS];
    PyObject *law_spec, *result = NULL;
    Py_buffer bp = {0}, bx = {0}, bs = {0}, bu = {0}, bxp = {0}, bsp = {0}, bd = {0};
    Py_ssize_t n_params = 0;
    LawJacobian law = NULL;
    const char *name = "";
    if (!PyArg_ParseTuple(args, "iiy*ddy*y*Oy*pw*w*w*:touchdown", &leg, &gleg, &bp, &tan_s, &t, &bx, &bs, &law_spec,
                          &bu, &last, &bxp, &bsp, &bd))
        return NULL;
    Py_ssize_t m = bd.len / (Py_ssize_t)sizeof(double);
    if ((leg != 1 && leg != 2) || (gleg != 1 && gleg != 2)) {
        PyErr_Format(PyExc_ValueError, "touchdown(): leg and gleg must be 1 or 2, got %d and %d", leg, gleg);
        goto done;
    }
    if (check(&bp, SD_N_PARAMETERS, "p") || check(&bx, SD_NX, "x") || check(&bs, SD_NX * m, "S")
        || check(&bu, SD_M, "u_held") || check(&bxp, SD_NX, "x_plus") || check(&bsp, SD_NX * m, "S_plus"))
        goto done;
    if (law_spec != Py_None && law_from(law_spec, &law, NULL, params, &n_params, &name) < 0) goto done;
    StanceConstants k;
    stance_constants((const double *)bp.buf, &k);
    if (touchdown(&k, leg, gleg, tan_s, t, (const double *)bx.buf, (const double *)bs.buf, m, law, params, name,
                  (const double *)bu.buf, last, (double *)bxp.buf, (double *)bsp.buf, (double *)bd.buf) < 0)
        goto done;
    result = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&bp); PyBuffer_Release(&bx); PyBuffer_Release(&bs); PyBuffer_Release(&bu);
    PyBuffer_Release(&bxp); PyBuffer_Release(&bsp); PyBuffer_Release(&bd);
    return result;
}

static PyMethodDef methods[] = {
    {"steps_transition", steps_transition, METH_VARARGS, steps_transition_doc},
    {"touchdown", touchdown_event, METH_VARARGS, touchdown_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_variational",
    "The variational terms of the three-link's DOP853 steps in stance, in C (biped_sim/engine/_variational.c).",
    -1, methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC
PyInit__variational(void)
{
    PyObject *m = PyModule_Create(&module);
    if (m == NULL) return NULL;
    if (PyModule_AddStringConstant(m, "KERNELS_SHA256", BIPED_SIM_KERNELS_SHA256) < 0
        || PyModule_AddStringConstant(m, "DERIVATIVES_SHA256", BIPED_SIM_DERIVATIVES_SHA256) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
