"""Sweeps (issue 17): load_scene's overrides, biped_sim.sweep on the process pool, biped-sim sweep.

The rows must be the single runs, bit for bit, whatever the number of workers; a bad name or value
is refused before any run; failing runs are rows. The Ray backend's agreement is
test/integration/test_sweep_ray.py.
"""
import contextlib
import csv
import errno
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import biped_sim as bs
from biped_sim.analysis.sweep import OUTCOME, SweepInterrupted, grid_runs, write_csv
from biped_sim.cli import main
from biped_sim.cli.sweep import parse_set

CLI = str(Path(sys.executable).parent / "biped-sim")
ROOT = Path(__file__).resolve().parents[2]
GRID = {"kp": [80.0, 400.0], "step_angle": [0.15, 0.25]}
DURATION = 0.6


# ---- load_scene(name, overrides=...) ----

def test_overrides_land_where_the_scene_file_would_put_them():
    s = bs.load_scene("walk", overrides={"kp": 300, "initial_q[4]": 0.2, "duration": 2.0,
                                         "walk_controller.torque_limit": 300.0, "biped_sim.torque_limit": 600.0})
    assert s.controller_params["kp"] == 300.0 and s.params["duration"] == 2.0
    assert s.params["initial_q"][4] == 0.2
    assert s.params["initial_q"][:4] == bs.load_scene("walk").params["initial_q"][:4]
    assert s.controller_params["torque_limit"] == 300.0 and s.params["torque_limit"] == 600.0
    # slope is in both sections and must match: a bare slope sets both, a qualified one only its own
    s = bs.load_scene("walk", overrides={"slope": 0.02})
    assert s.params["slope"] == s.controller_params["slope"] == 0.02
    s = bs.load_scene("walk", overrides={"biped_sim.slope": 0.02, "walk_controller.slope": 0.02})
    assert s.params["slope"] == s.controller_params["slope"] == 0.02
    assert bs.load_scene("passive", overrides={"slope": 0.01}).params["slope"] == 0.01   # no controller section
    assert bs.load_scene("walk", overrides={}).params == bs.load_scene("walk").params


@pytest.mark.parametrize("overrides, message", [
    ({"kpp": 1.0}, r"unknown override 'kpp'.*\(did you mean 'kp'\?\); allowed: control_period, duration"
                   r".*torso_pitch, step_angle.*initial_q\[i\]"),
    ({"walk_controller.duration": 1.0}, r"unknown override 'walk_controller.duration': no parameter 'duration' in "
                                        "section walk_controller"),
    ({"kp": "stiff"}, r"override 'kp': parameter 'kp' must be a number, got 'stiff'"),
    ({"kp": -1.0}, r"override 'kp': parameter 'kp' must be in \[0.0, 1000000.0\]"),
    ({"record": 1}, r"parameter 'record' must be true or false"),
    ({"initial_dq[1]": "x"}, r"override 'initial_dq\[1\]': parameter 'initial_dq' must hold finite numbers"),
    ({"initial_dq[5]": 0.0}, r"'initial_dq' has 5 entries \(indices 0 to 4\)"),
    ({"kp[0]": 1.0}, r"'kp' is not a list"),
    ({"torque_limit": 100.0}, r"'torque_limit' is a parameter of both sections.*biped_sim.torque_limit or "
                              "walk_controller.torque_limit"),
    ({"slope": 0.01, "biped_sim.slope": 0.01}, r"overrides 'slope' and 'biped_sim.slope' both set biped_sim.slope"),
    ({"initial_q": [0.0, 1.0, 3.0, 3.2, 0.1], "initial_q[0]": 0.0}, r"both set biped_sim.initial_q"),
    ({"walk_controller.slope": 0.02}, r"walk_controller parameter 'slope' = 0.02 differs from the simulation's"),
    ({"phases": ["stance", "hop"]}, r"'hop' is not one of"),
])
def test_a_bad_override_is_refused_as_in_a_scene_file(overrides, message):
    with pytest.raises(ValueError, match=message):
        bs.load_scene("walk", overrides=overrides)


