"""What ``make demo`` and ``make test`` install (issue 33): a run needs no test tools and no Ray (201 MB
as a wheel), the tests need them; and the environment's bytecode is compiled."""
import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DEV_ONLY = ("pytest", "hypothesis", "rosbags", "colcon-core", "ruff", "ray")


def pinned(path):
    return {line.split("==")[0].split("[")[0] for line in path.read_text().splitlines()
            if line and not line.startswith(("#", "-r"))}


def make_dry_run(target, tmp_path):
    """The commands of ``make -n TARGET`` for a venv that does not exist yet (nothing is run)."""
    done = subprocess.run(["make", "-n", target, f"VENV={tmp_path / 'venv'}"], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_a_run_installs_no_test_tool_and_no_ray_and_make_test_installs_them(tmp_path):
    run, dev = pinned(ROOT / "requirements.txt"), pinned(ROOT / "requirements-dev.txt")
    assert not run & set(DEV_ONLY), run & set(DEV_ONLY)
    assert set(DEV_ONLY) <= dev
    assert "-r requirements.txt" in (ROOT / "requirements-dev.txt").read_text().splitlines()
    demo, test = make_dry_run("demo", tmp_path), make_dry_run("test", tmp_path)
    assert "-r requirements.txt" in demo and "requirements-dev.txt" not in demo, demo
    assert "-r requirements-dev.txt" in test and "-m pytest" in test, test


def test_the_environment_has_its_bytecode_compiled():
    """uv writes no .pyc; where Python writes none either (PYTHONDONTWRITEBYTECODE) every process compiled
    its imports from source (simulate --duration 0.1: 0.86 s, 0.48 s compiled). make venv compiles them."""
    missing = [name for name in ("numpy", "scipy.optimize", "mcap.reader", "biped_sim.engine.hybrid")
               if not Path(importlib.util.cache_from_source(importlib.util.find_spec(name).origin)).exists()]
    assert not missing, f"no .pyc for {missing} in {sys.prefix}: run make venv"
