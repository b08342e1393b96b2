"""The compiled twin of a described robot's kernels: stance, flight, impact, feet and energy in C.

Owns :func:`compiled_kernels`, the C source it runs (:func:`kernel_source`, emitted from the robot's
generated module, :mod:`biped_sim.config.codegen`'s output) and the build and cache of a user's robot.

The twin is a Python extension with six functions that take and return lists of floats, the kernels of
the hybrid loop for a :class:`~biped_sim.engine.generated_model.GeneratedModel` (N coordinates, M
actuators, L contact points; docs/models.md):

    k_stance(q, dq, u, c) -> (ddq, F)      [D -J_c^T; J_c 0] [ddq; F] = [B u - (C dq + G); -Jdot_c dq]
    k_flight(q, dq, u) -> ddq               D ddq = B u - (C dq + G)
    k_impact(q, dq_minus, c) -> (dq_plus, F_imp)   [D -J_c^T; J_c 0] [dq+; F_imp] = [D dq-; 0]
    k_foot_positions(q) -> [p_1, p_2, ...]
    k_foot_kinematics(q, dq) -> [p_1, p_2, ..., v_1, v_2, ...]
    k_energy(q, dq) -> [T, V]

(``c`` is a contact point's 0-based index, each p and v an (x, y) pair). D, C dq + G, p_c, J_c, Jdot_c,
dp_c/dt and (T, V) are the generated module's statements translated one by one (same operations in the
same order, built without floating-point contraction: the same bits as the Python functions). The
KKT systems are solved by the Schur complement on D's Cholesky factor, D = L L^T:

    a = D^-1 r,  Y = D^-1 J_c^T,  (J_c Y) F = b - J_c a,  x = a + Y F

(r, b the two blocks of the right-hand side; for the impact a = dq-), which agrees with numpy's LU
of the whole (N+2)x(N+2) system to rounding, not bit for bit.

The shipped robots' twins (``biped_sim/engine/_gen/models/_kernels_<name>.c``, written by ``make
generate``) are built by setup.py. Each source holds the robot's part only and includes the part that is the
same for every robot, ``_kernels_runtime.h`` (with ``_kernel_table.h``), from this package's folder, which is on
the include path of every build. A user's robot's twin is emitted and compiled on first use with the C compiler
Python was built with and cached next to its generated module (``<module>.kernels-<hash>.so``; the hash is of
the C source and both headers' text, so a new description, generator or runtime builds anew). Where it cannot
be built or loaded, :func:`compiled_kernels` warns once per robot in one line and returns None: the
Python path runs. ``BIPED_SIM_PURE_PYTHON=1`` returns None without a word.
"""
from __future__ import annotations

import ast
import hashlib
import importlib
import importlib.machinery
import importlib.util
import os
import shlex
import shutil
import subprocess
import sysconfig
import tempfile
import warnings
from pathlib import Path

#: the kernels' names, the methods of the object :func:`compiled_kernels` returns
KERNELS = ("k_stance", "k_flight", "k_impact", "k_foot_positions", "k_foot_kinematics", "k_energy")
SHIPPED_PACKAGE = "biped_sim.engine._gen.models"
#: the generated module's functions the twin translates
TRANSLATED = ("mass_matrix", "bias_forces", "contact_positions", "contact_jacobians", "contact_jacobian_dots",
              "contact_velocities", "energy")
_HASH_PLACEHOLDER = "@SOURCE_SHA256@"
#: the C entry points' table (KernelTable), read by each twin's runtime and by the compiled loop
KERNEL_TABLE_HEADER = Path(__file__).with_name("_kernel_table.h")
#: the part of every twin that is the same for every robot (the solves, the entry points, the Python functions),
#: which each twin's source includes after its robot's part
RUNTIME_HEADER = Path(__file__).with_name("_kernels_runtime.h")
#: the folder of both headers: a twin is compiled with it on the include path
INCLUDE_DIR = RUNTIME_HEADER.parent
_FUNCTIONS = {"sin": "sin", "cos": "cos", "sqrt": "sqrt", "tan": "tan", "exp": "exp", "log": "log"}
_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}

