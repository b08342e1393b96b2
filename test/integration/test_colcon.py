"""The package built with colcon as a ROS user builds it, and run from the install.

Owns the packaging contract (issue 13): ``colcon build --packages-select biped_sim`` in a scratch
workspace (this repository linked under ``src/``); every executable in ``install/biped_sim/lib/biped_sim/``;
the scenes, ``package.xml`` and the launch file under ``share/biped_sim/``; the installed code (not the
editable checkout) imported with the environment of ``install/local_setup.sh``; the installed
``sim_node`` running; and the launch file's two nodes run as ``launch_ros`` would start them (the
``launch`` packages are not on PyPI, so the launch file is read from its syntax tree, not executed).
"""
from __future__ import annotations

import ast
import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest
import yaml

from ros_helpers import BIN, NodeProcess, ros_domain

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = "biped_sim"
EXECUTABLES = ("sim_node", "walk_controller", "torque_pub", "biped_echo", "biped-sim")
LAUNCH_FILE = "walk.launch.py"
BUILD_TIMEOUT = 300.0


@pytest.fixture(scope="module")
def install(tmp_path_factory) -> Path:
    """``install/`` of a fresh workspace in which colcon built this package."""
    colcon = BIN / "colcon"
    assert colcon.exists(), f"{colcon} is missing: `make test` installs colcon (requirements-dev.txt)"
    ws = tmp_path_factory.mktemp("colcon_ws")
    (ws / "src").mkdir()
    (ws / "src" / PACKAGE).symlink_to(ROOT, target_is_directory=True)
    # a colcon home of its own: no defaults.yaml of the user's changes the build
    env = dict(os.environ, COLCON_HOME=str(ws / "colcon_home"))
    argv = [str(colcon), "build", "--packages-select", PACKAGE]
    t0 = time.monotonic()
    done = subprocess.run(argv, cwd=ws, env=env, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          timeout=BUILD_TIMEOUT)
    assert done.returncode == 0, f"{' '.join(argv)} failed ({done.returncode}):\n{done.stdout}\n{done.stderr}"
    print(f"colcon build: {time.monotonic() - t0:.1f} s")
    return ws / "install"


def sourced(install: Path, argv, cwd: Path) -> list[str]:
    """``argv`` run in ``cwd`` after sourcing ``install/local_setup.sh``, as a ROS user's shell runs it
    (``cwd`` outside the checkout, or ``python -c`` would import the checkout's biped_sim from there)."""
    return ["sh", "-c", 'cd "$1" && . "$0" && shift && exec "$@"', str(install / "local_setup.sh"), str(cwd),
            *map(str, argv)]


def lib(install: Path) -> Path:
    return install / PACKAGE / "lib" / PACKAGE


def share(install: Path) -> Path:
    return install / PACKAGE / "share" / PACKAGE


def test_every_executable_is_installed_where_ros2_run_looks(install):
    for name in EXECUTABLES:
        exe = lib(install) / name
        assert exe.is_file() and os.access(exe, os.X_OK), f"{exe} is not an installed executable"


def test_scenes_package_xml_and_launch_file_are_installed_under_share(install):
    for scene in sorted((ROOT / "msg_configs").glob("*.yaml")):
        copy = share(install) / "msg_configs" / scene.name
        assert copy.is_file() and copy.read_bytes() == scene.read_bytes(), f"{copy} is not the scene {scene}"
    assert (share(install) / "package.xml").read_bytes() == (ROOT / "package.xml").read_bytes()
    assert (share(install) / "launch" / LAUNCH_FILE).read_bytes() == (ROOT / "launch" / LAUNCH_FILE).read_bytes()
    # what ament_index_python (and so ros2 run / ros2 launch) finds the package by
    assert (install / PACKAGE / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE).is_file()


def test_installed_package_is_the_one_imported(install, tmp_path):
    """After local_setup.sh the install's copy is imported (not the checkout), and scenes are found
    in share/ through the ament index."""
    code = ("import biped_sim, biped_sim.engine.compiled as c; print(biped_sim.__file__); "
            "print(biped_sim.load_scene('walk').path); print(c.IMPLEMENTATION)")
    done = subprocess.run(sourced(install, [BIN / "python", "-c", code], tmp_path), capture_output=True, text=True,
                          stdin=subprocess.DEVNULL, timeout=60)
    assert done.returncode == 0, done.stderr
    module, scene, implementation = done.stdout.split()[-3:]
    assert Path(module).is_relative_to(install / PACKAGE / "lib"), module
    assert Path(scene) == share(install) / "msg_configs" / "walk.yaml", scene
    print(f"installed generated code: {implementation}")


def test_installed_sim_node_runs(install, tmp_path):
    with ros_domain() as dom:
        proc = NodeProcess(sourced(install, [lib(install) / "sim_node", "--ros-args", "-p", "duration:=0.05",
                                             "-p", "time_mode:=fast", "-p", "record:=false"], tmp_path),
                           dom, tmp_path / "sim_node.log")
        with proc:
            assert proc.wait(60) == 0, proc.output()
        assert "duration 0.05 s reached" in proc.output(), proc.output()


