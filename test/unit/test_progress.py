"""The progress of long commands in a log: lines now and then, never a carriage return (config.progress).

A hand-written bar wrote ``\\r[1/256] ... ~866 s left   \\r[2/256] ...`` into a log, which kept it as
one ever longer line."""
import io
import subprocess
import sys

from biped_sim.config.progress import Progress

CLI = [sys.executable, "-c", "import sys; from biped_sim.cli import main; sys.exit(main())"]


def test_progress_to_a_file_writes_a_line_every_tenth_and_no_carriage_return():
    log = io.StringIO()
    display = Progress(256, "sweep", unit="runs", stream=log)
    for done in range(1, 257):
        display.update(done, f"{done // 50} not completed")
    display.close()
    text = log.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    assert 10 <= len(lines) <= 11, text
    assert lines[-1].startswith("[sweep] 256/256 runs (100 %)") and lines[-1].endswith("; 5 not completed"), text


def test_the_last_count_reported_again_is_one_line():
    """replay reports its last message again as it ends a pass: the 100 % line was written twice."""
    log = io.StringIO()
    display = Progress(10, "replay", unit="messages", stream=log)
    for done in (5, 10, 10):
        display.update(done, "bag time 3.000 / 3.000 s")
    display.close()
    assert [line.split(" (")[0] for line in log.getvalue().splitlines()] == ["[replay] 5/10 messages",
                                                                           "[replay] 10/10 messages"]


def test_a_sweep_with_stderr_to_a_file_logs_a_few_lines(tmp_path):
    err = tmp_path / "sweep.log"
    with open(err, "w") as stderr:
        out = subprocess.run(CLI + ["sweep", "walk", "--set", "kp=100:200:30", "--duration", "0.02", "--workers", "1",
                                    "-o", str(tmp_path / "rows.csv")],
                             stdout=subprocess.PIPE, stderr=stderr, text=True, timeout=120)
    text = err.read_text()
    assert out.returncode == 0, text
    assert "\r" not in text
    progress = [line for line in text.splitlines() if line.startswith("[sweep]")]
    assert 5 <= len(progress) <= 11 and len(text.splitlines()) <= 12, text
    assert progress[-1].startswith("[sweep] 30/30 runs (100 %)"), text
