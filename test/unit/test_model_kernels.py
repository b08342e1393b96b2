"""The compiled kernels of a described robot (biped_sim/engine/model_kernels.py; docs/models.md).

The twin agrees with the numpy path (the generated Python and ``np.linalg.solve`` of the KKT system) to
1e-12 relative at random states for the four shipped robots, and gives the generated Python's bits where
it runs the same statements (feet, energy); the shipped sources are what the generator writes; a
user's description is built on first use, cached next to its module and not built again; without a
compiler the Python path runs after one warning; ``BIPED_SIM_PURE_PYTHON=1`` forces the Python path.
"""
import ctypes
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

from biped_sim.config import models
from biped_sim.engine import model_kernels

SHIPPED_DIR = Path(model_kernels.__file__).parent / "_gen" / "models"


@pytest.fixture(autouse=True)
def fresh_kernels(monkeypatch):
    """Each test loads its twins itself (in-process memo cleared), with the environment choosing C."""
    monkeypatch.delenv("BIPED_SIM_PURE_PYTHON", raising=False)
    monkeypatch.setattr(model_kernels, "_LOADED", {})


def close(a, b, what):
    """|a - b| <= 1e-12 |b| (norm-wise: a component near zero is held to the vector's scale)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert np.max(np.abs(a - b)) <= 1e-12 * max(np.max(np.abs(b)), 1e-300), (what, a, b)


@pytest.mark.parametrize("name", models.SHIPPED)
def test_the_twin_agrees_with_the_numpy_path_at_random_states(name):
    model = models.generated_model(name)
    twin = model_kernels.compiled_kernels(model)
    assert twin is not None, "the shipped twin was not built: make venv"
    mod, n, m = model.module, model.n, model.B.shape[1]
    rng = np.random.default_rng(31)
    for _ in range(40):
        q, dq, u = rng.uniform(-2, 2, n), rng.uniform(-3, 3, n), rng.uniform(-20, 20, m)
        q[1] = rng.uniform(0.3, 1.5)
        ql, dql, ul = q.tolist(), dq.tolist(), u.tolist()
        for c in range(len(model.contacts)):
            ddq, F = twin.k_stance(ql, dql, ul, c)
            ddq_np, F_np = model.stance_dynamics(q, dq, u, c + 1)
            close(ddq, ddq_np, "ddq")
            close(F, F_np, "F")
            dqp, imp = twin.k_impact(ql, dql, c)
            dqp_np, imp_np = model.impact_map(q, dq, c + 1)
            close(dqp, dqp_np, "dq+")
            close(imp, imp_np, "impulse")
        close(twin.k_flight(ql, dql, ul), model.flight_dynamics(q, dq, u), "flight ddq")
        # the generated statements, one by one: the Python module's bits
        assert twin.k_foot_positions(ql) == list(map(float, mod.contact_positions(ql)))
        assert twin.k_foot_kinematics(ql, dql) == list(map(float, mod.contact_positions(ql)
                                                           + mod.contact_velocities(ql, dql)))
        assert twin.k_energy(ql, dql) == list(map(float, mod.energy(ql, dql)))
    # lists and tuples are read in place; a numpy array and ints are accepted as numbers
    assert twin.k_stance(tuple(ql), np.array(dql), [int(round(x)) for x in ul], 0)[1] == \
        twin.k_stance(ql, dql, [float(int(round(x))) for x in ul], 0)[1]


_D = ctypes.POINTER(ctypes.c_double)


class KernelTable(ctypes.Structure):
    """_kernel_table.h's KernelTable, read through ctypes as C code reads it."""
    _fields_ = [("version", ctypes.c_int), ("n", ctypes.c_int), ("contacts", ctypes.c_int),
                ("actuators", ctypes.c_int),
                ("stance", ctypes.CFUNCTYPE(ctypes.c_int, _D, _D, _D, ctypes.c_int, _D, _D)),
                ("flight", ctypes.CFUNCTYPE(ctypes.c_int, _D, _D, _D, _D)),
                ("impact", ctypes.CFUNCTYPE(ctypes.c_int, _D, _D, ctypes.c_int, _D, _D)),
                ("foot_positions", ctypes.CFUNCTYPE(ctypes.c_int, _D, _D)),
                ("foot_kinematics", ctypes.CFUNCTYPE(ctypes.c_int, _D, _D, _D)),
                ("energy", ctypes.CFUNCTYPE(ctypes.c_int, _D, _D, _D))]


