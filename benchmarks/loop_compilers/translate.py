"""A restricted-Python translator, the third candidate: rules.py's compiled functions to C by a walk of its
syntax tree, as tools/generate_c.py turns the closed forms into _cmodel.c (this prototype measures what
extending that generator to the loop's rules would take; it is not wired into it).

The subset: module constants ``X = cython.declare(type, value)``; functions decorated ``@cython.cfunc``
(translated) and ``@cython.ccall`` entry points (each becomes a METH_FASTCALL function of a CPython extension
that takes the state array by the buffer protocol); C types from the annotations (``cython.double``, ``int``,
``Py_ssize_t``, ``p_double``, ``void``, ``double[::1]``); statements: annotated and plain assignments (chains
too), ``+=`` and its kin, ``if``/``elif``/``else``, ``while``, ``for ... in range``, ``break``, ``continue``,
``return``, calls; expressions: numbers, names, ``S[i]``, + - * /, unary -, ``not``, comparisons, ``and``/``or``,
``x if c else y``, calls of the functions here, of the kernels (kernels.pxd's names, on S and offsets) and of
``fabs``, ``pow``, ``isfinite``, ``isnan``, ``int``. Every operation is parenthesised as Python parsed it, so
the C performs the same IEEE operations in the same order (built with -ffp-contract=off). What it does not
know stops it with the line. It infers no types: a division of two integers would be C's, not Python's
(rules.py has none; a checked translator would type every expression).

    python -m benchmarks.loop_compilers.translate OUT.c    # rules.py -> OUT.c (module rules_tr)
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
TYPES = {"cython.double": "double", "cython.int": "int", "cython.Py_ssize_t": "Py_ssize_t",
         "cython.p_double": "double *", "cython.void": "void", "cython.double[::1]": "double *",
         "cython.const[cython.Py_ssize_t]": "Py_ssize_t",
         "cython.const[cython.int]": "int"}
BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}
COMPARE = {ast.Gt: ">", ast.Lt: "<", ast.GtE: ">=", ast.LtE: "<=", ast.Eq: "==", ast.NotEq: "!="}
LIBM = {"fabs": "fabs", "pow": "pow", "isfinite": "isfinite", "isnan": "isnan"}
KERNELS = """
/* kernels.pxd's kernels on S and offsets into it */
static inline void probe_k_rhs(double *S, double t, Py_ssize_t y, Py_ssize_t dy) { g_rhs(S, t, S + y, S + dy); }
static inline void probe_k_step(double *S, double t, Py_ssize_t y, Py_ssize_t f, double h, double rtol, double atol,
                          Py_ssize_t out) { g_dop853_step(S, t, S + y, S + f, h, rtol, atol, S + out); }
static inline void probe_k_dense(double *S, double t_old, double h, Py_ssize_t y_old, Py_ssize_t y, Py_ssize_t k,
                           Py_ssize_t dense) { g_dop853_dense(S, t_old, h, S + y_old, S + y, S + k, S + dense); }
