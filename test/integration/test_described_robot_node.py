"""Described robots through the node (issue 31's "done when"): RABBIT walking in lockstep with walk_controller,
a user's own URDF robot headless, through the node with a controller node of the user's own
(examples/own_controller_node.py) and in a sweep, and a RABBIT command of the wrong length. Real processes over
DDS; bags read back by rosbags."""
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from ros_helpers import BIN, Client, bag_messages, ros_domain, ros_env, spin_while_running, start_node  # noqa: E402

pytest.importorskip("rclpy")
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

import biped_sim as bs  # noqa: E402
from biped_sim.config.scenes import load_scene  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
RABBIT_SCENE = ROOT / "msg_configs" / "rabbit.yaml"
RABBIT_JOINTS = ["base_x", "base_y", "hip_1", "hip_2", "knee_1", "knee_2", "torso_pitch"]


def _t(m):
    return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9


def _cli(*args, cwd=ROOT, env=None):
    return subprocess.run([str(BIN / "biped-sim"), *map(str, args)], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300)


def test_rabbit_walks_in_lockstep_with_walk_controller_and_its_bag_resimulates(tmp_path):
    """msg_configs/rabbit.yaml for both nodes (law rabbit_walking), 0.65 s: RABBIT's 7 joint names, the effort
    of its 4 motors on their joints (the command that ended each period), one /impact for its touchdown at
    0.589 s, the ground force in stance, markers; the run completes as the headless scene run does, bit for bit;
    its bag reads back by rosbags and bs.load_run (q of 7, u of 4), `biped-sim inspect` reads it and `biped-sim
    resim` reproduces it (failed before: resim refused the recorded model.* defaults of a described robot)."""
    duration = 0.65
    args = ["--ros-args", "--params-file", str(RABBIT_SCENE)]
    with ros_domain() as dom:
        with start_node({"duration": duration, "bag_dir": str(tmp_path)}, dom, extra_args=args) as sim, \
                Client(dom) as c:
            js = c.collect("/joint_states", JointState)
            impacts = c.collect("/impact", DiagnosticArray)
            grf = c.collect("/ground_reaction", WrenchStamped)
            markers = c.collect("/markers", MarkerArray, transient_local=False)
            c.wait_subscribed("/joint_states", proc=sim)
            with start_node(None, dom, executable="walk_controller", extra_args=args) as ctl:
                spin_while_running(c, lambda: js and _t(js[-1]) >= duration - 1e-9, 120,
                                   f"the state at t = {duration} s", [sim, ctl])
                assert ctl.stop() == 0
            assert sim.wait(30) == 0, sim.output()
            c.spin_once(0.1)
    ref = load_scene("rabbit", overrides={"duration": duration}).simulate()
    assert ref.status == "completed" and len(ref.impacts) == 1
    assert "duration 0.65 s reached: the run ends" in sim.output()
    assert all(list(m.name) == RABBIT_JOINTS for m in js) and len(js) == round(duration / 0.001) + 1
    assert list(js[-1].position) == ref.q[-1].tolist() and list(js[-1].velocity) == ref.dq[-1].tolist()
    # effort = B u: the motors' torques on hip_1, hip_2, knee_1, knee_2, zero on the base and the torso
    efforts = np.array([m.effort for m in js[1:]])
    assert efforts.shape == (len(js) - 1, 7) and not efforts[:, [0, 1, 6]].any()
    assert np.abs(efforts[:, 2:6]).max() > 10.0
    assert len(impacts) == 1 and abs(_t(impacts[0]) - ref.impacts[0].time) < 1e-9
    assert len(grf) == len(js) and min(m.wrench.force.y for m in grf) > 200.0    # RABBIT weighs 314 N
    assert markers and all(m.header.frame_id == "world" for m in markers[0].markers)

    (bag,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    got = bag_messages(bag)
    assert len(got["/joint_states"]) == len(js) and len(got["/impact"]) == 1 and got["/markers"]
    # each state's effort is the command that answered the state before it
    commands = np.array([list(m.data) for _t_ns, m in got["/hip_torque"]])    # (the bag's: a live subscriber
    assert commands.shape[1] == 4                                              # may match after a fast run)
    np.testing.assert_array_equal(efforts[:, 2:6], commands[:len(efforts)])
    run = bs.load_run(bag)
    assert run.q.shape == (len(js), 7) and run.u.shape == (len(js), 4)
    np.testing.assert_array_equal(run.q[-1], ref.q[-1])
    out = _cli("inspect", bag)
    assert out.returncode == 0 and "robot rabbit" in out.stdout and "impacts     1:" in out.stdout, out
    assert "|knee_1| max" in out.stdout and "end         biped_sim/run: completed" in out.stdout, out.stdout
    out = _cli("resim", bag)
    assert out.returncode == 0 and "IDENTICAL" in out.stdout, out.stdout + out.stderr


MY_WALKER_SCENE = """\
biped_sim:
  ros__parameters:
    scene: my_walker
    robot: my_walker.urdf
    time_mode: lockstep
    control_period: 0.001
    duration: 0.6
    initial_q: [0.05992503436700264, 0.7975017702691969, 3.241592653589793, 2.941592653589793, -0.05, 0.3, 0.0]
    initial_dq: [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    initial_stance_leg: 1
    phases: [stance, impact]
    outputs: [joint_states, ground_reaction, impact, clock, markers]
    torque_limit: 150.0
    record: true
"""


def write_my_walker(folder: Path) -> None:
    """A user's planar URDF (RABBIT's links, a 20 kg torso and 5 kg thighs) and a scene that names it: standing
    on foot 1, foot 2 a little in front, the posture held by PD while it tips onto foot 2."""
    urdf = (ROOT / "biped_sim" / "config" / "robots" / "rabbit.urdf").read_text()
    urdf = urdf.replace('robot name="rabbit"', 'robot name="my_walker"')
    urdf = urdf.replace('<mass value="12.0"/>', '<mass value="20.0"/>').replace('<mass value="6.8"/>',
                                                                                '<mass value="5.0"/>')
    (folder / "my_walker.urdf").write_text(urdf)
    (folder / "my_walker.yaml").write_text(MY_WALKER_SCENE)


def test_a_users_urdf_robot_runs_through_the_node_with_its_own_controller_headless_and_in_a_sweep(tmp_path,
                                                                                                   monkeypatch):
    """A robot of the user's own (write_my_walker), a fresh model cache: sim_node generates its dynamics on
    first use and says so in its log (failed before: nothing was said for the seconds of sympy), then runs in
    lockstep with examples/own_controller_node.py (the user's rclpy node: PD on the actuated joints named by a
    parameter); the run is `biped-sim simulate --scene` with the same law (PosturePD) bit for bit, and `biped-sim
    sweep` runs the scene over the law's gains."""
    write_my_walker(tmp_path)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("PYTHONPATH", str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    monkeypatch.chdir(tmp_path)            # the scene names its URDF relative to the current folder
    monkeypatch.syspath_prepend(str(ROOT))  # examples.own_controller_node
    names = ["base_x", "base_y", "hip_1", "hip_2", "knee_1", "knee_2", "torso_pitch"]
    with ros_domain() as dom:
        with start_node({"bag_dir": str(tmp_path / "bags")}, dom,
                        extra_args=["--ros-args", "--params-file", "my_walker.yaml"]) as sim, Client(dom) as c:
            js = c.collect("/joint_states", JointState)
            # the first start generates the robot's dynamics (seconds): the node stays up and says so
            c.spin_until(lambda: js, timeout=120, what="the state at t = 0", proc=sim)
            ctl = subprocess.Popen([sys.executable, str(ROOT / "examples" / "own_controller_node.py"), "--ros-args",
                                    "-p", "joints:=[hip_1, hip_2, knee_1, knee_2]"], env=ros_env(dom),
                                   stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            try:
                spin_while_running(c, lambda: _t(js[-1]) >= 0.6 - 1e-9, 120, "the state at t = 0.6 s", [sim])
                assert sim.wait(30) == 0, sim.output()
            finally:       # (as ros_helpers.NodeProcess.stop: SIGTERM, SIGKILL after 15 s; its exit is not the check)
                ctl.terminate()
                try:
                    ctl.wait(15)
                except subprocess.TimeoutExpired:
                    ctl.kill()
                    ctl.wait()
    log = sim.output()
    assert re.search(r"generating the dynamics of robot 'my_walker' \(my_walker.urdf\) with sympy on its first use",
                     log) and re.search(r"generated the dynamics of robot 'my_walker' .* in [\d.]+ s", log), log
    assert all(list(m.name) == names for m in js)
    (bag,) = (tmp_path / "bags").iterdir()
    run = bs.load_run(bag)
    assert run.q.shape == (601, 7) and run.u.shape == (601, 4) and len(run.impacts) == 1

    # headless, with the same law: the node's run, bit for bit (the cache is warm: no generation)
    from examples.own_controller_node import PosturePD
    ref = bs.load_scene("my_walker.yaml").simulate(controller=PosturePD)
    assert ref.status == "completed" and ref.q[-1].tolist() == list(js[-1].position)
    out = _cli("simulate", "--scene", "my_walker.yaml", "--controller", "examples.own_controller_node:PosturePD",
               cwd=tmp_path)
    assert out.returncode == 0 and "status  completed" in out.stdout and "touchdown 1" in out.stdout, out
    assert "generating" not in out.stderr, out.stderr
    out = _cli("sweep", "my_walker.yaml", "--controller", "examples.own_controller_node:PosturePD",
               "--set", "controller.kp=100,200", "--set", "controller.kd=20", "-o", "sweep.csv", cwd=tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    import csv
    with open(tmp_path / "sweep.csv", newline="") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    assert len(rows) == 2 and "q_end[6]" in rows[0]
    (row,) = [r for r in rows if float(r["controller.kp"]) == 200.0]
    assert row["status"] == "completed" and float(row["q_end[6]"]) == ref.q[-1][6]


def test_a_rabbit_command_of_the_wrong_length_is_one_line_and_the_node_runs_on():
    """RABBIT in lockstep: a command of 2 torques is refused in one warning line naming its 4 motors, advances
    nothing, and the next command of 4 advances the run."""
    args = ["--ros-args", "--params-file", str(RABBIT_SCENE)]
    with ros_domain() as dom:
        with start_node({"record": False, "duration": 1.0}, dom, extra_args=args) as sim, Client(dom) as c:
            js = c.collect("/joint_states", JointState)
            pub = c.publisher("/hip_torque", Float64MultiArray)
            c.wait_matched(pub, proc=sim)
            c.spin_until(lambda: js, what="the state at t = 0", proc=sim)
            pub.publish(Float64MultiArray(data=[1.0, 2.0]))
            c.spin_until(lambda: "instead of" in sim.output(), what="the warning", proc=sim)
            pub.publish(Float64MultiArray(data=[0.0, 0.0, 0.0, 0.0]))
            c.spin_until(lambda: len(js) >= 2, what="the state after one period", proc=sim)
            assert sim.alive
    lines = [x for x in sim.output().splitlines() if "instead of" in x]
    assert len(lines) == 1 and "2 values instead of 4, one per actuated joint (hip_1, hip_2, knee_1, knee_2)" \
        in lines[0], sim.output()
    assert "Traceback" not in sim.output() and [round(_t(m), 6) for m in js] == [0.0, 0.001]


def test_the_demo_runs_the_passive_compass_gait_through_the_node(tmp_path):
    """`python -m biped_sim.cli.demo --scene compass_gait`: the scene has no walk_controller section, so the node
    runs alone (fast, u = 0) and the bag is the node's, with its final status (failed before: walk_controller was
    started with the scene file, refused it, and the demo fell back to the headless run)."""
    with ros_domain() as dom:
        env = dict(ros_env(dom))
        done = subprocess.run([sys.executable, "-m", "biped_sim.cli.demo", "--scene", "compass_gait", "--duration",
                               "1", "--bag-dir", str(tmp_path)], cwd=ROOT, env=env, capture_output=True, text=True,
                              timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "falling back" not in done.stdout and "fast, 1 s, u = 0: the scene has no controller" in done.stdout
    assert "time_mode fast" in done.stdout and "impacts     1: t=0.4172 s foot 2" in done.stdout, done.stdout
    assert "end         biped_sim/run: completed" in done.stdout, done.stdout
