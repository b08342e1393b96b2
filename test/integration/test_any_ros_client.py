"""Any ROS client drives the node: a plain rclpy controller (rclpy's default QoS: volatile, depth 10)
started after sim_node in lockstep gets the state it must answer, and a controller that listens but
does not command is named for what it does."""
import re
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from ros_helpers import Client, NodeProcess, ros_domain, start_node  # noqa: E402

pytest.importorskip("rclpy")

ROOT = Path(__file__).resolve().parents[2]
CONTROLLER = ROOT / "examples" / "minimal_controller.py"
WALK = ["--ros-args", "--params-file", str(ROOT / "msg_configs" / "walk.yaml")]
pytestmark = pytest.mark.slow


def test_a_default_qos_controller_started_late_drives_a_lockstep_run():
    params = dict(time_mode="lockstep", duration=0.2, control_period=0.002, record=False, lockstep_timeout=20.0)
    with ros_domain() as dom, Client(dom) as c:
        with start_node(params, dom, extra_args=WALK) as sim:
            c.wait_for_publisher("/joint_states", proc=sim)
            time.sleep(1.0)           # the state at t = 0 is out before the controller subscribes
            with NodeProcess([sys.executable, str(CONTROLLER)], dom) as ctrl:
                code = sim.wait(60)
                ctrl.stop()
    log = sim.output()
    assert code == 0, log + ctrl.output()
    # (on a loaded machine the subscription can be discovered before its node's name)
    assert re.search(r"(/minimal_controller|a node not yet named) subscribed to /joint_states \(volatile\)", log), log
    assert "offered it again" in log and "duration 0.2 s reached" in log, log
    assert "100 control periods" in log, log


def test_a_controller_that_listens_but_commands_elsewhere_is_named():
    params = dict(time_mode="lockstep", duration=0.2, record=False, lockstep_warn_after=0.5, lockstep_timeout=4.0)
    with ros_domain() as dom:
        with start_node(params, dom, extra_args=WALK) as sim, \
                NodeProcess([sys.executable, str(CONTROLLER), "--ros-args", "-r", "hip_torque:=hip_torques"],
                            dom) as ctrl:
            code = sim.wait(60)
            ctrl.stop()
    log = sim.output()
    assert code == 1, log
    warning = next(ln for ln in log.splitlines() if "lockstep: waiting for a hip_torque command" in ln)
    assert ("/minimal_controller subscribes to /joint_states (so the controller runs on this ROS domain), but "
            "no node publishes /hip_torque") in warning, warning
    assert "Is the controller running" not in warning


def test_a_best_effort_command_publisher_is_named_in_any_time_mode():
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64MultiArray
    params = dict(time_mode="realtime", duration=0.0, record=False, command_timeout=0.0)
    with ros_domain() as dom, Client(dom, name="best_effort_controller") as c:
        with start_node(params, dom, extra_args=WALK) as sim:
            c.node.create_publisher(Float64MultiArray, "hip_torque",
                                    QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
            c.spin_until(lambda: "publishes /hip_torque best effort" in sim.output(), 30,
                         "the warning about a best-effort publisher", proc=sim)
            sim.stop()
    line = next(ln for ln in sim.output().splitlines() if "best effort" in ln)
    assert "[WARN]" in line and "/best_effort_controller publishes /hip_torque best effort" in line, line
    assert "Publish hip_torque reliable" in line