def test_a_controller_parameter_needs_a_controller_section():
    with pytest.raises(ValueError, match="override 'kp': this scene has no walk_controller section"):
        bs.load_scene("passive", overrides={"kp": 100.0})


# ---- the grid ----

def test_the_runs_are_the_product_row_major_over_the_names_in_order():
    names, columns, runs = grid_runs({"b": [1, 2], "a": np.array([0.5, 0.25, 0.0])})
    assert names == ["b", "a"] and columns[1] == [0.5, 0.25, 0.0] and type(columns[1][0]) is float
    assert [(r["b"], r["a"]) for r in runs] == [(1, 0.5), (1, 0.25), (1, 0.0), (2, 0.5), (2, 0.25), (2, 0.0)]


def test_the_command_line_values():
    assert parse_set("kp=50:150:3") == ("kp", [50.0, 100.0, 150.0])
    assert parse_set("initial_dq[2]=0.5, 1,2e-1") == ("initial_dq[2]", [0.5, 1, 0.2])
    assert parse_set("record=true,false") == ("record", [True, False])
    assert parse_set("x=1:2:1") == ("x", [1.0])
    for bad in ("kp", "kp=", "kp=1:2", "kp=1:2:x", "kp=1:2:0", "=1,2"):
        with pytest.raises(ValueError, match="--set"):
            parse_set(bad)


