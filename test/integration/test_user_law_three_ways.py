"""One user law three ways, one run: plain Python, compiled in the loop (numba through the torque-law
hook), and through a ROS controller node (walk_controller -p controller:=MODULE:ATTR) driving sim_node
in lockstep. The HZD law of examples/hzd_bezier.py, the walk scene, 0.6 s held at the scene's 1 ms."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from ros_helpers import BIN, NodeProcess, bag_messages, ros_domain, start_node  # noqa: E402

pytest.importorskip("rclpy")
pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parents[2]
WALK = ["--ros-args", "--params-file", str(ROOT / "msg_configs" / "walk.yaml")]
DURATION = 0.6
pytestmark = pytest.mark.slow


def test_one_user_law_plain_compiled_and_through_a_controller_node_gives_one_run(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT))
    monkeypatch.setenv("PYTHONPATH", str(ROOT))          # the controller node imports examples.hzd_bezier
    from biped_sim.config.scenes import load_scene
    from examples.hzd_bezier import hzd_controller

    scene = load_scene("walk", overrides={"duration": DURATION})
    model = scene.engine_arguments()["model"]
    law = hzd_controller(model)
    assert law.compiled_law(model) is not None            # the compiled path is there (numba)
    compiled = scene.simulate(controller=law)
    plain = scene.simulate(controller=lambda t, q, dq, leg: law(t, q, dq, leg))   # not compiled_law: called back
    assert compiled.status == plain.status == "completed" and len(compiled.impacts) >= 1
    assert compiled.q.tolist() == plain.q.tolist() and compiled.dq.tolist() == plain.dq.tolist()

    params = dict(time_mode="lockstep", duration=DURATION, record=True, bag_dir=str(tmp_path))
    with ros_domain() as dom:
        with start_node(params, dom, extra_args=WALK) as sim, \
                NodeProcess([str(BIN / "walk_controller"), *WALK, "-p",
                             "controller:=examples.hzd_bezier:hzd_controller"], dom) as ctrl:
            code = sim.wait(90)
            ctrl.stop()
    assert code == 0, sim.output() + ctrl.output()
    assert "controller='examples.hzd_bezier:hzd_controller'" in ctrl.output()
    bag = next(p for p in tmp_path.iterdir() if p.is_dir())
    states = bag_messages(bag)["/joint_states"]
    last = states[-1][1]
    assert last.header.stamp.sec + last.header.stamp.nanosec * 1e-9 == pytest.approx(DURATION)
    assert list(last.position) == compiled.q[-1].tolist() and list(last.velocity) == compiled.dq[-1].tolist()
    impacts = [s for _, a in bag_messages(bag).get("/impact", []) for s in a.status]
    assert len(impacts) == len(compiled.impacts)
