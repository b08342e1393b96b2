"""Bad input and faults around the nodes and the small tools (issue 18): one clear line or a quiet
exit, never a Python traceback, never a node started that was not asked for. Real processes over DDS."""
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from ros_helpers import BIN, Client, ros_domain, ros_env, start_node  # noqa: E402

pytest.importorskip("rclpy")
from biped_sim.config.parameters import PARAMETERS  # noqa: E402
from biped_sim.config.scenes import CONTROLLER_PARAMETERS  # noqa: E402

NODES = {"sim_node": (PARAMETERS, ["hip_torque", "joint_states", "ground_reaction", "impact", "diagnostics",
                                   "/clock"]),
         "walk_controller": (CONTROLLER_PARAMETERS, ["joint_states", "hip_torque"])}


def run(argv, dom, cwd, timeout=20.0):
    """``argv`` run to its end; the node it may start by mistake is killed after ``timeout`` s (a failure)."""
    start = time.monotonic()
    try:
        done = subprocess.run(argv, env=ros_env(dom), cwd=cwd, capture_output=True, text=True, timeout=timeout,
                              stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired as exc:
        raise AssertionError(f"{argv} still running after {timeout} s (a node started?)\n{exc.stderr}") from None
    return done, time.monotonic() - start


@pytest.mark.parametrize("program", sorted(NODES))
@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_node_help_prints_the_usage_and_starts_no_node(program, flag, tmp_path):
    table, topics = NODES[program]
    bags = tmp_path / "bags"
    with ros_domain() as dom:
        done, took = run([str(BIN / program), flag, "--ros-args", "-p", f"bag_dir:={bags}"], dom, tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"usage: {program}"), done.stdout
    for p in table:     # every parameter, with what it accepts and its default
        assert f"  {p.name}: " in done.stdout and f"default {p.default!r}" in done.stdout, p.name
    assert "[0.001, 1000.0]" in done.stdout or program != "sim_node"      # a range (rate_factor)
    for t in topics:
        assert t in done.stdout, t
    assert "Traceback" not in done.stderr and done.stderr == "", done.stderr
    assert not bags.exists() and list(tmp_path.iterdir()) == []        # nothing recorded, here or in bag_dir
    assert took < 15.0


@pytest.mark.parametrize("program", sorted(NODES))
def test_node_refuses_an_argument_before_ros_args(program, tmp_path):
    bags = tmp_path / "bags"
    with ros_domain() as dom:
        done, _took = run([str(BIN / program), "--duration", "1", "--ros-args", "-p", f"bag_dir:={bags}"],
                          dom, tmp_path)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{program}: error: unknown argument(s) --duration 1"), lines
    assert "--ros-args" in lines[0] and "--help" in lines[0]
    assert done.stdout == "" and not bags.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("how", ["-p", "--params-file"])
def test_integers_in_a_list_parameter_are_refused_with_what_to_write(how, tmp_path):
    if how == "-p":
        ros_args = ["-p", "initial_q:=[0, 1, 3.14, 3.14, 0]"]
    else:
        params = tmp_path / "walk.yaml"
        params.write_text("biped_sim:\n  ros__parameters:\n    record: false\n    initial_q: [0, 1, 3.14, 3.14, 0]\n")
        ros_args = ["--params-file", str(params)]
    with ros_domain() as dom:
        done, _took = run([str(BIN / "sim_node"), "--ros-args", *ros_args], dom, tmp_path)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    ours = [ln for ln in done.stderr.splitlines() if ln.startswith("sim_node: error:")]
    assert len(ours) == 1 and len(done.stderr.strip().splitlines()) == 1, done.stderr   # (rcl's ERROR line too, before)
    assert "'initial_q'" in ours[0] and "0.0" in ours[0] and "float" in ours[0], ours[0]


#: ROS arguments rcl refuses: (the arguments after --ros-args, a file's text, what the line must name)
UNREADABLE_ROS_ARGS = {
    "missing_params_file": (["--params-file", "{tmp}/nope.yaml"], None, "does not exist"),
    "params_file_a_folder": (["--params-file", "{tmp}"], None, "is a folder"),
    "params_file_bad_yaml": (["--params-file", "{tmp}/bad.yaml"],
                             "biped_sim:\n  ros__parameters:\n    duration: [1.0\n", "near line"),
    "override_without_value": (["-p", "duration"], None, "'-p duration'"),
}


@pytest.mark.parametrize("program", sorted(NODES))
def test_ros_arguments_rcl_cannot_read_are_refused_in_one_line(program, tmp_path):
    """rcl's own ERROR line came first, then ours with rcl's C source locations (", at
    /project/src/rcl/arguments.c:415"); a missing file was "Error opening YAML file". Now one line each."""
    with ros_domain() as dom:
        for case, (ros_args, text, names) in UNREADABLE_ROS_ARGS.items():
            if text is not None:
                (tmp_path / "bad.yaml").write_text(text)
            args = [a.format(tmp=tmp_path) for a in ros_args]
            done, _took = run([str(BIN / program), "--ros-args", *args], dom, tmp_path)
            lines = done.stderr.strip().splitlines()
            assert done.returncode == 2 and len(lines) == 1, (case, done.stderr)
            assert lines[0].startswith(f"{program}: error: ") and names in lines[0], (case, lines[0])
            assert "/project/src" not in lines[0] and "lexeme" not in lines[0], (case, lines[0])


@pytest.mark.parametrize("tool", [["biped_echo"], ["torque_pub", "1", "2", "--rate", "10", "--wait", "60"]],
                         ids=["biped_echo", "torque_pub"])
def test_sigterm_stops_a_tool_without_a_traceback(tool, tmp_path):
    with ros_domain() as dom, start_node(None, dom, executable=tool[0], extra_args=tool[1:],
                                         log_path=tmp_path / "tool.log") as proc, Client(dom) as c:
        # its node up, then a while in its loop (a SIGTERM while rclpy builds the node is not covered yet)
        c.wait_for_node(tool[0], proc=proc)
        time.sleep(1.0)
        assert proc.alive, proc.output()
        code = proc.stop()
    assert code == 0, proc.output()
    assert "Traceback" not in proc.output() and "ExternalShutdownException" not in proc.output(), proc.output()


def test_echo_into_head_ends_quietly(tmp_path):
    """``biped_echo joint_states | head -n 3``: head closes the pipe after three lines."""
    with ros_domain() as dom, start_node({"duration": 30.0, "record": False}, dom,
                                         log_path=tmp_path / "node.log") as node:
        done, took = run(["sh", "-c", f"'{BIN / 'biped_echo'}' joint_states --timeout 40 | head -n 3"], dom,
                         tmp_path, timeout=40.0)
        assert node.alive, node.output()     # the echo ended on the closed pipe, not with the run
    assert len(done.stdout.splitlines()) == 3 and "joint_states" in done.stdout, done.stdout
    assert "Traceback" not in done.stderr and "BrokenPipe" not in done.stderr, done.stderr
    assert done.stderr == "", done.stderr


@pytest.mark.parametrize("program", sorted(NODES))
def test_a_stop_signal_during_start_up_is_one_line(program, tmp_path):
    """Ctrl-C in the node's first half second (its imports) printed a KeyboardInterrupt traceback, and
    SIGTERM or SIGHUP killed it without a word (exit -15). Now one line and 128 + the signal."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        with ros_domain() as dom:
            args = ["--ros-args", "-p", "record:=false"] if program == "sim_node" else []   # (walk_controller has no
            proc = subprocess.Popen([str(BIN / program), *args], env=ros_env(dom),              # `record`)
                                    stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                    text=True)
            time.sleep(0.15)        # inside the imports (0.3-0.6 s here)
            proc.send_signal(sig)
            out, _ = proc.communicate(timeout=20)
        assert "Traceback" not in out, out
        if f"{sig.name}: shutting down" in out:     # a fast machine: the node was up already; it said so
            assert proc.returncode == 0, out
            continue
        assert proc.returncode == 128 + sig, (sig.name, proc.returncode, out)
        assert out.strip() == (f"{program}: {sig.name} during start-up: stopped before it ran anything (nothing was "
                               "simulated, sent or recorded)"), out
