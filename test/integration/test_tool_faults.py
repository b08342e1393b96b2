"""Faults and bad input around the command-line tools and the bags (issue 18, items 2, 7, 9, 10, 11, 12
and the one place for errors, biped_sim.config.command_errors): one clear line or a quiet exit, never a
Python traceback, never a changed or lost bag. Real processes, real files; the nodes over DDS.
(test_faults.py holds the node-side cases.)"""
import os
import shutil
import signal
import struct
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_faults import run  # noqa: E402
from test_recorder import count_complete, read_all, start_recording, writer_pid  # noqa: E402

from ros_helpers import BIN, ros_domain, start_node  # noqa: E402

pytest.importorskip("rclpy")
from biped_sim.cli import COMMANDS  # noqa: E402


def biped_sim(*args, timeout=120.0, cwd=None):
    return subprocess.run([str(BIN / "biped-sim"), *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, cwd=cwd, stdin=subprocess.DEVNULL)


def one_error_line(done, program):
    """The command failed with exactly one line on stderr, ``PROGRAM: error: ...``, and no traceback."""
    assert done.returncode != 0, done.stdout + done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{program}: error: "), done.stderr
    return lines[0]


@pytest.fixture(scope="module")
def whole_bag(tmp_path_factory):
    """A complete bag of 0.5 s of the walk scene, recorded once (tests copy it)."""
    out = tmp_path_factory.mktemp("whole")
    done = biped_sim("simulate", "--scene", "walk", "--duration", "0.5", "--record", out)
    assert done.returncode == 0, done.stdout + done.stderr
    return next(out.glob("walk-*"))


def copy_bag(bag, where):
    dst = where / bag.name
    shutil.copytree(bag, dst)
    return dst, dst / f"{bag.name}_0.mcap"


def cut_before_summary(mcap):
    """Cut an MCAP file where its summary starts (what a killed writer leaves: every chunk, no end)."""
    data = mcap.read_bytes()
    _op, _len, summary_start, _offsets, _crc = struct.unpack("<BQQQI", data[-37:-8])
    mcap.write_bytes(data[:summary_start])
    (mcap.parent / "metadata.yaml").unlink(missing_ok=True)
    return summary_start


def foreign_bag(path):
    """An MCAP file of another program: one std_msgs/String topic, no biped_sim record."""
    from mcap.writer import Writer
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="another program")
        schema = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        channel = w.register_channel("/chatter", "cdr", schema)
        for i in range(5):
            text = f"hello {i}".encode() + b"\0"
            w.add_message(channel, log_time=i * 10**8, publish_time=i * 10**8,
                          data=b"\0\1\0\0" + struct.pack("<I", len(text)) + text)
        w.finish()
    return path


def test_recover_refuses_a_complete_bag_and_changes_nothing(whole_bag, tmp_path):
    bag, mcap = copy_bag(whole_bag, tmp_path)
    before = mcap.read_bytes()
    line = one_error_line(biped_sim("recover", bag), "biped-sim recover")
    assert "nothing to recover" in line and "complete" in line, line
    assert mcap.read_bytes() == before and sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", mcap.name]


def test_recover_never_overwrites_a_kept_original(whole_bag, tmp_path):
    bag, mcap = copy_bag(whole_bag, tmp_path)
    cut_before_summary(mcap)
    first_cut = mcap.read_bytes()
    done = biped_sim("recover", bag)
    assert done.returncode == 0, done.stdout + done.stderr
    kept = bag / f"{mcap.name}.truncated"
    assert kept.read_bytes() == first_cut
    recovered = read_all(bag)
    # run again on the recovered bag, or on the kept original: refused, nothing touched
    metadata = (bag / "metadata.yaml").read_bytes()
    one_error_line(biped_sim("recover", bag), "biped-sim recover")
    assert "give the bag directory" in one_error_line(biped_sim("recover", kept), "biped-sim recover")
    assert kept.read_bytes() == first_cut and read_all(bag) == recovered
    assert (bag / "metadata.yaml").read_bytes() == metadata
    # the bag cut again (another kill of a recording into the same folder): a new free name for its original
    cut_before_summary(mcap)
    second_cut = mcap.read_bytes()
    done = biped_sim("recover", bag)
    assert done.returncode == 0, done.stdout + done.stderr
    assert kept.read_bytes() == first_cut and (bag / f"{mcap.name}.truncated.1").read_bytes() == second_cut
    assert f"{mcap.name}.truncated.1" in done.stdout and read_all(bag) == recovered


@pytest.mark.parametrize("content", [b"", b"\x00garbage" * 40, b"\x89MCAP0\r\n\x01\x02"],
                         ids=["empty", "garbage", "cut_to_10_bytes"])
