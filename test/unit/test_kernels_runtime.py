"""The compiled kernels' runtime written once (biped_sim/engine/_kernels_runtime.h; docs/models.md).

A twin's generated source holds its robot's part only (the translated formulas and B u) and includes the
runtime every robot shares; the headers it includes ship as package data; their text keys the source's
digest, so a user's twin cached with another runtime is built anew, not loaded.
"""
import ast
import re
from pathlib import Path

import pytest

from biped_sim.config import models
from biped_sim.engine import model_kernels

ROOT = Path(__file__).resolve().parents[2]
INCLUDE = re.compile(r'^#include "([^"]+)"', re.MULTILINE)
DEFINED = re.compile(r"^static [^;{]*?\n?(\w+)\(", re.MULTILINE)
#: the runtime's header, in the package's folder
RUNTIME = Path(model_kernels.__file__).with_name("_kernels_runtime.h")


@pytest.mark.parametrize("name", models.SHIPPED)
def test_a_twins_source_is_its_robots_part_and_includes_the_runtime(name):
    module = models.dynamics_module(models.load_description(name))
    source = model_kernels.kernel_source(module, f"_kernels_{name}")
    assert INCLUDE.findall(source) == [RUNTIME.name]
    # the functions it defines are the robot's formulas; the solves and Python functions are the runtime's
    assert sorted(DEFINED.findall(source)) == sorted(model_kernels.TRANSLATED + ("b_times_u",))
    runtime = RUNTIME.read_text() if RUNTIME.is_file() else ""
    for shared in ("cholesky", "schur_solve", "c_stance", "k_stance", "read_vector", "INIT_FUNCTION(void)"):
        assert shared in runtime and shared not in source, shared


def test_the_headers_a_twin_includes_ship_with_the_package():
    includes = set(INCLUDE.findall(RUNTIME.read_text())) | {RUNTIME.name}
    call = next(n for n in ast.walk(ast.parse((ROOT / "setup.py").read_text()))
                if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "setup")
    package_data = ast.literal_eval(next(k.value for k in call.keywords if k.arg == "package_data"))
    assert includes <= set(package_data["biped_sim.engine"]), (includes, package_data)
    assert all((RUNTIME.parent / h).is_file() for h in includes)


def _copy_headers(folder: Path, doc: str) -> None:
    """Both headers into ``folder``, the runtime's module docstring starting with ``doc`` (a build that includes
    it says so in its ``__doc__``)."""
    folder.mkdir()
    (folder / model_kernels.KERNEL_TABLE_HEADER.name).write_text(model_kernels.KERNEL_TABLE_HEADER.read_text())
    runtime = model_kernels.RUNTIME_HEADER.read_text()
    assert runtime.count('"The compiled kernels of the robot "') == 1
    (folder / model_kernels.RUNTIME_HEADER.name).write_text(
        runtime.replace('"The compiled kernels of the robot "', f'"{doc} of the robot "'))


def test_a_new_runtime_changes_the_digest_and_a_cached_user_twin_is_built_anew(tmp_path, monkeypatch):
    pytest.importorskip("sympy")
    monkeypatch.delenv("BIPED_SIM_PURE_PYTHON", raising=False)
    monkeypatch.setattr(model_kernels, "_LOADED", {})
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    description = tmp_path / "shipped_runtime.yaml"
    description.write_text((models.ROBOTS_DIR / "three_link.yaml").read_text()
                           .replace("name: three_link", "name: shipped_runtime"))
    model = models.generated_model(str(description))
    mod = model.module
    ext_name = f"_kernels_{mod.NAME}_{mod.DIGEST}_g{int(mod.GENERATOR_VERSION)}"     # as compiled_kernels names it
    old = model_kernels.kernel_source(mod, ext_name)
    first = model_kernels.compiled_kernels(model)
    assert first is not None and first.SOURCE_SHA256 == model_kernels.source_sha256(old)
    builds = model_kernels.BUILDS
    # the same robot, another runtime (its headers in another folder, which the build then includes)
    _copy_headers(tmp_path / "runtime", "Another runtime's kernels")
    monkeypatch.setattr(model_kernels, "RUNTIME_HEADER", tmp_path / "runtime" / model_kernels.RUNTIME_HEADER.name)
    monkeypatch.setattr(model_kernels, "KERNEL_TABLE_HEADER",
                        tmp_path / "runtime" / model_kernels.KERNEL_TABLE_HEADER.name)
    monkeypatch.setattr(model_kernels, "INCLUDE_DIR", tmp_path / "runtime")
    new = model_kernels.kernel_source(mod, ext_name)
    assert model_kernels.source_sha256(new) != model_kernels.source_sha256(old)
    assert new.replace(model_kernels.source_sha256(new), "") == old.replace(model_kernels.source_sha256(old), "")
    monkeypatch.setattr(model_kernels, "_LOADED", {})
    second = model_kernels.compiled_kernels(models.generated_model(str(description)))
    assert second is not None and model_kernels.BUILDS == builds + 1
    assert second.SOURCE_SHA256 == model_kernels.source_sha256(new)
    assert second.__doc__.startswith("Another runtime's kernels") and first.__doc__.startswith("The compiled kernels")
    cache = Path(mod.__file__).parent
    assert len([p for p in cache.iterdir() if p.name.endswith(".c") and ".kernels-" in p.name]) == 2
    q, dq = [0.1, 0.9, 3.0, 3.4, 0.1], [0.2, -0.1, 0.5, -1.0, 0.3]
    assert second.k_stance(q, dq, [1.0, -2.0], 1) == first.k_stance(q, dq, [1.0, -2.0], 1)
