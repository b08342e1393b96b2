/* The compiled hybrid loop: floating-base stance, stepped by dop853 or dopri5, under a held torque,
 * a compiled torque law plugged in through the hook, or a Python controller called back
 * (biped_sim/engine/compiled_loop.py drives it; biped_sim/engine/torque_hook.py describes the hook).
 *
 * It runs biped_sim/engine/hybrid.py's loop for the steps whose outcome it can decide exactly as the
 * Python code would: the step with its error control, the guards of the locator (touchdown of the
 * armed swing foot with the dip search of grazing.py, liftoff, slip), a crossing located by brentq,
 * a scuff behind the stance foot started, followed and ended, the arming of the feet, the projection
 * onto the pin, the sample with its energy balance, the invariants of invariants.py, and a
 * touchdown in front with its impact map (the generated closed form's kernel), relabeling and the next
 * mode's start. A step in which anything else would happen (a liftoff, a slip, a foot pushed into
 * the ground, a violated invariant, a diverging speed, an impact with a warning, a possible Zeno
 * stop, ...) is not accepted here: it is handed back to Python as it was taken ("pending"), and
 * hybrid.py's own code locates, resets, reports or fails it. The Events and their messages are made
 * by the Python code (from what this file measured, for a scuff or a touchdown it applied).
 *
 * Every formula comes from the generated kernels (_gen/_kernels.h: the closed forms, the unrolled
 * steps and their dense output) or from the rules compiled from loop_rules.py (below), which perform the
 * Python code's operations in the same order; what is written here is the loop's glue (the samples, the
 * event records, relabeling, the hand-overs, the hook), so that a run gives the same bits on both paths
 * (test/unit/test_compiled_loop.py).
 */
/* The rules written once (loop_rules.py: the step with its error control, the dense output, a foot's height,
 * the dip search, brentq), compiled by Cython into the committed _loop_rules.c (tools/generate_loop.py), are
 * part of this translation unit: the loop calls them by name (rk_step, rk_dense_at, ev_may_dip...) on its
 * state, and the compiler sees them with the loop's right-hand side (docs/engine.md, "The core"). They
 * include _gen/_kernels.h and _loop_state.h. */
#include "_loop_rules.c"

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>
#include <math.h>
#include <time.h>
#include <string.h>

/* a described robot's kernels as C entry points (model_kernels.py: its twin's capsule KERNEL_TABLE) */
#include "_kernel_table.h"
/* sequences of numbers from Python (doubles) */
#include "_py_doubles.h"

#define N 11                 /* the floating base's integrated state: q (5), dq (5), motor work */
#define MAX_STAGES 13        /* dop853's k0..k12 */
#define KMAX 32              /* room for any closed form's constants */
/* a sample's row of the widest model (loop_state.sample_row(NQ_MAX, NQ_MAX)) */
#define ROW_MAX (1 + 2 * LS_NQ_MAX + 4 + LS_NQ_MAX)

enum { DOP853 = 0, DOPRI5 = 1 };
enum { HELD = 0, COMPILED = 1, CALLBACK = 2 };   /* the kinds of torque law */
enum { FAIL_NONE = 0, FAIL_STEP_SIZE = 1, FAIL_NON_FINITE = 2, FAIL_CALLBACK = 3 };

typedef struct { double x, height, dx, dheight; } Foot;

/* The touchdowns applied and the scuffs ended are rows of the state's records (loop_state.RECORD_ROW: kind, a, b,
 * v), the first n_records in use. A run returns OUTCOME_NEED_ROOM when they are full: a step makes at most one. */
static double *
new_record(double *S, int kind, int a, int b)
{
    double *r = S + LS_RECORDS + REC_WIDTH * (int)S[LS_N_RECORDS];
    S[LS_N_RECORDS] += 1.0;
    r[REC_KIND] = kind;
    r[REC_A] = a;
    r[REC_B] = b;
    return r + REC_V;
}

/* A compiled torque law (biped_sim/engine/torque_hook.py's SIGNATURE): u from t, q, dq, the stance leg and
 * its parameters; nonzero: it failed */
typedef int (*TorqueLaw)(double t, const double *q, const double *dq, int stance_leg, const double *params,
                         double *u);
#define MAX_LAW_PARAMETERS 128
typedef struct {
    TorqueLaw fn;
    double params[MAX_LAW_PARAMETERS];
    char name[64];     /* for the message of a failure */
} CompiledLaw;

typedef struct {
    PyObject_HEAD
    /* model: the constants of the closed forms (BipedModel.k; k_feet, k_energy and k_impact are the state's) */
    double k_stance[KMAX], k_terms[KMAX];
    /* the state the rules read and write (loop_state.py): S by offset, the same memory by member (the model's
     * k_pos and l_leg, the options rtol, atol, max_step, graze_tol, event_tol, tan_s, the method, the stepper,
     * callback_failed, the failure of the last step) */
    union {
        double S[LOOP_STATE_SIZE];
        struct { LOOP_STATE_MEMBERS };
    };
    /* (the options, the stance leg, the pin and the held torque are the state's: max_speed ... max_events,
     * stance_leg, pin, u_hold) */
    /* (the impact history and the mode events are the state's: last_impact, n_impacts, recent_impacts,
     * n_recent, mode_events, ring) */
    /* (the touchdowns applied and the scuffs ended, whose Events the Python code makes, are the state's: records,
     * n_records) */
    /* the torque law */
    int law_kind;     /* HELD (the state's u_hold), COMPILED (law) or CALLBACK (callback) */
    CompiledLaw law;
    /* a Python controller, called back as controller(t, q, dq, stance_leg) and checked (call_controller).
     * The first failure of the law (the controller raised, a compiled law returned nonzero) is kept as an
     * exception and the computation it spoiled is thrown away (callback_failed) */
    PyObject *callback;
    PyObject *exc_type, *exc_value, *exc_tb;
    double last_F[2], last_u[LS_NQ_MAX];
    /* a described robot (set_kernels): its kernels' table (NULL: the three-link's closed forms above), the capsule
     * that owns it, and the entries of q its M actuators turn (B a selection: modes.py's joints) */
    const KernelTable *table;
    PyObject *table_owner;
    char robot[64];    /* its name, for the message of a kernel's failure */
    /* a described robot's coordinates n, actuators m and a sample's row width (loop_state.sample_row(n, m)); the
     * three-link's are 5, 2 and ROW_WIDTH (loop_n, loop_m, loop_row_width) */
    int n, m, row_width;
    double joints[LS_NQ_MAX];
    /* (the locator's armed feet, scuffs and the step end's feet and force are the state's: armed, scuffing,
     * scuff, deepest_scuff, scuffs, feet_end, force_end) */
    /* (why the last step was handed back, its end's torque and force, and the run's statistics are the state's: why,
     * end_u, end_F, steps, max_drift, max_rate, max_residual, wall_time) */
} Loop;

/* the model's coordinates, actuators and sample row width: a described robot's, or the three-link's */
static inline int loop_n(const Loop *L) { return L->table ? L->n : 5; }
static inline int loop_m(const Loop *L) { return L->table ? L->m : 2; }
static inline int loop_row_width(const Loop *L) { return L->table ? L->row_width : ROW_WIDTH; }

/* the table of the Loop whose state S is (_loop_table.h: the compiled rules' kernel glue) */
static const KernelTable *
loop_table(double *S)
{
    return ((const Loop *)((const char *)S - offsetof(Loop, S)))->table;
}

/* -- the torque law: held, compiled (the hook) or called back ------------------------------------- */

/* the type of the exception a compiled law's failure raises (set_python_checks: the engine's ControllerError) */
static PyObject *law_failure_type;

static PyObject *list_of(const double *v, Py_ssize_t n);

static int m_finite(PyObject *u, int m, double *out);

/* the engine's Python side of a controller's call (set_python_checks: modes.controller_failure and
 * modes.checked_torques, for what this file does not judge itself, and numpy's ndarray type) */
static PyObject *controller_failure_fn, *checked_torques_fn, *ndarray_type;

/* u as two finite floats from a numpy float64 array of shape (2,) in native byte order (what
 * modes.two_finite_floats takes from an array without the general check): 0, or -1 (no exception) for
 * anything else, which the Python code judges */