def test_recover_refuses_a_file_that_is_not_mcap_or_holds_no_message(content, tmp_path):
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "bag_0.mcap").write_bytes(content)
    line = one_error_line(biped_sim("recover", bag), "biped-sim recover")
    assert ("not an MCAP file" in line) if content[:1] != b"\x89" else ("nothing to recover" in line), line
    assert [p.name for p in bag.iterdir()] == ["bag_0.mcap"] and (bag / "bag_0.mcap").read_bytes() == content


def test_recover_refuses_a_bag_being_recorded_and_the_recording_ends_whole(tmp_path):
    proc, bag = start_recording(tmp_path)        # biped-sim simulate --record, some chunks on disk
    try:
        line = one_error_line(biped_sim("recover", bag), "biped-sim recover")
        assert "being recorded right now" in line, line
        assert sorted(p.name for p in bag.iterdir()) == [f"{bag.name}_0.mcap"]      # not renamed
        looked = biped_sim("inspect", bag, "--no-png")
        assert looked.returncode == 0 and "BEING RECORDED right now" in looked.stdout, looked.stdout + looked.stderr
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(60) == 143
    got = read_all(bag)                           # metadata.yaml counts what the file holds
    assert got["/joint_states"] >= 300
    # the writer's lock went with the writer: a complete bag now, refused as such
    assert "nothing to recover" in one_error_line(biped_sim("recover", bag), "biped-sim recover")


def test_recover_takes_a_bag_whose_writer_was_killed(tmp_path):
    # the kernel releases a dead writer's lock: its bag is recoverable (test_recorder checks the content)
    proc, bag = start_recording(tmp_path)
    os.kill(writer_pid(proc.pid), signal.SIGKILL)
    proc.kill()
    proc.wait(10)
    kept, _chunks = count_complete(bag / f"{bag.name}_0.mcap")
    done = biped_sim("recover", bag)
    assert done.returncode == 0 and f"recovered {kept} messages" in done.stdout, done.stdout + done.stderr


@pytest.mark.parametrize("command", ["inspect", "resim", "replay"])
@pytest.mark.parametrize("content", [b"", b"\x00garbage" * 40, b"MCAP"], ids=["empty", "garbage", "4_bytes"])
def test_bag_tools_refuse_a_file_that_is_not_mcap_in_one_line(command, content, tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(content)
    line = one_error_line(biped_sim(command, bad), f"biped-sim {command}")
    assert "is not an MCAP file" in line and "biped_sim" not in line.split("error:")[1].split("(")[0], line


@pytest.mark.parametrize("command", ["inspect", "resim", "replay"])
def test_bag_tools_say_a_file_cut_to_a_few_bytes_holds_nothing(command, tmp_path):
    bad = tmp_path / "cut.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n\x01\x02")
    line = one_error_line(biped_sim(command, bad), f"biped-sim {command}")
    assert "cut short at 10 bytes" in line and "not recorded by biped_sim" not in line, line


def test_inspect_says_a_bag_is_cut_short_and_to_recover_it(whole_bag, tmp_path):
    bag, mcap = copy_bag(whole_bag, tmp_path)
    whole = biped_sim("inspect", bag, "--no-png")
    assert whole.returncode == 0 and "CUT SHORT" not in whole.stdout, whole.stdout + whole.stderr
    cut_before_summary(mcap)
    done = biped_sim("inspect", bag, "--no-png")
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stdout + done.stderr
    assert "CUT SHORT" in done.stdout and f"biped-sim recover {bag}" in done.stdout, done.stdout
    resim = biped_sim("resim", bag)
    assert resim.returncode == 0 and "cut short" in resim.stdout, resim.stdout + resim.stderr
    replay = biped_sim("replay", bag, "--list")
    assert replay.returncode == 0 and "/joint_states" in replay.stdout, replay.stdout + replay.stderr
    assert "cut short" in replay.stderr and "biped-sim recover" in replay.stderr, replay.stderr


def test_a_bag_of_another_program_is_announced_or_refused(tmp_path):
    bag = foreign_bag(tmp_path / "chatter.mcap")
    done = biped_sim("inspect", bag)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stdout + done.stderr
    assert "NOT RECORDED BY biped_sim" in done.stdout and "/chatter" in done.stdout, done.stdout
    assert "figure      none" in done.stdout and not (tmp_path / "chatter.png").exists()
    line = one_error_line(biped_sim("resim", bag), "biped-sim resim")
    assert "not recorded by biped_sim" in line, line
    line = one_error_line(biped_sim("recover", bag), "biped-sim recover")
    assert "nothing to recover" in line, line


def test_inspect_refuses_bad_frames_and_a_missing_png_folder(whole_bag, tmp_path):
    done = biped_sim("inspect", whole_bag, "--frames", "0")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last == "biped-sim inspect: error: argument --frames: must be at least 1, got 0", done.stderr
    line = one_error_line(biped_sim("inspect", whole_bag, "--png", tmp_path / "no" / "such.png"), "biped-sim inspect")
    assert f"the folder {tmp_path / 'no'} does not exist" in line, line


