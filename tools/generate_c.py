"""Generate biped_sim/_cmodel.c, the compiled twin of biped_sim/_generated.py (run by `make generate`).

Every run-time function of _generated.py (all but the ``*_constants`` ones, which run once per
model) becomes a C function of the extension module ``biped_sim._cmodel`` with the same name,
arguments and result shape (a tuple stays a tuple, a list a list, an integer literal an int).

The translation is of the Python syntax tree, expression by expression, every operation
parenthesised as Python parsed it, numbers as doubles, ``a**b`` as libm's ``pow(a, b)`` (what CPython's
float power calls), ``sin``/``cos`` from libm (what ``math.sin``/``math.cos`` call). Built without
floating-point contraction (setup.py), the C code performs the same IEEE operations in the same
order as the Python code, so the two agree bit for bit (test/test_closed_form.py checks it).

    python tools/generate_c.py           # write biped_sim/_cmodel.c
    python tools/generate_c.py --check   # exit 1 if the committed file differs from a fresh one
"""
from __future__ import annotations

import argparse
import ast
import hashlib
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "biped_sim" / "_generated.py"
TARGET = ROOT / "biped_sim" / "_cmodel.c"

BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}
FUNCTIONS = {"sin", "cos"}


def source_hash(text: str) -> str:
    """The digest the module carries as SOURCE_SHA256, so that a stale build can be detected."""
    return hashlib.sha256(text.encode()).hexdigest()


def c_expr(node) -> str:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return repr(float(node.value))
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        return f"(-{c_expr(node.operand)})"
    if isinstance(node, ast.BinOp) and type(node.op) in BINARY:
        return f"({c_expr(node.left)} {BINARY[type(node.op)]} {c_expr(node.right)})"
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
        return f"libm_pow({c_expr(node.left)}, {c_expr(node.right)})"
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS
            and len(node.args) == 1 and not node.keywords):
        return f"{node.func.id}({c_expr(node.args[0])})"
    raise ValueError(f"line {node.lineno}: no C translation for {ast.unparse(node)!r}")


def c_function(fn: ast.FunctionDef) -> tuple[str, str]:
    """(C definition, method-table row) of one run-time function."""
    params = [a.arg for a in fn.args.args]
    unpacked: dict[str, list[str]] = {}
    body = [s for s in fn.body if not (isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant))]
    doc = ast.get_docstring(fn) or fn.name
    lines = [f"static PyObject *\n{fn.name}(PyObject *self, PyObject *const *args, Py_ssize_t nargs)\n{{",
             f"    if (nargs != {len(params)}) {{",
             f"        PyErr_SetString(PyExc_TypeError, \"{fn.name}() takes {len(params)} arguments "
             f"({', '.join(params)})\");",
             "        return NULL;", "    }"]
    statements = []
    result = None
    for s in body:
        if (isinstance(s, ast.Assign) and len(s.targets) == 1 and isinstance(s.targets[0], ast.Tuple)
                and isinstance(s.value, ast.Name) and s.value.id in params):
            unpacked[s.value.id] = [e.id for e in s.targets[0].elts]
        elif isinstance(s, ast.Assign) and len(s.targets) == 1 and isinstance(s.targets[0], ast.Name):
            statements.append(f"    const double {s.targets[0].id} = {c_expr(s.value)};")
        elif isinstance(s, ast.Return):
            result = s.value
        else:
            raise ValueError(f"{fn.name}, line {s.lineno}: no C translation for {ast.unparse(s)!r}")
    if set(unpacked) != set(params) or result is None:
        raise ValueError(f"{fn.name}: every argument must be unpacked and the function must return")
    used = {n.id for s in body[len(unpacked):] for n in ast.walk(s) if isinstance(n, ast.Name)}
    for i, p in enumerate(params):
        names = unpacked[p]
        lines.append(f"    double {p}_[{len(names)}];")
        lines.append(f"    if (unpack(args[{i}], {p}_, {len(names)}, \"{fn.name}\", \"{p}\") < 0) return NULL;")
        lines += [f"    const double {n} = {p}_[{j}];" for j, n in enumerate(names) if n in used]
    lines += statements
    build: list[str] = []
    top = build_result(result, build)
    lines += build
    lines.append(f"    return {top};")
    lines.append("}")
    row = f"    {{\"{fn.name}\", (PyCFunction)(void (*)(void)){fn.name}, METH_FASTCALL, {c_string(doc)}}},"
    return "\n".join(lines), row