static int
two_finite_array(PyObject *u, double *out)
{
    if (ndarray_type == NULL || (PyObject *)Py_TYPE(u) != ndarray_type) return -1;
    Py_buffer b;
    if (PyObject_GetBuffer(u, &b, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyErr_Clear();
        return -1;
    }
    int ok = b.ndim == 1 && b.shape != NULL && b.shape[0] == 2 && b.itemsize == sizeof(double) && b.format != NULL
             && strcmp(b.format, "d") == 0;
    if (ok) memcpy(out, b.buf, 2 * sizeof(double));
    PyBuffer_Release(&b);
    return ok && ev_finite_torques(out[0], out[1]) ? 0 : -1;
}

/* u = controller(t, q, dq, stance_leg), a Python controller called straight from here with lists q and dq of the
 * loop's robot's N coordinates and the stance leg the loop runs, its M torques checked as modes.checked_command
 * checks them: M finite floats or ints from a list or tuple (m_finite; for two torques also a float64 array of two,
 * two_finite_array) taken here, anything else judged by modes.checked_torques (which takes what it takes, or
 * raises the ControllerError naming it); an exception of the controller becomes modes.controller_failure's
 * ControllerError, the controller's exception its cause with its traceback. The first failure is kept
 * (callback_failed) with its exception, and the computation it spoiled is thrown away. */
static void
call_controller(Loop *L, PyObject *controller, double t, const double *q, const double *dq, double *u)
{
    int n = loop_n(L), m = loop_m(L);
    for (int i = 0; i < m; i++) u[i] = 0.0;
    if (L->callback_failed) return;
    if (controller_failure_fn == NULL || checked_torques_fn == NULL) {     /* (compiled_loop sets them at import) */
        PyErr_SetString(PyExc_RuntimeError, "a Python controller needs set_python_checks() first");
        L->callback_failed = 1;
        PyErr_Fetch(&L->exc_type, &L->exc_value, &L->exc_tb);
        return;
    }
    PyObject *args[4] = {PyFloat_FromDouble(t), list_of(q, n), list_of(dq, n), PyLong_FromLong((long)L->stance_leg)}, *r = NULL;
    if (args[0] && args[1] && args[2] && args[3]) r = PyObject_Vectorcall(controller, args, 4, NULL);
    for (int i = 0; i < 4; i++) Py_XDECREF(args[i]);
    if (r != NULL) {
        if (m_finite(r, m, u) < 0 && (m != 2 || two_finite_array(r, u) < 0)) {
            PyObject *checked = PyObject_CallFunction(checked_torques_fn, "Odi", r, t, m);
            if (checked != NULL) {
                if (PyList_CheckExact(checked) && PyList_GET_SIZE(checked) == m) {
                    for (int i = 0; i < m; i++) u[i] = PyFloat_AsDouble(PyList_GET_ITEM(checked, i));
                } else {
                    PyErr_SetString(PyExc_TypeError, "checked_torques must return a list of m floats");
                }
                Py_DECREF(checked);
            }
        }
        Py_DECREF(r);
    } else if (PyErr_ExceptionMatches(PyExc_Exception)) {     /* (a KeyboardInterrupt goes on as it is) */
        PyObject *type, *value, *tb;
        PyErr_Fetch(&type, &value, &tb);
        PyErr_NormalizeException(&type, &value, &tb);
        if (tb != NULL) PyException_SetTraceback(value, tb);
        PyObject *error = PyObject_CallFunction(controller_failure_fn, "Od", value, t);
        Py_XDECREF(type);
        Py_XDECREF(value);
        Py_XDECREF(tb);
        if (error != NULL) {
            PyErr_SetObject((PyObject *)Py_TYPE(error), error);
            Py_DECREF(error);
        }
    }
    if (PyErr_Occurred()) {
        L->callback_failed = 1;
        PyErr_Fetch(&L->exc_type, &L->exc_value, &L->exc_tb);
        for (int i = 0; i < m; i++) u[i] = 0.0;
    }
}

/* u = law(t, q, dq) in stance on L->stance_leg; a failure kept as call_controller keeps an exception */
static void
apply_law(Loop *L, const CompiledLaw *law, double t, const double *q, const double *dq, double *u)
{
    u[0] = u[1] = 0.0;
    if (L->callback_failed) return;
    int code = law->fn(t, q, dq, (int)L->stance_leg, law->params, u);
    if (code != 0) {
        char when[32];
        snprintf(when, sizeof when, "%.9g", t);      /* (as Python's f"{t:.9g}") */
        PyErr_Format(law_failure_type ? law_failure_type : PyExc_RuntimeError,
                     "the torque law %s returned %d at t=%s s", law->name, code, when);
        L->callback_failed = 1;
        PyErr_Fetch(&L->exc_type, &L->exc_value, &L->exc_tb);
        u[0] = u[1] = 0.0;
    }
}

static void
torque(Loop *L, double t, const double *q, const double *dq, double *u)
{
    if (L->law_kind == COMPILED) apply_law(L, &L->law, t, q, dq, u);
    else if (L->law_kind == CALLBACK) call_controller(L, L->callback, t, q, dq, u);
    else { u[0] = L->u_hold[0]; u[1] = L->u_hold[1]; }
}

/* m finite floats from a list or tuple of m floats or ints with a finite sum (modes.finite_floats' fast path, its
 * sum the rule's: loop_rules.ev_finite_sum): 0, or -1 (no exception) for anything the Python code must judge */
static int
m_finite(PyObject *u, int m, double *out)
{
    if (!(PyList_CheckExact(u) || PyTuple_CheckExact(u)) || PySequence_Fast_GET_SIZE(u) != m) return -1;
    for (int i = 0; i < m; i++) {
        PyObject *v = PySequence_Fast_GET_ITEM(u, i);
        if ((!PyFloat_Check(v) && !PyLong_Check(v)) || PyBool_Check(v)) return -1;
        out[i] = PyFloat_AsDouble(v);
        if (out[i] == -1.0 && PyErr_Occurred()) {
            PyErr_Clear();
            return -1;
        }
    }
    return ev_finite_sum(out, m) ? 0 : -1;
}

static void
torque_described(Loop *L, double t, const double *q, const double *dq, double *u)
{
    if (L->law_kind == CALLBACK) call_controller(L, L->callback, t, q, dq, u);
    else memcpy(u, L->u_hold, L->table->actuators * sizeof(double));
}

/* A compiled law from its description (address, parameters, name) (torque_hook.hook_argument);
 * 0, or -1 with an exception */
static int
compiled_law_from(PyObject *spec, CompiledLaw *law)
{
    PyObject *address, *params;
    const char *name;
    if (!PyTuple_Check(spec) || !PyArg_ParseTuple(spec, "OOs", &address, &params, &name)) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_TypeError, "a compiled law is (address, parameters, name)");
        return -1;
    }
    void *fn = PyLong_AsVoidPtr(address);
    if (fn == NULL) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "a compiled law's address must not be 0");
        return -1;
    }
    if (doubles(params, law->params, 0, MAX_LAW_PARAMETERS, "a compiled law's parameters", NULL)) return -1;
    law->fn = (TorqueLaw)fn;
    snprintf(law->name, sizeof law->name, "%s", name);
    return 0;
}

/* the kept exception of the callback, raised (NULL), after the spoiled computation was thrown away */
static PyObject *
raise_callback_error(Loop *L)
{
    L->callback_failed = 0;
    PyErr_Restore(L->exc_type, L->exc_value, L->exc_tb);
    L->exc_type = L->exc_value = L->exc_tb = NULL;
    return NULL;
}

/* -- the mode's right-hand side and the stance force (modes.mode_functions, HybridSimulator._force_at) -- */

static void
stance(Loop *L, const double *q, const double *dq, const double *u, double *out7)
{
    if (L->stance_leg == 1) k_stance_floating_1(q, dq, u, L->k_stance, out7);
    else k_stance_floating_2(q, dq, u, L->k_stance, out7);
}

/* A described robot's torque law (the state's held u_hold of M entries, or a Python controller called back with
 * q and dq of N entries and its M torques checked as modes.checked_command checks them) */
static void torque_described(Loop *L, double t, const double *q, const double *dq, double *u);

/* A kernel's failure (D not positive definite, the contact's Jacobian singular) at t, kept as a failure of the
 * torque law is kept (the step fails; the message is the compiled twin's Python function's) */
static void
kernel_failed(Loop *L, int code)
{
    const char *kernel = L->stance_leg ? "k_stance" : "k_flight";
    if (L->callback_failed) return;
    if (code == KERNEL_NOT_POSITIVE_DEFINITE)
        PyErr_Format(PyExc_ValueError, "%s: D(q) of the robot %s is not positive definite at this q", kernel, L->robot);
    else
        PyErr_Format(PyExc_ValueError, "%s: the contact's Jacobian J_c D^-1 J_c^T is singular at this q", kernel);
    L->callback_failed = 1;
    PyErr_Fetch(&L->exc_type, &L->exc_value, &L->exc_tb);
}

/* A described robot's mode (modes._generated_functions): y = q + dq + [work] (N coordinates), floating-base
 * stance on contact point stance_leg (the KKT solve: the table's stance) or flight (stance_leg 0: its flight);
 * the motors' power u . (B^T dq) (loop_rules.ev_actuated_power) */
