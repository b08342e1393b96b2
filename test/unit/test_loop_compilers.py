"""The single-source slice of the hybrid loop (benchmarks/loop_compilers/rules.py: the dop853 step with its error
control, the dense output, the swing foot's height on it, the dip search and brentq) gives today's hand C's
bits (biped_sim.engine._core; the Python engine's grazing.dip_bracket for the dip) on random inputs, compiled by
Cython and run as Python, and compiled by numba where it is installed (docs/engine.md, "How the compiled loop
is made: the choice"). Skipped where Cython is not installed."""
import shutil

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from biped_sim.engine import compiled_loop

pytest.importorskip("Cython")
pytestmark = [pytest.mark.skipif(not compiled_loop.AVAILABLE, reason=f"no compiled loop: {compiled_loop.WHY_NOT}"),
              pytest.mark.skipif(shutil.which("gcc") is None, reason="no C compiler")]

from benchmarks.loop_compilers import build, measure as M, rules  # noqa: E402  (needs Cython's shadow module)

CASES = st.builds(
    lambda landing, i, noise, u, h_abs, tol, slope, graze: (
        M.make_case(M.landing_states()[i % len(M.landing_states())], [0.0] * 5, (0.0, 0.0), 0.02 + 0.08 * h_abs,
                    10 ** (-10 + 2 * tol), 0.0, 10 ** (-12 + 6 * graze)) if landing else
        M.make_case(i, noise, u, 10 ** (-4 + 3 * h_abs), 10 ** (-11 + 6 * tol), slope, 10 ** (-12 + 6 * graze))),
    st.booleans(), st.integers(0, 1 << 20), st.lists(st.floats(-0.5, 0.5), min_size=5, max_size=5),
    st.tuples(st.floats(-20, 20), st.floats(-20, 20)), st.floats(0, 1), st.floats(0, 1), st.floats(-0.1, 0.1),
    st.floats(0, 1))


@pytest.fixture(scope="module")
def compiled():
    """rules.py compiled by Cython (the choice; the last build is reused while its inputs are the same)."""
    return {"cython": build.build_cython()[0]}


def _same_bits(impl, case, python=None):
    ref = M.hand_outputs(case)
    got = M.outputs(impl, case)
    for part, value in got.items():   # what the hand C does not give (the dip's bound): the Python run's
        assert value == (ref[part] if part in ref else python[part]), (part, case)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=CASES)
def test_the_compiled_slice_gives_the_hand_c_bits(compiled, case):
    python = M.outputs(rules, case)
    _same_bits(rules, case, python)
    for impl in compiled.values():
        _same_bits(impl, case, python)


def test_the_cases_reach_a_crossing_and_a_dip(compiled):
    """The inputs above exercise brentq's iterations and the dip search's halving (not only their early
    returns): the walk's landing states carry the swing foot through the ground in one step."""
    mismatches, seen = M.compare_bits(compiled, M.random_cases(30))
    assert mismatches == {"cython": {}}
    assert seen["brentq roots"] >= 3 and seen["steps with rejections"] >= 1


def test_numba_gives_the_same_bits():
    numba_binding = pytest.importorskip("benchmarks.loop_compilers.numba_binding")
    impl = numba_binding.load(build.build_glue_so()[0])
    mismatches, _ = M.compare_bits({"numba": impl, "python": rules}, M.random_cases(15))
    assert mismatches == {"numba": {}, "python": {}}