# -- the launch file -----------------------------------------------------------------------------------
def launch_plan(path: Path, share_of) -> list[dict]:
    """The nodes ``generate_launch_description`` starts, read from the file's syntax tree: for each,
    its package, executable, name, parameter files (launch arguments at their defaults; ``share_of``
    gives a package's share folder, as FindPackageShare) and whether its exit shuts the launch down."""
    tree = ast.parse(path.read_text(), str(path))
    for node in ast.walk(tree):
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            top = {(node.module or "").split(".")[0]} if isinstance(node, ast.ImportFrom) else \
                {a.name.split(".")[0] for a in node.names}
            assert top <= {"launch", "launch_ros"}, f"{path}:{node.lineno} imports {top}"
    fn = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "generate_launch_description")
    names = {t.id: a.value for a in fn.body if isinstance(a, ast.Assign) for t in a.targets}
    defaults, nodes = {}, []

    def value(n):
        if isinstance(n, ast.Constant):
            return n.value
        if isinstance(n, ast.List):
            return [value(e) for e in n.elts]
        if isinstance(n, ast.Name) and n.id in names:
            return value(names[n.id])
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Name):
            args = [value(a) for a in n.args]
            if n.func.id == "FindPackageShare":
                return str(share_of(args[0]))
            if n.func.id == "PathJoinSubstitution":
                return os.path.join(*args[0])
            if n.func.id == "LaunchConfiguration":
                return defaults[args[0]]
            if n.func.id == "Shutdown":
                return "shutdown"
        raise AssertionError(f"{path}:{n.lineno}: cannot read {ast.unparse(n)} without launch")

    ret = next(n for n in fn.body if isinstance(n, ast.Return)).value
    assert isinstance(ret, ast.Call) and ret.func.id == "LaunchDescription", ast.unparse(ret)
    for action in ret.args[0].elts:
        kw = {k.arg: k.value for k in action.keywords}
        if action.func.id == "DeclareLaunchArgument":
            defaults[value(action.args[0])] = value(kw["default_value"])
        elif action.func.id == "Node":
            nodes.append({"package": value(kw["package"]), "executable": value(kw["executable"]),
                          "name": value(kw["name"]), "parameters": value(kw["parameters"]),
                          "on_exit": value(kw["on_exit"]) if "on_exit" in kw else None})
        else:
            raise AssertionError(f"{path}:{action.lineno}: unexpected action {action.func.id}")
    return nodes


def test_launch_file_starts_the_walk_scene_and_runs_as_launch_ros_would(install, tmp_path):
    """sim_node and walk_controller from the installed scene file; their command lines as launch_ros
    builds them (``--ros-args -r __node:=NAME --params-file FILE``), the run shortened to 0.2 s."""
    plan = launch_plan(share(install) / "launch" / LAUNCH_FILE, lambda pkg: install / pkg / "share" / pkg)
    assert [(n["package"], n["executable"], n["name"]) for n in plan] == [
        (PACKAGE, "sim_node", "biped_sim"), (PACKAGE, "walk_controller", "walk_controller")]
    assert plan[0]["on_exit"] == "shutdown", "the launch must end when the simulator ends its run"
    for n in plan:
        assert n["parameters"] == [str(share(install) / "msg_configs" / "walk.yaml")], n
        assert n["name"] in yaml.safe_load(Path(n["parameters"][0]).read_text()), \
            f"{n['parameters'][0]} has no section for the node {n['name']}: its parameters would not apply"

    def argv(n, *extra):  # in tmp_path, the launch's working folder (the scene records to ./bags)
        files = [a for f in n["parameters"] for a in ("--params-file", f)]
        return sourced(install, [lib(install) / n["executable"], "--ros-args", "-r", f"__node:={n['name']}",
                                 *files, *extra], cwd=tmp_path)

    with ros_domain() as dom:
        sim = NodeProcess(argv(plan[0], "-p", "duration:=0.2"), dom, tmp_path / "sim_node.log")
        ctl = NodeProcess(argv(plan[1]), dom, tmp_path / "walk_controller.log")
        with sim, ctl:
            end = time.monotonic() + 60
            while sim.alive and time.monotonic() < end:
                assert ctl.alive, f"walk_controller exited:\n{ctl.output()}"
                time.sleep(0.1)
            assert sim.wait(1) == 0, f"{sim.output()}\n--- walk_controller ---\n{ctl.output()}"
            assert ctl.stop(signal.SIGINT) == 0, ctl.output()   # what the launch's Shutdown sends
    assert "duration 0.2 s reached" in sim.output(), sim.output()
    answered = re.search(r"shutting down after (\d+) commands", ctl.output())
    assert answered and int(answered.group(1)) >= 200, ctl.output()
    bags = [p for p in (tmp_path / "bags").glob("walk-*") if p.is_dir()] if (tmp_path / "bags").is_dir() else []
    assert len(bags) == 1 and list(bags[0].glob("*.mcap")), f"no bag in {tmp_path / 'bags'}:\n{sim.output()}"