def kernel_table(twin) -> KernelTable:
    """The twin's table of C entry points, from its capsule KERNEL_TABLE (checked by name)."""
    get = ctypes.pythonapi.PyCapsule_GetPointer
    get.restype, get.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]
    address = get(twin.KERNEL_TABLE, b"biped_sim.engine.model_kernels.KernelTable")
    return KernelTable.from_address(address)


def doubles(values, n=None):
    return (ctypes.c_double * (n if n is not None else len(values)))(*values)


def assert_entry_points_give_the_functions_bits(twin, n, nc, m, rng):
    """The table's C entry points, called on double arrays, return KERNEL_OK and the bits of the twin's Python
    functions at random states."""
    table = kernel_table(twin)
    assert (table.version, table.n, table.contacts, table.actuators) == (twin.KERNEL_TABLE_VERSION, n, nc, m)
    for _ in range(10):
        q, dq, u = rng.uniform(-2, 2, n).tolist(), rng.uniform(-3, 3, n).tolist(), rng.uniform(-20, 20, m).tolist()
        q[1] = rng.uniform(0.3, 1.5)
        cq, cdq, cu = doubles(q), doubles(dq), doubles(u, max(m, 1))
        for c in range(nc):
            x, F = doubles([], n), doubles([], 2)
            assert table.stance(cq, cdq, cu, c, x, F) == 0
            assert [list(x), list(F)] == list(map(list, twin.k_stance(q, dq, u, c)))
            assert table.impact(cq, cdq, c, x, F) == 0
            assert [list(x), list(F)] == list(map(list, twin.k_impact(q, dq, c)))
        x = doubles([], n)
        assert table.flight(cq, cdq, cu, x) == 0 and list(x) == twin.k_flight(q, dq, u)
        p = doubles([], 4 * nc)
        assert table.foot_positions(cq, p) == 0 and list(p)[:2 * nc] == twin.k_foot_positions(q)
        assert table.foot_kinematics(cq, cdq, p) == 0 and list(p) == twin.k_foot_kinematics(q, dq)
        e = doubles([], 2)
        assert table.energy(cq, cdq, e) == 0 and list(e) == twin.k_energy(q, dq)


@pytest.mark.parametrize("name", models.SHIPPED)
def test_the_twin_exports_c_entry_points_that_give_its_functions_bits(name):
    model = models.generated_model(name)
    twin = model_kernels.compiled_kernels(model)
    assert twin is not None, "the shipped twin was not built: make venv"
    assert_entry_points_give_the_functions_bits(twin, model.n, len(model.contacts), model.B.shape[1],
                                                np.random.default_rng(310))


def test_bad_input_is_refused_in_one_line():
    twin = model_kernels.compiled_kernels(models.generated_model("rabbit"))
    q, dq, u = [0.0, 1.0, 3.0, 3.2, 0.1, 0.2, 0.0], [0.0] * 7, [0.0] * 4
    refusals = [
        (lambda: twin.k_stance(q[:5], dq, u, 0), ValueError, "k_stance: q must have 7 numbers, got 5"),
        (lambda: twin.k_stance(q, dq, u, 2), ValueError, "k_stance: the contact index must be 0..1, got 2"),
        (lambda: twin.k_impact(q, dq, True), TypeError, "the contact index must be an int"),
        (lambda: twin.k_flight(q, dq, 3.0), TypeError, "k_flight: u must be a sequence of 4 numbers"),
        (lambda: twin.k_energy(q, ["x"] * 7), TypeError, "k_energy: dq[0] must be a number, got str"),
        (lambda: twin.k_foot_positions(), TypeError, "k_foot_positions takes 1 arguments, got 0"),
    ]
    for call, error, text in refusals:
        with pytest.raises(error) as e:
            call()
        assert text in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_the_shipped_twins_are_what_the_generator_writes_and_were_built_from_it():
    for name in models.SHIPPED:
        module = models.dynamics_module(models.load_description(name))
        fresh = model_kernels.kernel_source(module, f"_kernels_{name}")
        assert (SHIPPED_DIR / f"_kernels_{name}.c").read_text() == fresh, \
            "run make generate (tools/generate_models.py --kernels-only), then make venv"
        twin = model_kernels.compiled_kernels(models.generated_model(name))
        assert twin.SOURCE_SHA256 == model_kernels.source_sha256(fresh) and twin.DIGEST == module.DIGEST


