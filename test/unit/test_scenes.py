"""Scenes: loading and checking, each scene's run, and what a scene leaves out (issue 6)."""
import math

import numpy as np
import pytest
import yaml

from biped_sim.cli import main as cli_main
from biped_sim.config import parameters as P
from biped_sim.config.scenes import CONTROLLER_PARAMETERS, available_scenes, load_scene
from biped_sim.control.walking import WalkingController
from biped_sim.engine.hybrid import HybridSimulator

SCENES = ("walk", "slope", "drop", "stance_fixed", "passive")


def _scene_file(tmp_path, name="walk", sim=None, ctrl=None, drop_ctrl=False):
    doc = yaml.safe_load(load_scene(name).path.read_text())
    doc["biped_sim"]["ros__parameters"].update(sim or {})
    if drop_ctrl:
        doc.pop("walk_controller", None)
    elif ctrl:
        doc["walk_controller"]["ros__parameters"].update(ctrl)
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_the_five_scenes_exist_and_declare_phases_and_outputs():
    assert set(SCENES) <= set(available_scenes())
    for name in SCENES:
        s = load_scene(name)
        assert s.name == name
        assert "phases" in s.given and "outputs" in s.given
        assert s.phases <= set(P.BY_NAME["phases"].choices) and set(s.outputs) <= set(P.OUTPUTS)


def test_load_by_path_and_unknown_name(tmp_path):
    s = load_scene(load_scene("walk").path)
    assert s.params["initial_stance_leg"] == 1
    with pytest.raises(ValueError, match="unknown scene 'nope'.*walk"):
        load_scene("nope")


def test_unknown_or_ill_typed_keys_are_named_with_the_allowed_values(tmp_path):
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) \['bogus'\]; allowed: .*time_mode"):
        load_scene(_scene_file(tmp_path, sim={"bogus": 1}))
    with pytest.raises(ValueError, match="'phases': 'jump' is not one of"):
        load_scene(_scene_file(tmp_path, sim={"phases": ["stance", "jump"]}))
    with pytest.raises(ValueError, match="'time_mode' must be one of"):
        load_scene(_scene_file(tmp_path, sim={"time_mode": "slow"}))
    with pytest.raises(ValueError, match="'duration' must be a number"):
        load_scene(_scene_file(tmp_path, sim={"duration": "long"}))
    with pytest.raises(ValueError,
                       match=r"walk_controller.*unknown walk_controller parameter\(s\) \['kq'\]; allowed: .*kp"):
        load_scene(_scene_file(tmp_path, ctrl={"kq": 1.0}))
    with pytest.raises(ValueError, match="'slope' = 0.1 differs from the simulation's 0.0"):
        load_scene(_scene_file(tmp_path, ctrl={"slope": 0.1}))


def test_a_scene_must_declare_phases_and_outputs(tmp_path):
    path = _scene_file(tmp_path)
    doc = yaml.safe_load(path.read_text())
    del doc["biped_sim"]["ros__parameters"]["outputs"]
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ValueError, match="must declare 'outputs'"):
        load_scene(path)


def test_controller_follows_the_scene():
    walk = load_scene("walk")
    c = walk.controller()
    assert isinstance(c, WalkingController) and c.torso_pitch == 0.15 and c.kp == 200.0
    assert load_scene("slope").controller().torso_pitch == 0.05
    assert load_scene("passive").controller() is None
    assert {p.name for p in CONTROLLER_PARAMETERS} >= {"torso_pitch", "step_angle", "kp", "kd", "slope"}


def test_walk_reaches_20_steps_and_hold_matches_continuous():
    walk = load_scene("walk")
    assert walk.phases == {"stance", "impact"}
    cont = walk.simulate(hold=False)
    assert cont.status == "completed" and len(cont.impacts) >= 20
    assert all(e.kind in ("touchdown", "scuff") and not e.warnings for e in cont.events)
    # the straight swing leg grazes the ground behind the stance foot once a step, 0.6 mm deep
    scuffs = [e for e in cont.events if e.kind == "scuff"]
    assert len(scuffs) == cont.stats["scuffs_ignored"] >= 20 and 1e-4 < cont.stats["deepest_scuff"] < 1e-3
    # the node's run (torques held over control_period) gives the same gait
    held = walk.simulate(hold=True, t_final=3.0)
    assert held.status == "completed"
    tc = [e.time for e in cont.impacts if e.time < 3.0]
    th = [e.time for e in held.impacts]
    assert len(tc) == len(th) and np.max(np.abs(np.subtract(tc, th))) < 2e-3


