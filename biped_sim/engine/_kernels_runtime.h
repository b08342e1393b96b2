/* The runtime of a described robot's compiled kernels (biped_sim/engine/model_kernels.py): the part of every
 * robot's twin that is the same for every robot -- reading a sequence of numbers, D's Cholesky factor and the
 * Schur-complement solves of the KKT systems, the C entry points of the KernelTable (_kernel_table.h), the
 * Python functions k_stance ... k_energy on lists, the method table and the module definition.
 *
 * A twin's generated source includes it last, after its robot's part:
 *   - Python.h (with PY_SSIZE_T_CLEAN) and math.h;
 *   - the #defines N (coordinates), NC (contact points), NU (actuators M), MODULE_NAME, INIT_FUNCTION,
 *     ROBOT_NAME, ROBOT_DIGEST, GENERATOR_VERSION and SOURCE_SHA256;
 *   - the translated formulas mass_matrix(q, D), bias_forces(q, dq, out), contact_positions(q, p),
 *     contact_jacobians(q, J), contact_jacobian_dots(q, dq, Jd), contact_velocities(q, dq, v), energy(q, dq, tv)
 *     and b_times_u(u, out) (out += B u).
 * It is compiled with this folder on the include path (setup.py for the shipped robots, model_kernels.build for
 * a user's); model_kernels hashes its text into each twin's SOURCE_SHA256, so a cached twin built with another
 * runtime is not loaded. One translation unit includes it once: it defines the module. */
#ifndef BIPED_SIM_KERNELS_RUNTIME_H
#define BIPED_SIM_KERNELS_RUNTIME_H

#if !defined(N) || !defined(NC) || !defined(NU) || !defined(MODULE_NAME) || !defined(INIT_FUNCTION) \
    || !defined(ROBOT_NAME) || !defined(ROBOT_DIGEST) || !defined(GENERATOR_VERSION) || !defined(SOURCE_SHA256)
#error "_kernels_runtime.h: the generated source defines N, NC, NU, MODULE_NAME, INIT_FUNCTION, ROBOT_NAME, ROBOT_DIGEST, GENERATOR_VERSION and SOURCE_SHA256 before it"
#endif

#include "_kernel_table.h"

/* ---- reading the arguments, building the results ---------------------------------------------------- */

/* x of a sequence of n numbers (a list or tuple is read in place); -1 with the error set */
static int
read_vector(PyObject *obj, Py_ssize_t n, const char *kernel, const char *what, double *x)
{
    PyObject *seq;
    Py_ssize_t i, len;
    if (PyList_CheckExact(obj) || PyTuple_CheckExact(obj)) {
        seq = obj;
        Py_INCREF(seq);
    } else {
        seq = PySequence_Fast(obj, "");
        if (seq == NULL) {
            PyErr_Format(PyExc_TypeError, "%s: %s must be a sequence of %zd numbers, got %.100s",
                         kernel, what, n, Py_TYPE(obj)->tp_name);
            return -1;
        }
    }
    len = PySequence_Fast_GET_SIZE(seq);
    if (len != n) {
        PyErr_Format(PyExc_ValueError, "%s: %s must have %zd numbers, got %zd", kernel, what, n, len);
        Py_DECREF(seq);
        return -1;
    }
    for (i = 0; i < n; i++) {
        PyObject *item = PySequence_Fast_GET_ITEM(seq, i);
        double v = PyFloat_CheckExact(item) ? PyFloat_AS_DOUBLE(item) : PyFloat_AsDouble(item);
        if (v == -1.0 && PyErr_Occurred()) {
            if (PyErr_ExceptionMatches(PyExc_TypeError)) {
                PyErr_Clear();
                PyErr_Format(PyExc_TypeError, "%s: %s[%zd] must be a number, got %.100s",
                             kernel, what, i, Py_TYPE(item)->tp_name);
            }
            Py_DECREF(seq);
            return -1;
        }
        x[i] = v;
    }
    Py_DECREF(seq);
    return 0;
}

static int
read_contact(PyObject *obj, const char *kernel, int *c)
{
    long v;
    if (!PyLong_Check(obj) || PyBool_Check(obj)) {
        PyErr_Format(PyExc_TypeError, "%s: the contact index must be an int 0..%d, got %.100s",
                     kernel, NC - 1, Py_TYPE(obj)->tp_name);
        return -1;
    }
    v = PyLong_AsLong(obj);
    if (v == -1 && PyErr_Occurred())
        return -1;
    if (v < 0 || v >= NC) {
        PyErr_Format(PyExc_ValueError, "%s: the contact index must be 0..%d, got %ld", kernel, NC - 1, v);
        return -1;
    }
    *c = (int)v;
    return 0;
}

