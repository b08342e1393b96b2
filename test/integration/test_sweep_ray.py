"""The Ray backend of biped_sim.sweep gives the process pool's rows (issue 17).

A local Ray (``ray.init`` with 2 CPUs, started and stopped by the sweep); a cluster is the same
code with ``ray_address``. Ray is pinned in requirements.txt; without it the test skips saying so.
"""
import pytest

import biped_sim as bs

GRID = {"kp": [80.0, 400.0], "step_angle": [0.15, 0.25]}


def _outcome(rows):
    return [{k: v for k, v in r.items() if k != "wall_time"} for r in rows]


def test_ray_rows_equal_the_process_pool_rows():
    pytest.importorskip("ray", reason="Ray is not installed: pip install 'biped_sim[ray]' (requirements.txt pins it)")
    ray_rows = bs.sweep("walk", GRID, duration=0.6, workers=2, backend="ray")
    pool_rows = bs.sweep("walk", GRID, duration=0.6, workers=2)
    assert _outcome(ray_rows) == _outcome(pool_rows)
    assert [r["status"] for r in ray_rows] == ["completed"] * 4


def test_ray_keeps_failed_runs_as_rows():
    pytest.importorskip("ray", reason="Ray is not installed: pip install 'biped_sim[ray]' (requirements.txt pins it)")
    rows = bs.sweep("passive", {"initial_dq[0]": [0.0, 0.3]}, duration=2.0, workers=2, backend="ray")
    # the passive robot falls back onto its rear foot: the scuff is too deep, the run stops
    assert rows[0]["status"] == "stopped" and "deeper than scuff_depth" in rows[0]["message"]
    assert rows[1]["status"] == "error" and "the stance foot (leg 1) moves" in rows[1]["message"]


def test_no_cluster_at_the_address_is_one_value_error():
    pytest.importorskip("ray", reason="Ray is not installed: pip install 'biped_sim[ray]' (requirements.txt pins it)")
    with pytest.raises(ValueError, match="no Ray cluster at 127.0.0.1:1"):
        bs.sweep("walk", {"kp": [100.0]}, duration=0.1, backend="ray", ray_address="127.0.0.1:1")