def test_slope_walks_down():
    s = load_scene("slope")
    r = s.simulate(hold=False)
    assert r.status == "completed" and len(r.impacts) >= 20
    periods = np.diff([e.time for e in r.impacts])
    assert np.ptp(periods[-4:]) < 1e-3          # periodic
    x = r.q[-1][0]
    assert x > 5.0 and r.q[-1][1] < r.q[0][1] - 5.0 * math.tan(0.03) + 0.05   # downhill


def test_drop_flight_touchdown_stance():
    s = load_scene("drop")
    assert s.params["initial_stance_leg"] == 0 and "flight" in s.phases
    r = s.simulate(hold=False)
    assert r.status == "completed"
    first = r.events[0]
    assert first.kind == "touchdown" and first.stance_leg_before == 0 and first.stance_leg_after == 1
    assert r.stance_leg[0] == 0 and r.stance_leg[-1] in (1, 2) and len(r.impacts) >= 2


def test_stance_fixed_integrates_three_coordinates_and_builds_no_impact_guard():
    s = load_scene("stance_fixed")
    kw = s.engine_arguments()
    assert kw["base"] == "fixed" and kw["phases"] == {"stance"} and kw["compute_grf"] is False
    sim = HybridSimulator(**kw)
    assert all(kind != "touchdown" for kind, _ in sim.active_guards())
    sim.advance(0.01, controller=s.controller())
    assert sim.integrated_size == 7         # (q1, q2, q3, dq1, dq2, dq3, work): the 3-coordinate chain
    r = s.simulate()
    assert r.status == "completed" and not r.events and r.t[-1] == pytest.approx(0.4)
    assert r.stats["max_constraint_drift_position"] == 0.0
    # the floating-base engine integrates the 11-dimensional state
    sim = HybridSimulator(**dict(kw, base="floating"))
    sim.advance(0.01, controller=s.controller())
    assert sim.integrated_size == 11


def test_no_impact_guard_without_impact_and_no_grf_without_the_output():
    kw = load_scene("walk").engine_arguments()
    assert kw["compute_grf"] is True
    assert ("touchdown", 2) in _guards_after_swing_lifts(kw)
    assert all(k != "touchdown" for k, _ in _guards_after_swing_lifts(dict(kw, phases=frozenset({"stance"}))))
    assert load_scene("stance_fixed").engine_arguments()["compute_grf"] is False


def _guards_after_swing_lifts(kw):
    sim = HybridSimulator(**kw)
    sim.advance(0.05, controller=load_scene("walk").controller())
    return sim.active_guards()


def test_passive_runs_without_controller_to_a_touchdown():
    s = load_scene("passive")
    assert s.controller_params is None
    r = s.simulate()
    assert r.status == "completed" and [e.kind for e in r.events] == ["touchdown"]
    assert r.events[0].time == pytest.approx(0.214, abs=2e-3)
    assert np.all(r.u == 0.0)


def test_liftoff_in_a_scene_without_flight_stops_and_names_the_phase(tmp_path):
    q, dq = WalkingController(load_scene("walk").engine_arguments()["model"]).initial_state(speed=4.0)
    path = _scene_file(tmp_path, sim={"initial_q": q.tolist(), "initial_dq": dq.tolist(), "duration": 1.0})
    r = load_scene(path).simulate(hold=False)
    assert r.status == "stopped"
    assert "add 'flight' to its phases" in r.message and r.events[-1].kind == "error"


def test_slip_in_a_scene_without_slip_stops_with_a_message(tmp_path):
    path = _scene_file(tmp_path, sim={"mu": 0.05, "on_slip": "stop", "duration": 2.0})
    r = load_scene(path).simulate(hold=False)
    assert r.status == "stopped" and "slip" in r.message and "no sliding phase" in r.message