static PyObject *
list_of(const double *x, Py_ssize_t n)
{
    Py_ssize_t i;
    PyObject *list = PyList_New(n);
    if (list == NULL)
        return NULL;
    for (i = 0; i < n; i++) {
        PyObject *v = PyFloat_FromDouble(x[i]);
        if (v == NULL) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SET_ITEM(list, i, v);
    }
    return list;
}

static PyObject *
pair_of(const double *x, Py_ssize_t n, const double *y, Py_ssize_t m)
{
    PyObject *a = list_of(x, n), *b, *pair;
    if (a == NULL)
        return NULL;
    b = list_of(y, m);
    if (b == NULL) {
        Py_DECREF(a);
        return NULL;
    }
    pair = PyTuple_New(2);
    if (pair == NULL) {
        Py_DECREF(a);
        Py_DECREF(b);
        return NULL;
    }
    PyTuple_SET_ITEM(pair, 0, a);
    PyTuple_SET_ITEM(pair, 1, b);
    return pair;
}

/* ---- the solves: D's Cholesky factor, the Schur complement of the contact's 2x2 block ----------------- */

/* D = L L^T, L written over D's lower triangle; -1 when D is not positive definite */
static int
cholesky(double *A)
{
    int i, j, k;
    for (j = 0; j < N; j++) {
        double s = A[j * N + j], d;
        for (k = 0; k < j; k++)
            s -= A[j * N + k] * A[j * N + k];
        if (!(s > 0.0))
            return -1;
        d = sqrt(s);
        A[j * N + j] = d;
        for (i = j + 1; i < N; i++) {
            double t = A[i * N + j];
            for (k = 0; k < j; k++)
                t -= A[i * N + k] * A[j * N + k];
            A[i * N + j] = t / d;
        }
    }
    return 0;
}

/* x = (L L^T)^-1 x */
static void
cholesky_solve(const double *L, double *x)
{
    int i, k;
    for (i = 0; i < N; i++) {
        double s = x[i];
        for (k = 0; k < i; k++)
            s -= L[i * N + k] * x[k];
        x[i] = s / L[i * N + i];
    }
    for (i = N - 1; i >= 0; i--) {
        double s = x[i];
        for (k = i + 1; k < N; k++)
            s -= L[k * N + i] * x[k];
        x[i] = s / L[i * N + i];
    }
}

/* With L the factor of D and J = J_c (2xN): x = a + Y F, (J Y) F = b - J a, Y = D^-1 J^T.
   a is overwritten by x. KERNEL_SINGULAR_CONTACT when J Y is singular (the contact's Jacobian has lost rank). */
static int
schur_solve(const double *L, const double *J, const double *b, double *a, double *F)
{
    double Y[2][N], S[2][2], g[2], det;
    int r, s, k;
    for (r = 0; r < 2; r++) {
        for (k = 0; k < N; k++)
            Y[r][k] = J[r * N + k];
        cholesky_solve(L, Y[r]);
    }
    for (r = 0; r < 2; r++) {
        double ja = 0.0;
        for (k = 0; k < N; k++)
            ja += J[r * N + k] * a[k];
        g[r] = b[r] - ja;
        for (s = 0; s < 2; s++) {
            double t = 0.0;
            for (k = 0; k < N; k++)
                t += J[r * N + k] * Y[s][k];
            S[r][s] = t;
        }
    }
    det = S[0][0] * S[1][1] - S[0][1] * S[1][0];
    if (!(det != 0.0) || !isfinite(det))
        return KERNEL_SINGULAR_CONTACT;
    F[0] = (g[0] * S[1][1] - g[1] * S[0][1]) / det;
    F[1] = (S[0][0] * g[1] - S[1][0] * g[0]) / det;
    for (k = 0; k < N; k++)
        a[k] += Y[0][k] * F[0] + Y[1][k] * F[1];
    return KERNEL_OK;
}

/* ---- the C entry points (the KernelTable's: _kernel_table.h) --------------------------------------- */