#: compiler runs in this process (a cached twin is loaded without one)
BUILDS = 0
#: loaded twins: (module file, its digest) -> extension or None
_LOADED: dict = {}


class KernelBuildError(RuntimeError):
    """The twin of a user's robot could not be built; the message is one line."""


# ---- the C source ------------------------------------------------------------------------------

def _expression(node, fn) -> str:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return repr(float(node.value))
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        return f"(-{_expression(node.operand, fn)})"
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        return f"({_expression(node.left, fn)} {_BINARY[type(node.op)]} {_expression(node.right, fn)})"
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
        # float ** int calls libm's pow with the exponent as a double, as this does (through a pointer, so
        # that the compiler cannot make pow(x, 2.0) x * x, which may round otherwise)
        return f"libm_pow({_expression(node.left, fn)}, {_expression(node.right, fn)})"
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCTIONS
            and len(node.args) == 1 and not node.keywords):
        return f"{_FUNCTIONS[node.func.id]}({_expression(node.args[0], fn)})"
    raise ValueError(f"{fn.name}, line {node.lineno}: no C translation for {ast.unparse(node)!r}")


def _c_function(fn: ast.FunctionDef) -> tuple[str, int]:
    """(the C function ``static void <name>(const double *q[, const double *dq], double *out)``, the
    number of outputs) of a generated function: unpacking, assignments, one returned tuple."""
    params = [a.arg for a in fn.args.args]
    used = {n.id for n in ast.walk(fn) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)}
    lines = []
    outputs = None
    for s in fn.body:
        if isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant):
            continue
        if (isinstance(s, ast.Assign) and isinstance(s.targets[0], ast.Tuple) and isinstance(s.value, ast.Name)
                and s.value.id in params):
            lines += [f"    const double {e.id} = {s.value.id}[{i}];"
                      for i, e in enumerate(s.targets[0].elts) if e.id in used]
        elif isinstance(s, ast.Assign) and len(s.targets) == 1 and isinstance(s.targets[0], ast.Name):
            lines.append(f"    const double {s.targets[0].id} = {_expression(s.value, fn)};")
        elif isinstance(s, ast.Return) and isinstance(s.value, ast.Tuple):
            outputs = len(s.value.elts)
            lines += [f"    out[{i}] = {_expression(e, fn)};" for i, e in enumerate(s.value.elts)]
        else:
            raise ValueError(f"{fn.name}, line {s.lineno}: no C translation for {ast.unparse(s)!r}")
    if outputs is None:
        raise ValueError(f"{fn.name}: no returned tuple")
    args = ", ".join(f"const double *{p}" for p in params) + ", double *out"
    return f"static void\n{fn.name}({args})\n{{\n" + "\n".join(lines) + "\n}\n", outputs


