"""Bags of any described robot read back by its names and sizes: ``bs.load_run``, ``biped-sim inspect`` and the
animation's track size a run from the robot the bag recorded (its ``robot`` parameter), not the three-link's.

The bags are written without the engine: the node's own state serializer (``StateSerializer`` with the robot's
``joint_layout``: names, effort = B u) and message builders (``impact_msg`` of an engine ``Event``), fed states
of RABBIT's 7 coordinates and 4 torques, through the recorder (``BagRecorder``) the node records with; they are
read back by ``bs.load_run`` and by ``rosbags`` (the independent reader).
"""
from __future__ import annotations

import shutil
import warnings

import numpy as np
import pytest

import biped_sim as bs
from biped_sim.cli import main as biped_sim

Q0 = np.array([0.0, 0.75, 3.3, 2.9, 0.35, 0.1, 0.2])       # RABBIT standing on foot 1, knees bent
SAMPLES = 120                                                # states, 1 ms apart
IMPACT_AT = 60                                               # the state at which foot 2 lands


def rabbit_states():
    """(t, q, dq, u) of a made-up RABBIT run: every coordinate and torque its own values."""
    t = np.arange(SAMPLES) * 1_000_000 / 1e9                 # as a reader gets it back from the stamp (ns)
    q = Q0 + np.outer(t, [0.5, -0.1, 0.4, -0.6, 0.8, -0.3, 0.2])
    dq = np.tile([0.5, -0.1, 0.4, -0.6, 0.8, -0.3, 0.2], (SAMPLES, 1)) + np.outer(t, np.arange(7.0))
    u = np.column_stack([np.sin(10 * t), -2 + t, 3 * np.cos(5 * t), 0.5 + 4 * t])
    return t, q, dq, u


def write_bag(path, params, layout, states, impact=None):
    """A bag as the node records one: its state messages each period, a command, an impact."""
    from biped_sim.recording import messages as M
    from biped_sim.recording.cdr import StateSerializer, float64_multi_array_data
    from biped_sim.recording.recorder import BagRecorder
    serializer = StateSerializer(layout.coordinates, labels={n: "/" + n for n in M.TOPIC_TYPES},
                                 effort=layout.effort_function())
    rec = BagRecorder(path, parameters=params)
    for name in ("joint_states", "ground_reaction", "clock", "impact", "diagnostics", "hip_torque"):
        rec.add_topic("/" + name, M.TOPIC_TYPES[name])
    t, q, dq, u = states
    for k in range(len(t)):
        t_ns = M.to_ns(t[k])
        rec.write("/hip_torque", float64_multi_array_data(u[k]), t_ns)
        if impact is not None and k == IMPACT_AT:
            rec.write("/impact", M.impact_msg(impact), t_ns)
        leg = 1 if impact is None or k < IMPACT_AT else 2
        rec.write_messages(t_ns, serializer.period(t_ns, M.foot_frame(leg), q[k].tolist(), dq[k].tolist(),
                                                   u[k].tolist(), [3.0 + k, 300.0 - k]))
    rec.close()


def rabbit_impact(states):
    """Foot 2 lands: the event as the engine reports it, its dq+ and impulse from RABBIT's impact map."""
    from biped_sim.engine.results import Event
    t, q, dq, _u = states
    rabbit = bs.load_model("rabbit")
    dq_plus, impulse = rabbit.impact_map(q[IMPACT_AT], dq[IMPACT_AT], 2)
    return Event(time=float(t[IMPACT_AT]), kind="touchdown", leg=2, q=q[IMPACT_AT], dq_minus=dq[IMPACT_AT],
                 dq_plus=dq_plus, impulse=impulse, stance_leg_before=1, stance_leg_after=2, energy_loss=1.25)


def scene_params(robot, **values):
    from biped_sim.config.parameters import validate
    if robot not in ("three_link", "compass_gait", "three_link_hip_mass"):   # a described robot's own start
        values = dict(dict(initial_q=[0.0, 0.75, 3.3, 2.9, 0.35, 0.1, 0.2], initial_dq=[0.0] * 7), **values)
    return validate(dict(scene="synthetic", robot=robot, duration=0.2, **values))