def bad_inputs(tmp_path):
    """A bad input for every sub-command of biped-sim (errors each meets at once)."""
    a_file = tmp_path / "a_file"
    a_file.write_text("not a folder")
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"\x00garbage" * 40)
    empty_bag = tmp_path / "empty_bag"
    empty_bag.mkdir()
    (empty_bag / "empty_bag_0.mcap").write_bytes(b"")
    return {
        "simulate": (["--scene", "walk", "--duration", "0.1", "--record", a_file / "bags"], "Not a directory"),
        "accuracy": (["--quick", "--out", a_file / "out"], "Not a directory"),
        "stability": (["--case", "no_such_case"], "unknown case"),
        "gait": (["--scene", "no_such_scene"], "unknown scene"),
        "sweep": (["walk", "--set", "no_such=1", "-o", tmp_path / "s.csv"], "unknown override"),
        "basin": (["walk", "-o", a_file / "b.csv"], "does not exist"),
        "resim": ([garbage], "not an MCAP file"),
        "inspect": ([tmp_path / "no_such_bag"], "no bag at"),
        "recover": ([empty_bag], "not an MCAP file"),
        "replay": ([garbage], "not an MCAP file"),
        "animate": ([garbage, "-o", tmp_path / "x.gif"], "not an MCAP file"),
    }


def test_every_biped_sim_command_answers_bad_input_with_one_line(tmp_path):
    cases = bad_inputs(tmp_path)
    assert set(cases) == set(COMMANDS), "give every new sub-command a bad input here"
    for command, (args, expected) in cases.items():
        line = one_error_line(biped_sim(command, *args, timeout=60), f"biped-sim {command}")
        assert expected in line, (command, line)


def test_an_unexpected_error_is_one_line_saying_it_is_a_bug(tmp_path):
    # a bug, made by a sitecustomize that breaks load_scene with a TypeError; BIPED_SIM_DEBUG=1 shows the
    # traceback as well
    (tmp_path / "sitecustomize.py").write_text(
        "import biped_sim.config.scenes as s\n"
        "def broken(*a, **k):\n    raise TypeError('a bug')\n"
        "s.load_scene = broken\n")
    env = dict(os.environ, PYTHONPATH=str(tmp_path))
    argv = [str(BIN / "biped-sim"), "gait", "--scene", "walk"]
    done = subprocess.run(argv, capture_output=True, text=True, env=env, timeout=60)
    line = one_error_line(done, "biped-sim gait")
    assert "unexpected TypeError: a bug" in line and "this is a bug" in line and "BIPED_SIM_DEBUG=1" in line, line
    done = subprocess.run(argv, capture_output=True, text=True, env=dict(env, BIPED_SIM_DEBUG="1"), timeout=60)
    assert done.returncode == 1 and "Traceback" in done.stderr and "TypeError: a bug" in done.stderr


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_simulate_record_cut_by_a_signal_says_interrupted_and_closes_its_bag(signum, tmp_path):
    proc, bag = start_recording(tmp_path)
    proc.send_signal(signum)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signum, out
    assert "Traceback" not in out and "KeyboardInterrupt" not in out, out
    status = next(ln for ln in out.splitlines() if ln.strip().startswith("status"))
    assert "interrupted" in status and signal.Signals(signum).name in status and "completed" not in status, status
    assert read_all(bag)["/joint_states"] >= 300


def test_make_demo_names_the_cause_of_an_os_error_and_does_not_fall_back(tmp_path):
    bags = tmp_path / "bags"
    (bags / "demo-logs" / "sim_node.log").mkdir(parents=True)      # a log file that cannot be opened
    with ros_domain() as dom:
        done, _took = run([sys.executable, "-m", "biped_sim.cli.demo", "--bag-dir", str(bags)], dom, tmp_path,
                          timeout=120.0)
    line = one_error_line(done, "make demo")
    assert f"{bags / 'demo-logs' / 'sim_node.log'}: Is a directory" in line, line
    assert "generator" not in done.stdout + done.stderr and "falling back" not in done.stdout, done.stdout
    assert sorted(p.name for p in bags.iterdir()) == ["demo-logs"]     # no bag: nothing ran


def test_torque_pub_expression_undefined_at_t0_is_one_line(tmp_path):
    with ros_domain() as dom:
        done, _took = run([str(BIN / "torque_pub"), "--expr", "1/t", "0"], dom, tmp_path)
    line = one_error_line(done, "torque_pub")
    assert "'1/t' failed at t = 0 s" in line and "division by zero" in line, line