def kernel_source(module, module_name: str) -> str:
    """The C source of the twin of a generated module (its ``__file__``), as an extension named
    ``module_name`` (the last part of the import name)."""
    text = Path(module.__file__).read_text()
    tree = ast.parse(text)
    functions = {f.name: f for f in tree.body if isinstance(f, ast.FunctionDef)}
    missing = [name for name in TRANSLATED if name not in functions]
    if missing:
        raise ValueError(f"{module.__file__}: the generated module has no {', '.join(missing)}: regenerate it")
    n, nc, nu = len(module.COORDINATES), len(module.CONTACTS), len(module.ACTUATED)
    bodies, sizes = [], {}
    for name in TRANSLATED:
        body, sizes[name] = _c_function(functions[name])
        bodies.append(body)
    expected = {"mass_matrix": n * n, "bias_forces": n, "contact_positions": 2 * nc, "contact_jacobians": 2 * n * nc,
                "contact_jacobian_dots": 2 * n * nc, "contact_velocities": 2 * nc, "energy": 2}
    wrong = [f"{k} returns {sizes[k]}, not {v}" for k, v in expected.items() if sizes[k] != v]
    if wrong:
        raise ValueError(f"{module.__file__}: {'; '.join(wrong)}: regenerate it")
    b_times_u = [f"    out[{i}] += {float(b)!r} * u[{j}];" for i, row in enumerate(module.B)
                 for j, b in enumerate(row) if b]
    head = (f"/* GENERATED by biped_sim.engine.model_kernels from the generated module of the robot {module.NAME!r}\n"
            f" * (digest {module.DIGEST}, generator version {module.GENERATOR_VERSION}) -- do not edit.\n"
            f" * The robot's part; the rest is {RUNTIME_HEADER.name}, included at the end. */\n"
            "#define PY_SSIZE_T_CLEAN\n#include <Python.h>\n#include <math.h>\n\n"
            "static double (*volatile libm_pow)(double, double) = pow;\n\n"
            f"#define N {n}\n#define NC {nc}\n#define NU {nu}\n"
            f"#define MODULE_NAME \"{module_name}\"\n#define INIT_FUNCTION PyInit_{module_name}\n"
            f"#define ROBOT_NAME \"{module.NAME}\"\n#define ROBOT_DIGEST \"{module.DIGEST}\"\n"
            f"#define GENERATOR_VERSION {int(module.GENERATOR_VERSION)}\n"
            f"#define SOURCE_SHA256 \"{_HASH_PLACEHOLDER}\"\n\n")
    generated = "\n".join(bodies) + ("\n/* out += B u: one unit column per actuator */\nstatic void\n"
                                     "b_times_u(const double *u, double *out)\n{\n" + "\n".join(b_times_u)
                                     + ("\n" if b_times_u else "    (void)u; (void)out;\n") + "}\n")
    source = head + generated + f'\n#include "{RUNTIME_HEADER.name}"\n'
    # the included headers' text is part of what is built: a new runtime gives a new digest (and cache key)
    digest = hashlib.sha256("".join([source, RUNTIME_HEADER.read_text(), KERNEL_TABLE_HEADER.read_text()])
                            .encode()).hexdigest()
    return source.replace(_HASH_PLACEHOLDER, digest)


def source_sha256(source: str) -> str:
    """The digest a twin carries as SOURCE_SHA256 (of its source with the digest left out, then the text of
    :data:`RUNTIME_HEADER` and :data:`KERNEL_TABLE_HEADER`)."""
    start = source.index('#define SOURCE_SHA256 "') + len('#define SOURCE_SHA256 "')
    return source[start:start + 64]


def shipped_extension(name: str) -> str:
    """The import name of a shipped robot's twin."""
    return f"{SHIPPED_PACKAGE}._kernels_{name}"


# ---- build and load ------------------------------------------------------------------------------

def _toolchain():
    """(compile argv prefix, link argv prefix): Python's own compiler and flags (sysconfig), with the CC and
    LDSHARED environment variables honoured as setuptools does; a KernelBuildError says what to install."""
    cc = shlex.split(os.environ.get("CC") or sysconfig.get_config_var("CC") or "cc")
    if not cc or shutil.which(cc[0]) is None:
        raise KernelBuildError(f"no C compiler ({cc[0] if cc else 'cc'}) found: install gcc (apt-get install gcc)")
    include = sysconfig.get_paths()["include"]
    if not (Path(include) / "Python.h").is_file():
        raise KernelBuildError(f"the Python headers are missing ({include}/Python.h): install them "
                               "(apt-get install python3-dev)")
    ccshared = shlex.split(sysconfig.get_config_var("CCSHARED") or "-fPIC")
    if os.environ.get("LDSHARED"):
        ldshared = shlex.split(os.environ["LDSHARED"])
    else:
        # Python's link line with the compiler of the compile line (setuptools does the same with CC)
        ldshared = cc + shlex.split(sysconfig.get_config_var("LDSHARED") or "cc -shared")[1:]
    return cc + ccshared + ["-O2", "-ffp-contract=off", "-I", include, "-I", str(INCLUDE_DIR)], ldshared