static int
rhs_described(Loop *L, double t, const double *y, double *dy)
{
    const KernelTable *K = L->table;
    int n = K->n, m = K->actuators, code;
    double u[LS_NQ_MAX], F[2] = {0.0, 0.0};
    const double *q = y, *dq = y + n;
    torque_described(L, t, q, dq, u);
    code = L->stance_leg ? K->stance(q, dq, u, (int)L->stance_leg - 1, dy + n, F) : K->flight(q, dq, u, dy + n);
    if (code != KERNEL_OK) {
        kernel_failed(L, code);
        return -1;
    }
    L->last_F[0] = F[0]; L->last_F[1] = F[1];
    memcpy(L->last_u, u, m * sizeof(double));
    memcpy(dy, dq, n * sizeof(double));
    dy[2 * n] = ev_actuated_power(u, (double *)dq, L->joints, m);
    return 0;
}

static int
rhs(void *ctx, double t, const double *y, double *dy)
{
    Loop *L = ctx;
    double u[2], out[7];
    if (L->table) return rhs_described(L, t, y, dy);
    torque(L, t, y, y + 5, u);
    stance(L, y, y + 5, u, out);
    L->last_F[0] = out[5]; L->last_F[1] = out[6];
    L->last_u[0] = u[0]; L->last_u[1] = u[1];
    for (int i = 0; i < 5; i++) dy[i] = y[5 + i];
    for (int i = 0; i < 5; i++) dy[5 + i] = out[i];
    dy[10] = ev_motor_power(u, y[7], y[8]);
    return 0;
}

/* the stance force F under u at (q, dq) on the stance leg (a described robot's: its table's stance; a failure kept as
 * a failure of the torque law is kept, F NaN) */
static void
stance_force(Loop *L, const double *q, const double *dq, const double *u, double *F)
{
    if (L->table) {
        double ddq[LS_NQ_MAX];
        int code = L->table->stance(q, dq, u, (int)L->stance_leg - 1, ddq, F);
        if (code != KERNEL_OK) {
            kernel_failed(L, code);
            F[0] = F[1] = NAN;
        }
        return;
    }
    double out[7];
    stance(L, q, dq, u, out);
    F[0] = out[5]; F[1] = out[6];
}

/* the torque law's u at (t, q, dq): the three-link's or a described robot's */
static void
torque_of(Loop *L, double t, const double *q, const double *dq, double *u)
{
    if (L->table) torque_described(L, t, q, dq, u);
    else torque(L, t, q, dq, u);
}

static void
force_at(Loop *L, double t, const double *q, const double *dq, double *F)
{
    double u[LS_NQ_MAX];
    torque_of(L, t, q, dq, u);
    stance_force(L, q, dq, u, F);
}

/* guards.foot_states: per foot x, height across the slope, and their rates (loop_rules.ev_foot_states) */
static void
feet(const Loop *L, const double *q, const double *dq, double *ft)
{
    double p[8];
    if (L->table) L->table->foot_kinematics(q, dq, p);
    else k_foot_kinematics(q, dq, L->k_feet, p);
    ev_foot_states(p, 0, L->tan_s, ft, 0);
}

/* -- the stepper: the rules of loop_rules.py (integrators._ListRungeKutta), compiled -------------------- */

/* A mode's start at time t from the current y (integrators._ListRungeKutta.restart): f = rhs(t, y)
 * under the torque now set, the step's fields reset; t_bound the end of the interval */
static void
restart(Loop *L, double t, double t_bound)
{
    L->t = t;
    L->t_bound = t_bound;
    rk_begin(L->S, rhs, L);
}

/* The step size a new stepper starts with: the carried-over h, capped by max_step (restart's min) */
static void
carry_step(Loop *L, double h)
{
    L->h_abs = rk_carried_step(h, L->max_step);
}

/* EventLocator._feet_at: the feet on the dense output at tt */
static void
feet_at(const Loop *L, double tt, double *ft)
{
    double qd[2 * LS_NQ_MAX];
    for (int j = 0; j < 2 * loop_n(L); j++) qd[j] = rk_dense_at((double *)L->S, j, tt);
    feet(L, qd, qd + loop_n(L), ft);
}

/* -- the quiet steps ----------------------------------------------------------------------------- */

/* the feet on the dense output at tt into S[LS_FEET] (the scuff's tracking: loop_rules.ev_track_scuff) */
static void
feet_into_state(double *S, void *ctx, double tt)
{
    feet_at((Loop *)ctx, tt, S + LS_FEET);
}

/* How the stance starts under the ground force F (loop_rules.ev_stance_start: HybridSimulator._check_stance_start);
 * the slip witness is watched whenever there is a friction coefficient (nothing is latched while the loop runs) */
static int
stance_start(Loop *L, const double *F)
{
    return ev_stance_start(L->has_mu, L->mu, ev_normal_force(L->S, F[0], F[1]), ev_tangential_force(L->S, F[0], F[1]));
}

/* a sample into row: the three-link's (loop_rules.ev_sample_row) or a described robot's (ev_sample_row_of, n
 * coordinates and m torques) */
static void
sample_row(const Loop *L, double *row, double t, const double *q, const double *dq, int leg, const double *F,
           const double *u, double residual)
{
    if (L->table)
        ev_sample_row_of(row, t, (double *)q, (double *)dq, loop_n(L), leg, (double *)F, (double *)u, loop_m(L),
                         residual);
    else ev_sample_row(row, t, (double *)q, (double *)dq, leg, (double *)F, (double *)u, residual);
}

/* HybridSimulator._integrate's event branch for a touchdown in front at t_ev, then _reset's: the event's
 * sample (_accept), the impact (loop_rules.ev_impact, as resets.touchdown_reset calls it), relabeling, the
 * sample after it, the next mode's start. Whatever the Python code would report or act on (a warning of the
 * impact, an invariant of check_impact, a possible Zeno stop, max_events, an event loop, a new stance that the
 * ground pulls or that slips at once: the rules' answers; a Python controller) hands the step back instead: 0.
 * Else 3, two samples in rows (2 ROW_WIDTH values), residual_out the larger |residual|, the record in the state's records. */
static int
touchdown(Loop *L, double t_ev, double *rows, double E0, double push_work, double energy_lost, double *residual_out)
{
    int old = (int)L->stance_leg, nw = 3 - old;
    if (L->law_kind == CALLBACK) { L->why = WHY_CALLED_BACK_LAW; return 0; }
    /* the impact history's rules (loop_rules: ImpactHistory.record, HybridSimulator._add_event); the ring holds
     * the last 49 mode events, so the 50th before this one where there are that many */
    long m = (long)L->mode_events;
    if (ev_impacts_close(L->n_impacts, L->last_impact, t_ev, L->zeno_interval)) { L->why = WHY_IMPACTS_CLOSE; return 0; }
    if (ev_over_budget(m + 1, L->max_events)) { L->why = WHY_MAX_EVENTS; return 0; }
    if (ev_event_loop(m + 1, ev_ring_oldest(L->S), t_ev)) { L->why = WHY_EVENT_LOOP; return 0; }
    int n = loop_n(L), w_at = 2 * n;
    double y[LS_NMAX], ue[LS_NQ_MAX], Fe[2] = {0.0, 0.0};
    for (int j = 0; j <= w_at; j++) y[j] = rk_dense_at(L->S, j, t_ev);
    double *q = y, *dqm = y + n, w = y[w_at];
    torque_of(L, t_ev, q, dqm, ue);
    if (L->compute_grf) stance_force(L, q, dqm, ue, Fe);
    if (L->callback_failed) { L->why = WHY_LAW_FAILED; return 0; }
    /* the impact and its checks (loop_rules.ev_impact: resets.impact_warnings' and invariants.check_impact's) */
    memcpy(L->q_impact, q, n * sizeof(double));
    memcpy(L->dq_minus, dqm, n * sizeof(double));
    int checks = ev_impact(L->S, nw, old, L->has_mu);
    double *dqp = L->dq_plus, *imp = L->impulse, loss = ev_impact_loss(L->S);
    if (checks & IMPACT_OLD_FOOT_SINKS) { L->why = WHY_OLD_FOOT_SINKS; return 0; }
    if (checks & (IMPACT_PULLS | IMPACT_OUTSIDE_CONE)) { L->why = WHY_IMPULSE_CHECK; return 0; }
    if (L->check_invariants && ev_stays_down(L->feet_after[old - 1][3], L->contact_tol)) { L->why = WHY_OLD_FOOT_STAYS; return 0; }
    /* the new stance (_check_stance_start): the ground must push, inside the friction cone */
    double up[LS_NQ_MAX], Fp[2];
    L->stance_leg = nw;
    torque_of(L, t_ev, q, dqp, up);
    stance_force(L, q, dqp, up, Fp);
    L->stance_leg = old;
    if (L->callback_failed) { L->why = WHY_LAW_FAILED; return 0; }
    if (stance_start(L, Fp) != STANCE_HOLDS) { L->why = WHY_STANCE_REFUSED; return 0; }
    /* applied */
    double lost = ev_energy_lost_after(energy_lost, loss);
    double res_e = ev_energy_residual(L->energy_before, E0, w, push_work, energy_lost);
    double res_p = ev_energy_residual(L->energy_after, E0, w, push_work, lost);
    sample_row(L, rows, t_ev, q, dqm, old, Fe, ue, res_e);
    sample_row(L, rows + loop_row_width(L), t_ev, q, dqp, nw, Fp, up, res_p);
    *residual_out = ev_running_max(fabs(res_e), fabs(res_p));
    double p[4];
    if (L->table) L->table->foot_positions(q, p);
    else k_foot_positions(q, L->k_pos, p);
    ev_foot_point(p, nw, L->pin);
    double *v = new_record(L->S, RECORD_TOUCHDOWN, old, nw);
    v[REC_TD_T] = t_ev;
    memcpy(v + REC_TD_Q, q, n * sizeof(double));
    memcpy(v + REC_TD_DQ_MINUS, dqm, n * sizeof(double));
    memcpy(v + REC_TD_DQ_PLUS, dqp, n * sizeof(double));
    memcpy(v + REC_TD_IMPULSE, imp, 2 * sizeof(double));
    v[REC_TD_LOSS] = loss;
    v[REC_TD_LOST] = lost;
    memcpy(v + REC_TD_PIN, L->pin, 2 * sizeof(double));
    L->stance_leg = nw;
    for (int leg = 1; leg <= 2; leg++)
        if (ev_disarmed_by_reset(leg, 0, old, nw)) L->armed[leg - 1] = 0;
    ev_forget_feet_end(L->S);     /* EventLocator.after_reset: the step end's are not the new state's */
    ev_forget_force_end(L->S);
    ev_count_impact(L->S, t_ev);
    ev_count_mode_event(L->S, t_ev);
    /* the next mode's start (begin): f at the state after the impact, the step size carried over */
    memcpy(L->y, q, n * sizeof(double));
    memcpy(L->y + n, dqp, n * sizeof(double));
    L->y[w_at] = w;
    carry_step(L, L->h_abs);
    restart(L, t_ev, L->t_bound);
    return 3;
}