def test_cli_simulate_scene(capsys):
    assert cli_main(["simulate", "--scene", "passive"]) == 0
    out = capsys.readouterr().out
    assert "scene passive" in out and "touchdown 1" in out
    assert cli_main(["simulate", "--scene", "walk", "--duration", "1"]) == 0
    assert "touchdown 2" in capsys.readouterr().out
    assert cli_main(["simulate", "--scene", "nope"]) == 2


def test_touchdown_in_a_scene_without_impact_stops_and_names_the_phase():
    r = load_scene("stance_fixed").simulate(hold=False, t_final=1.0)
    assert r.status == "stopped" and "add 'impact'" in r.message and r.t[-1] < 0.6


# -- issue 34 (round 3), item 2: one params file, read the same by the node (rcl) and the headless tools --
def _params_text(tmp_path, lines: str):
    path = tmp_path / "scene.yaml"
    path.write_text("biped_sim:\n  ros__parameters:\n    phases: [stance, impact]\n    outputs: [joint_states]\n"
                    + lines)
    return path


#: each case's reading by the node was measured by starting sim_node with the file
#: (test_node_faults.py::test_a_parameters_file_is_read_by_the_node_as_by_the_headless_tools)
READ_AS_RCL_DOES = [
    # (file lines, {parameter: the value rcl gives the node}); PyYAML read 1e-2, 2e-3, 09 as strings, n as 'n'
    ("    duration: 1e-2\n    control_period: 2e-3\n    record: n\n",
     {"duration": 0.01, "control_period": 0.002, "record": False}),
    ("    duration: 09\n    start_paused: y\n", {"duration": 9.0, "start_paused": True}),
]
REFUSED_AS_BY_THE_NODE = [
    # (file lines, the one line's words); PyYAML took the last of two keys or sections, 1_000 as 1000, and
    # the mixed list as floats, where rcl keeps the string '1_000', merges the sections, refuses the list
    ("    duration: 1.0\n    duration: 2.0\n",
     r"'biped_sim\.ros__parameters\.duration' is given twice \(lines 5 and 6\); rcl \(the node\) would take the "
     r"second.*\(1\.0 and 2\.0 given\)"),
    ("    duration: 1.0\nbiped_sim:\n  ros__parameters:\n    control_period: 0.002\n",
     r"'biped_sim' is given twice \(lines 1 and 6\); rcl \(the node\) would merge the two.*write 'biped_sim:' once"),
    ("    duration: 1_000\n", r"parameter 'duration' must be a number, got '1_000'"),
    ("    scene: n\n", r"parameter 'scene' must be a string, got False \(unquoted, y, n, .*quote the string"),
    ("    initial_dq: [0, 0.5, 0.0, 0.0, 0.0]\n",
     r"the list 'biped_sim\.ros__parameters\.initial_dq' \(line 5\) mixes float and integer entries.*rcl refuses"
     r".*write every number with a decimal point"),
    ("    duration:\n", r"'biped_sim\.ros__parameters\.duration' \(line 5\) has no value, which rcl refuses"),
]


@pytest.mark.parametrize("lines,expected", READ_AS_RCL_DOES)
def test_a_scene_file_is_read_as_the_node_reads_it(lines, expected, tmp_path):
    params = load_scene(_params_text(tmp_path, lines)).params
    assert {name: params[name] for name in expected} == expected


@pytest.mark.parametrize("lines,words", REFUSED_AS_BY_THE_NODE)
def test_a_scene_file_the_node_reads_otherwise_or_refuses_is_refused_in_one_line(lines, words, tmp_path):
    with pytest.raises(ValueError, match=words) as refused:
        load_scene(_params_text(tmp_path, lines))
    assert "\n" not in str(refused.value) and str(tmp_path / "scene.yaml") in str(refused.value)


