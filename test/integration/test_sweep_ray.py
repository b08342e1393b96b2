"""The Ray backend of biped_sim.sweep gives the process pool's rows (issue 17).

A local Ray (``ray.init`` with 2 CPUs, started and stopped by the sweep); a cluster is the same
code with ``ray_address``. Ray is pinned in requirements-dev.txt; without it the test skips saying so.
"""
import contextlib
import socket
import subprocess
import sys
import threading
import time

import pytest

import biped_sim as bs

GRID = {"kp": [80.0, 400.0], "step_angle": [0.15, 0.25]}


def _outcome(rows):
    return [{k: v for k, v in r.items() if k != "wall_time"} for r in rows]


def test_ray_rows_equal_the_process_pool_rows():
    pytest.importorskip("ray", reason="Ray is not installed: pip install 'biped_sim[ray]' (make test installs it)")
    ray_rows = bs.sweep("walk", GRID, duration=0.6, workers=2, backend="ray")
    pool_rows = bs.sweep("walk", GRID, duration=0.6, workers=2)
    assert _outcome(ray_rows) == _outcome(pool_rows)
    assert [r["status"] for r in ray_rows] == ["completed"] * 4


def test_ray_keeps_failed_runs_as_rows():
    pytest.importorskip("ray", reason="Ray is not installed: pip install 'biped_sim[ray]' (make test installs it)")
    rows = bs.sweep("passive", {"initial_dq[0]": [0.0, 0.3]}, duration=2.0, workers=2, backend="ray")
    # the passive robot falls back onto its rear foot and rocks until the impacts accumulate: it stops as Zeno
    assert rows[0]["status"] == "stopped" and "the impacts accumulate (Zeno behaviour)" in rows[0]["message"]
    assert rows[1]["status"] == "error" and "the stance foot (leg 1) moves" in rows[1]["message"]


def test_no_cluster_at_the_address_is_one_value_error():
    pytest.importorskip("ray", reason="Ray is not installed: pip install 'biped_sim[ray]' (make test installs it)")
    with pytest.raises(ValueError, match="no Ray cluster at 127.0.0.1:1"):
        bs.sweep("walk", {"kp": [100.0]}, duration=0.1, backend="ray", ray_address="127.0.0.1:1")


def test_something_else_at_the_address_is_one_value_error_at_once(tmp_path):
    """A web server where the Ray head should be: one line within seconds (ray.init retried it for
    minutes). Run in a process of its own, bounded, so that a hang fails the test instead of holding it."""
    pytest.importorskip("ray", reason="Ray is not installed: pip install 'biped_sim[ray]' (make test installs it)")
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()

        def answer_as_a_web_server():
            with contextlib.suppress(OSError):
                while True:
                    connection, _ = server.accept()
                    with connection:
                        connection.recv(1024)
                        connection.sendall(b"HTTP/1.0 400 Bad request\r\n\r\n")

        threading.Thread(target=answer_as_a_web_server, daemon=True).start()
        address = f"127.0.0.1:{server.getsockname()[1]}"
        code = (f"import biped_sim as bs\nbs.sweep('walk', {{'kp': [100.0]}}, duration=0.1, backend='ray', "
                f"ray_address={address!r})")
        t0 = time.perf_counter()
        try:
            p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30)
        except subprocess.TimeoutExpired:
            pytest.fail(f"the sweep waited more than 30 s for a Ray cluster at {address}")
    assert p.returncode == 1 and time.perf_counter() - t0 < 30
    assert (f"ValueError: no Ray cluster at {address}: something else listens there (it answered 'HTTP/1.0', not "
            "gRPC); give the Ray head's GCS port, 6379 by default") in p.stderr, p.stderr