def test_torque_pub_takes_negative_numbers_and_stops_when_a_lockstep_run_ends(tmp_path):
    with ros_domain() as dom, start_node({"time_mode": "lockstep", "duration": 0.2, "record": False}, dom,
                                         log_path=tmp_path / "node.log") as node:
        done, _took = run([str(BIN / "torque_pub"), "5e-1", "-5e-1", "--lockstep", "--wait", "30"], dom, tmp_path,
                          timeout=90.0)
        assert done.returncode == 0, done.stdout + done.stderr
        assert "run has ended (biped_sim/run: completed)" in done.stderr, done.stderr
        assert "Traceback" not in done.stderr
        sent = int(done.stdout.split("published ")[1].split()[0])
        assert sent >= 200, done.stdout                 # one command a period of the 0.2 s run at least
        node.stop()
    assert "'rejected': 0" in node.output(), node.output()      # -5e-1 was taken as the torque it is


# -- issue 34, item 3: the bag's folder becomes unwritable before the close ------------------------------------
READ_ONLY_BEFORE_CLOSE = """
{bin}/biped-sim simulate --scene walk --duration 60 --record {bags} > {out} 2> {err} &
pid=$!
for i in $(seq 300); do
  sleep 0.05; f=$(ls {bags}/*/*.mcap 2>/dev/null) && [ "$(stat -c %s "$f")" -gt 50000 ] && break
done
d=$(ls -d {bags}/*)
mount --bind "$d" "$d" && mount -o remount,ro,bind "$d" || {{ kill -KILL $pid; exit 97; }}
touch "$d/probe" 2>/dev/null && {{ kill -KILL $pid; exit 98; }}
kill -TERM $pid
wait $pid
"""


def test_a_bag_folder_made_read_only_before_the_close_leaves_a_bag_recover_completes(tmp_path):
    """The bag's folder becomes read-only during ``simulate --record`` (a read-only bind mount over it
    in the run's own mount namespace, ``unshare -rm``: also as root); then SIGTERM closes the bag. The
    MCAP, written through its open file, is complete; metadata.yaml cannot be created. The run says so
    in one line and names ``biped-sim recover``, which (the folder writable again, outside the
    namespace) writes metadata.yaml: rosbags reads every message. Before, recover refused the bag
    ("nothing to recover") and rosbags could not open it."""
    probe = subprocess.run(["unshare", "-rm", "sh", "-c", f"mount --bind {tmp_path} {tmp_path}"],
                           capture_output=True, text=True, timeout=20)
    if probe.returncode != 0:
        pytest.skip(f"unshare -rm cannot bind-mount here: {probe.stderr.strip()}")
    bags, out, err = tmp_path / "bags", tmp_path / "sim.out", tmp_path / "sim.err"
    bags.mkdir()
    script = READ_ONLY_BEFORE_CLOSE.format(bin=BIN, bags=bags, out=out, err=err)
    done = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True, timeout=120,
                          stdin=subprocess.DEVNULL)
    assert done.returncode == 1, (done.returncode, done.stdout, done.stderr, err.read_text())
    bag = next(bags.iterdir())
    line = one_error_line(subprocess.CompletedProcess([], 1, "", err.read_text()), "biped-sim simulate")
    assert "MCAP is complete but its metadata.yaml could not be written (Read-only file system)" in line, line
    assert f"'biped-sim recover {bag}'" in line, line
    assert sorted(p.name for p in bag.iterdir()) == [f"{bag.name}_0.mcap"]     # no metadata.yaml, no .tmp
    mcap_before = (bag / f"{bag.name}_0.mcap").read_bytes()
    rec = biped_sim("recover", bag)
    assert rec.returncode == 0 and "is complete; wrote the bag's missing metadata.yaml" in rec.stdout, \
        rec.stdout + rec.stderr
    assert (bag / f"{bag.name}_0.mcap").read_bytes() == mcap_before               # the MCAP untouched
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader
    with open(bag / f"{bag.name}_0.mcap", "rb") as f:
        in_file = make_reader(f).get_summary().statistics.message_count
    with Reader(bag) as reader:
        assert reader.message_count == in_file == sum(1 for _ in reader.messages()) > 1000


def test_a_scene_file_that_is_bad_yaml_or_a_folder_is_one_line(tmp_path):
    """PyYAML's five-line error (what it parsed, the line copied with a caret, the problem) came through
    as five lines; a folder given as the scene was said not to exist."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("biped_sim:\n  ros__parameters:\n    duration: [1.0\n")
    line = one_error_line(biped_sim("simulate", "--scene", bad), "biped-sim simulate")
    assert f"scene {bad}: not valid YAML at line 4, column 1: expected ',' or ']'" in line, line
    assert "started at line 3, column 15" in line, line
    line = one_error_line(biped_sim("simulate", "--scene", tmp_path), "biped-sim simulate")
    assert "is a folder: give a .yaml file" in line, line
