"""A user's controller in every tool: simulate (API and CLI), sweep (API and CLI, controller.NAME grid
names), animate --scene; given as an object, a class or "MODULE:ATTR"; a wrong signature refused before
the run."""
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import biped_sim as bs
from biped_sim.config.controllers import make_controller
from biped_sim.config.scenes import load_scene
from biped_sim.engine.model import BipedModel

BIN = Path(sys.executable).parent

# a PD law on the hips that a user would write in a file of their own (not walking: a run of a few
# tenths of a second that ends the same way every time is all these tests need)
USER_MODULE = textwrap.dedent('''
    class HipPD:
        """u = -kp (q_hip - target) - kd dq_hip on each hip."""
        def __init__(self, model, kp=20.0, kd=2.0, target=0.3):
            self.model, self.kp, self.kd, self.target = model, kp, kd, target

        def __call__(self, t, q, dq, stance_leg):
            return [-self.kp * (q[2] - self.target) - self.kd * dq[2],
                    -self.kp * (q[3] + self.target) - self.kd * dq[3]]

    def make_pd(kp=20.0):
        return HipPD(None, kp=kp)

    def zero_law(t, q, dq, stance_leg):
        return [0.0, 0.0]

    def two_arguments(t, q):
        return [0.0, 0.0]
''')


@pytest.fixture()
def user_folder(tmp_path, monkeypatch):
    (tmp_path / "my_controllers.py").write_text(USER_MODULE)
    monkeypatch.chdir(tmp_path)
    yield tmp_path
    sys.modules.pop("my_controllers", None)
    while str(tmp_path) in sys.path:
        sys.path.remove(str(tmp_path))


def test_module_attr_class_factory_and_law_are_made_alike(user_folder):
    model = BipedModel()
    pd = make_controller("my_controllers:HipPD", model, kp=5.0)
    assert pd.kp == 5.0 and pd.model is model           # the class gets the scene's model
    assert make_controller("my_controllers:make_pd", model, kp=7.0).kp == 7.0    # a factory
    law = make_controller("my_controllers:zero_law", model)                        # a controller itself
    assert law(0.0, [0] * 5, [0] * 5, 1) == [0.0, 0.0]
    with pytest.raises(ValueError, match="takes no argument 'kq'; its parameters: model, kp, kd, target"):
        make_controller("my_controllers:HipPD", model, kq=1.0)
    with pytest.raises(ValueError, match="has no 'HipDP'; it has: HipPD, make_pd"):
        make_controller("my_controllers:HipDP", model)
    with pytest.raises(ValueError, match="cannot import 'no_such_module'"):
        make_controller("no_such_module:X", model)
    with pytest.raises(ValueError, match="expected MODULE:ATTR"):
        make_controller("my_controllers.HipPD", model)
    (user_folder / "broken_controllers.py").write_text("x = 1\nundefined_name\n")
    with pytest.raises(ValueError, match=r"importing 'broken_controllers' raised NameError: name 'undefined_name' is "
                                         r"not defined \(.*broken_controllers\.py:2\)"):
        make_controller("broken_controllers:X", model)


def test_a_controller_with_the_wrong_signature_is_refused_before_the_run(user_folder):
    scene = load_scene("walk")
    for bad in ("my_controllers:two_arguments", lambda t, q: [0.0, 0.0]):
        with pytest.raises(ValueError, match=r"cannot be called as controller\(t, q, dq, stance_leg\): its "
                                             r"signature is .*\(t, q\)"):
            scene.simulate(controller=bad, t_final=0.1)
    with pytest.raises(ValueError, match="cannot be called as controller"):
        bs.simulate(BipedModel(), *scene.controller().initial_state(), 0.1, controller=lambda t: [0.0, 0.0])


def test_a_sweep_of_your_controllers_arguments_gives_the_single_runs(user_folder):
    grid = {"controller.kp": [10.0, 30.0], "slope": [0.0, 0.05]}
    rows = bs.sweep("walk", grid, duration=0.3, workers=2, controller="my_controllers:HipPD")
    assert len(rows) == 4
    for row in rows:
        single = load_scene("walk", overrides={"slope": row["slope"]}).simulate(
            t_final=0.3, controller="my_controllers:HipPD", controller_args={"kp": row["controller.kp"]})
        assert row["status"] == single.status and row["t_end"] == float(single.t[-1])
        assert row["q_end"] == [float(v) for v in single.q[-1]]
    assert rows[0]["q_end"] != rows[2]["q_end"]      # kp reached the controller
    with pytest.raises(ValueError, match="sets an argument of the controller: give the controller"):
        bs.sweep("walk", {"controller.kp": [1.0]}, duration=0.1)
    with pytest.raises(ValueError, match="takes no argument 'kq'"):
        bs.sweep("walk", {"controller.kq": [1.0]}, duration=0.1, controller="my_controllers:HipPD")