/* The feet and the force at the step's end, kept for the next step's start (EventLocator's _feet_end
 * and _force_end: loop_rules.ev_keep_feet_end, ev_keep_force_end) */
static void
cache_step_end(Loop *L, double t, double *feet8, const double *F)
{
    ev_keep_feet_end(L->S, t, feet8, 0);
    ev_keep_force_end(L->S, t, F[0], F[1]);
}

/* The body of HybridSimulator._integrate for the step just taken, when nothing happens in it but a
 * scuff (its start, its end): 1 and the step accepted (sample written to row, state projected), 2 the
 * same and a scuff ended in it (its record in the state's records, its Event the Python code's to make), or 0 (pending:
 * nothing changed but the cache of the step's start). */
static int
quiet_step(Loop *L, double *row, double E0, double push_work, double energy_lost, double *drift_out,
           double *rate_out, double *residual_out)
{
    int n = loop_n(L);
    double q[LS_NQ_MAX], dq[LS_NQ_MAX], w = L->y[2 * n], ft1[8], ft0[8], F0[2], F1[2];
    memcpy(q, L->y, n * sizeof(double));
    memcpy(dq, L->y + n, n * sizeof(double));
    if (ev_diverging(dq, n, L->max_speed)) { L->why = WHY_DIVERGING; return 0; }
    feet(L, q, dq, ft1);
    /* the torque and force of the step's last evaluation, at its end (FSAL) */
    memcpy(L->end_u, L->last_u, loop_m(L) * sizeof(double));
    F1[0] = L->end_F[0] = L->last_F[0];
    F1[1] = L->end_F[1] = L->last_F[1];
    if (ev_feet_kept_at(L->S, L->t_old) && ev_force_kept_at(L->S, L->t_old)) {
        memcpy(ft0, L->feet_end, sizeof ft0);
        F0[0] = L->force_end[0]; F0[1] = L->force_end[1];
    } else {
        feet(L, L->y_old, L->y_old + n, ft0);
        force_at(L, L->t_old, L->y_old, L->y_old + n, F0);
        cache_step_end(L, L->t_old, ft0, F0);   /* a step handed back starts from them (EventLocator.locate) */
    }
    int st = (int)L->stance_leg, sw = 3 - st;
    int scuffing = L->scuffing[sw - 1] != 0.0;
    double *kept = L->scuff[sw - 1], scuff[3] = {kept[0], kept[1], kept[2]}, deepest = L->deepest_scuff;
    double scuffs = L->scuffs;
    int touching = 0;
    double t_touch = 0.0;
    /* EventLocator.locate: the witnesses of stance, in witnesses.witnesses' order (touchdown, liftoff, slip) */
    if (L->impact_phase && L->armed[sw - 1]) {
        double g1 = ft1[4 * (sw - 1) + 1], g0 = ft0[4 * (sw - 1) + 1], bracket[2] = {L->t_old, L->t}, t_root;
        int crossing = ev_triggered(g0, g1);
        if (!crossing && g0 > 0 && g1 > 0 && ev_may_dip(L->S, rhs, L, sw, g0, g1)) {
            crossing = 1;
            bracket[0] = L->S[LS_RESULT];
            bracket[1] = L->S[LS_RESULT + 1];
        }
        if (crossing) {
            if (ev_locate_height_crossing(L->S, rhs, L, sw, bracket[0], bracket[1]) < 0 || !L->front_rule) {
                L->why = WHY_CROSSING_IN_PYTHON;
                return 0;
            }
            t_root = L->S[LS_RESULT];
            /* _is_scuff (guards.starts_scuff): at or behind the stance foot, and under scuff_rule "forward"
             * moving forward, a scuff; else a touchdown (the Python code's) */
            double fr[8];
            feet_at(L, t_root, fr);
            const double *fw = fr + 4 * (sw - 1);
            if (!ev_starts_scuff(L->forward_rule != 0.0, L->front_tol, fw[0], fw[2], fw[3], fr[4 * (st - 1)])) {
                touching = 1;         /* a touchdown: applied below if nothing else happens in the step */
                t_touch = t_root;
            } else {
                /* ImpactHistory.accumulating: a crossing that continues impacts whose gaps shrink is the Python
                 * code's to decide (an impact of the Zeno limit) */
                if (ev_accumulating(L->recent_impacts, L->n_recent, t_root)) { L->why = WHY_ACCUMULATING; return 0; }
                scuffing = 1;
                scuffs = ev_start_scuff(scuff, 0, t_root, scuffs);
            }
        }
    }
    {
        if (ev_triggered(ev_normal_force(L->S, F0[0], F0[1]), ev_normal_force(L->S, F1[0], F1[1]))) { L->why = WHY_LIFTOFF; return 0; }
    }
    if (L->has_mu) {
        if (ev_triggered(ev_cone_margin(L->S, F0[0], F0[1]), ev_cone_margin(L->S, F1[0], F1[1]))) { L->why = WHY_SLIP; return 0; }
    }
    if (touching) {
        if (scuffing) { L->why = WHY_TOUCHDOWN_WHILE_SCUFFING; return 0; }
        /* the locator's cache is of the step's end (EventLocator.locate sets it before it looks) */
        cache_step_end(L, L->t, ft1, F1);
        return touchdown(L, t_touch, row, E0, push_work, energy_lost, residual_out);
    }
    /* a resting free foot pushed into the ground, at the step's end or inside it (EventLocator._resting_feet) */
    if (L->impact_phase && !L->armed[sw - 1] && !scuffing
        && (ev_violated(ft1[4 * (sw - 1) + 1], L->ground_tol)
            || ev_resting_foot_dips(L->S, rhs, L, sw, ft0[4 * (sw - 1) + 1], ft1[4 * (sw - 1) + 1]))) {
        L->why = WHY_FOOT_PUSHED_IN;
        return 0;
    }
    int ended = 0;
    if (scuffing) {
        /* EventLocator._track_scuffs, on copies: a scuff that leaves the model is the Python code's to report */
        rk_dense(L->S, rhs, L);
        memcpy(L->scuff_trial, scuff, sizeof scuff);
        L->deepest_trial = deepest;
        ended = ev_track_scuff(L->S, feet_into_state, L, sw, st, L->t);
        if (ended < 0) { L->why = WHY_SCUFF_LEAVES_MODEL; return 0; }
        memcpy(scuff, L->scuff_trial, sizeof scuff);
        deepest = L->deepest_trial;
    }
    /* modes.project_onto_pin */
    double *fs = ft1 + 4 * (st - 1);
    double drift = ev_pin_drift(fs, L->pin, L->tan_s), rate = ev_pin_drift_rate(fs);
    if (L->project) ev_project_onto_pin(q, dq, fs, L->pin, L->tan_s);
    /* invariants.check_sample (a violation: pending, and the Python code reports it) */
    if (L->check_invariants) {
        if (!ev_finite_state(q, dq, n)) { L->why = WHY_NON_FINITE; return 0; }
        if (!scuffing && ev_violated(ft1[4 * (sw - 1) + 1], L->ground_tol)) { L->why = WHY_FOOT_BELOW_GROUND; return 0; }
        if (ev_violated(ev_normal_force(L->S, F1[0], F1[1]), L->force_tol)) { L->why = WHY_GROUND_PULLS; return 0; }
        if (L->has_mu && L->stop_on_slip && ev_violated(ev_cone_margin(L->S, F1[0], F1[1]), L->force_tol)) {
            L->why = WHY_OUTSIDE_CONE;
            return 0;
        }
    }
    if (L->callback_failed) { L->why = WHY_LAW_FAILED; return 0; }
    /* accepted: the locator's state, the sample, the projected state */
    memcpy(kept, scuff, sizeof scuff);
    L->deepest_scuff = deepest;
    L->scuffs = scuffs;
    L->scuffing[sw - 1] = scuffing && !ended;
    if (ended) {     /* EventLocator._scuff_event's data */
        double *v = new_record(L->S, RECORD_SCUFF_ENDED, sw, st);
        memcpy(v + REC_SCUFF_SCUFF, scuff, sizeof scuff);
        v[REC_SCUFF_T_UP] = L->t;
        for (int j = 0; j < n; j++) {     /* q, then dq */
            int in_step = ev_within_step(L->t_old, L->t, scuff[2]);
            v[REC_SCUFF_Q + j] = in_step ? rk_dense_at(L->S, j, scuff[2]) : NAN;
            v[REC_SCUFF_DQ + j] = in_step ? rk_dense_at(L->S, n + j, scuff[2]) : NAN;
        }
    }
    cache_step_end(L, L->t, ft1, F1);
    for (int leg = 1; leg <= 2; leg++)
        if (!L->armed[leg - 1] && ev_arms(leg != st, ft1[4 * (leg - 1) + 1], L->arm_height)) L->armed[leg - 1] = 1;
    double TV[2];
    if (L->table) L->table->energy(q, dq, TV);
    else k_energy(q, dq, L->k_energy, TV);
    double residual = ev_energy_residual(TV[0] + TV[1], E0, w, push_work, energy_lost);
    sample_row(L, row, L->t, q, dq, st, F1, L->end_u, residual);
    if (L->project) {
        memcpy(L->y, q, n * sizeof(double));
        memcpy(L->y + n, dq, n * sizeof(double));
    }
    *drift_out = drift;
    *rate_out = rate;
    *residual_out = residual;
    return ended ? 2 : 1;
}

