"""Torque laws written in Python at compiled speed (biped_sim/control/compiled_laws.py): one law function
gives the same run compiled through the hook (numba) and as plain Python, on the compiled loop and the
pure-Python one; it works in a sweep; a failing law ends the run "failed" naming it; without numba it
runs as plain Python after one line."""
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import biped_sim as bs
from biped_sim.analysis.edge_cases import on_both_loops
from biped_sim.config.scenes import load_scene
from biped_sim.control import compiled_laws
from biped_sim.engine import compiled_loop
from biped_sim.engine.dynamics import stance_joint_affine_fast
from biped_sim.engine.model import BipedModel

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from examples.hzd_bezier import hzd_controller  # noqa: E402

HAVE_NUMBA, WHY = compiled_laws.numba_available()
needs_numba = pytest.mark.skipif(not HAVE_NUMBA, reason=WHY)
needs_loop = pytest.mark.skipif(not compiled_loop.AVAILABLE, reason=f"no compiled loop: {compiled_loop.WHY_NOT}")
MODEL = BipedModel()
FIELDS = ("t", "q", "dq", "u", "grf")


class PlainOnly:
    """The same law object, offered to the engine as a Python controller only (no compiled_law)."""
    accepts_lists = True

    def __init__(self, law):
        self.law = law

    def __call__(self, t, q, dq, stance_leg):
        return self.law(t, q, dq, stance_leg)


def walk(ctrl, period, t_final=1.1):
    return load_scene("walk").simulate(controller=ctrl, t_final=t_final, hold=period is not None)


def assert_same_bits(a, b):
    assert (a.status, a.message) == (b.status, b.message)
    assert [(e.kind, e.time) for e in a.events] == [(e.kind, e.time) for e in b.events]
    for field in FIELDS:
        assert getattr(a, field).tobytes() == getattr(b, field).tobytes(), field


@needs_numba
@needs_loop
@pytest.mark.parametrize("period", [None, 1e-3])
def test_one_law_gives_the_same_run_compiled_and_as_plain_python_on_both_loops(period):
    law = hzd_controller(MODEL)
    assert law.compiled_law(MODEL) is not None
    compiled, python_loop = on_both_loops(lambda: walk(law, period))
    plain, plain_python_loop = on_both_loops(lambda: walk(PlainOnly(law), period))
    assert compiled.status == "completed" and len(compiled.impacts) == 2
    assert compiled.stats["compiled_loop_steps"] > 0
    for other in (python_loop, plain, plain_python_loop):
        assert_same_bits(compiled, other)


@needs_numba
def test_the_pure_python_process_gives_the_compiled_run_bit_for_bit():
    code = ("import sys, numpy as np; sys.path.insert(0, '.'); from examples.hzd_bezier import hzd_controller; "
            "import biped_sim as bs; from biped_sim.config.scenes import load_scene; "
            "r = load_scene('walk').simulate(controller=hzd_controller(bs.BipedModel()), t_final=1.1); "
            "sys.stdout.write(np.concatenate([r.q.ravel(), r.u.ravel()]).tobytes().hex())")
    env = dict(os.environ, BIPED_SIM_PURE_PYTHON="1")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    r = walk(hzd_controller(MODEL), 1e-3)
    assert bytes.fromhex(done.stdout) == np.concatenate([r.q.ravel(), r.u.ravel()]).tobytes()


def test_the_dynamics_a_law_calls_are_the_engines_bits():
    rng = np.random.default_rng(3)
    k = MODEL.k[compiled_laws.STANCE_CONSTANTS]
    for _ in range(20):
        q = (rng.uniform(-1, 1, 5) + [0, 0.9, math.pi, math.pi, 0]).tolist()
        dq = rng.uniform(-4, 4, 5).tolist()
        for leg in (1, 2):
            a, Bu = stance_joint_affine_fast(MODEL, q, dq, leg)
            flat = compiled_laws.stance_joint_affine(np.array(q), np.array(dq), leg, np.array(k))
            assert [float(v) for v in flat] == a + [Bu[0][0], Bu[0][1], Bu[1][0], Bu[1][1], Bu[2][0], Bu[2][1]]


@needs_numba
def test_a_sweep_of_a_compiled_law_gives_the_single_runs(monkeypatch):
    monkeypatch.chdir(ROOT)
    name = "examples.hzd_bezier:hzd_controller"
    rows = bs.sweep("walk", {"controller.kp": [150.0, 250.0]}, duration=0.6, workers=2, controller=name)
    for row in rows:
        single = load_scene("walk").simulate(t_final=0.6, controller=name, controller_args={"kp": row["controller.kp"]})
        assert row["status"] == single.status == "completed"
        assert row["q_end"] == [float(v) for v in single.q[-1]]
    assert rows[0]["q_end"] != rows[1]["q_end"]


def failing_law(t, q, dq, stance_leg, params, u):
    u[0] = -params[0] * dq[2]
    u[1] = -params[0] * dq[3]
    if t >= 0.2:
        return 7
    return 0