@pytest.fixture(scope="module")
def rabbit_bag(tmp_path_factory):
    from biped_sim.config.joints import joint_layout
    states = rabbit_states()
    bag = tmp_path_factory.mktemp("rabbit") / "rabbit-bag"
    write_bag(bag, scene_params("rabbit"), joint_layout("rabbit"), states, rabbit_impact(states))
    return bag, states


RABBIT_COORDINATES = ("base_x", "base_y", "hip_1", "hip_2", "knee_1", "knee_2", "torso_pitch")
RABBIT_ACTUATORS = ("hip_1", "hip_2", "knee_1", "knee_2")


def test_load_run_sizes_a_rabbit_bag_by_its_robot(rabbit_bag):
    bag, (t, q, dq, u) = rabbit_bag
    run = bs.load_run(bag)
    assert run.robot == "rabbit" and run.robot_problem == ""
    assert run.coordinates == RABBIT_COORDINATES and run.actuators == RABBIT_ACTUATORS
    assert run.q.shape == run.dq.shape == run.effort.shape == (SAMPLES, 7) and run.u.shape == (SAMPLES, 4)
    np.testing.assert_array_equal(run.t, t)
    np.testing.assert_array_equal(run.q, q)
    np.testing.assert_array_equal(run.dq, dq)
    np.testing.assert_array_equal(run.u, u)                               # each torque from its joint's column
    np.testing.assert_array_equal(run.effort[:, [0, 1, 6]], 0.0)         # the base and the torso have no motor
    np.testing.assert_array_equal(run.effort[:, [2, 3, 4, 5]], u)
    assert list(run.stance_leg[IMPACT_AT - 1:IMPACT_AT + 1]) == [1, 2]
    (touchdown,) = run.impacts
    assert touchdown["foot"] == 2 and touchdown["time"] == t[IMPACT_AT]
    assert touchdown["q"] == q[IMPACT_AT].tolist() and len(touchdown["dq_plus"]) == 7
    assert touchdown["dq_minus"] == dq[IMPACT_AT].tolist()


def test_rosbags_reads_a_rabbit_bag_as_load_run_does(rabbit_bag):
    """The independent reader: joint_states name RABBIT's coordinates and carry each motor's torque on its
    joint; the impact's state has 7 values."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore
    bag, (_t, q, _dq, u) = rabbit_bag
    ts = get_typestore(Stores.ROS2_JAZZY)
    states, impacts = [], []
    with Reader(bag) as reader:
        for conn, _t_ns, raw in reader.messages():
            msg = ts.deserialize_cdr(raw, conn.msgtype)
            if conn.topic == "/joint_states":
                states.append(msg)
            elif conn.topic == "/impact":
                impacts.append({kv.key: kv.value for kv in msg.status[0].values})
    assert len(states) == SAMPLES and tuple(states[0].name) == RABBIT_COORDINATES
    knee_1 = RABBIT_COORDINATES.index("knee_1")
    assert [m.effort[knee_1] for m in states] == u[:, 2].tolist()
    np.testing.assert_array_equal(np.array([m.position for m in states]), q)
    assert len(impacts) == 1 and impacts[0]["q"] == repr(q[IMPACT_AT].tolist())


def test_inspect_summarises_and_draws_a_rabbit_bag(rabbit_bag, tmp_path, capsys):
    from biped_sim.recording import inspect_bag
    bag, (_t, q, _dq, u) = rabbit_bag
    png = tmp_path / "rabbit.png"
    assert biped_sim(["inspect", str(bag), "--png", str(png), "--frames", "3"]) == 0
    out = capsys.readouterr().out
    assert "run         scene synthetic" in out and ", robot rabbit" in out, out
    assert f"|knee_1| max {np.max(np.abs(u[:, 2])):.4g} N m" in out, out
    assert f"base_y {q[:, 1].min():.3g} .. {q[:, 1].max():.3g} m" in out, out
    assert png.stat().st_size > 20_000
    fig = inspect_bag.plot(bag, tmp_path / "again.png", frames=3)
    labels = [line.get_label() for line in fig.axes[0].lines if not line.get_label().startswith("_")]
    assert labels[:5] == ["hip_1", "hip_2", "knee_1", "knee_2", "torso_pitch"], labels
    assert [line.get_label() for line in fig.axes[2].lines][:4] == list(RABBIT_ACTUATORS)


def test_the_animation_draws_a_rabbit_bag_and_a_rabbit_result(rabbit_bag, tmp_path):
    """The bag's track (its impact drawn at RABBIT's foot 2) and the bag streamed to a GIF; a result's track."""
    from types import SimpleNamespace

    from biped_sim.recording import animation as A
    bag, (t, q, _dq, _u) = rabbit_bag
    rabbit = bs.load_model("rabbit")
    track = A.track_from_bag(bag)
    assert track.q.shape == (SAMPLES, 7)
    foot_2 = tuple(rabbit.contact_position(q[IMPACT_AT], 2))
    assert track.impacts == [(t[IMPACT_AT], foot_2)]
    n, _fps, states = A.write_bag(bag, tmp_path / "rabbit.gif", fps=50)
    assert n == 6 and (tmp_path / "rabbit.gif").stat().st_size > 1000
    assert states.model.coordinates == RABBIT_COORDINATES
    result = SimpleNamespace(t=t, q=q, stance_leg=np.ones(SAMPLES, int), grf=np.zeros((SAMPLES, 2)),
                             impacts=[SimpleNamespace(time=t[IMPACT_AT], q=q[IMPACT_AT], leg=2)])
    assert A.track_from_result(result, rabbit).impacts == [(t[IMPACT_AT], foot_2)]