/* -- Python interface ------------------------------------------------------------------------------ */

static PyObject *
list_of(const double *v, Py_ssize_t n)
{
    PyObject *lst = PyList_New(n);
    if (lst == NULL) return NULL;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *x = PyFloat_FromDouble(v[i]);
        if (x == NULL) {
            Py_DECREF(lst);
            return NULL;
        }
        PyList_SET_ITEM(lst, i, x);
    }
    return lst;
}

/* set_model(k_stance, k_feet, k_pos, k_energy, k_terms, k_impact, l_leg) */
static PyObject *
Loop_set_model(Loop *L, PyObject *args)
{
    PyObject *a, *b, *c, *d, *e, *f;
    if (!PyArg_ParseTuple(args, "OOOOOOd", &a, &b, &c, &d, &e, &f, &L->l_leg)) return NULL;
    if (doubles(a, L->k_stance, 22, 22, "k_stance", NULL) || doubles(b, L->k_feet, 9, 9, "k_feet", NULL)
        || doubles(c, L->k_pos, 9, 9, "k_pos", NULL) || doubles(d, L->k_energy, 9, 9, "k_energy", NULL)
        || doubles(e, L->k_terms, 22, 22, "k_terms", NULL) || doubles(f, L->k_impact, 26, 26, "k_impact", NULL))
        return NULL;
    Py_RETURN_NONE;
}

/* set_kernels(table, joints, robot): the loop's model becomes a described robot, whose kernels are the C entry
 * points of its compiled twin's capsule KERNEL_TABLE (model_kernels.py; _kernel_table.h), its M actuators turning
 * the entries joints of q, its name robot. Its right-hand side (rhs, begin) is then modes._generated_functions',
 * its steps the generated ones of its size, its quiet steps, touchdowns and samples the three-link's rules with its
 * sizes; the control periods' commands are the three-link's only (three_link_only) */
static PyObject *
Loop_set_kernels(Loop *L, PyObject *args)
{
    PyObject *capsule, *joints;
    const char *robot;
    Py_ssize_t m;
    double j[LS_NQ_MAX];
    if (!PyArg_ParseTuple(args, "OOs", &capsule, &joints, &robot)) return NULL;
    const KernelTable *K = PyCapsule_GetPointer(capsule, KERNEL_TABLE_CAPSULE);
    if (K == NULL) return NULL;
    if (K->version != KERNEL_TABLE_VERSION) {
        PyErr_Format(PyExc_ValueError, "set_kernels(): a kernel table of version %d, this loop reads version %d: "
                     "rebuild the robot's kernels", K->version, KERNEL_TABLE_VERSION);
        return NULL;
    }
    /* (two contact points: the feet, whose positions and kinematics fill the state's fields of 4 and 8) */
    if (K->n < 3 || K->n > LS_NQ_MAX || K->contacts != 2 || K->actuators < 1 || K->actuators > LS_NQ_MAX - 3) {
        PyErr_Format(PyExc_ValueError, "set_kernels(): the loop runs robots of 3 to %d coordinates, 2 contact points "
                     "and 1 to %d actuators (this one: %d, %d, %d)", LS_NQ_MAX, LS_NQ_MAX - 3, K->n, K->contacts,
                     K->actuators);
        return NULL;
    }
    if (doubles(joints, j, K->actuators, K->actuators, "set_kernels(): joints", &m)) return NULL;
    for (Py_ssize_t i = 0; i < m; i++)
        if (!(j[i] >= 0.0 && j[i] < K->n && j[i] == floor(j[i]))) {
            PyErr_Format(PyExc_ValueError, "set_kernels(): joints[%zd] is not an entry of q (0..%d)", i, K->n - 1);
            return NULL;
        }
    Py_INCREF(capsule);
    Py_XSETREF(L->table_owner, capsule);
    L->table = K;
    memcpy(L->joints, j, m * sizeof(double));
    snprintf(L->robot, sizeof L->robot, "%s", robot);
    L->n_q = K->n;
    L->n_y = 2 * K->n + 1;
    L->n = K->n;
    L->m = K->actuators;
    L->row_width = 1 + 2 * K->n + 4 + K->actuators;     /* (loop_state.sample_row) */
    Py_RETURN_NONE;
}

/* The entry point that computes a compiled law's command (law_torque): NULL with a ValueError where the loop's model
 * is a described robot's (set_kernels), whose laws are Python controllers (its steps, quiet steps, touchdowns and
 * periods run here: begin, step, run, held, periods) */
static int
three_link_only(Loop *L, const char *what)
{
    if (L->table == NULL) return 0;
    PyErr_Format(PyExc_ValueError, "%s(): a compiled law runs the three-link biped only; a described robot's law is "
                 "a Python controller", what);
    return 1;
}

/* rhs(t, y) -> dy, for the initial step size */
static PyObject *
Loop_rhs(Loop *L, PyObject *args)
{
    PyObject *y;
    Py_ssize_t n = L->table ? 2 * L->table->n + 1 : N;
    double t, yy[LS_NMAX], dy[LS_NMAX];
    if (!PyArg_ParseTuple(args, "dO", &t, &y) || doubles(y, yy, n, n, "y", NULL)) return NULL;
    int rc = rhs(L, t, yy, dy);
    if (L->callback_failed) return raise_callback_error(L);
    if (rc < 0) return NULL;
    return list_of(dy, n);
}

/* step() -> OUTCOME_DONE, OUTCOME_FAILED (the state's fail_kind, fail_value, fail_t) or OUTCOME_RAISED */
static PyObject *
Loop_step(Loop *L, PyObject *unused)
{
    (void)unused;
    if (rk_step(L->S, rhs, L) < 0) return PyLong_FromLong(L->callback_failed ? OUTCOME_RAISED : OUTCOME_FAILED);
    /* the torque and force of the step's last evaluation, at its end (FSAL), as handed() gives them */
    memcpy(L->end_u, L->last_u, loop_m(L) * sizeof(double));
    L->end_F[0] = L->last_F[0]; L->end_F[1] = L->last_F[1];
    return PyLong_FromLong(OUTCOME_DONE);
}