#: unquoted scalars as rcl (Jazzy) read them, measured: rclpy's parameter overrides from a params file
RCL_SCALARS = [("yes", True), ("Off", False), ("y", True), ("N", False), ("1e3", 1000.0), ("1.0e3", 1000.0),
               ("1E-3", 0.001), ("09", 9.0), ("010", 8), ("-010", -8), ("0x10", 16), ("0X1F", 31), ("+5", 5),
               ("+1.5", 1.5), ("5.", 5.0), (".5", 0.5), ("0x1p3", 8.0), ("-0", 0), ("1_000", "1_000"),
               ("0b101", "0b101"), ("0o10", "0o10"), ("1:30", "1:30"), ("~", "~"), ("null", "null"),
               ("1e999", "1e999"), ("1e-400", "1e-400"), ("5e", "5e"), ("0x", "0x"), ("1.5.2", "1.5.2"),
               ("9223372036854775808", 9.223372036854776e18), ("-9223372036854775808", -9223372036854775808)]


@pytest.mark.parametrize("text,value", RCL_SCALARS)
def test_unquoted_scalars_are_read_by_rcl_rules(text, value):
    from biped_sim.config.params_yaml import rcl_scalar
    got = rcl_scalar(text)
    assert type(got) is type(value) and got == value


def test_infinities_nan_quotes_and_tags_as_rcl_reads_them():
    from biped_sim.config.params_yaml import load
    doc = load("a: .inf\nb: -.Inf\nc: inf\nd: .nan\ne: '1e3'\nf: \"y\"\ng: !!str 12\nh: !!float 1\ni: [y, n]\n", "t")
    assert doc["a"] == math.inf and doc["b"] == -math.inf and doc["c"] == math.inf and math.isnan(doc["d"])
    assert doc["e"] == "1e3" and doc["f"] == "y" and doc["g"] == "12"      # quoted, !!str: strings
    assert type(doc["h"]) is int and doc["i"] == [True, False]               # rcl ignores other tags


# -- issue 31, item 1: scenes name their robot ------------------------------------------------------------
def _robot_scene(tmp_path, robot, **extra):
    path = tmp_path / f"robot_{abs(hash(robot))}.yaml"
    path.write_text(yaml.safe_dump({"biped_sim": {"ros__parameters": dict(
        robot=robot, phases=["stance", "impact"], outputs=["joint_states"], duration=0.1) | extra}}))
    return path


def test_a_scene_names_its_robot_whose_numbers_are_the_model_parameters(tmp_path):
    from biped_sim.config.models import load_model
    assert load_scene("walk").robot == "three_link" and P.BY_NAME["robot"].default == "three_link"
    cg = load_scene("compass_gait")
    assert cg.robot == "compass_gait" and "model.m_torso" not in cg.given   # the robot gives the numbers
    assert cg.engine_arguments()["model"].parameters == load_model("compass_gait").parameters
    hip_mass = load_scene(_robot_scene(tmp_path, "three_link_hip_mass"))
    assert hip_mass.engine_arguments()["model"].parameters == load_model("three_link_hip_mass").parameters
    heavier = load_scene(_robot_scene(tmp_path, "compass_gait", **{"model.m_torso": 12.0}))   # a model.* given wins
    assert heavier.engine_arguments()["model"].parameters.m_torso == 12.0
    assert heavier.engine_arguments()["model"].parameters.I_leg == 0.0
    over = load_scene("walk", overrides={"robot": "compass_gait"})      # an override names both sections' robot
    assert over.robot == over.controller_params["robot"] == "compass_gait"
    assert over.controller().model.parameters == load_model("compass_gait").parameters


def test_the_hip_mass_walker_s_scene_walks_on_its_gait():
    """msg_configs/three_link_hip_mass.yaml: the robot in both sections, started on the gait biped-sim gait finds
    for it: every step of the 10 s within 0.5 ms of the first (held 1 ms torques against continuous feedback)."""
    from biped_sim.config.models import load_model
    scene = load_scene("three_link_hip_mass")
    assert scene.robot == scene.controller_params["robot"] == "three_link_hip_mass"
    assert scene.controller().model.parameters == load_model("three_link_hip_mass").parameters
    r = scene.simulate()
    assert r.status == "completed" and len(r.impacts) == 22, (r.status, r.message)
    steps = np.diff([e.time for e in r.impacts])
    assert np.all(np.abs(steps - 0.4489) < 5e-4), steps


