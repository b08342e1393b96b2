"""Generate biped_sim/engine/_gen/_cmodel.c, the compiled twin of the generated Python code (run by `make generate`).

Two generated modules have a twin in the one extension module ``biped_sim.engine._gen._cmodel``:
  * biped_sim/engine/_gen/closed_forms.py: every run-time closed form (all but the ``*_constants`` functions,
    which run once per model);
  * biped_sim/engine/_gen/rk_steps.py: the unrolled Runge-Kutta steps (``*_step_<n>``), which call back the
    right-hand side, a Python callable, with Python lists.
Each twin has the same name, arguments and result shape as its Python function (a tuple stays a
tuple, a list a list, an integer literal an int; the right-hand side's results and the lists
passed to it are the same kind of objects), and raises what the Python code raises for a wrong
length (ValueError) or a non-number (TypeError).

The translation is of the Python syntax tree, statement by statement, every operation
parenthesised as Python parsed it, numbers as doubles, ``a**b`` as libm's ``pow(a, b)`` (what
CPython's float power calls), ``sin``, ``cos``, ``sqrt`` and ``abs`` from libm (what ``math``
calls). Built without floating-point contraction (setup.py), the C code performs the same IEEE
operations in the same order as the Python code, so the two agree bit for bit
(test/test_compiled.py checks it). A construct it does not know stops the generator.

    python tools/generate_c.py           # write biped_sim/engine/_gen/_cmodel.c
    python tools/generate_c.py --check   # exit 1 if the committed file differs from a fresh one
"""
from __future__ import annotations

import argparse
import ast
import hashlib
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GEN = ROOT / "biped_sim" / "engine" / "_gen"
SOURCES = (GEN / "closed_forms.py", GEN / "rk_steps.py")
TARGET = GEN / "_cmodel.c"

BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}
COMPARE = {ast.Gt: ">", ast.Lt: "<", ast.GtE: ">=", ast.LtE: "<=", ast.Eq: "==", ast.NotEq: "!="}
FUNCTIONS = {"sin": "sin", "cos": "cos", "sqrt": "sqrt", "abs": "fabs"}


def source_hash(texts) -> str:
    """The digest the module carries as SOURCE_SHA256, so that a stale build can be detected."""
    return hashlib.sha256("".join(texts).encode()).hexdigest()


def is_twinned(fn: ast.FunctionDef) -> bool:
    """Run-time closed forms and the unrolled steps; not the per-model constants, not the generic
    steps over lists of any length (loops and comprehensions)."""
    return not fn.name.endswith("_constants") and not re.fullmatch(r"\w+_step", fn.name)