/* A run (run, held, periods, period): quiet steps until t_end, the samples written into the Samples' array
 * (handed to the run as a buffer: Samples._data); its outcome OUTCOME_DONE, OUTCOME_EVENT (a step taken, for Python to
 * handle), OUTCOME_NEED_ROOM (the sample array or the event records are full), OUTCOME_FAILED (the step failed: failure = (kind,
 * value, t)) or OUTCOME_RAISED. Its counters are the state's (n_samples, appended, provisional, every, last_only,
 * the energy terms), held in locals while it runs. */
typedef struct {
    double E0, push_work, energy_lost;
    double *data;
    long cap, n, appended, every, accepted;
    int provisional, last_only;
    double t_accepted, w_accepted, h_accepted;   /* the last accepted step's */
} RunState;

/* The quiet steps to t_end (the loop of HybridSimulator._integrate), writing samples as Samples.append
 * does: OUTCOME_DONE, OUTCOME_EVENT, OUTCOME_NEED_ROOM (no room for a step's samples or its event: the Python code makes room and calls
 * again) or OUTCOME_FAILED. Touchdowns and ended scuffs are applied and recorded in the state's records, and the steps go on. */
static int
quiet_until(Loop *L, double t_end, RunState *rs)
{
    while (L->t < t_end) {
        if ((!rs->last_only && rs->n + 2 > rs->cap) || (int)L->n_records == LS_EVENT_ROOM) return OUTCOME_NEED_ROOM;
        if (rk_step(L->S, rhs, L) < 0) return OUTCOME_FAILED;
        double drift = 0.0, rate = 0.0, residual, row[2 * ROW_MAX];
        int width = loop_row_width(L);
        int accepted_how = quiet_step(L, row, rs->E0, rs->push_work, rs->energy_lost, &drift, &rate, &residual);
        if (!accepted_how) return OUTCOME_EVENT;
        long at = ev_sample_slot(rs->n, rs->provisional, rs->last_only);
        if (accepted_how == 3) {
            /* the event's sample (kept: _reset's keep_last), then the one after the impact (kept) */
            memcpy(rs->data + width * at, row, width * sizeof(double));
            rs->n = at + 1;
            at = ev_sample_slot(rs->n, 0, rs->last_only);
            memcpy(rs->data + width * at, row + width, width * sizeof(double));
            rs->n = at + 1;
            rs->appended += 2;
            rs->provisional = 0;
            rs->energy_lost = L->records[(int)L->n_records - 1][REC_V + REC_TD_LOST];
        } else {
            if (accepted_how == 2) {
                /* the scuff's Event comes before this step's sample (HybridSimulator._push_event: keep_last) */
                rs->provisional = 0;
                at = ev_sample_slot(rs->n, 0, rs->last_only);
            }
            memcpy(rs->data + width * at, row, width * sizeof(double));
            rs->n = at + 1;
            rs->appended += 1;
            rs->provisional = ev_provisional(rs->appended, rs->every);
            L->max_drift = ev_running_max(L->max_drift, drift);
            L->max_rate = ev_running_max(L->max_rate, rate);
        }
        rs->t_accepted = L->t;
        rs->w_accepted = L->y[2 * loop_n(L)];
        rs->h_accepted = L->h_abs;
        rs->accepted++;
        L->steps += 1;
        L->max_residual = ev_running_max(L->max_residual, fabs(residual));
    }
    return OUTCOME_DONE;
}

/* A run's state: its energy terms and the Samples' counters from the state, and the Samples' array ``data``
 * (a writable C-contiguous buffer of rows of ROW_WIDTH doubles), whose counters end_run writes back. 0, or -1 with
 * an exception. */
static int
run_state(Loop *L, PyObject *data, RunState *rs, Py_buffer *buf)
{
    if (PyObject_GetBuffer(data, buf, PyBUF_C_CONTIGUOUS | PyBUF_WRITABLE) < 0) return -1;
    rs->E0 = L->e0;
    rs->push_work = L->push_work;
    rs->energy_lost = L->energy_lost;
    rs->n = (long)L->n_samples;
    rs->appended = (long)L->appended;
    rs->every = (long)L->every;
    rs->provisional = L->provisional != 0.0;
    rs->last_only = L->last_only != 0.0;
    rs->data = buf->buf;
    rs->cap = (long)(buf->len / (Py_ssize_t)(loop_row_width(L) * sizeof(double)));
    rs->accepted = 0;
    rs->t_accepted = L->t_old;
    rs->w_accepted = 0.0;
    rs->h_accepted = L->h_abs;
    return 0;
}

/* the end of a run: the Samples' counters and the energy lost written back into the state, and where a step
 * was accepted the simulator's time, work, step size and state (the last sample's q and dq, its arrays made
 * when read: sim_state_unmade) */
static void
end_run(Loop *L, RunState *rs, Py_buffer *buf)
{
    L->n_samples = rs->n;
    L->appended = rs->appended;
    L->provisional = rs->provisional;
    L->energy_lost = rs->energy_lost;
    if (rs->accepted > 0) {
        L->sim_t = rs->t_accepted;
        L->sim_work = rs->w_accepted;
        L->sim_h = rs->h_accepted;
        /* (q and dq follow ROW_Q in every model's row: loop_state.sample_row) */
        memcpy(L->sim_q, rs->data + loop_row_width(L) * (rs->n - 1) + ROW_Q, loop_n(L) * sizeof(double));
        memcpy(L->sim_dq, rs->data + loop_row_width(L) * (rs->n - 1) + ROW_Q + loop_n(L), loop_n(L) * sizeof(double));
        L->sim_state_unmade = 1.0;
    }
    PyBuffer_Release(buf);
}

/* end_run, then the run's Outcome (OUTCOME_RAISED where the torque law failed: the caller takes the steps
 * accepted before it, then raise_error()) */
static PyObject *
run_result(Loop *L, int outcome, RunState *rs, Py_buffer *buf)
{
    end_run(L, rs, buf);
    return PyLong_FromLong(L->callback_failed ? OUTCOME_RAISED : outcome);
}

/* the start of a control period under a held torque (begin() in the same mode) */
static void
hold(Loop *L, double u0, double u1, double t_bound)
{
    L->law_kind = HELD;
    L->u_hold[0] = u0;
    L->u_hold[1] = u1;
    restart(L, L->t, t_bound);
}

/* Whether the stance guards refuse the torque hold() just set, at the period's start: the ground would
 * pull (normal force < 0) or the force leave the friction cone, on the force restart() evaluated there (the
 * test of HybridSimulator._check_stance_start). Then the period is the Python code's, which reports the
 * liftoff or the slip at that instant: the start's evaluation is taken back (the Python code makes its
 * own), nothing else was changed. */
static int
refused_at_start(Loop *L)
{
    if (stance_start(L, L->last_F) == STANCE_HOLDS) return 0;
    L->nfev -= 1;
    return 1;
}

/* The end of the control period under way at t, *k the periods begun so far (loop_rules.ev_period_index and
 * ev_period_end, as HybridSimulator.advance_period calls them): *k becomes the count of periods begun. NAN (and *k
 * unchanged) where the index would pass 2^53 (hybrid.period_index refuses it). */
static double
period_end(double t, double period, double t_final, long *k)
{
    long j = ev_period_index(t, period, *k);
    if (j < 0) return NAN;
    *k = j + 1;
    return ev_period_end(j, period, t_final);
}

/* Whether a METH_FASTCALL entry point got other than n arguments (then its TypeError is set) */
static int
wrong_nargs(Py_ssize_t nargs, Py_ssize_t n, const char *name)
{
    if (nargs == n) return 0;
    PyErr_Format(PyExc_TypeError, "%s() takes %zd arguments (%zd given)", name, n, nargs);
    return 1;
}

/* periods(law, period, t_final, t_stop, data) -> an Outcome (and t_next, refused_u): control periods held (as
 * HybridSimulator.advance_period computes them, the command at each period's start: a compiled law's
 * (address, parameters, name), or a Python controller, called once a period and checked by
 * call_controller) until t_final, or the first period boundary at or after t_stop - 1e-9 period (a push due),
 * or a run outcome the Python code must see (then mid-period: its end t_next and its torque come back), or
 * a period whose command the stance guards refuse at its start (OUTCOME_TORQUE_CHANGE: not begun, the count and
 * torque of the periods before it are the state's control_periods and sim_u, and refused, its command (else
 * None): the Python code runs the
 * period with that command, so that a controller is called once a period on both loops). A command that fails (OUTCOME_RAISED)
 * counts its period as begun, as advance_period does. */
