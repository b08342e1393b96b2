"""rules.py compiled by numba: the same source text loaded as a fresh module (``rules_nb``) whose kernels are
glue.h's C entry points in a shared library (build.build_glue_so) and whose functions are wrapped in
``numba.njit``. ``NUMBA_DISABLE_JIT=1`` would run the text as Python, as rules.py itself does."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import llvmlite.binding
import numba

HERE = Path(__file__).resolve().parent
MODULE = "rules_nb"
ENTRIES = ("begin", "step", "steps", "dense_at", "dense_state", "height_at", "may_dip", "locate_crossing")
FUNCTIONS = ENTRIES + tuple("_" + name for name in ENTRIES + ("dense",))


# glue_so.c's symbols by name (numba.types.ExternalFunction, linked when a function is compiled; load() loads the
# library first): unlike ctypes function objects, which numba bakes in as addresses, they let cache=True keep
# the compiled code
_d, _p, _void = numba.types.float64, numba.types.voidptr, numba.types.void
c_rhs = numba.types.ExternalFunction("so_rhs", _void(_p, _d, _p, _p))
c_step = numba.types.ExternalFunction("so_dop853_step", _void(_p, _d, _p, _p, _d, _d, _d, _p))
c_dense = numba.types.ExternalFunction("so_dop853_dense", _void(_p, _d, _d, _p, _p, _p, _p))
c_feet = numba.types.ExternalFunction("so_foot_positions", _void(_p, _p, _p))
c_ulp = numba.types.ExternalFunction("so_ulp", _d(_d))


# the kernels as kernels.py gives them (S and offsets into it): S's address plus 8 bytes an entry
def k_rhs(S, t, y, dy):
    a = S.ctypes.data
    c_rhs(a, t, a + 8 * y, a + 8 * dy)


def k_step(S, t, y, f, h, rtol, atol, out):
    a = S.ctypes.data
    c_step(a, t, a + 8 * y, a + 8 * f, h, rtol, atol, a + 8 * out)


def k_dense(S, t_old, h, y_old, y, k, dense):
    a = S.ctypes.data
    c_dense(a, t_old, h, a + 8 * y_old, a + 8 * y, a + 8 * k, a + 8 * dense)


def k_foot_positions(S, q, p):
    a = S.ctypes.data
    c_feet(a, a + 8 * q, a + 8 * p)


def k_ulp(x):
    return c_ulp(x)


def ptr(S):
    return S


KERNELS = (k_rhs, k_step, k_dense, k_foot_positions, k_ulp, ptr)


def load(so, cache=False):
    """rules.py as a module of numba-compiled functions (compiled at their first call)."""
    # (registered by its name before it runs: numba's cache finds a function's module again by that name)
    spec = importlib.util.spec_from_file_location(MODULE, HERE / "rules.py")
    module = sys.modules[MODULE] = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    llvmlite.binding.load_library_permanently(str(so))
    for fn in KERNELS:
        setattr(module, fn.__name__, numba.njit(cache=cache)(fn))
    for name in FUNCTIONS:
        setattr(module, name, numba.njit(cache=cache)(getattr(module, name)))
    return module
