"""The closed forms of MODEL.md (D, C, G, feet, J, Jdot, energy, the stance KKT solution) as the
engine calls them: ``gen``.

Owns one choice. ``_generated.py`` (Python, generated from the energies by tools/generate_model.py)
is the definition; ``_cmodel`` is its compiled twin (C, generated from ``_generated.py`` by
tools/generate_c.py and built by setup.py as an optional extension), which performs the same IEEE
operations in the same order and so returns the same bits, about ten times faster. ``gen`` is the
twin when it was built from the current ``_generated.py``, else ``_generated`` itself; results do
not depend on which (test/test_closed_form.py). ``BIPED_SIM_CLOSED_FORM=python`` forces the
Python code.
"""
from __future__ import annotations

import hashlib
import os
import types
from pathlib import Path

from . import _generated


def _compiled_twin():
    """(the _cmodel module or None, why not)."""
    if os.environ.get("BIPED_SIM_CLOSED_FORM", "").lower() == "python":
        return None, "BIPED_SIM_CLOSED_FORM=python"
    try:
        from . import _cmodel
    except ImportError as exc:
        return None, f"the compiled twin was not built ({exc}); reinstall with a C compiler: make venv"
    digest = hashlib.sha256(Path(_generated.__file__).read_bytes()).hexdigest()
    if _cmodel.SOURCE_SHA256 != digest:
        return None, "the compiled twin is older than _generated.py; rebuild it: make venv"
    return _cmodel, ""


_twin, WHY_PYTHON = _compiled_twin()
#: "C" or "Python": which code ``gen`` runs (``WHY_PYTHON`` says why when it is Python)
IMPLEMENTATION = "C" if _twin else "Python"

gen = types.SimpleNamespace(**{name: getattr(_generated, name) for name in dir(_generated) if not name.startswith("_")})
if _twin is not None:
    for _name in dir(_twin):
        if not _name.startswith("_") and _name != "SOURCE_SHA256":
            setattr(gen, _name, getattr(_twin, _name))