def nan_law(t, q, dq, stance_leg, params, u):
    u[0] = 0.0
    u[1] = math.nan if t >= 0.2 else 0.0
    return 0


@needs_numba
@needs_loop
@pytest.mark.parametrize("period", [None, 1e-3])
def test_a_law_that_fails_or_writes_a_nan_ends_the_run_failed_naming_it(period):
    for fn, compiled_says, plain_says in (
            (failing_law, r"the torque law failing_law returned 7 at t=0\.2\d* s$",
             r"TorqueLawError at t=0\.2\d* s: the torque law failing_law returned 7 \(\S+:\d+ in __call__\)$"),
            (nan_law, rf"the torque law nan_law returned {compiled_laws.NOT_FINITE} at t=0\.2\d* s$",
             r"TorqueLawError at t=0\.2\d* s: the torque law nan_law wrote u = \[0\.0, nan\]: not finite "
             r"\(\S+:\d+ in __call__\)$")):
        law = bs.torque_law(fn, [1.0])
        compiled, python_loop = on_both_loops(lambda: walk(law, period, t_final=0.4))
        assert compiled.status == python_loop.status == "failed"
        assert re.search(compiled_says, compiled.message), compiled.message
        assert re.search(plain_says, python_loop.message), python_loop.message
        assert 0.15 < compiled.t[-1] <= 0.2 + 1e-12 and compiled.t[-1] == python_loop.t[-1]


@needs_numba
def test_a_law_numba_cannot_compile_is_one_line():
    def bad(t, q, dq, stance_leg, params, u):
        u[0] = {"a": 1}["a"] + "text"
        return 0
    with pytest.raises(ValueError, match=r"^the torque law .*bad does not compile with numba: ") as info:
        bs.torque_law(bad).compiled_law(MODEL)
    assert "\n" not in str(info.value)


def test_without_numba_a_law_runs_as_plain_python_after_one_line():
    code = ("import sys, warnings; sys.modules['numba'] = None; sys.path.insert(0, '.'); "
            "from examples.hzd_bezier import hzd_controller; import biped_sim as bs; "
            "from biped_sim.config.scenes import load_scene; "
            "law = hzd_controller(bs.BipedModel()); assert law.compiled_law(bs.BipedModel()) is None; "
            "r = load_scene('walk').simulate(controller=law, t_final=0.6); print(r.status, len(r.impacts))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout == "completed 1\n"
    lines = [line for line in done.stderr.splitlines() if "numba is not installed" in line]
    assert len(lines) == 1 and "pip install 'biped_sim[numba]'" in lines[0], done.stderr


def test_a_law_of_the_wrong_form_is_refused_when_made():
    with pytest.raises(ValueError, match=r"takes 4 arguments; a law is law\(t, q, dq, stance_leg, params, u\)"):
        bs.torque_law(lambda t, q, dq, stance_leg: 0)
    with pytest.raises(ValueError, match="params must be at most 128 finite real numbers"):
        bs.torque_law(failing_law, [math.nan])


@needs_numba
def test_a_law_already_under_njit_is_taken_as_its_python_function():
    import numba
    law = bs.torque_law(numba.njit(failing_law), [2.0])
    assert law.fn is failing_law and law(0.0, [0.0] * 5, [0.0, 0.0, 1.0, -1.0, 0.0], 1) == [-2.0, 2.0]


@needs_numba
def test_a_law_file_compiles_as_a_script_after_it_was_imported_as_a_module(tmp_path):
    """numba's cache beside a law's file is keyed by the file, not by the module's name: a law imported as
    ``pkg.law`` (a test, ``--controller pkg.law:ATTR``) and then run as ``python pkg/law.py`` must compile
    in both (the documented ``python examples/hzd_bezier.py`` raised ModuleNotFoundError: 'examples')."""
    pkg = tmp_path / "lawpkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "law.py").write_text(
        "from biped_sim.control.compiled_laws import torque_law\n"
        "from biped_sim.engine.model import BipedModel\n\n"
        "def gain(x, k):\n    return k * x\n\n"
        "def law(t, q, dq, stance_leg, params, u):\n"
        "    u[0] = gain(q[2], params[0])\n    u[1] = -u[0]\n    return 0\n\n"
        "def compiled():\n    return torque_law(law, [2.0]).compiled_law(BipedModel()) is not None\n\n"
        "if __name__ == '__main__':\n    print('compiled', compiled())\n")
    as_module = (["-c", "import lawpkg.law as m; print('compiled', m.compiled())"], str(tmp_path))
    as_script = ([str(pkg / "law.py")], str(ROOT))      # (the package is not on the script's path)
    for args, path in (as_module, as_script):
        env = {**os.environ, "PYTHONPATH": path}
        done = subprocess.run([sys.executable, *args], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=300)
        assert done.returncode == 0 and "compiled True" in done.stdout, done.stderr[-2000:]