class Function:
    """One Python function translated to a METH_FASTCALL C function.

    Names are doubles, or objects: the arguments that are unpacked or called, the right-hand
    side's results, and list literals (kept both as an object and, for reading, as the object's
    items). Objects are owned and released at ``done:``; any failure jumps there with
    ``result`` NULL and the Python error set.
    """

    def __init__(self, fn: ast.FunctionDef):
        self.fn = fn
        self.params = [a.arg for a in fn.args.args]
        body = [s for s in fn.body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant))]
        self.objects = {p for p in self.params for s in body if self._unpacks(s) == p or self._calls(s) == p}
        self.owned: list[str] = []
        self.declared = set(self.params) - self.objects
        self.used = {n.id for s in body for n in ast.walk(s) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)}
        self.lines: list[str] = []
        for s in body:
            self.statement(s)

    @staticmethod
    def _unpacks(s):
        if isinstance(s, ast.Assign) and isinstance(s.targets[0], ast.Tuple) and isinstance(s.value, ast.Name):
            return s.value.id

    @staticmethod
    def _calls(s):
        if isinstance(s, ast.Assign) and isinstance(s.value, ast.Call) and isinstance(s.value.func, ast.Name) \
                and s.value.func.id not in FUNCTIONS:
            return s.value.func.id

    def fail(self, node, what="no C translation"):
        raise ValueError(f"{self.fn.name}, line {node.lineno}: {what} for {ast.unparse(node)!r}")

    # -- expressions (doubles) -------------------------------------------------------------------
    def expr(self, node) -> str:
        if isinstance(node, ast.Name) and node.id not in self.objects:
            return node.id
        if isinstance(node, ast.Constant) and type(node.value) in (int, float):
            return repr(float(node.value))
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return f"(-{self.expr(node.operand)})"
        if isinstance(node, ast.BinOp) and type(node.op) in BINARY:
            return f"({self.expr(node.left)} {BINARY[type(node.op)]} {self.expr(node.right)})"
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            return f"libm_pow({self.expr(node.left)}, {self.expr(node.right)})"
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS
                and len(node.args) == 1 and not node.keywords):
            return f"{FUNCTIONS[node.func.id]}({self.expr(node.args[0])})"
        if isinstance(node, ast.IfExp):
            return f"({self.expr(node.test)} ? {self.expr(node.body)} : {self.expr(node.orelse)})"
        if isinstance(node, ast.Compare) and len(node.ops) == 1 and type(node.ops[0]) in COMPARE:
            return f"({self.expr(node.left)} {COMPARE[type(node.ops[0])]} {self.expr(node.comparators[0])})"
        if isinstance(node, ast.BoolOp):
            op = " && " if isinstance(node.op, ast.And) else " || "
            return "(" + op.join(self.expr(v) for v in node.values) + ")"
        if (isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and node.value.id in self.objects
                and isinstance(node.slice, ast.Constant) and type(node.slice.value) is int):
            # the list as it is now (the right-hand side it was passed to may have changed it)
            return f"item({node.value.id}, {node.slice.value}, &failed)"
        self.fail(node)

    # -- statements ----------------------------------------------------------------------------
    def assign_double(self, name, value):
        code = self.expr(value)
        decl = "" if name in self.declared else "double "
        self.declared.add(name)
        self.lines.append(f"    {decl}{name} = {code};")
        if "&failed" in code:
            self.lines.append("    if (failed) goto done;")

    def own(self, name):
        self.objects.add(name)
        self.owned.append(name)

    def statement(self, s):
        name = self.fn.name
        if self._unpacks(s) is not None and s.value.id in self.objects:
            src, targets = s.value.id, [e.id for e in s.targets[0].elts]
            self.lines.append(f"    double {src}_[{len(targets)}];")
            self.lines.append(f"    if (unpack({src}, {src}_, {len(targets)}, \"{name}\", \"{src}\") < 0) goto done;")
            for j, t in enumerate(targets):
                if t in self.used:
                    self.declared.add(t)
                    self.lines.append(f"    double {t} = {src}_[{j}];")
        elif self._calls(s) is not None:
            call, target = s.value, s.targets[0].id
            if s.value.func.id not in self.objects or len(call.args) != 2 or call.keywords:
                self.fail(s, "only fun(t, y) calls of an argument are translated")
            t, y = call.args
            if isinstance(y, ast.List):
                items = ", ".join(self.expr(e) for e in y.elts)
                self.lines.append(f"    {target} = call_with_new_list({call.func.id}, {self.expr(t)}, "
                                  f"(const double[]){{{items}}}, {len(y.elts)});")
            elif isinstance(y, ast.Name) and y.id in self.objects:
                self.lines.append(f"    {target} = call_with({call.func.id}, {self.expr(t)}, {y.id});")
            else:
                self.fail(s)
            self.own(target)
            self.lines.append(f"    if ({target} == NULL) goto done;")
        elif isinstance(s, ast.Assign) and isinstance(s.value, ast.List) and isinstance(s.targets[0], ast.Name):
            target = s.targets[0].id
            items = ", ".join(self.expr(e) for e in s.value.elts)
            self.own(target)
            self.lines.append(f"    {target} = new_list((const double[]){{{items}}}, {len(s.value.elts)});")
            self.lines.append(f"    if ({target} == NULL) goto done;")
        elif isinstance(s, ast.Assign) and all(isinstance(t, ast.Name) for t in s.targets):
            for t in reversed(s.targets):   # a = b = v assigns a, then b, the same value
                self.assign_double(t.id, s.value)
        elif isinstance(s, ast.AugAssign) and isinstance(s.op, ast.Add) and isinstance(s.target, ast.Name):
            self.assign_double(s.target.id, ast.BinOp(ast.Name(s.target.id, ast.Load()), ast.Add(), s.value))
        elif isinstance(s, ast.Return):
            self.lines.append(f"    result = {self.build(s.value, iter(range(10 ** 6)))};")
        else:
            self.fail(s)

    def build(self, node, counter, parent=None) -> str:
        """C statements that build the result ``node``; returns the C name of the outermost object.
        Each part is put into its parent as soon as it exists (a tuple or list being filled may
        hold NULLs), so after a failed allocation releasing the outermost one releases all."""
        name = f"py_r{next(counter)}"   # generated names never start with py_
        if isinstance(node, ast.Name) and node.id in self.objects:   # an object at hand: no allocation
            self.lines.append(f"    PyObject *{name} = {node.id};")
            self.lines.append(f"    Py_INCREF({name});")
        else:
            if isinstance(node, (ast.Tuple, ast.List)):
                self.lines.append(f"    PyObject *{name} = Py{kind(node)}_New({len(node.elts)});")
            elif isinstance(node, ast.Constant) and type(node.value) is int:
                self.lines.append(f"    PyObject *{name} = PyLong_FromLong({node.value}L);")
            else:
                self.lines.append(f"    PyObject *{name} = PyFloat_FromDouble({self.expr(node)});")
            on_null = "goto done;" if parent is None else "{ Py_DECREF(py_r0); goto done; }"
            self.lines.append(f"    if ({name} == NULL) " + on_null)
        if parent is not None:
            self.lines.append(f"    Py{kind(parent[0])}_SET_ITEM({parent[1]}, {parent[2]}, {name});")
        if isinstance(node, (ast.Tuple, ast.List)):
            for i, elt in enumerate(node.elts):
                self.build(elt, counter, (node, name, i))
        return name

    def c(self) -> str:
        fn, params = self.fn.name, self.params
        out = [f"static PyObject *\n{fn}(PyObject *self, PyObject *const *args, Py_ssize_t nargs)\n{{",
               "    PyObject *result = NULL;",
               "    int failed = 0;"]
        out += [f"    PyObject *{o} = NULL;" for o in self.owned]
        out += [f"    if (nargs != {len(params)}) {{",
                f"        PyErr_SetString(PyExc_TypeError, "
                f"\"{fn}() takes {len(params)} arguments ({', '.join(params)})\");",
                "        return NULL;", "    }"]
        for i, p in enumerate(params):
            if p in self.objects:
                out.append(f"    PyObject *{p} = args[{i}];")
            else:
                out.append(f"    const double {p} = PyFloat_AsDouble(args[{i}]);")
                out.append(f"    if ({p} == -1.0 && PyErr_Occurred()) return NULL;")
        out += self.lines
        out.append("done:")
        out += [f"    Py_XDECREF({o});" for o in self.owned]
        out.append("    (void)failed;")
        out.append("    return result;")
        out.append("}")
        return "\n".join(out)

    def row(self) -> str:
        doc = ast.get_docstring(self.fn) or self.fn.name
        name = self.fn.name
        return f"    {{\"{name}\", (PyCFunction)(void (*)(void)){name}, METH_FASTCALL, {c_string(doc)}}},"


