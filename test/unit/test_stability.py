"""``biped-sim stability --quick``: every case passes, and each deliberately broken setting makes
exactly the case it targets fail (the checks can fail)."""
import contextlib
import io

import pytest

from biped_sim.analysis import stability
from biped_sim.cli import main


def _run(argv):
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        rc = main(["stability"] + argv)
    lines = [l for l in out.getvalue().splitlines() if l[:4] in ("PASS", "FAIL", "SKIP")]
    return rc, lines


@pytest.fixture(scope="module")
def quick():
    return _run(["--quick"])


def test_quick_suite_passes(quick):
    rc, lines = quick
    assert rc == 0, "\n".join(l for l in lines if l.startswith("FAIL"))
    assert not [l for l in lines if l.startswith("FAIL")]
    text = "\n".join(lines)
    for name in ("hip_pd kp=1e+06", "constraint_drift", "compliant_ground", "mass+inertia ratio",
                 "inertia ratio", "torque 1e+07", "joint rates 1e3", "coincident feet", "grazing_touchdown",
                 "near_zeno", "double_touchdown", "guard_zero_after_reset", "walk 40 steps", "passive spin",
                 "NaN in q0", "inf in dq0", "NaN torque from controller", "scuffs_bounded", "liftoff_at_start",
                 "grazing_dip_20um", "crossing_at_stance_x", "foot_just_above_ground"):
        assert name in text, name
    assert sum(l.startswith("SKIP") for l in lines) == 1          # no compliant ground: said so
    stiff = next(l for l in lines if "hip_pd kp=1e+06" in l)
    assert "radau" in stiff and "bdf" in stiff and "steps" in stiff


@pytest.mark.parametrize("broken", sorted(stability.BREAKS))
def test_broken_setting_fails_the_right_case(broken):
    target = stability.BREAKS[broken][0]
    case = {"constraint_drift": "constraint_drift", "grazing_touchdown": "grazing",
            "near_zeno": "near_zeno"}[target]
    rc, lines = _run(["--quick", "--break", broken, "--case", case, "--case", "bad_numbers"])
    assert rc == 1
    failed = [l for l in lines if l.startswith("FAIL")]
    assert failed and all(target in l for l in failed), lines
    assert any(l.startswith("PASS") and "NaN in q0" in l for l in lines)


def test_unknown_break_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown --break"):
        stability.run_suite(quick=True, broken="nonsense", only=["bad_numbers"])


def test_the_sample_check_fails_a_run_with_a_foot_under_the_ground_or_the_ground_pulling():
    import biped_sim as bs
    from biped_sim.analysis.verify import result_violations
    m = bs.BipedModel()
    r = bs.load_scene("walk").simulate(t_final=1.0, hold=False)
    assert r.status == "completed" and result_violations(m, r) == []
    k = len(r.t) // 2
    r.q[k, 1] -= 0.01           # the hip 1 cm lower and the robot at rest: the swing foot is under the
    r.dq[k] = 0.0               # ground, not swinging through it
    r.grf[k + 1, 1] = -5.0      # and a stance sample where the ground pulls
    found = result_violations(m, r)
    assert any("below the ground" in v for v in found) and any("pulls" in v for v in found), found