#: RABBIT standing on foot 1 at the origin, leg 2 bent (its foot 2 cm up), at rest (test_generic_engine.py's)
RABBIT_Q0 = [0.0997086196481708, 0.7935100972856273, 3.241592653589793, 2.941592653589793, -0.05, 0.5, 0.05]


def test_a_described_robots_scene_runs_and_what_does_not_fit_it_is_refused_in_one_line(tmp_path, capsys):
    """A scene with ``robot: rabbit`` runs headless (RABBIT falls over and its swing foot lands), from the scene and
    the CLI; a scene that does not fit the robot is refused in one line that says what to give: the three-link's
    initial state, a model.* number, the reference walking controller."""
    with pytest.raises(ValueError) as err:
        load_scene(_robot_scene(tmp_path, "rabbit"))
    line = str(err.value)
    assert "\n" not in line and "parameter 'initial_q' must be given for robot 'rabbit': 7 entries" in line, line
    path = tmp_path / "rabbit_falls.yaml"       # (_robot_scene's file is rewritten below)
    path.write_text(_robot_scene(tmp_path, "rabbit", initial_q=RABBIT_Q0, initial_dq=[0.0] * 7, duration=0.2)
                    .read_text())
    scene = load_scene(path)
    assert scene.robot == "rabbit" and scene.engine_arguments()["model"].n == 7
    r = scene.simulate()
    assert r.status == "completed" and [(e.kind, e.leg) for e in r.impacts] == [("touchdown", 2)], r.message
    assert cli_main(["simulate", "--scene", str(path)]) == 0
    with pytest.raises(ValueError, match=r"parameter 'initial_q' must have 7 entries, one for each coordinate of "
                                         r"robot 'rabbit' \(base_x, base_y, hip_1, hip_2, knee_1, knee_2, "
                                         r"torso_pitch\), got 5"):
        load_scene("walk", overrides={"robot": "rabbit"})
    with pytest.raises(ValueError, match=r"parameter 'model.m_leg' sets a number of the three-link biped; robot "
                                         r"'rabbit' takes its numbers from its description"):
        load_scene(_robot_scene(tmp_path, "rabbit", initial_q=RABBIT_Q0, initial_dq=[0.0] * 7, **{"model.m_leg": 3.0}))
    walking = load_scene("walk", overrides={"robot": "rabbit", "initial_q": RABBIT_Q0, "initial_dq": [0.0] * 7})
    with pytest.raises(ValueError) as err:
        walking.simulate()
    line = str(err.value)
    assert "\n" not in line and line.startswith("the reference walking controller (walk_controller) runs the "
                                                "three-link robots (three_link, compass_gait, three_link_hip_mass); "
                                                "robot 'rabbit' has 7 coordinates and 4 motors"), line
    capsys.readouterr()
    assert cli_main(["simulate", "--scene", str(_robot_scene(tmp_path, "rabbit"))]) == 2
    err_text = capsys.readouterr().err
    assert err_text.count("\n") == 1 and "for robot 'rabbit': 7 entries" in err_text, err_text


def test_a_robot_that_is_no_shipped_name_nor_a_file_is_named_with_the_choices(tmp_path):
    with pytest.raises(ValueError, match=r"parameter 'robot': unknown model 'rabit'; shipped: three_link, "
                                         r"compass_gait, three_link_hip_mass, rabbit"):
        load_scene(_robot_scene(tmp_path, "rabit"))
    with pytest.raises(ValueError, match=r"parameter 'robot': robot description '.*nowhere.urdf' does not exist"):
        load_scene(_robot_scene(tmp_path, str(tmp_path / "nowhere.urdf")))
    with pytest.raises(ValueError, match="walk_controller parameter 'robot' = 'compass_gait' differs from the "
                                         "simulation's 'three_link'"):
        load_scene(_scene_file(tmp_path, ctrl={"robot": "compass_gait"}))