static PyObject *
Loop_periods(Loop *L, PyObject *const *args, Py_ssize_t nargs)
{
    if (wrong_nargs(nargs, 5, "periods")) return NULL;
    double period = PyFloat_AsDouble(args[1]), t_final = PyFloat_AsDouble(args[2]), t_stop = PyFloat_AsDouble(args[3]);
    long k0 = (long)L->control_periods;
    if (PyErr_Occurred()) return NULL;
    if (!(period > 0.0 && period < INFINITY)) {
        PyErr_SetString(PyExc_ValueError, "periods(): period must be a positive finite number");
        return NULL;
    }
    CompiledLaw law;
    PyObject *command = PyCallable_Check(args[0]) ? args[0] : NULL;
    if (command == NULL && L->table) {
        PyErr_SetString(PyExc_ValueError, "periods(): a described robot's law is a Python controller (a compiled law "
                        "is the three-link's)");
        return NULL;
    }
    if (command == NULL && compiled_law_from(args[0], &law) < 0) return NULL;
    int m = loop_m(L);
    long k_first = k0;
    if (isnan(period_end(L->t, period, t_final, &k_first))) {   /* (the first period's index only can be late) */
        PyErr_SetString(PyExc_ValueError, "periods(): more than 2**53 control periods before t");
        return NULL;
    }
    RunState rs;
    Py_buffer buf;
    if (run_state(L, args[4], &rs, &buf) < 0) return NULL;
    int outcome = OUTCOME_DONE;
    double t_next = L->t, u[LS_NQ_MAX], refused[LS_NQ_MAX];
    memcpy(u, L->u_hold, m * sizeof(double));
    for (int i = 0; i < m; i++) refused[i] = NAN;
    while (ev_next_period_runs(L->t, t_final, t_stop, period)) {
        long k = k0;
        double t_end = period_end(L->t, period, t_final, &k), u_now[LS_NQ_MAX];
        if (command != NULL) call_controller(L, command, L->t, L->y, L->y + loop_n(L), u_now);
        else apply_law(L, &law, L->t, L->y, L->y + 5, u_now);
        if (L->callback_failed) {       /* (run_result: OUTCOME_RAISED) */
            k0 = k;
            break;
        }
        carry_step(L, L->h_abs);     /* as begin() carries it over */
        memcpy(L->u_hold, u_now, m * sizeof(double));     /* (a described robot's M torques: hold's first two) */
        hold(L, u_now[0], u_now[1], t_end);
        if (refused_at_start(L)) {
            outcome = OUTCOME_TORQUE_CHANGE;
            memcpy(refused, u_now, m * sizeof(double));
            break;
        }
        k0 = k;
        t_next = t_end;
        memcpy(u, u_now, m * sizeof(double));
        outcome = quiet_until(L, t_next, &rs);
        if (outcome != OUTCOME_DONE) break;
    }
    L->control_periods = (double)k0;
    memcpy(L->sim_u, u, m * sizeof(double));
    L->t_next = t_next;
    memcpy(L->refused_u, refused, m * sizeof(double));
    return run_result(L, outcome, &rs, &buf);
}

/* run(t_end, data) -> the Outcome of the quiet steps to t_end */
static PyObject *
Loop_run(Loop *L, PyObject *const *args, Py_ssize_t nargs)
{
    RunState rs;
    Py_buffer buf;
    if (wrong_nargs(nargs, 2, "run")) return NULL;
    double t_end = PyFloat_AsDouble(args[0]);
    if (PyErr_Occurred() || run_state(L, args[1], &rs, &buf) < 0) return NULL;
    return run_result(L, quiet_until(L, t_end, &rs), &rs, &buf);
}

/* held(t_end, data): a control period under the state's held torque sim_u from where the last run left the
 * state (the same mode): the start of begin() (f = rhs(t, y) under the new torque, the carried-over step size
 * sim_h), then run() to its end, in one call (the node's period) */
static PyObject *
Loop_held(Loop *L, PyObject *const *args, Py_ssize_t nargs)
{
    if (wrong_nargs(nargs, 2, "held")) return NULL;
    double t_bound = PyFloat_AsDouble(args[0]);
    if (PyErr_Occurred()) return NULL;
    if (!isnan(L->sim_h)) carry_step(L, L->sim_h);
    if (L->table) {     /* (its M torques) */
        memcpy(L->u_hold, L->sim_u, loop_m(L) * sizeof(double));
        hold(L, L->sim_u[0], L->sim_u[1], t_bound);
    } else {
        hold(L, L->sim_u[0], L->sim_u[1], t_bound);
    }
    if (L->callback_failed) return raise_callback_error(L);
    return Loop_run(L, args, nargs);
}