def test_a_bracketed_list_of_values_is_one_line_that_shows_the_form_to_use(tmp_path, capsys):
    """``--set duration=[1.0,2.0]`` was split at its comma: 'must be a number, got '[1.0''."""
    out = tmp_path / "rows.csv"
    assert main(["sweep", "walk", "--set", "duration=[1.0,2.0]", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "got '[1.0'" not in err, err
    assert "give the values without brackets" in err and "--set duration=1.0,2.0" in err, err
    assert not out.exists()


# ---- bs.sweep ----

def _outcome(rows):
    """The rows without their wall times (the one column that is not the run's)."""
    return [{k: v for k, v in r.items() if k != "wall_time"} for r in rows]


def test_rows_are_the_single_runs_bit_for_bit_and_workers_do_not_change_them():
    calls = []
    rows2 = bs.sweep("walk", GRID, duration=DURATION, workers=2, progress=lambda d, n, r: calls.append((d, n)))
    rows1 = bs.sweep("walk", GRID, duration=DURATION, workers=1)
    assert calls == [(i, 4) for i in range(1, 5)]
    assert _outcome(rows1) == _outcome(rows2)
    assert [(r["index"], r["kp"], r["step_angle"]) for r in rows2] == [
        (0, 80.0, 0.15), (1, 80.0, 0.25), (2, 400.0, 0.15), (3, 400.0, 0.25)]
    for row in rows2:
        assert list(row) == ["index", "kp", "step_angle", *OUTCOME]
        s = bs.load_scene("walk", overrides={"kp": row["kp"], "step_angle": row["step_angle"]})
        r = s.simulate(t_final=DURATION)
        assert row["status"] == r.status == "completed" and row["message"] == r.message
        assert row["q_end"] == r.q[-1].tolist() and row["dq_end"] == r.dq[-1].tolist()   # ==: the same bits
        assert row["impacts"] == len(r.impacts) >= 1 and row["t_end"] == r.t[-1] == DURATION
        assert row["x_end"] == r.q[-1][0] - r.q[0][0] > 0.2
        assert row["mean_speed"] == row["x_end"] / DURATION
        assert row["energy_residual"] == r.stats["max_energy_balance_residual"] < 1e-6
        assert row["drift"] == max(r.stats["max_constraint_drift_position"], r.stats["max_constraint_drift_velocity"])
        assert row["wall_time"] > 0
    assert len({tuple(r["q_end"]) for r in rows2}) == 4   # the parameters did reach the runs


def test_failing_runs_are_rows_and_the_sweep_completes():
    # passive falls when run past 0.5 s (back onto its rear foot, rocking on both feet until the impacts
    # accumulate: the run stops as Zeno); a moving stance foot is refused by the engine when the run starts
    rows = bs.sweep("passive", {"initial_dq[0]": [0.0, 0.3], "duration": [0.5, 2.0]}, workers=2)
    assert [(r["status"], r["impacts"]) for r in rows][:2] == [("completed", 1), ("stopped", 5)]
    assert "the impacts accumulate (Zeno behaviour)" in rows[1]["message"]
    for r in rows[2:]:
        assert r["status"] == "error" and "ValueError: initial state: the stance foot (leg 1) moves" in r["message"]
        assert math.isnan(r["x_end"]) and r["impacts"] == 0


@pytest.mark.parametrize("kwargs, message", [
    (dict(grid={"kpp": [1.0]}), "unknown override 'kpp'"),
    (dict(grid={"kp": [100.0, 200.0, "x"]}), "override 'kp': parameter 'kp' must be a number, got 'x'"),
    (dict(grid={"kp": []}), r"grid\['kp'\] is empty"),
    (dict(grid={"kp": 3.0}), r"grid\['kp'\] must be a list"),
    (dict(grid={"kp": [1.0]}, duration=-1), "duration must be a positive number"),
    (dict(grid={"kp": [1.0]}, rtoll=1e-6), r"unknown run option\(s\) \['rtoll'\]"),
    (dict(grid={"kp": [1.0]}, touchdown_rule="back"), "touchdown_rule must be 'front' or 'any'"),
    (dict(grid={"kp": [1.0]}, backend="dask"), "backend must be one of process, ray"),
    (dict(grid={"kp": [1.0]}, workers=0), "workers must be a positive integer"),
    (dict(grid={"kp": [1.0]}, scene="nowhere"), "unknown scene 'nowhere'"),
    (dict(grid={"robot": ["three_link", "rabbit"]}), "parameter 'initial_q' must have 7 entries, one for each "
                                                     "coordinate of robot 'rabbit'"),
])
def test_a_bad_sweep_is_refused_before_any_run(kwargs, message):
    calls = []
    kwargs = dict(dict(scene="walk", duration=0.1, progress=lambda *a: calls.append(a)), **kwargs)
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=message):
        bs.sweep(**kwargs)
    assert not calls and time.perf_counter() - t0 < 2.0   # no pool was started, no run made


# ---- biped-sim sweep ----

def test_the_command_writes_a_row_per_run_and_the_map(tmp_path, capsys):
    out, png = tmp_path / "gains.csv", tmp_path / "gains.png"
    assert main(["sweep", "walk", "--set", "kp=80:400:2", "--set", "step_angle=0.15,0.25", "--duration",
                 str(DURATION), "--workers", "2", "-o", str(out), "--plot", str(png)]) == 0
    with open(out) as f:
        table = list(csv.DictReader(f))
    rows = bs.sweep("walk", GRID, duration=DURATION, workers=2)
    assert len(table) == 4 and [float(t["kp"]) for t in table] == [80.0, 80.0, 400.0, 400.0]
    for t, r in zip(table, rows):   # the CSV reads back to the same bits
        assert [float(t[f"q_end[{i}]"]) for i in range(5)] == r["q_end"] and int(t["impacts"]) == r["impacts"]
        assert t["status"] == "completed" and float(t["x_end"]) == r["x_end"]
    assert png.stat().st_size > 10_000
    err = capsys.readouterr().err
    assert "[sweep] 4/4 runs (100 %), " in err and "; 0 not completed" in err


def test_a_users_mistake_is_one_line_and_exit_2(tmp_path):
    for args in (["--set", "kpx=1,2"], ["--set", "kp=1:2"], ["--set", "kp=1", "--set", "kp=2"],
                 ["--set", "kp=1", "-o", str(tmp_path / "no" / "x.csv")]):
        argv = ["sweep", "walk", *args] + ([] if "-o" in args else ["-o", str(tmp_path / "x.csv")])
        p = subprocess.run([CLI, *argv], capture_output=True, text=True)
        assert p.returncode == 2 and p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr
        assert p.stderr.startswith("biped-sim sweep: error: ")


def _ctrl_c_as_in_a_terminal():
    """The sweep's SIGINT as a terminal leaves it (default): a test run started in the background by a
    non-interactive shell would hand its children SIGINT ignored, and they would rightly ignore Ctrl-C."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_stops_the_sweep_and_writes_the_runs_done(tmp_path):
    out = tmp_path / "partial.csv"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    # runs of 100 s (about 0.3 s each): the whole sweep takes seconds, so Ctrl-C after two runs comes in
    # the middle of it (1 s runs take 3 ms now: the sweep could end before the signal arrived)
    p = subprocess.Popen([CLI, "sweep", "walk", "--set", "kp=50:500:40",
                          "--duration", "100", "--workers", "2", "-o", str(out)], stderr=subprocess.PIPE, text=True,
                         env=env, start_new_session=True, preexec_fn=_ctrl_c_as_in_a_terminal)
    seen = ""
    while "[sweep] 4/40 runs" not in seen:    # the first progress line (4 runs done): the pool is running
        ch = p.stderr.read(1)
        assert ch, seen
        seen += ch
    os.killpg(p.pid, signal.SIGINT)        # Ctrl-C reaches the terminal's whole process group
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    assert "interrupted:" in err and "Traceback" not in err
    with open(out) as f:
        table = list(csv.DictReader(f))
    assert 2 <= len(table) < 40 and all(t["status"] == "completed" for t in table)
    assert [int(t["index"]) for t in table] == sorted(int(t["index"]) for t in table)


def _children(pid):
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return out


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc to see the pool's processes")
@pytest.mark.parametrize("moment", ["fork server starts", "first worker starts"])
def test_ctrl_c_while_the_pool_starts_is_quiet(tmp_path, moment):
    """Ctrl-C the moment the fork server (which imports the engine) or the first worker appears: no
    process prints a traceback (each did: a KeyboardInterrupt inside the fork server's import, or a
    worker not yet known to the pool, left alive to fail once its parent had gone)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    p = subprocess.Popen([CLI, "sweep", "walk", "--set", "kp=50:500:8", "--duration", "1", "--workers", "2",
                          "-o", str(tmp_path / "s.csv")], stderr=subprocess.PIPE, text=True, env=env,
                         start_new_session=True, preexec_fn=_ctrl_c_as_in_a_terminal)
    end = time.monotonic() + 60
    while True:
        assert time.monotonic() < end and p.poll() is None, "the pool never started"
        servers = _children(p.pid)
        if servers and (moment == "fork server starts" or any(_children(s) for s in servers)):
            break
        time.sleep(0.001)
    os.killpg(p.pid, signal.SIGINT)        # Ctrl-C reaches the terminal's whole process group
    _, err = p.communicate(timeout=60)
    time.sleep(1.0)                        # a worker left behind would print after its parent is gone
    assert p.returncode == 130, err
    assert "Traceback" not in err and "Error" not in err, err


def test_a_sweep_started_with_sigint_ignored_keeps_ignoring_it(tmp_path):
    """Started as by a shell's '&' (SIGINT ignored), a Ctrl-C while its pool starts (when the sweep
    holds a Ctrl-C back) neither stops it nor turns into an interruption later: it runs to the end."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    out = tmp_path / "s.csv"
    p = subprocess.Popen([CLI, "sweep", "walk", "--set", "kp=50:500:8", "--duration", "1", "--workers", "2",
                          "-o", str(out)], stderr=subprocess.PIPE, text=True, env=env, start_new_session=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    end = time.monotonic() + 60
    while not _children(p.pid):
        assert time.monotonic() < end and p.poll() is None, "the pool never started"
        time.sleep(0.001)
    os.killpg(p.pid, signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 0 and "interrupted" not in err and "Traceback" not in err, err
    with open(out) as f:
        assert len(list(csv.DictReader(f))) == 8


def test_interrupted_sweep_keeps_its_rows():
    stop = SweepInterrupted([{"index": 0}], 4)
    assert isinstance(stop, KeyboardInterrupt) and stop.rows == [{"index": 0}] and stop.total == 4


def test_the_basin_is_a_sweep_around_the_fixed_point():
    from biped_sim.analysis.basin import AXES, basin
    gait, rows = basin("walk", span=(0.2, 0.4), num=3, duration=1.0, workers=2)
    assert [(r[AXES[0]], r[AXES[1]]) for r in rows] == [(a, b) for a in (-0.2, 0.0, 0.2) for b in (-0.4, 0.0, 0.4)]
    centre = rows[4]
    assert centre["status"] == "completed" and centre["impacts"] >= 2     # z* walks
    assert centre["initial_dq"][2:] == gait.z[3:6].tolist() and centre["initial_stance_leg"] == 1
    # a row is the single run with its overrides (continuous feedback, as biped-sim gait)
    overrides = {k: centre[k] for k in ("initial_stance_leg", "initial_q", "initial_dq")}
    r = bs.load_scene("walk", overrides=overrides).simulate(hold=False, t_final=1.0)
    assert centre["q_end"] == r.q[-1].tolist()
    with pytest.raises(ValueError, match="num must be an integer >= 2"):
        basin("walk", num=1)


def test_a_scene_file_given_by_a_relative_path(tmp_path, monkeypatch):
    bs.sweep("passive", {"duration": [0.1]}, workers=1)       # the fork server starts in this directory
    (tmp_path / "mine.yaml").write_text((ROOT / "msg_configs" / "passive.yaml").read_text())
    monkeypatch.chdir(tmp_path)
    rows = bs.sweep("mine.yaml", {"duration": [0.1, 0.2]}, workers=2)
    assert [r["status"] for r in rows] == ["completed"] * 2 and rows[1]["t_end"] == 0.2


# ---- faults, round 3 (issue 34) ----

PLAIN_SCRIPT = '''
import json
import biped_sim as bs

def my_controller(t, q, dq, stance_leg):
    return [0.0, 0.0]

grid = {"kp": [80.0, 400.0], "step_angle": [0.15, 0.25]}
two = bs.sweep("walk", grid, duration=0.3, workers=2)
one = bs.sweep("walk", grid, duration=0.3, workers=1)
try:
    bs.sweep("walk", grid, duration=0.3, workers=2, controller=my_controller)
    refused = None
except ValueError as exc:
    refused = str(exc)
strip = lambda rows: [{k: v for k, v in r.items() if k != "wall_time"} for r in rows]
print(json.dumps({"statuses": [r["status"] for r in two], "same": strip(one) == strip(two), "refused": refused}))
'''


def test_a_sweep_from_a_plain_script_without_a_main_guard(tmp_path):
    """A script that calls bs.sweep at its top level (no ``if __name__ == "__main__":``): its workers
    do not run the script again (each did, and failed in its bootstrapping phase: error rows and a
    screen of RuntimeError tracebacks); the rows do not depend on the number of workers. A run
    option defined in the script, which the workers cannot import, is refused before any run."""
    script = tmp_path / "first_sweep.py"
    script.write_text(PLAIN_SCRIPT)
    p = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert p.returncode == 0 and "Traceback" not in p.stderr and "bootstrapping" not in p.stderr, p.stderr
    result = json.loads(p.stdout.splitlines()[-1])
    assert result["statuses"] == ["completed"] * 4 and result["same"]
    assert result["refused"] == ("run option 'controller': my_controller is defined in the script (__main__), which "
                                 "the workers do not run: define it in a module of its own and import it from there")


def _descendants(pid):
    found, todo = [], [pid]
    while todo:
        kids = _children(todo.pop())
        found += kids
        todo += kids
    return found


def _alive(pid):
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except (OSError, IndexError):
        return False


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc to see the pool's processes")
@pytest.mark.parametrize("signum, to_group", [(signal.SIGTERM, True), (signal.SIGHUP, False), (signal.SIGKILL, False)])
def test_a_sweep_ended_by_a_signal_keeps_its_rows_and_leaves_no_process(tmp_path, signum, to_group):
    """SIGTERM (as ``timeout``, a batch scheduler or systemd send it: to the whole process group) and
    SIGHUP (a closed terminal) end the sweep as Ctrl-C does: the runs done in the CSV, one line, exit
    128 + the signal (SIGTERM left no CSV at all). Whatever ended it, SIGKILL included, neither the
    fork server nor a worker outlives it (they ran on for ever, re-parented to init)."""
    out = tmp_path / "partial.csv"
    p = subprocess.Popen([CLI, "sweep", "walk", "--set", "kp=50:500:40", "--duration", "100", "--workers", "2",
                          "-o", str(out)], stderr=subprocess.PIPE, text=True,
                         env=dict(os.environ, PYTHONUNBUFFERED="1"), start_new_session=True)
    seen = ""
    while "[sweep] 4/40 runs" not in seen:    # the first progress line (4 runs done): the pool is running
        ch = p.stderr.read(1)
        assert ch, seen
        seen += ch
    pool = _descendants(p.pid)
    assert len(pool) >= 3, pool            # the fork server and two workers (and the resource tracker)
    if to_group:
        os.killpg(p.pid, signum)
    else:
        os.kill(p.pid, signum)
    _, err = p.communicate(timeout=60)
    end = time.monotonic() + 10
    while any(_alive(pid) for pid in pool) and time.monotonic() < end:
        time.sleep(0.05)
    assert not [pid for pid in pool if _alive(pid)], "processes of the sweep left behind"
    if signum == signal.SIGKILL:
        assert p.returncode == -signal.SIGKILL
        return
    assert p.returncode == 128 + signum, err
    assert f"stopped by {signum.name}: " in err and "Traceback" not in err, err
    with open(out) as f:
        table = list(csv.DictReader(f))
    assert 2 <= len(table) < 40 and all(t["status"] == "completed" for t in table)
    assert err.strip().splitlines()[-1].endswith(f"{len(table)} of 40 runs done, written to {out}")


@pytest.fixture
def small_tmpfs(tmp_path):
    """A folder on a tmpfs of 64 KiB of our own (mount needs root): a disk to fill or make read-only."""
    mounted = []

    def mount(name, *options):
        folder = tmp_path / name
        folder.mkdir()
        p = subprocess.run(["mount", "-t", "tmpfs", "-o", ",".join(["size=64k", *options]), "tmpfs", str(folder)],
                           capture_output=True, text=True)
        if p.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here (needs root): {p.stderr.strip()}")
        mounted.append(folder)
        return folder

    yield mount
    for folder in mounted:
        subprocess.run(["umount", str(folder)], check=False)


def test_a_result_that_cannot_be_written_loses_nothing(tmp_path, small_tmpfs):
    """A read-only destination is refused before any run (found after every run, it lost them all).
    On a full disk the CSV is the old file, whole, not one cut mid-row; the rows are kept in a file
    in the temp folder, and the one line names the CSV, the reason and that file. /dev/full (ENOSPC
    on every write) the same, from Python."""
    env = dict(os.environ, TMPDIR=str(tmp_path))
    read_only = small_tmpfs("ro", "ro")
    p = subprocess.run([CLI, "sweep", "walk", "--set", "kp=80,400", "--duration", "0.3", "-o",
                        str(read_only / "gains.csv")], capture_output=True, text=True, env=env, timeout=60)
    assert p.returncode == 1 and "[sweep]" not in p.stderr, p.stderr       # no run was made
    assert p.stderr == (f"biped-sim sweep: error: {read_only / 'gains.csv'}: Read-only file system; "
                        "choose a folder on a writable file system\n")

    full = small_tmpfs("full")
    (full / "gains.csv").write_text("index,kp\n")                        # the result of an earlier sweep
    with open(full / "filler", "wb", buffering=0) as f, contextlib.suppress(OSError):   # the disk, full
        while True:
            f.write(b"\0" * 4096)
    p = subprocess.run([CLI, "sweep", "walk", "--set", "kp=80,400", "--set", "step_angle=0.15,0.25", "--duration",
                        "0.3", "--workers", "2", "--no-progress", "-o", str(full / "gains.csv")],
                       capture_output=True, text=True, env=env, timeout=120)
    assert p.returncode == 1 and p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr
    kept = sorted(tmp_path.glob("gains-*.csv"))
    assert len(kept) == 1
    assert p.stderr == (f"biped-sim sweep: error: {full / 'gains.csv'}: No space left on device; the 4 rows are kept "
                        f"in {kept[0]}; free some disk space or choose another disk\n")
    assert (full / "gains.csv").read_text() == "index,kp\n"              # the old file, whole
    assert sorted(f.name for f in full.iterdir()) == ["filler", "gains.csv"]   # no half-written file beside it
    with open(kept[0]) as f:
        table = list(csv.DictReader(f))
    assert [int(t["index"]) for t in table] == [0, 1, 2, 3] and all(t["status"] == "completed" for t in table)

    rows = [dict(index=0, kp=1.0, **dict({c: 0.0 for c in OUTCOME}, q_end=[0.0] * 5, dq_end=[0.0] * 5))]
    with pytest.raises(OSError, match=r"No space left on device; the 1 rows are kept in .*/full-\w+\.csv") as caught:
        write_csv(rows, ["kp"], "/dev/full")
    assert caught.value.filename == "/dev/full" and caught.value.errno == errno.ENOSPC


KILLING_SCRIPT = '''
import json, os, signal, sys
from multiprocessing import forkserver
from pathlib import Path
import biped_sim as bs

def children(pid):
    return [int(c) for t in Path(f"/proc/{pid}/task").glob("*") for c in (t / "children").read_text().split()]

killed = []
def kill_once(victim):
    def progress(done, total, row):
        if not killed:
            server = forkserver._forkserver._forkserver_pid
            pid = server if victim == "server" else children(server)[0]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)
    return progress

out = {}
for victim in ("worker", "server"):
    killed.clear()
    rows = bs.sweep("walk", {"kp": [float(k) for k in range(50, 650, 50)]}, duration=100.0, workers=2,
                    progress=kill_once(victim))
    out[victim] = {"pid": killed[0], "errors": sorted({r["message"] for r in rows if r["status"] == "error"}),
                   "completed": sum(r["status"] == "completed" for r in rows)}
print(json.dumps(out))
'''


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc to find the pool's processes")
def test_a_run_lost_with_its_worker_says_which_process_ended_and_how(tmp_path):
    """A worker, then the fork server, killed (SIGKILL: what the out-of-memory killer sends) during a
    sweep: the runs in flight are error rows naming the pid and the signal (they blamed "a crash or
    the out-of-memory killer", no process named), and the sweep goes on with a new pool."""
    script = tmp_path / "kill_a_worker.py"
    script.write_text(KILLING_SCRIPT)
    p = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout.splitlines()[-1])
    worker, server = out["worker"], out["server"]
    assert worker["errors"] == [f"during this run or one beside it, worker pid {worker['pid']} was killed by SIGKILL "
                                "(the out-of-memory killer sends it)"], worker
    assert server["errors"] == [f"during this run or one beside it, the fork server (pid {server['pid']}) was killed "
                                "by SIGKILL (the out-of-memory killer sends it), and its workers with it"], server
    assert worker["completed"] >= 4 and server["completed"] >= 4   # the runs not in flight ran on a new pool


def test_a_grid_too_large_says_how_large_and_asks_for_yes(tmp_path):
    """101,000 runs: one line with the number of runs and about how long they would take, and no run
    without --yes (such a grid said nothing for minutes)."""
    out = tmp_path / "big.csv"
    t0 = time.perf_counter()
    p = subprocess.run([CLI, "sweep", "walk", "--set", "kp=1:1000:1010", "--set", "kd=1:100:100", "--duration", "1",
                        "--workers", "2", "-o", str(out)], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and p.stderr.count("\n") == 1, p.stderr
    assert re.fullmatch(r"biped-sim sweep: error: 101,000 runs of walk, 1 s each: about \d+ (s|min|h) on 2 workers "
                        r"\(a run took \d+ ms here\); more than 100,000: add --yes to start them\n", p.stderr), p.stderr
    assert not out.exists() and time.perf_counter() - t0 < 30