def build(source: str, target: Path, source_copy: Path | None = None) -> None:
    """Compile ``source`` into the extension ``target`` (and keep the source as ``source_copy``): built under a
    temporary name in ``target``'s folder and renamed into place, so that two processes building the same
    robot at once each load a whole file."""
    global BUILDS
    compile_argv, link_argv = _toolchain()
    target.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".kernels-", dir=target.parent))
    try:
        src, obj, lib = work / "kernels.c", work / "kernels.o", work / target.name
        src.write_text(source)
        BUILDS += 1
        for argv in (compile_argv + ["-c", str(src), "-o", str(obj)], link_argv + [str(obj), "-o", str(lib)]):
            try:
                out = subprocess.run(argv, capture_output=True, text=True, timeout=300)
            except (OSError, subprocess.TimeoutExpired) as e:
                raise KernelBuildError(f"{argv[0]} did not run: {e}") from None
            if out.returncode != 0:
                first = next((line for line in out.stderr.splitlines() if "error" in line.lower()),
                             (out.stderr.strip().splitlines() or ["no message"])[0])
                raise KernelBuildError(f"{argv[0]} failed ({first.strip()})")
        if source_copy is not None:
            os.replace(src, source_copy)
        os.replace(lib, target)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _load_extension(name: str, path: Path):
    loader = importlib.machinery.ExtensionFileLoader(name, str(path))
    spec = importlib.util.spec_from_file_location(name, str(path), loader=loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def _user_kernels(module, name: str, source: str):
    """The twin of a user's robot from the cache next to its module, built now when it is not there."""
    stem = Path(module.__file__).with_suffix("").name
    base = f"{stem}.kernels-{source_sha256(source)[:16]}"
    target = Path(module.__file__).with_name(base + (sysconfig.get_config_var("EXT_SUFFIX") or ".so"))
    if not target.is_file():
        build(source, target, target.with_name(base + ".c"))
    return _load_extension(name, target)


def _why_python(model, why: str) -> None:
    warnings.warn(f"biped_sim: robot {model.name!r} runs its dynamics on the Python path (numpy, slower): its "
                  f"compiled kernels are not available: {why}", RuntimeWarning, stacklevel=3)


def compiled_kernels(model):
    """The compiled twin of ``model``'s six kernels (:data:`KERNELS`; ``model`` a GeneratedModel), or None
    where the Python path must run: ``BIPED_SIM_PURE_PYTHON`` is set (silently), or the twin cannot be
    built or loaded (one warning per robot that says what to install)."""
    if os.environ.get("BIPED_SIM_PURE_PYTHON", "") not in ("", "0"):
        return None
    module = model.module
    key = (getattr(module, "__file__", None), module.DIGEST)
    if key in _LOADED:
        return _LOADED[key]
    ext = None
    try:
        shipped = module.__name__.startswith(SHIPPED_PACKAGE + ".")
        name = module.__name__.rsplit(".", 1)[-1]
        ext_name = (f"_kernels_{name}" if shipped
                    else f"_kernels_{module.NAME}_{module.DIGEST}_g{int(module.GENERATOR_VERSION)}")
        source = kernel_source(module, ext_name)
        if shipped:
            try:
                ext = importlib.import_module(shipped_extension(name))
            except ImportError:
                raise KernelBuildError(f"the shipped twin {shipped_extension(name)} was not built: install gcc and the "
                                       "Python headers, then reinstall (make venv)") from None
        else:
            ext = _user_kernels(module, ext_name, source)
        if ext.SOURCE_SHA256 != source_sha256(source):
            ext = None
            raise KernelBuildError("the compiled twin is older than its generated module: rebuild it (make venv)"
                                   if shipped else "the cached twin is not of its source: delete it")
    except (KernelBuildError, ValueError, OSError, ImportError) as e:
        _why_python(model, str(e))
        ext = None
    _LOADED[key] = ext
    return ext
