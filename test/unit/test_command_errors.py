"""One line and an exit code for every way a command can stop (biped_sim.config.command_errors), and the
command-line input that used to be ignored or refused (issue 18, items 11 and 12). The process-level
cases (tracebacks in stderr, signals, bags) are in test/integration/test_faults.py."""
import errno
import glob

import pytest

from biped_sim.cli import main as cli_main
from biped_sim.config.command_errors import CommandError, explain, run_command


@pytest.mark.parametrize("exc, code, expected", [
    (ValueError("--rate must be positive"), 2, "prog: error: --rate must be positive"),
    (FileNotFoundError(errno.ENOENT, "No such file or directory", "/no/such"), 1,
     "prog: error: /no/such: No such file or directory; check the path"),
    (PermissionError(errno.EACCES, "Permission denied", "/root/bags"), 1,
     "prog: error: /root/bags: Permission denied; choose a folder you can write to, or change its permissions"),
    (OSError(errno.ENOSPC, "not enough free disk space for the bag b: 3 MB free"), 1,
     "prog: error: not enough free disk space for the bag b: 3 MB free; free some disk space or choose another disk"),
    (CommandError("nothing to recover: b is complete"), 1, "prog: error: nothing to recover: b is complete"),
    (KeyboardInterrupt(), 130, None),
    (BrokenPipeError(), 1, None),
    (SystemExit(2), 2, None),
    (ModuleNotFoundError("No module named 'rclpy'", name="rclpy"), 2, "prog: error: cannot import rclpy"),
    (TypeError("unsupported operand"), 1, "prog: error: unexpected TypeError: unsupported operand -- this is a bug"),
])
def test_each_kind_of_error_has_its_exit_code_and_one_line(exc, code, expected):
    got_code, line = explain("prog", exc)
    assert got_code == code
    if expected is None:
        assert line is None
    else:
        assert line.startswith(expected) and "\n" not in line, line


def test_run_command_prints_the_line_and_returns_the_code(capsys, monkeypatch):
    monkeypatch.delenv("BIPED_SIM_DEBUG", raising=False)

    def fails():
        raise RuntimeError("the wheel came off")
    assert run_command("prog", fails) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "BIPED_SIM_DEBUG=1" in err, err
    monkeypatch.setenv("BIPED_SIM_DEBUG", "1")
    assert run_command("prog", fails) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and err.strip().endswith("for the traceback"), err
    assert run_command("prog", lambda: 3) == 3 and run_command("prog", lambda: None) == 0


def test_simulate_scene_applies_the_engine_options_given(capsys):
    assert cli_main(["simulate", "--scene", "walk", "--duration", "0.2"]) == 0
    assert "method  dopri5" in capsys.readouterr().out          # the scene's (auto)
    assert cli_main(["simulate", "--scene", "walk", "--duration", "0.2", "--method", "rk4", "--step", "5e-4"]) == 0
    out = capsys.readouterr().out
    assert "method  rk4" in out and "given on the command line: method rk4, step 0.0005, duration 0.2" in out, out


@pytest.mark.parametrize("args, expected", [
    (["--controller", "my_missing_module:Law"], "cannot import 'my_missing_module'"),
    (["--controller", "biped_sim.control.walking:WalkingController.swing_target"],
     "cannot be called as controller(t, q, dq, stance_leg)"),
    (["--rtol", "5"], "override 'rtol': parameter 'rtol' must be in [1e-14, 0.1], got 5.0"),
    (["--mu", "-1"], "override 'mu': parameter 'mu' must be in [0.0, 100.0], got -1.0"),
])
def test_simulate_scene_refuses_an_option_it_cannot_apply(args, expected, capsys):
    assert cli_main(["simulate", "--scene", "walk", "--duration", "0.2", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("biped-sim simulate: error: ") and expected in err[0], err


def test_simulate_controller_walk_needs_a_scene_with_its_parameters(capsys):
    assert cli_main(["simulate", "--scene", "passive", "--duration", "0.1", "--controller", "walk"]) == 2
    assert "scene passive has no walk_controller section" in capsys.readouterr().err
    assert cli_main(["simulate", "--scene", "walk", "--duration", "0.1", "--controller", "none"]) == 0
    assert "controller none (u = 0)" in capsys.readouterr().out


def test_simulate_scene_record_records_the_options_given(tmp_path, capsys):
    from biped_sim.recording import bagio
    assert cli_main(["simulate", "--scene", "walk", "--duration", "0.1", "--method", "rk4", "--record",
                     str(tmp_path)]) == 0
    params = bagio.run_parameters(glob.glob(f"{tmp_path}/walk-*")[0])
    assert params["method"] == "rk4" and params["scene"] == "walk"


def test_torque_pub_reads_negative_numbers_and_expressions_as_values():
    from biped_sim.ros.torque_pub import build_parser, compile_expr, negative_numbers_as_values
    parse = build_parser().parse_args
    assert parse(negative_numbers_as_values(["1e8", "-1e8"])).torques == [1e8, -1e8]
    args = parse(negative_numbers_as_values(["--expr", "-t", "-3*cos(t)", "--rate", "10"]))
    assert [compile_expr(e)(1.0) for e in args.expr] == [-1.0, pytest.approx(-3 * 0.5403023058681398)]
    with pytest.raises(ValueError, match=r"'1/t' failed at t = 0 s: float division by zero"):
        compile_expr("1/t")
    f = compile_expr("1/(t - 2)")
    with pytest.raises(ValueError, match=r"failed at t = 2 s"):
        f(2.0)


def test_a_recovered_original_gets_a_free_name(tmp_path):
    from biped_sim.recording.recover import kept_name
    src = tmp_path / "b_0.mcap"
    assert kept_name(src).name == "b_0.mcap.truncated"
    (tmp_path / "b_0.mcap.truncated").write_bytes(b"1")
    (tmp_path / "b_0.mcap.truncated.1").write_bytes(b"2")
    assert kept_name(src).name == "b_0.mcap.truncated.2"


def test_torque_pub_takes_one_torque_per_actuated_joint_of_its_robot(capsys):
    """Issue 31, item 2: how many torques a command holds comes from the robot's description (--robot, default
    three_link); a wrong count is one line naming the actuated joints, before any ROS start."""
    from biped_sim.ros.torque_pub import main
    cases = [(["1", "2", "3"], "give 2 torques, one per actuated joint (hip_1, hip_2) of robot three_link; got 3"),
             (["--robot", "rabbit", "1", "2"],
              "give 4 torques, one per actuated joint (hip_1, hip_2, knee_1, knee_2) of robot rabbit; got 2"),
             (["--robot", "rabbit", "--expr", "t", "0"], "--expr takes 4 torques, one per actuated joint"),
             (["--robot", "rabit", "1", "2"], "--robot: unknown model 'rabit'; shipped: three_link")]
    for argv, expected in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(f"torque_pub: error: {expected}"), (argv, err)