def build_result(node, out: list[str]) -> str:
    """C statements that build the Python result of ``node`` (tuples, lists, numbers); returns the
    C name of the outermost object. Each container is put into its parent as soon as it exists (a
    tuple or list being filled may hold NULLs), so after a failed allocation releasing the
    outermost object releases everything made so far."""
    names = iter(f"py_r{i}" for i in range(10 ** 6))   # generated names never start with py_

    def build(node, parent=None):
        name = next(names)
        fail = "return NULL;" if name == "py_r0" else "{ Py_DECREF(py_r0); return NULL; }"
        if isinstance(node, (ast.Tuple, ast.List)):
            out.append(f"    PyObject *{name} = Py{kind(node)}_New({len(node.elts)});")
        elif isinstance(node, ast.Constant) and type(node.value) is int:
            out.append(f"    PyObject *{name} = PyLong_FromLong({node.value}L);")
        else:
            out.append(f"    PyObject *{name} = PyFloat_FromDouble({c_expr(node)});")
        out.append(f"    if ({name} == NULL) {fail}")
        if parent is not None:
            out.append(f"    Py{kind(parent[0])}_SET_ITEM({parent[1]}, {parent[2]}, {name});")
        if isinstance(node, (ast.Tuple, ast.List)):
            for i, elt in enumerate(node.elts):
                build(elt, (node, name, i))
        return name

    return build(node)


def kind(node) -> str:
    return "Tuple" if isinstance(node, ast.Tuple) else "List"


def c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


HEADER = '''\
/* GENERATED by tools/generate_c.py from biped_sim/_generated.py -- do not edit.
 *
 * The compiled twin of _generated.py: the same run-time closed forms, the same arguments and
 * result shapes, the same IEEE operations in the same order (built with -ffp-contract=off), so
 * the results are bit for bit those of the Python code. biped_sim/closed_form.py chooses it when
 * it was built and SOURCE_SHA256 matches _generated.py.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

/* CPython's float power calls libm's pow; a compiler may turn pow(a, 2.0) into a * a, which can
 * differ in the last bit, so pow is called through a pointer it cannot see through. */
static double (*volatile libm_pow)(double, double) = pow;

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
        PyObject *item = items[i];
        out[i] = PyFloat_CheckExact(item) ? PyFloat_AS_DOUBLE(item) : PyFloat_AsDouble(item);
        if (out[i] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(seq);
            return -1;
        }
    }
    Py_DECREF(seq);
    return 0;
}
'''

FOOTER = '''
static struct PyModuleDef module = {{
    PyModuleDef_HEAD_INIT, "_cmodel",
    "Compiled twin of biped_sim._generated (generated by tools/generate_c.py).", -1, methods,
    NULL, NULL, NULL, NULL,
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


def generate(text: str) -> str:
    tree = ast.parse(text)
    functions = [n for n in tree.body if isinstance(n, ast.FunctionDef) and not n.name.endswith("_constants")]
    defs, rows = zip(*(c_function(fn) for fn in functions))
    table = "static PyMethodDef methods[] = {\n" + "\n".join(rows) + "\n    {NULL, NULL, 0, NULL},\n};\n"
    return HEADER + "\n" + "\n\n".join(defs) + "\n\n" + table + FOOTER.format(digest=source_hash(text))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="compare with the committed file instead of writing")
    args = parser.parse_args(argv)
    code = generate(SOURCE.read_text())
    if args.check:
        if TARGET.read_text() != code:
            print(f"{TARGET.relative_to(ROOT)} is stale: run `make generate`", file=sys.stderr)
            return 1
        print(f"{TARGET.relative_to(ROOT)} matches {SOURCE.relative_to(ROOT)}")
        return 0
    TARGET.write_text(code)
    print(f"wrote {TARGET.relative_to(ROOT)} ({len(code.splitlines())} lines, {code.count('METH_FASTCALL')} functions)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
