"""The package tree is the architecture: each layer imports only from the layers before it.

    engine <- control <- config <- analysis, recording <- ros <- cli

Every import counts, also one inside a function (a lazy import is still a dependency), and the
engine imports nothing but the standard library, numpy and scipy (no ROS, not even lazily). One
exception: engine/figure.py (``SimulationResult.plot()``) imports matplotlib inside its function, so
that a result can draw itself and nothing else pays for matplotlib.
"""
import ast
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "biped_sim"
LEVEL = {"engine": 0, "control": 1, "config": 2, "analysis": 3, "recording": 3, "ros": 4, "cli": 5}
ENGINE_THIRD_PARTY = {"numpy", "scipy"}
#: engine files allowed one more third-party package, imported inside a function (or a branch) only; the rules'
#: `import cython` takes Cython's magic module only where Cython is imported already, else the shim
#: (engine/_cython_shim.py): Cython is needed only to generate _loop_rules.c
ENGINE_LAZY_EXTRA = {"figure.py": {"matplotlib"}, "loop_rules.py": {"cython"}}


def _imports(path):
    """(line, module) of every import in a file, relative imports resolved."""
    tree = ast.parse(path.read_text(), str(path))
    package = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts[:-1])
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                yield node.lineno, ".".join(base + ([node.module] if node.module else []))
            else:
                yield node.lineno, node.module


def _layer(module):
    parts = module.split(".")
    return parts[1] if parts[0] == "biped_sim" and len(parts) > 1 and parts[1] in LEVEL else None


def test_every_layer_imports_only_from_the_layers_before_it():
    wrong = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE)
        if len(rel.parts) == 1:          # biped_sim/__init__.py re-exports the public API
            continue
        own = rel.parts[0]
        for line, module in _imports(path):
            target = _layer(module)
            if target is not None and target != own and LEVEL[target] >= LEVEL[own]:
                wrong.append(f"{rel}:{line} ({own}) imports {module} ({target})")
    assert not wrong, "imports against the layer order:\n" + "\n".join(wrong)


def test_the_engine_imports_only_the_standard_library_numpy_and_scipy():
    wrong = []
    for path in sorted((PACKAGE / "engine").rglob("*.py")):
        top_level = {node.lineno for node in ast.parse(path.read_text()).body
                     if isinstance(node, (ast.Import, ast.ImportFrom))}
        for line, module in _imports(path):
            if module.split(".")[0] in ENGINE_LAZY_EXTRA.get(path.name, ()) and line not in top_level:
                continue
            top = module.split(".")[0]
            if top == "biped_sim":
                if _layer(module) != "engine":
                    wrong.append(f"{path.relative_to(PACKAGE)}:{line} imports {module}")
            elif top not in ENGINE_THIRD_PARTY and top not in sys.stdlib_module_names and top != "__future__":
                wrong.append(f"{path.relative_to(PACKAGE)}:{line} imports {module}")
    assert not wrong, "the engine imports outside numpy, scipy and the standard library:\n" + "\n".join(wrong)


def test_the_engine_names_no_controller():
    """A torque law enters the engine through the hook (engine/torque_hook.py); the walking laws live in
    control/, and no engine source, Python or C, names them."""
    engine = PACKAGE / "engine"
    sources = sorted(p for p in engine.rglob("*") if p.suffix in (".py", ".c", ".h") and "__pycache__" not in p.parts)
    assert any(p.name == "_core.c" for p in sources)
    wrong = [f"{p.relative_to(PACKAGE)}:{i}: {line.strip()}" for p in sources
             for i, line in enumerate(p.read_text().splitlines(), 1)
             if "walking" in line.lower() or "WalkingController" in line]
    assert not wrong, "the engine names a controller:\n" + "\n".join(wrong)


def run_python(code, timeout):
    """``code`` run by a fresh interpreter (imports as a user's process makes them)."""
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout)


def test_a_whole_scene_runs_with_rclpy_and_mcap_absent():
    code = ("import sys\n"
            "for name in ('rclpy', 'mcap', 'mcap_ros2', 'rosbags', 'sensor_msgs', 'std_msgs'):\n"
            "    sys.modules[name] = None   # any import of them raises ImportError\n"
            "import biped_sim as bs\n"
            "r = bs.load_scene('walk').simulate(t_final=1)\n"
            "print(r.status, len(r.impacts))\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'mcap', 'rosidl_runtime_py')"
            " and sys.modules[m] is not None))\n")
    out = run_python(code, timeout=120)
    assert out.returncode == 0, out.stderr
    status, impacts = out.stdout.splitlines()[0].split()
    assert status == "completed" and int(impacts) >= 2, out.stdout
    assert out.stdout.splitlines()[1] == "[]", out.stdout


def test_a_ros_command_without_rclpy_says_what_to_install_in_one_line():
    code = ("import sys\nsys.modules['rclpy'] = None\n"
            "from biped_sim.ros import sim_node\nsys.exit(sim_node())\n")
    out = run_python(code, timeout=60)
    assert out.returncode == 2, out
    assert out.stderr.startswith("sim_node: error: cannot import the ROS 2 Python packages"), out.stderr
    assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1


def test_a_command_that_integrates_nothing_does_not_import_scipy_integrate():
    """scipy.integrate costs ~1.5 s to import: every biped-sim command and node start paid it before
    checking its arguments (2.7 s to refuse a bad bag). A simulator imports it (and the root finder)
    when it is built, not inside its first step: a realtime node stalled 1.6 s in its first control
    period, long enough for its command timeout to fire (a fresh-clone run of test_node). Since the
    dense output of dop853 and dopri5 is generated too, their simulators need neither: the root finder
    is imported by the first event located in Python, or up front by the realtime node."""
    code = ("import sys\nfrom biped_sim.cli import main\n"
            "code = main(['resim', '/etc/passwd'])\n"
            "import biped_sim.engine.hybrid, biped_sim.ros.sim_node\n"
            "print(code, sorted(m for m in ('scipy.integrate', 'scipy.optimize') if m in sys.modules))\n"
            "import biped_sim as bs\nscene = bs.load_scene('walk')\n"
            "bs.HybridSimulator(**scene.engine_arguments())\n"
            "print(sorted(m for m in ('scipy.integrate', 'scipy.optimize') if m in sys.modules))\n")
    out = run_python(code, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == ["2 []", "[]"], out.stdout + out.stderr


HEAVY_MODULES = ("scipy.optimize", "scipy.integrate", "matplotlib", "rclpy")


def test_import_help_and_a_short_simulate_import_no_heavy_module():
    """Each biped-sim process pays its imports: scipy.optimize alone ~0.4-0.6 s here, matplotlib ~0.4 s,
    rclpy ~0.2 s. ``import biped_sim``, ``biped-sim --help`` and a short ``simulate`` (whose events the
    compiled loop locates) import none of them (the speed itself is timed in make bench, cli_start)."""
    code = ("import sys, contextlib, io\n"
            f"heavy = {HEAVY_MODULES!r}\n"
            "def loaded(): return sorted(m for m in heavy if m in sys.modules)\n"
            "import biped_sim\nprint('import', loaded())\n"
            "from biped_sim.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    code = main(['--help'])\n"
            "print('help', code, loaded())\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    code = main(['simulate', '--duration', '0.5'])\n"
            "print('simulate', code, loaded())\n")
    out = run_python(code, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == ["import []", "help 0 []", "simulate 0 []"], out.stdout + out.stderr