static int
c_stance(const double *q, const double *dq, const double *u, int c, double *x, double *F)
{
    double D[N * N], J[NC * 2 * N], Jd[NC * 2 * N], b[2];
    const double *Jc, *Jdc;
    int r, k;
    mass_matrix(q, D);
    bias_forces(q, dq, x);
    for (k = 0; k < N; k++)
        x[k] = -x[k];
    b_times_u(u, x);
    contact_jacobians(q, J);
    contact_jacobian_dots(q, dq, Jd);
    Jc = J + c * 2 * N;
    Jdc = Jd + c * 2 * N;
    for (r = 0; r < 2; r++) {
        double s = 0.0;
        for (k = 0; k < N; k++)
            s += Jdc[r * N + k] * dq[k];
        b[r] = -s;
    }
    if (cholesky(D))
        return KERNEL_NOT_POSITIVE_DEFINITE;
    cholesky_solve(D, x);
    return schur_solve(D, Jc, b, x, F);
}

static int
c_flight(const double *q, const double *dq, const double *u, double *x)
{
    double D[N * N];
    int k;
    mass_matrix(q, D);
    bias_forces(q, dq, x);
    for (k = 0; k < N; k++)
        x[k] = -x[k];
    b_times_u(u, x);
    if (cholesky(D))
        return KERNEL_NOT_POSITIVE_DEFINITE;
    cholesky_solve(D, x);
    return KERNEL_OK;
}

static int
c_impact(const double *q, const double *dq_minus, int c, double *x, double *F)
{
    double D[N * N], J[NC * 2 * N], zero[2] = {0.0, 0.0};
    int k;
    /* D^-1 (D dq-) = dq-: x starts at dq- */
    for (k = 0; k < N; k++)
        x[k] = dq_minus[k];
    mass_matrix(q, D);
    contact_jacobians(q, J);
    if (cholesky(D))
        return KERNEL_NOT_POSITIVE_DEFINITE;
    return schur_solve(D, J + c * 2 * N, zero, x, F);
}

static int
c_foot_positions(const double *q, double *p)
{
    contact_positions(q, p);
    return KERNEL_OK;
}

static int
c_foot_kinematics(const double *q, const double *dq, double *pv)
{
    contact_positions(q, pv);
    contact_velocities(q, dq, pv + 2 * NC);
    return KERNEL_OK;
}

static int
c_energy(const double *q, const double *dq, double *tv)
{
    energy(q, dq, tv);
    return KERNEL_OK;
}

static const KernelTable kernel_table = {
    KERNEL_TABLE_VERSION, N, NC, NU, c_stance, c_flight, c_impact, c_foot_positions, c_foot_kinematics, c_energy
};

/* ---- the Python functions: the entry points on lists ---------------------------------------------- */

/* NULL with the error of a kernel's code */
static PyObject *
kernel_failed(const char *kernel, int code)
{
    if (code == KERNEL_NOT_POSITIVE_DEFINITE)
        PyErr_Format(PyExc_ValueError, "%s: D(q) of the robot " ROBOT_NAME " is not positive definite at this q",
                     kernel);
    else
        PyErr_Format(PyExc_ValueError, "%s: the contact's Jacobian J_c D^-1 J_c^T is singular at this q", kernel);
    return NULL;
}

#define CHECK_NARGS(kernel, want) \
    if (nargs != (want)) { \
        PyErr_Format(PyExc_TypeError, "%s takes %d arguments, got %zd", kernel, (want), nargs); \
        return NULL; \
    }

static PyObject *
k_stance(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double q[N], dq[N], u[NU > 0 ? NU : 1], x[N], F[2];
    int c, code;
    CHECK_NARGS("k_stance", 4)
    if (read_vector(args[0], N, "k_stance", "q", q) || read_vector(args[1], N, "k_stance", "dq", dq)
            || read_vector(args[2], NU, "k_stance", "u", u) || read_contact(args[3], "k_stance", &c))
        return NULL;
    if ((code = c_stance(q, dq, u, c, x, F)) != KERNEL_OK)
        return kernel_failed("k_stance", code);
    return pair_of(x, N, F, 2);
}

static PyObject *
k_flight(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double q[N], dq[N], u[NU > 0 ? NU : 1], x[N];
    int code;
    CHECK_NARGS("k_flight", 3)
    if (read_vector(args[0], N, "k_flight", "q", q) || read_vector(args[1], N, "k_flight", "dq", dq)
            || read_vector(args[2], NU, "k_flight", "u", u))
        return NULL;
    if ((code = c_flight(q, dq, u, x)) != KERNEL_OK)
        return kernel_failed("k_flight", code);
    return list_of(x, N);
}