def kind(node) -> str:
    return "Tuple" if isinstance(node, ast.Tuple) else "List"


def c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


HEADER = '''\
/* GENERATED by tools/generate_c.py from biped_sim/engine/_gen/{closed_forms,rk_steps}.py -- do not edit.
 *
 * The compiled twin of the generated Python code: the same closed forms and unrolled Runge-Kutta
 * steps, the same arguments and result shapes, the same IEEE operations in the same order (built
 * with -ffp-contract=off), so the results are bit for bit those of the Python code.
 * biped_sim/engine/compiled.py chooses it when it was built and SOURCE_SHA256 matches the sources.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

/* CPython's float power calls libm's pow; a compiler may turn pow(a, 2.0) into a * a, which can
 * differ in the last bit, so pow is called through a pointer it cannot see through. */
static double (*volatile libm_pow)(double, double) = pow;

static double
as_double(PyObject *item)
{
    return PyFloat_CheckExact(item) ? PyFloat_AS_DOUBLE(item) : PyFloat_AsDouble(item);
}

/* Python's ``a, b, c = seq`` for n floats: TypeError if seq is not a sequence of numbers,
 * ValueError if its length is not n (what the Python twin raises). */
static int
unpack(PyObject *obj, double *out, Py_ssize_t n, const char *func, const char *arg)
{
    PyObject *seq = PySequence_Fast(obj, "expected a sequence of numbers");
    if (seq == NULL) return -1;
    Py_ssize_t size = PySequence_Fast_GET_SIZE(seq);
    if (size != n) {
        PyErr_Format(PyExc_ValueError, "%s(): %s must have %zd values, got %zd", func, arg, n, size);
        Py_DECREF(seq);
        return -1;
    }
    PyObject **items = PySequence_Fast_ITEMS(seq);
    for (Py_ssize_t i = 0; i < n; i++) {
        out[i] = as_double(items[i]);
        if (out[i] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(seq);
            return -1;
        }
    }
    Py_DECREF(seq);
    return 0;
}

/* lst[i] as a double (lst a list this module made); sets *failed on an error. */
static double
item(PyObject *lst, Py_ssize_t i, int *failed)
{
    if (i >= PyList_GET_SIZE(lst)) {
        PyErr_SetString(PyExc_IndexError, "list index out of range");
        *failed = 1;
        return 0.0;
    }
    double v = as_double(PyList_GET_ITEM(lst, i));
    if (v == -1.0 && PyErr_Occurred()) *failed = 1;
    return v;
}

static PyObject *
new_list(const double *values, Py_ssize_t n)
{
    PyObject *lst = PyList_New(n);
    if (lst == NULL) return NULL;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *v = PyFloat_FromDouble(values[i]);
        if (v == NULL) {
            Py_DECREF(lst);
            return NULL;
        }
        PyList_SET_ITEM(lst, i, v);
    }
    return lst;
}

/* fun(t, y) */
static PyObject *
call_with(PyObject *fun, double t, PyObject *y)
{
    PyObject *argv[2] = {PyFloat_FromDouble(t), y};
    if (argv[0] == NULL) return NULL;
    PyObject *r = PyObject_Vectorcall(fun, argv, 2, NULL);
    Py_DECREF(argv[0]);
    return r;
}

/* fun(t, [values...]) */
static PyObject *
call_with_new_list(PyObject *fun, double t, const double *values, Py_ssize_t n)
{
    PyObject *y = new_list(values, n);
    if (y == NULL) return NULL;
    PyObject *r = call_with(fun, t, y);
    Py_DECREF(y);
    return r;
}
'''