def test_a_bag_whose_robot_file_is_gone_reads_what_it_can(tmp_path, capsys):
    """Its robot (a description file) deleted after the recording: one line names it, and q, dq (by the
    recorded names), effort, the ground force and the impacts are read; inspect summarises it, exit code 0."""
    from biped_sim.config.joints import joint_layout
    from biped_sim.config.models import ROBOTS_DIR
    robot = tmp_path / "my_rabbit.yaml"
    shutil.copy(ROBOTS_DIR / "rabbit.yaml", robot)
    states = rabbit_states()
    bag = tmp_path / "bag"
    write_bag(bag, scene_params(str(robot)), joint_layout("rabbit"), states, rabbit_impact(states))
    robot.unlink()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = bs.load_run(bag)
    (warning,) = caught
    line = str(warning.message)
    assert "\n" not in line and f"the bag's robot {str(robot)!r} cannot be loaded" in line, line
    assert "does not exist" in line and "knee_1" in line, line
    assert run.robot_problem in line and run.robot == str(robot)
    assert run.coordinates == RABBIT_COORDINATES and run.actuators == () and run.u.shape == (SAMPLES, 0)
    np.testing.assert_array_equal(run.q, states[1])
    np.testing.assert_array_equal(run.effort[:, 2:6], states[3])
    assert len(run.grf) == SAMPLES and len(run.impacts) == 1
    assert biped_sim(["inspect", str(bag)]) == 0
    out = capsys.readouterr().out
    assert f"robot       the bag's robot {str(robot)!r} cannot be loaded" in out, out
    assert "figure      none (the robot cannot be loaded: see the robot line)" in out, out
    assert "impacts     1: t=0.0600 s foot 2" in out, out
    assert biped_sim(["animate", str(bag), "-o", str(tmp_path / "gone.gif"), "-q"]) == 2
    assert biped_sim(["resim", str(bag)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and all(f"{str(robot)!r}" in line for line in err), err
    assert err[0].endswith("its links cannot be drawn") and "cannot re-simulate" in err[1], err


@pytest.mark.parametrize("robot", ["three_link", "compass_gait"])
def test_a_three_link_robots_bag_reads_as_before(robot, tmp_path, capsys):
    """A three-link robot's bag: the three-link biped's without a ``robot`` parameter (recorded before robots had
    names), the compass gait's (its base angle named hip_pitch): q and dq of 5, u the hips' two torques, the
    summary's lines and the figure as they were."""
    from biped_sim.config.joints import joint_layout
    params = scene_params(robot)
    if robot == "three_link":
        del params["robot"]
    t = np.arange(50) * 1_000_000 / 1e9
    q = np.array([0.0, 0.98, 2.9, 3.4, 0.1]) + np.outer(t, [0.8, 0.0, 0.5, -0.5, 0.1])
    dq = np.tile([0.8, 0.0, 0.5, -0.5, 0.1], (50, 1))
    u = np.column_stack([5 + t, -3 - t])
    write_bag(tmp_path / "bag", params, joint_layout(robot), (t, q, dq, u))
    run = bs.load_run(tmp_path / "bag")
    assert run.robot == robot and run.coordinates == joint_layout(robot).coordinates
    assert run.actuators == ("hip_1", "hip_2") and run.q.shape == (50, 5) and run.u.shape == (50, 2)
    np.testing.assert_array_equal(run.q, q)
    np.testing.assert_array_equal(run.u, u)
    assert biped_sim(["inspect", str(tmp_path / "bag"), "--frames", "2"]) == 0
    out = capsys.readouterr().out
    assert ("run         scene synthetic, time_mode realtime, control_period 0.001 s, method auto (dopri5)"
            + ("" if robot == "three_link" else ", robot compass_gait") + "\n") in out, out
    assert f"hip height {q[:, 1].min():.3g} .. {q[:, 1].max():.3g} m" in out, out
    rms = np.sqrt(np.sum(u ** 2) / 100)
    assert f"torques     |u1| max {5.049:.4g} N m, |u2| max {3.049:.4g} N m, rms {rms:.4g} N m" in out, out
    assert (tmp_path / "bag.png").stat().st_size > 20_000


def test_a_bag_of_another_program_is_read_by_its_joint_names(tmp_path, capsys):
    """No biped_sim record and joint_states of one joint named 'elbow': one column of q by that name, no
    torques, a summary and no figure (the robot is not known)."""
    from biped_sim.recording import messages as M
    from biped_sim.recording.cdr import StateSerializer
    from biped_sim.recording.recorder import BagRecorder
    serializer = StateSerializer(("elbow",))
    rec = BagRecorder(tmp_path / "bag")
    rec.add_topic("/joint_states", M.TOPIC_TYPES["joint_states"])
    for k in range(3):
        rec.write("/joint_states", serializer.joint_state(0, k * 1_000_000, "", [0.1 * k], [1.0], [2.0 + k]),
                  k * 1_000_000)
    rec.close()
    run = bs.load_run(tmp_path / "bag")
    assert run.robot is None and run.params is None and run.coordinates == ("elbow",) and run.actuators == ()
    assert run.q.tolist() == [[0.0], [0.1], [0.2]] and run.u.shape == (3, 0) and run.effort[:, 0].tolist() == [2, 3, 4]
    assert biped_sim(["inspect", str(tmp_path / "bag")]) == 0
    out = capsys.readouterr().out
    assert "NOT RECORDED BY biped_sim" in out and "distance    0.2 m in 0.002 s (mean speed 100 m/s)\n" in out, out
    assert "figure      none (the bag does not say which robot it recorded" in out, out


def test_biped_echo_prints_a_described_robots_torques_on_its_joints():
    """biped_echo's joint_states line: a three-link robot's u1, u2 as before; RABBIT's effort (B u) whole, by
    joint name (its knees' torques too), not entries 2 and 3 only."""
    from sensor_msgs.msg import JointState

    from biped_sim.config.joints import joint_layout
    from biped_sim.ros.echo import format_message
    for robot, u, shown in (("rabbit", [1.0, 2.0, 3.0, 4.0], "effort={base_x: 0.00, base_y: 0.00, hip_1: 1.00, "
                             "hip_2: 2.00, knee_1: 3.00, knee_2: 4.00, torso_pitch: 0.00}"),
                            ("compass_gait", [1.0, 2.0], "u=[1.00, 2.00]")):
        layout = joint_layout(robot)
        n = len(layout.coordinates)
        msg = JointState(name=list(layout.coordinates), position=[0.0] * n, velocity=[0.0] * n,
                         effort=layout.effort(u))
        line = format_message("joint_states", msg)
        assert line.endswith(" " + shown), line
