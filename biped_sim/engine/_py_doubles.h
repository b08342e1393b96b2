/* A Python sequence of numbers read into doubles, for the C extensions that take arrays of parameters from
 * Python (the compiled loop, _core.c; the variational steps, _variational.c): one reader, one message. */
#ifndef BIPED_SIM_PY_DOUBLES_H
#define BIPED_SIM_PY_DOUBLES_H

#include <Python.h>

/* seq's lo to hi numbers into out (their count into *n_out unless NULL); -1 with a ValueError naming what
 * otherwise */
static int
doubles(PyObject *seq, double *out, Py_ssize_t lo, Py_ssize_t hi, const char *what, Py_ssize_t *n_out)
{
    PyObject *fast = PySequence_Fast(seq, what);
    if (fast == NULL) return -1;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(fast);
    if (n < lo || n > hi) {
        PyErr_Format(PyExc_ValueError, "%s: %zd values, expected %zd to %zd", what, n, lo, hi);
        Py_DECREF(fast);
        return -1;
    }
    PyObject **items = PySequence_Fast_ITEMS(fast);
    for (Py_ssize_t i = 0; i < n; i++) {
        out[i] = PyFloat_AsDouble(items[i]);
        if (out[i] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(fast);
            return -1;
        }
    }
    Py_DECREF(fast);
    if (n_out) *n_out = n;
    return 0;
}

#endif
