"""The generated code as the engine calls it: ``gen``, the closed forms of docs/model.md (D, C, G, feet,
J, Jdot, energy, the stance KKT solution), and ``rk``, the unrolled Runge-Kutta steps.

Owns one choice. ``_gen/closed_forms.py`` (generated from the energies by tools/generate_model.py) and
``_gen/rk_steps.py`` (generated from scipy's tableaux by tools/generate_rk.py) are the definitions;
``_gen/_cmodel`` is their compiled twin (C, generated from both by tools/generate_c.py and built by
setup.py as an optional extension), which performs the same IEEE operations in the same order and
so returns the same bits, faster (docs/performance.md). ``gen`` and ``rk`` use the twin when it was built
from the current sources, else the Python code; results do not depend on which
(test/unit/test_compiled.py). ``BIPED_SIM_PURE_PYTHON=1`` forces the Python code.
"""
from __future__ import annotations

import functools
import hashlib
import os
import types
from pathlib import Path

from biped_sim.engine._gen import closed_forms, rk_steps

SOURCES = (closed_forms, rk_steps)


def _compiled_twin():
    """(the _cmodel module or None, why not)."""
    if os.environ.get("BIPED_SIM_PURE_PYTHON", "") not in ("", "0"):
        return None, "BIPED_SIM_PURE_PYTHON is set"
    try:
        from biped_sim.engine._gen import _cmodel
    except ImportError:
        return None, ("the compiled twin biped_sim/engine/_gen/_cmodel was not built: install gcc and the Python "
                      "headers, then make venv")
    digest = hashlib.sha256(b"".join(Path(m.__file__).read_bytes() for m in SOURCES)).hexdigest()
    if _cmodel.SOURCE_SHA256 != digest:
        return None, "the compiled twin is older than the generated Python code; rebuild it: make venv"
    return _cmodel, ""


@functools.lru_cache(maxsize=1)
def derivatives_digest():
    """The digest of the sources of ``_gen/_derivatives.h`` (derivatives.py and closed_forms.py), which the C
    built on it carries as DERIVATIVES_SHA256 (tools/generate_c.py), so that a stale build can be detected."""
    from biped_sim.engine._gen import derivatives
    return hashlib.sha256(b"".join(Path(m.__file__).read_bytes() for m in (derivatives, closed_forms))).hexdigest()


def _with_twin(module, twin):
    """The module's public names, its functions replaced by their twins (in its tables too)."""
    ns = types.SimpleNamespace(**{n: v for n, v in vars(module).items() if not n.startswith("_")})
    if twin is None:
        return ns
    for name, value in vars(ns).items():
        if callable(value) and hasattr(twin, name):
            setattr(ns, name, getattr(twin, name))
        elif isinstance(value, dict):   # e.g. DOP853_STEPS: state size -> step function
            setattr(ns, name, {k: getattr(twin, getattr(v, "__name__", ""), v) for k, v in value.items()})
    return ns


_twin, WHY_PYTHON = _compiled_twin()
#: "C" or "Python": which code ``gen`` and ``rk`` run (``WHY_PYTHON`` says why when it is Python)
IMPLEMENTATION = "C" if _twin else "Python"
gen = _with_twin(closed_forms, _twin)
rk = _with_twin(rk_steps, _twin)
