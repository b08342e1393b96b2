"""The loop-compiler probe of issue 29: one slice of the hybrid loop's numerics (the dop853 step with its error
control, the dense output, the swing foot's height on it, the dip bound and brentq) written once in
``rules.py`` and run four ways: as Python, compiled by Cython (pure-Python mode), compiled by numba, and
beside today's hand-written C (``biped_sim.engine._core``). ``measure.py`` compares their bits, speed and
costs; docs/engine.md, "How the compiled loop is made: the choice", reads the figures."""
import importlib
import sys

# Run as Python, ``from cython.cimports.<package>.kernels import ...`` (rules.py) is resolved by Cython's shadow
# module only for top-level modules: the probe's kernels are registered under their cimport name here.
_CIMPORT_NAME = "cython.cimports.benchmarks.loop_compilers.kernels"
if _CIMPORT_NAME not in sys.modules:
    sys.modules[_CIMPORT_NAME] = importlib.import_module("benchmarks.loop_compilers.kernels")