FOOTER = '''
static struct PyModuleDef module = {{
    PyModuleDef_HEAD_INIT, "_cmodel",
    "Compiled twin of biped_sim.engine._gen.closed_forms and .rk_steps (generated by tools/generate_c.py).",
    -1, methods, NULL, NULL, NULL, NULL,
}};

PyMODINIT_FUNC
PyInit__cmodel(void)
{{
    PyObject *m = PyModule_Create(&module);
    if (m == NULL) return NULL;
    if (PyModule_AddStringConstant(m, "SOURCE_SHA256", "{digest}") < 0) {{
        Py_DECREF(m);
        return NULL;
    }}
    return m;
}}
'''


def twinned_functions(text: str):
    return [Function(n) for n in ast.parse(text).body if isinstance(n, ast.FunctionDef) and is_twinned(n)]


def generate(texts) -> str:
    functions = [f for text in texts for f in twinned_functions(text)]
    table = "static PyMethodDef methods[] = {\n" + "\n".join(f.row() for f in functions) + \
        "\n    {NULL, NULL, 0, NULL},\n};\n"
    return HEADER + "\n" + "\n\n".join(f.c() for f in functions) + "\n\n" + table + \
        FOOTER.format(digest=source_hash(texts))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="compare with the committed file instead of writing")
    args = parser.parse_args(argv)
    code = generate([s.read_text() for s in SOURCES])
    if args.check:
        if not TARGET.exists() or TARGET.read_text() != code:
            print(f"{TARGET.relative_to(ROOT)} is stale: run `make generate`", file=sys.stderr)
            return 1
        print(f"{TARGET.relative_to(ROOT)} matches its sources")
        return 0
    TARGET.write_text(code)
    print(f"wrote {TARGET.relative_to(ROOT)} ({len(code.splitlines())} lines, {code.count('METH_FASTCALL')} functions)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