static inline void probe_k_foot_positions(double *S, Py_ssize_t q, Py_ssize_t p) { g_foot_positions(S, S + q, S + p); }
static inline double probe_k_ulp(double x) { return g_ulp(x); }
"""


class Unsupported(ValueError):
    pass


def c_type(annotation) -> str:
    text = ast.unparse(annotation)
    if text not in TYPES:
        raise Unsupported(f"line {annotation.lineno}: type {text!r}")
    return TYPES[text]


def decorators(fn):
    return {ast.unparse(d) for d in fn.decorator_list}


class Translator:
    def __init__(self, tree):
        self.consts = {}
        self.functions = []
        for node in tree.body:
            if (isinstance(node, ast.Assign) and isinstance(node.value, ast.Call)
                    and ast.unparse(node.value.func) == "cython.declare"):
                self.consts[node.targets[0].id] = (c_type(node.value.args[0]), ast.unparse(node.value.args[1]))
            elif isinstance(node, ast.FunctionDef):
                self.functions.append(node)
        self.names = {fn.name for fn in self.functions}

    # -- expressions
    def expr(self, node) -> str:
        if isinstance(node, ast.Constant) and type(node.value) in (int, float, bool):
            return repr(float(node.value)) if type(node.value) is float else str(int(node.value))
        if isinstance(node, ast.Name):
            return node.id
        if isinstance(node, ast.Subscript) and not isinstance(node.slice, ast.Slice):
            return f"{self.expr(node.value)}[{self.expr(node.slice)}]"
        if isinstance(node, ast.BinOp) and type(node.op) in BINARY:
            return f"({self.expr(node.left)} {BINARY[type(node.op)]} {self.expr(node.right)})"
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return f"(-{self.expr(node.operand)})"
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            return f"(!{self.expr(node.operand)})"
        if isinstance(node, ast.Compare) and len(node.ops) == 1 and type(node.ops[0]) in COMPARE:
            return f"({self.expr(node.left)} {COMPARE[type(node.ops[0])]} {self.expr(node.comparators[0])})"
        if isinstance(node, ast.BoolOp):
            op = " && " if isinstance(node.op, ast.And) else " || "
            return "(" + op.join(self.expr(v) for v in node.values) + ")"
        if isinstance(node, ast.IfExp):
            return f"({self.expr(node.test)} ? {self.expr(node.body)} : {self.expr(node.orelse)})"
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and not node.keywords:
            name, args = node.func.id, [self.expr(a) for a in node.args]
            if name == "int" and len(args) == 1:
                return f"((int){args[0]})"
            if name.startswith("k_"):        # (prefixed: _kernels.h has k_foot_positions too)
                return f"probe_{name}({', '.join(args)})"
            if name in LIBM or name in self.names:
                return f"{LIBM.get(name, name)}({', '.join(args)})"
        raise Unsupported(f"line {node.lineno}: {ast.unparse(node)!r}")

    # -- statements
    def block(self, body, depth) -> list[str]:
        return [line for s in body for line in self.stmt(s, depth)]

    def stmt(self, s, depth) -> list[str]:
        pad = "    " * depth
        if isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant):
            return []                                   # a docstring
        if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name):
            init = f" = {self.expr(s.value)}" if s.value is not None else ""
            return [f"{pad}{c_type(s.annotation)} {s.target.id}{init};"]
        if isinstance(s, ast.Assign):
            return [pad + " = ".join(self.expr(t) for t in s.targets) + f" = {self.expr(s.value)};"]
        if isinstance(s, ast.AugAssign) and type(s.op) in BINARY:
            return [f"{pad}{self.expr(s.target)} {BINARY[type(s.op)]}= {self.expr(s.value)};"]
        if isinstance(s, ast.Expr) and isinstance(s.value, ast.Call):
            return [f"{pad}{self.expr(s.value)};"]
        if isinstance(s, ast.Return):
            return [f"{pad}return{'' if s.value is None else ' ' + self.expr(s.value)};"]
        if isinstance(s, ast.Break):
            return [f"{pad}break;"]
        if isinstance(s, ast.Continue):
            return [f"{pad}continue;"]
        if isinstance(s, ast.If):
            out = [f"{pad}if {self.cond(s.test)} {{", *self.block(s.body, depth + 1)]
            if s.orelse:
                out += [f"{pad}}} else {{", *self.block(s.orelse, depth + 1)]
            return out + [f"{pad}}}"]
        if isinstance(s, ast.While) and not s.orelse:
            return [f"{pad}while {self.cond(s.test)} {{", *self.block(s.body, depth + 1), f"{pad}}}"]
        if (isinstance(s, ast.For) and isinstance(s.target, ast.Name) and isinstance(s.iter, ast.Call)
                and ast.unparse(s.iter.func) == "range" and len(s.iter.args) in (1, 2) and not s.orelse):
            lo, hi = (["0"] + [self.expr(a) for a in s.iter.args])[-2:]
            i = s.target.id
            return [f"{pad}for ({i} = {lo}; {i} < {hi}; {i}++) {{", *self.block(s.body, depth + 1), f"{pad}}}"]
        raise Unsupported(f"line {s.lineno}: {ast.unparse(s).splitlines()[0]!r}")

    def cond(self, node) -> str:
        text = self.expr(node)
        return text if text.startswith("(") else f"({text})"

    # -- functions
    def signature(self, fn, name=None) -> str:
        args = ", ".join(f"{c_type(a.annotation)} {a.arg}" for a in fn.args.args)
        return f"static {c_type(fn.returns)}\n{name or fn.name}({args})"

    def function(self, fn) -> str:
        return "\n".join([self.signature(fn), "{", *self.block(fn.body, 1), "}", ""])

    def entry(self, fn) -> str:
        """The METH_FASTCALL wrapper of an entry point: S by the buffer protocol, the scalars by value."""
        args, body = fn.args.args, []
        body.append(f"    if (nargs != {len(args)}) {{ PyErr_SetString(PyExc_TypeError, "
                    f"\"{fn.name}() takes {len(args)} arguments\"); return NULL; }}")
        body.append("    Py_buffer buf;")
        body.append("    if (PyObject_GetBuffer(args[0], &buf, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)"
                    " return NULL;")
        body.append("    if (buf.itemsize != 8 || strcmp(buf.format, \"d\") != 0) { PyBuffer_Release(&buf); "
                    "PyErr_SetString(PyExc_TypeError, \"S: a float64 array\"); return NULL; }")
        call = ["(double *)buf.buf"]
        for k, a in enumerate(args[1:], start=1):
            t = c_type(a.annotation)
            conv = "PyFloat_AsDouble" if t == "double" else "PyLong_AsSsize_t"
            body.append(f"    {t} {a.arg} = ({t}){conv}(args[{k}]);")
            call.append(a.arg)
        body.append("    if (PyErr_Occurred()) { PyBuffer_Release(&buf); return NULL; }")
        ret, target = c_type(fn.returns), "_" + fn.name
        invocation = f"{target}({', '.join(call)})"
        if ret == "void":
            body += [f"    {invocation};", "    PyBuffer_Release(&buf);", "    Py_RETURN_NONE;"]
        else:
            box = "PyFloat_FromDouble" if ret == "double" else "PyLong_FromLong"
            body += [f"    {ret} r = {invocation};", "    PyBuffer_Release(&buf);", f"    return {box}(r);"]
        return "\n".join([f"static PyObject *\npy_{fn.name}(PyObject *self, PyObject *const *args, Py_ssize_t nargs)",
                          "{", *body, "}", ""])

    def module(self, name) -> str:
        internal = [fn for fn in self.functions if "cython.cfunc" in decorators(fn)]
        entries = [fn for fn in self.functions if "cython.ccall" in decorators(fn)]
        out = ["/* GENERATED by benchmarks/loop_compilers/translate.py from rules.py -- do not edit. */",
               "#define PY_SSIZE_T_CLEAN", "#include <Python.h>", "#include <string.h>", "#include \"glue.h\"",
               KERNELS]
        out += [f"static const {t} {k} = {v};" for k, (t, v) in self.consts.items()] + [""]
        out += [self.signature(fn) + ";" for fn in internal] + [""]
        out += [self.function(fn) for fn in internal]
        out += [self.entry(fn) for fn in entries]
        out.append("static PyMethodDef methods[] = {")
        out += [f"    {{\"{fn.name}\", (PyCFunction)(void (*)(void))py_{fn.name}, METH_FASTCALL, NULL}},"
                for fn in entries]
        out += ["    {NULL, NULL, 0, NULL},", "};", "",
                f"static struct PyModuleDef module = {{PyModuleDef_HEAD_INIT, \"{name}\", NULL, -1, methods}};", "",
                f"PyMODINIT_FUNC\nPyInit_{name}(void)\n{{\n    return PyModule_Create(&module);\n}}", ""]
        return "\n".join(out)


def translate(source: Path = HERE / "rules.py", name="rules_tr") -> str:
    return Translator(ast.parse(source.read_text())).module(name)


if __name__ == "__main__":
    Path(sys.argv[1]).write_text(translate())
