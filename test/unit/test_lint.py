"""Static checks of the source, no process of ours: ``ruff check`` is clean (rules in ruff.toml), and
every import of the installed package is declared where its installer reads it (package.xml for ROS
and rosdep, setup.py for pip)."""
from __future__ import annotations

import ast
import importlib.metadata
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# the rosdep key package.xml names for each pip distribution imported (rosdep has no key for mcap
# alone; mcap-ros2-support's key installs it)
ROSDEP_KEY = {"numpy": "python3-numpy", "scipy": "python3-scipy", "PyYAML": "python3-yaml",
              "mcap": "mcap-ros2-support", "matplotlib": "python3-matplotlib", "zstandard": "python3-zstandard",
              "lz4": "python3-lz4", "pillow": "python3-pil", "tqdm": "python3-tqdm"}
# optional extras that rosdep has no key for: declared in setup.py's extras_require only (a ROS user
# installs them with pip when wanted); package.xml cannot say "optional"
# [ray]: the sweep's Ray backend; [video]: MP4; [numba]: torque laws compiled in the loop; [models]: sympy
# for a user's robot description
NO_ROSDEP_KEY = {"ray", "imageio-ffmpeg", "numba", "sympy"}
# imported but never required at run time: Cython's magic module, which loop_rules.py takes only where Cython
# is imported already (else engine/_cython_shim.py stands in); Cython generates _loop_rules.c
# (requirements-dev.txt, make generate-loop) and nothing installs it
BUILD_ONLY = {"cython"}
# optional extras that need not be installed here: {module: distribution}, checked against extras_require
OPTIONAL_MAY_BE_ABSENT = {"imageio_ffmpeg": "imageio-ffmpeg",   # biped-sim animate -o x.mp4
                          "pandas": "pandas"}                    # RecordedRun.to_dataframe


def test_ruff_is_clean():
    try:
        import ruff  # noqa: F401
    except ImportError:
        pytest.fail("ruff is not installed: `make test` installs it (requirements-dev.txt)")
    argv = [sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format", "concise", "."]
    done = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=120)
    assert done.returncode == 0, f"{' '.join(argv[2:])} in {ROOT}:\n{done.stdout}{done.stderr}"


def imported_top_level_modules(package: Path) -> set[str]:
    """Top-level names of every import under ``package``, inside functions too."""
    found = set()
    for path in package.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                found.add(node.module.split(".")[0])
    return found - set(sys.stdlib_module_names) - {package.name}


def setup_keyword(name: str):
    tree = ast.parse((ROOT / "setup.py").read_text())
    call = next(n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "setup")
    return ast.literal_eval(next(k.value for k in call.keywords if k.arg == name))


def test_every_import_of_the_package_is_declared():
    """A ROS package (its wheel here is ``ros-<name>``) in package.xml under its own name; any other
    distribution in setup.py (install_requires, or an extra for what is imported only lazily) and in
    package.xml under its rosdep key."""
    declared_ros = {e.text for e in ET.parse(ROOT / "package.xml").getroot() if e.tag in ("depend", "exec_depend")}
    pip = set(setup_keyword("install_requires")) | {d for ds in setup_keyword("extras_require").values() for d in ds}
    by_module = importlib.metadata.packages_distributions()
    problems = []
    for module in sorted(imported_top_level_modules(ROOT / "biped_sim") - BUILD_ONLY):
        dists = by_module.get(module)
        if not dists and module in OPTIONAL_MAY_BE_ABSENT:
            if OPTIONAL_MAY_BE_ABSENT[module] not in pip:
                problems.append(f"{module}: {OPTIONAL_MAY_BE_ABSENT[module]} missing from setup.py extras_require")
        elif not dists:
            problems.append(f"{module}: no installed distribution provides it (cannot check its declaration)")
        elif any(d.startswith("ros-") for d in dists):
            if module not in declared_ros:
                problems.append(f"{module}: ROS package missing from package.xml <exec_depend>")
        else:
            if dists[0] not in pip:
                problems.append(f"{module}: {dists[0]} missing from setup.py install_requires / extras_require")
            if dists[0] not in NO_ROSDEP_KEY and ROSDEP_KEY.get(dists[0]) not in declared_ros:
                problems.append(f"{module}: rosdep key for {dists[0]} ({ROSDEP_KEY.get(dists[0])}) missing from "
                                "package.xml (or from ROSDEP_KEY here)")
    assert not problems, "\n".join(problems)