static PyObject *
k_impact(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double q[N], dqm[N], x[N], F[2];
    int c, code;
    CHECK_NARGS("k_impact", 3)
    if (read_vector(args[0], N, "k_impact", "q", q) || read_vector(args[1], N, "k_impact", "dq_minus", dqm)
            || read_contact(args[2], "k_impact", &c))
        return NULL;
    if ((code = c_impact(q, dqm, c, x, F)) != KERNEL_OK)
        return kernel_failed("k_impact", code);
    return pair_of(x, N, F, 2);
}

static PyObject *
k_foot_positions(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double q[N], p[2 * NC];
    CHECK_NARGS("k_foot_positions", 1)
    if (read_vector(args[0], N, "k_foot_positions", "q", q))
        return NULL;
    c_foot_positions(q, p);
    return list_of(p, 2 * NC);
}

static PyObject *
k_foot_kinematics(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double q[N], dq[N], pv[4 * NC];
    CHECK_NARGS("k_foot_kinematics", 2)
    if (read_vector(args[0], N, "k_foot_kinematics", "q", q) || read_vector(args[1], N, "k_foot_kinematics", "dq", dq))
        return NULL;
    c_foot_kinematics(q, dq, pv);
    return list_of(pv, 4 * NC);
}

static PyObject *
k_energy(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    double q[N], dq[N], e[2];
    CHECK_NARGS("k_energy", 2)
    if (read_vector(args[0], N, "k_energy", "q", q) || read_vector(args[1], N, "k_energy", "dq", dq))
        return NULL;
    c_energy(q, dq, e);
    return list_of(e, 2);
}

static PyMethodDef methods[] = {
    {"k_stance", (PyCFunction)(void (*)(void))k_stance, METH_FASTCALL,
     "k_stance(q, dq, u, c) -> (ddq, F): stance on contact point c (0-based), its point pinned."},
    {"k_flight", (PyCFunction)(void (*)(void))k_flight, METH_FASTCALL, "k_flight(q, dq, u) -> ddq."},
    {"k_impact", (PyCFunction)(void (*)(void))k_impact, METH_FASTCALL,
     "k_impact(q, dq_minus, c) -> (dq_plus, impulse): the rigid plastic impact of contact point c."},
    {"k_foot_positions", (PyCFunction)(void (*)(void))k_foot_positions, METH_FASTCALL,
     "k_foot_positions(q) -> [x1, y1, x2, y2, ...]."},
    {"k_foot_kinematics", (PyCFunction)(void (*)(void))k_foot_kinematics, METH_FASTCALL,
     "k_foot_kinematics(q, dq) -> [p_1, p_2, ..., v_1, v_2, ...]."},
    {"k_energy", (PyCFunction)(void (*)(void))k_energy, METH_FASTCALL, "k_energy(q, dq) -> [T, V]."},
    {NULL, NULL, 0, NULL}
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, MODULE_NAME,
    "The compiled kernels of the robot " ROBOT_NAME " (biped_sim.engine.model_kernels).", -1, methods
};

PyMODINIT_FUNC
INIT_FUNCTION(void)
{
    PyObject *m = PyModule_Create(&module_def), *table;
    if (m == NULL)
        return NULL;
    if (PyModule_AddStringConstant(m, "NAME", ROBOT_NAME) || PyModule_AddStringConstant(m, "DIGEST", ROBOT_DIGEST)
            || PyModule_AddIntConstant(m, "GENERATOR_VERSION", GENERATOR_VERSION)
            || PyModule_AddStringConstant(m, "SOURCE_SHA256", SOURCE_SHA256)
            || PyModule_AddIntConstant(m, "N", N) || PyModule_AddIntConstant(m, "CONTACTS", NC)
            || PyModule_AddIntConstant(m, "ACTUATORS", NU)
            || PyModule_AddIntConstant(m, "KERNEL_TABLE_VERSION", KERNEL_TABLE_VERSION)) {
        Py_DECREF(m);
        return NULL;
    }
    /* the C entry points, for C code that runs the robot without a Python call (_kernel_table.h) */
    table = PyCapsule_New((void *)&kernel_table, KERNEL_TABLE_CAPSULE, NULL);
    if (table == NULL || PyModule_AddObject(m, "KERNEL_TABLE", table) < 0) {
        Py_XDECREF(table);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}

#endif