def cli(*args, cwd):
    env = dict(os.environ, PYTHONPATH="")
    return subprocess.run([str(BIN / "biped-sim"), *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=120)


def test_the_command_line_takes_your_controller_from_the_current_folder(user_folder):
    run = cli("simulate", "--scene", "walk", "--duration", "0.2", "--controller", "my_controllers:HipPD",
              cwd=user_folder)
    assert "controller my_controllers:HipPD" in run.stdout, run.stdout + run.stderr
    single = load_scene("walk").simulate(t_final=0.2, controller="my_controllers:HipPD")
    assert f"status  {single.status}" in run.stdout
    out = user_folder / "rows.csv"
    run = cli("sweep", "walk", "--set", "controller.kp=10,30", "--duration", "0.2", "--controller",
              "my_controllers:HipPD", "-o", str(out), "--workers", "1", "--no-progress", cwd=user_folder)
    assert run.returncode == 0, run.stderr
    assert out.read_text().splitlines()[0].startswith("index,controller.kp,status")
    gif = user_folder / "pd.gif"
    run = cli("animate", "--scene", "walk", "--controller", "my_controllers:HipPD", "--duration", "0.2", "-o", str(gif),
              "-q", cwd=user_folder)
    assert run.returncode == 0 and gif.stat().st_size > 0, run.stderr
    bad = cli("simulate", "--scene", "walk", "--controller", "my_controllers:Nope", cwd=user_folder)

    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "has no 'Nope'" in bad.stderr, bad.stderr


def test_the_example_module_is_the_one_docs_controllers_shows():
    root = Path(__file__).resolve().parents[2]
    page = (root / "docs" / "controllers.md").read_text()
    shown = page.split("```py\n", 1)[1].split("```", 1)[0]
    assert shown == (root / "examples" / "my_controllers.py").read_text()


def test_the_minimal_controller_node_is_the_one_docs_node_shows():
    root = Path(__file__).resolve().parents[2]
    page = (root / "docs" / "node.md").read_text()
    shown = page.split("### A controller node of your own", 1)[1].split("```py\n", 1)[1].split("```", 1)[0]
    assert shown == (root / "examples" / "minimal_controller.py").read_text()


ROOT = Path(__file__).resolve().parents[2]
HZD = "examples.hzd_bezier:hzd_controller"


def test_gait_and_basin_take_your_controller(monkeypatch, tmp_path):
    """find_gait(scene, controller=...) and basin(..., controller=...) with the HZD law of examples/ (its
    Bezier coefficients are fitted to the reference law's outputs: the walk scene's own gait); the basin's
    workers, started elsewhere, import examples.hzd_bezier from the folder it was found in."""
    monkeypatch.syspath_prepend(str(ROOT))
    monkeypatch.chdir(tmp_path)
    from biped_sim.analysis.basin import basin
    own = bs.find_gait("walk")
    hzd = bs.find_gait("walk", controller=HZD)
    assert hzd.stable and np.allclose(hzd.fixed_point, own.fixed_point, atol=1e-6)
    gait, rows = basin("walk", span=(0.2, 0.2), num=2, duration=1.2, workers=1, controller=HZD)
    assert np.allclose(gait.fixed_point, hzd.fixed_point, atol=1e-9)
    assert [r["status"] for r in rows] == ["completed"] * 4 and all(r["impacts"] >= 1 for r in rows)
    sys.modules.pop("examples.hzd_bezier", None)
    sys.modules.pop("examples", None)


def test_a_controller_that_does_not_walk_has_no_gait_in_one_line(user_folder):
    run = cli("gait", "--scene", "walk", "--controller", "my_controllers:HipPD", cwd=user_folder)
    assert run.returncode == 1 and run.stdout.startswith("scene walk: no periodic gait: the step from z="), run.stdout
    assert run.stdout.count("\n") == 1 and not run.stderr


def test_find_gait_of_a_model_and_a_controller_without_initial_state_asks_for_z0():
    with pytest.raises(ValueError, match=r"give z0, the post-impact state .* or a scene"):
        bs.find_gait(BipedModel(), lambda t, q, dq, leg: [0.0, 0.0])


def test_gait_takes_walk_and_none_as_the_other_tools_do(user_folder):
    """gait's --controller is simulate's and sweep's: walk (the scene's law) and none (u = 0: the compass
    gait's passive gait, whose leg multipliers have moduli 0.5798 and 0.1314) were taken for MODULE:ATTR."""
    walk = cli("gait", "--scene", "walk", "--controller", "walk", cwd=user_folder)
    assert walk.returncode == 0 and "stable  yes" in walk.stdout, walk.stdout + walk.stderr
    passive = cli("gait", "--scene", "compass_gait", "--controller", "none", cwd=user_folder)
    assert "|eigenvalues|  1, 1, 0.5798, 0.5798, 0.1314" in passive.stdout, passive.stdout + passive.stderr