static double
seconds_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);     /* time.perf_counter's clock */
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* period(period, u, t_final, data) -> an Outcome: HybridSimulator.advance_period(period, u, t_final=t_final)
 * under a held torque, in one call (the node's control period), when the loop holds the simulator's state and
 * the run goes on past its first sample. OUTCOME_DONE with no records waiting (n_records): a period run quiet
 * to its end (the state's sim_t, sim_work, sim_h, control_periods, sim_u, sim_q and sim_dq written, its wall
 * time kept for stats()); another outcome, or records to take, for the Python code to finish the period that
 * ends at the state's t_next (a touchdown or an ended scuff to make Events of, a step handed back, room to
 * make, a failure); OUTCOME_DECLINED having changed nothing: the Python code runs the period (the loop is
 * stale, the run has ended, u is not two finite numbers, a bad period, the stance guards refuse u at the
 * period's start, ...). */
static PyObject *
Loop_period(Loop *L, PyObject *const *args, Py_ssize_t nargs)
{
    if (wrong_nargs(nargs, 4, "period")) return NULL;
    double wall0 = seconds_now(), u[LS_NQ_MAX];
    int m = loop_m(L);
    if (L->mode_begun == 0.0 || L->n_latched != 0.0 || (L->scuffing[0] != 0.0 && L->scuffing[1] != 0.0)
        || m_finite(args[1], m, u) < 0)
        /* (a latched guard, two scuffs: the Python code follows them; u not M finite numbers: it says why) */
        return PyLong_FromLong(OUTCOME_DECLINED);
    double period = PyFloat_AsDouble(args[0]), t_final = PyFloat_AsDouble(args[2]);
    if (PyErr_Occurred() || PyBool_Check(args[0]) || !(period > 0.0 && period < INFINITY) || PyBool_Check(args[2])
        || !(t_final >= 0.0)) {   /* Python says why */
        PyErr_Clear();
        return PyLong_FromLong(OUTCOME_DECLINED);
    }
    if (L->running == 0.0 || L->initial_sample_pending != 0.0) return PyLong_FromLong(OUTCOME_DECLINED);
    long k = (long)L->control_periods;
    double t_next = period_end(L->t, period, t_final, &k);
    if (!isfinite(t_next)) return PyLong_FromLong(OUTCOME_DECLINED);     /* the Python code says why */
    if (!isnan(L->sim_h)) carry_step(L, L->sim_h);
    memcpy(L->u_hold, u, m * sizeof(double));     /* (a described robot's M torques: hold's first two) */
    hold(L, u[0], u[1], t_next);
    if (refused_at_start(L)) return PyLong_FromLong(OUTCOME_DECLINED);
    L->control_periods = (double)k;
    memcpy(L->sim_u, u, m * sizeof(double));
    L->t_next = t_next;
    RunState rs;
    Py_buffer buf;
    if (run_state(L, args[3], &rs, &buf) < 0) return NULL;
    PyObject *r = run_result(L, quiet_until(L, t_next, &rs), &rs, &buf);
    L->wall_time += seconds_now() - wall0;
    return r;
}

/* locate_crossing(leg, ta, tb) -> the time foot leg's height crosses zero on the last step's dense output
 * (guards.locate_crossing, by the same brentq), or None where brentq would raise */
static PyObject *
Loop_locate_crossing(Loop *L, PyObject *args)
{
    int leg;
    double ta, tb;
    if (!PyArg_ParseTuple(args, "idd", &leg, &ta, &tb)) return NULL;
    if (leg != 1 && leg != 2) {
        PyErr_SetString(PyExc_ValueError, "locate_crossing(): leg 1 or 2");
        return NULL;
    }
    int rc = ev_locate_height_crossing(L->S, rhs, L, leg, ta, tb);
    if (L->callback_failed) return raise_callback_error(L);
    if (rc < 0) Py_RETURN_NONE;
    return PyFloat_FromDouble(L->S[LS_RESULT]);
}

/* raise_error(): raise the Python controller's exception that ended the last run (outcome OUTCOME_RAISED) */
static PyObject *
Loop_raise_error(Loop *L, PyObject *unused)
{
    (void)unused;
    if (!L->callback_failed) Py_RETURN_NONE;
    return raise_callback_error(L);
}

/* begin(law): a mode's start, as make_stepper builds a stepper (integrators._ListRungeKutta restart: f = rhs(t,
 * y)), from the state's method, stance_leg, pin, u_hold, t, y, t_bound and h_abs (the carried-over step size),
 * which the Python code wrote (CompiledStepper.start); law None (u_hold held), a Python callable (called
 * back) or a compiled law (address, parameters, name) */
static PyObject *
Loop_begin(Loop *L, PyObject *law)
{
    int kind = law == Py_None ? HELD : PyCallable_Check(law) ? CALLBACK : COMPILED;
    if (L->table) {     /* a described robot: stance on a contact point or flight, a held or called-back law */
        if ((L->method != DOP853 && L->method != DOPRI5) || L->stance_leg < 0 || L->stance_leg > L->table->contacts
            || L->stance_leg != floor(L->stance_leg) || kind == COMPILED) {
            PyErr_Format(PyExc_ValueError, "begin(): a described robot runs dop853 (0) or dopri5 (1) in stance on a "
                         "contact point 1..%d or in flight (0), under a held torque or a Python controller",
                         L->table->contacts);
            return NULL;
        }
        int n_y = 2 * L->table->n + 1;
        if (n_y != 9 && n_y != 11 && n_y != 15) {    /* (loop_kernels.k_step: the generated steps' sizes) */
            PyErr_Format(PyExc_ValueError, "begin(): the compiled loop has no generated step for a state of %d entries "
                         "(a robot of %d coordinates): 9, 11 or 15 (tools/generate_rk.py's UNROLLED)", n_y,
                         L->table->n);
            return NULL;
        }
    } else if ((L->method != DOP853 && L->method != DOPRI5) || (L->stance_leg != 1 && L->stance_leg != 2)) {
        PyErr_SetString(PyExc_ValueError, "begin(): the loop steps dop853 (0) or dopri5 (1) in stance on leg 1 or 2");
        return NULL;
    }
    if (kind == CALLBACK) {
        Py_INCREF(law);
        Py_XSETREF(L->callback, law);
    } else if (kind == COMPILED && compiled_law_from(law, &L->law) < 0) {
        return NULL;
    }
    L->n_y = L->table ? 2 * L->table->n + 1 : N;
    L->law_kind = kind;
    L->mode_begun = 1.0;
    restart(L, L->t, L->t_bound);
    if (L->callback_failed) return raise_callback_error(L);
    Py_RETURN_NONE;
}

/* dense(): the last step's dense output into the state's dense rows (rk_dense: a row of the method's width per
 * entry of y, packed), which the Python code reads */
static PyObject *
Loop_dense(Loop *L, PyObject *unused)
{
    (void)unused;
    rk_dense(L->S, rhs, L);
    if (L->callback_failed) return raise_callback_error(L);
    Py_RETURN_NONE;
}

/* dense_at(t) -> the dense output of the last step at t (a list), as integrators' interpolants give it */
static PyObject *
Loop_dense_at(Loop *L, PyObject *arg)
{
    double tt = PyFloat_AsDouble(arg), v[LS_NMAX];
    int n = (int)L->n_y;
    if (tt == -1.0 && PyErr_Occurred()) return NULL;
    rk_dense(L->S, rhs, L);
    if (L->callback_failed) return raise_callback_error(L);
    for (int i = 0; i < n; i++) v[i] = rk_dense_at(L->S, i, tt);
    return list_of(v, n);
}

/* law_torque(law) -> [u1, u2]: a compiled law's (address, parameters, name) torque at the loop's current
 * state and stance leg (the command of a control period); the law is not kept (a held period follows) */
static PyObject *
Loop_law_torque(Loop *L, PyObject *spec)
{
    CompiledLaw law;
    double u[2];
    if (three_link_only(L, "law_torque") || compiled_law_from(spec, &law) < 0) return NULL;
    apply_law(L, &law, L->t, L->y, L->y + 5, u);
    if (L->callback_failed) return raise_callback_error(L);
    return Py_BuildValue("[dd]", u[0], u[1]);
}

/* set_python_checks(failure_type, controller_failure, checked_torques, ndarray): the exception type a compiled
 * law's failure raises (a subclass of Exception); modes.controller_failure(exc, t) -> the ControllerError of a
 * controller that raised exc at t, modes.checked_torques(u, t) -> [u1, u2] or raises; and numpy.ndarray */
static PyObject *
set_python_checks(PyObject *module, PyObject *args)
{
    (void)module;
    PyObject *cls, *failure, *checked, *array_type;
    if (!PyArg_ParseTuple(args, "OOOO", &cls, &failure, &checked, &array_type)) return NULL;
    if (!PyExceptionClass_Check(cls) || !PyCallable_Check(failure) || !PyCallable_Check(checked)
        || !PyType_Check(array_type)) {
        PyErr_SetString(PyExc_TypeError, "set_python_checks(): an exception class, two callables and a type");
        return NULL;
    }
    PyObject **slots[] = {&law_failure_type, &controller_failure_fn, &checked_torques_fn, &ndarray_type};
    PyObject *values[] = {cls, failure, checked, array_type};
    for (int i = 0; i < 4; i++) {
        Py_INCREF(values[i]);
        Py_XSETREF(*slots[i], values[i]);
    }
    Py_RETURN_NONE;
}

static PyMethodDef module_methods[] = {
    {"set_python_checks", set_python_checks, METH_VARARGS, NULL},
    {NULL, NULL, 0, NULL},
};


static PyMethodDef Loop_methods[] = {
    {"set_model", (PyCFunction)Loop_set_model, METH_VARARGS, NULL},
    {"set_kernels", (PyCFunction)Loop_set_kernels, METH_VARARGS, NULL},
    {"rhs", (PyCFunction)Loop_rhs, METH_VARARGS, NULL},
    {"step", (PyCFunction)Loop_step, METH_NOARGS, NULL},
    {"run", (PyCFunction)(void (*)(void))Loop_run, METH_FASTCALL, NULL},
    {"begin", (PyCFunction)Loop_begin, METH_O, NULL},
    {"held", (PyCFunction)(void (*)(void))Loop_held, METH_FASTCALL, NULL},
    {"periods", (PyCFunction)(void (*)(void))Loop_periods, METH_FASTCALL, NULL},
    {"period", (PyCFunction)(void (*)(void))Loop_period, METH_FASTCALL, NULL},
    {"raise_error", (PyCFunction)Loop_raise_error, METH_NOARGS, NULL},
    {"locate_crossing", (PyCFunction)Loop_locate_crossing, METH_VARARGS, NULL},
    {"dense", (PyCFunction)Loop_dense, METH_NOARGS, NULL},
    {"dense_at", (PyCFunction)Loop_dense_at, METH_O, NULL},
    {"law_torque", (PyCFunction)Loop_law_torque, METH_O, NULL},
    {NULL, NULL, 0, NULL},
};

/* The state S exported as bytes (memoryview(loop).cast("d") is S: compiled_loop.run_state): the simulator, its
 * Samples and its locator read and write the same memory as the loop */
static int
Loop_getbuffer(Loop *L, Py_buffer *view, int flags)
{
    return PyBuffer_FillInfo(view, (PyObject *)L, L->S, sizeof L->S, 0, flags);
}

static PyBufferProcs Loop_as_buffer = {.bf_getbuffer = (getbufferproc)Loop_getbuffer};

static void
Loop_dealloc(Loop *L)
{
    Py_XDECREF(L->callback);
    Py_XDECREF(L->table_owner);
    Py_XDECREF(L->exc_type);
    Py_XDECREF(L->exc_value);
    Py_XDECREF(L->exc_tb);
    Py_TYPE(L)->tp_free((PyObject *)L);
}

static PyTypeObject LoopType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_dealloc = (destructor)Loop_dealloc,
    .tp_name = "biped_sim.engine._core.Loop",
    .tp_basicsize = sizeof(Loop),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = PyType_GenericNew,
    .tp_methods = Loop_methods,
    .tp_as_buffer = &Loop_as_buffer,
    .tp_doc = "The compiled hybrid loop's state (see biped_sim/engine/compiled_loop.py).",
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_core",
    "The compiled hybrid loop (biped_sim/engine/_core.c; driven by biped_sim/engine/compiled_loop.py).",
    -1, module_methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC
PyInit__core(void)
{
    if (PyType_Ready(&LoopType) < 0) return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL) return NULL;
    Py_INCREF(&LoopType);
    if (PyModule_AddObject(m, "Loop", (PyObject *)&LoopType) < 0
        || PyModule_AddStringConstant(m, "KERNELS_SHA256", BIPED_SIM_KERNELS_SHA256) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