def _user_description(tmp_path, name="stilts", leg_mass=4.0):
    data = yaml.safe_load((models.ROBOTS_DIR / "three_link.yaml").read_text())
    data["name"] = name
    for leg in ("leg_1", "leg_2"):
        data["links"][leg]["mass"] = leg_mass
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_a_users_description_is_built_once_cached_next_to_its_module_and_runs(tmp_path, monkeypatch):
    pytest.importorskip("sympy")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    builds = model_kernels.BUILDS
    model = models.generated_model(str(_user_description(tmp_path)))
    twin = model_kernels.compiled_kernels(model)
    assert twin is not None and model_kernels.BUILDS == builds + 1
    cache = Path(model.module.__file__).parent
    assert cache == tmp_path / "cache" / "biped_sim" / "models"
    built = sorted(p.name for p in cache.iterdir() if ".kernels-" in p.name)
    assert len(built) == 2 and built[0].endswith(".c") and built[0].startswith(Path(model.module.__file__).stem)
    lib = cache / built[1]
    stamp = lib.stat().st_mtime_ns
    # a second load (another process's, or this one's after forgetting it) takes the cached file
    monkeypatch.setattr(model_kernels, "_LOADED", {})
    again = model_kernels.compiled_kernels(models.generated_model(str(tmp_path / "stilts.yaml")))
    assert again is not None and model_kernels.BUILDS == builds + 1 and lib.stat().st_mtime_ns == stamp
    q, dq, u = [0.1, 0.9, 3.0, 3.4, 0.1], [0.2, -0.1, 0.5, -1.0, 0.3], [1.0, -2.0]
    ddq, F = again.k_stance(q, dq, u, 1)
    ddq_np, F_np = model.stance_dynamics(q, dq, u, 2)
    close(ddq, ddq_np, "ddq")
    close(F, F_np, "F")
    assert again.NAME == "stilts" and again.k_foot_positions(q) == list(model.module.contact_positions(q))
    assert_entry_points_give_the_functions_bits(again, model.n, len(model.contacts), model.B.shape[1],
                                                np.random.default_rng(311))


def test_two_processes_building_the_same_robot_at_once_each_load_a_whole_twin(tmp_path):
    pytest.importorskip("sympy")
    env_cache = tmp_path / "cache"
    path = _user_description(tmp_path, name="twins")
    code = ("import sys\nfrom biped_sim.config import models\nfrom biped_sim.engine import model_kernels as mk\n"
            f"m = models.generated_model({str(path)!r})\n"
            "k = mk.compiled_kernels(m)\n"
            "print(mk.BUILDS, k.k_energy([0.0, 1.0, 3.0, 3.3, 0.0], [0.0] * 5)[1])\n")
    env = dict(os.environ, XDG_CACHE_HOME=str(env_cache))
    env.pop("BIPED_SIM_PURE_PYTHON", None)
    # the generated module first (sympy), so that both processes race on the compiler only
    generate = f"from biped_sim.config import models\nmodels.dynamics_module(models.load_description({str(path)!r}))"
    subprocess.run([sys.executable, "-c", generate], env=env, check=True, timeout=120)
    runs = [subprocess.Popen([sys.executable, "-W", "error", "-c", code], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [r.communicate(timeout=180) for r in runs]
    assert [r.returncode for r in runs] == [0, 0], outs
    lines = [o[0].split() for o in outs]
    assert lines[0][1] == lines[1][1] and {line[0] for line in lines} <= {"0", "1"}
    cache = env_cache / "biped_sim" / "models"
    # the module, the twin and its source (no temporary file left; __pycache__ where bytecode is written)
    assert sorted(p.suffix for p in cache.iterdir() if p.is_file()) == [".c", ".py", ".so"], list(cache.iterdir())


def test_without_a_compiler_the_python_path_runs_after_one_line(tmp_path, monkeypatch):
    pytest.importorskip("sympy")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = models.generated_model(str(_user_description(tmp_path, name="nocc")))
        assert model_kernels.compiled_kernels(model) is None
        assert model_kernels.compiled_kernels(model) is None      # once per robot
    assert len(caught) == 1, [str(w.message) for w in caught]
    text = str(caught[0].message)
    assert "robot 'nocc' runs its dynamics on the Python path" in text and "install gcc" in text and "\n" not in text
    assert model.stance_dynamics([0.1, 0.9, 3.0, 3.4, 0.1], [0.0] * 5, [0.0, 0.0], 1)[1][1] > 0


def test_biped_sim_pure_python_forces_the_python_path_without_a_word(monkeypatch):
    monkeypatch.setenv("BIPED_SIM_PURE_PYTHON", "1")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert model_kernels.compiled_kernels(models.generated_model("rabbit")) is None

