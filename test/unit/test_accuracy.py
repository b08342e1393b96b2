"""``biped-sim accuracy --quick``: the work-precision benchmark runs and its figures make sense."""
import contextlib
import csv
import io
import math
import re

import pytest

from biped_sim.analysis import workprecision as wp
from biped_sim.cli import main


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    out = tmp_path_factory.mktemp("accuracy")
    err, std = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(std):
        rc = main(["accuracy", "--quick", "--out", str(out)])
    with open(out / "accuracy.csv") as f:
        rows = list(csv.DictReader(f))
    return dict(rc=rc, out=out, stderr=err.getvalue(), stdout=std.getvalue(), rows=rows)


def _rows(bench, case, method):
    return [r for r in bench["rows"] if r["case"] == case and r["method"] == method]


def test_outputs_written(bench):
    assert bench["rc"] == 0
    for name in ("accuracy.md", "accuracy.csv", "work_precision.png"):
        assert (bench["out"] / name).stat().st_size > 1000
    assert (bench["out"] / "work_precision.png").read_bytes()[:4] == b"\x89PNG"
    # the progress to a non-terminal: a line every 10 % (config.progress), no carriage return
    assert "\r" not in bench["stderr"] and re.search(r"^\[accuracy\] (\d+)/\1 runs \(100 %\)", bench["stderr"], re.M)
    md = (bench["out"] / "accuracy.md").read_text()
    assert "| walking | **dop853** | **tol=1e-09** (default)" in md


def test_every_case_and_method(bench):
    cases = {r["case"] for r in bench["rows"]}
    assert cases == {"passive_fall", "walking", "drop"}
    for case in cases:
        methods = {r["method"] for r in bench["rows"] if r["case"] == case}
        assert {"dop853", "scipy_dop853", "scipy_rk45", "radau", "rk4", "semi_implicit_euler"} <= methods
    assert _rows(bench, "passive_fall", "solve_ivp_DOP853")


def test_errors_fall_with_tolerance_and_events_match(bench):
    for case in ("passive_fall", "walking", "drop"):
        loose, tight = sorted(_rows(bench, case, "dop853"), key=lambda r: -float(r["err_run"]))
        assert float(tight["err_run"]) < float(loose["err_run"]) / 100
        assert float(tight["err_run"]) < 1e-6 and float(tight["energy"]) < 1e-6
    walk = [r for r in bench["rows"] if r["case"] == "walking" and r["status"] == "completed"]
    assert walk and all(int(r["impacts"]) == 10 for r in walk)
    default = [r for r in bench["rows"] if r["default"] == "True"]
    assert len(default) == 3
    for r in default:
        assert r["status"] in ("completed", "stopped")
        assert float(r["drift"]) < 1e-9
        if r["case"] != "passive_fall":
            assert float(r["err_event"]) < 1e-7


def test_reference_error_estimated_and_default_on_front(bench):
    out = bench["stdout"]
    assert "scipy_dop853 rtol=atol=1e-12" in out
    for case in ("passive_fall", "walking", "drop"):
        assert f"default dop853 tol=1e-9 on {case}: " in out
        # on the front in work (right-hand-side evaluations: the same on every machine, unlike wall
        # time, which the report's front uses and which a loaded machine reorders): no run that
        # places its events right takes at most the default's evaluations and is more accurate
        d = next(r for r in bench["rows"] if r["case"] == case and r["default"] == "True")
        better = [f"{r['method']} {r['setting']}: {r['rhs']} evaluations, error {r['err_run']}"
                  for r in bench["rows"] if r["case"] == case and r is not d and r["rhs"]
                  and not math.isinf(float(r["err_event"]))
                  and int(r["rhs"]) <= int(d["rhs"]) and float(r["err_run"]) < float(d["err_run"])]
        assert not better, (case, d["rhs"], d["err_run"], better)


def test_front_logic():
    rows = [dict(case="c", time=1.0, err_run=1e-3, err_event=math.nan),
            dict(case="c", time=2.0, err_run=1e-6, err_event=0.0),
            dict(case="c", time=3.0, err_run=1e-5, err_event=0.0),
            dict(case="c", time=0.5, err_run=1e-9, err_event=math.inf)]   # wrong number of events
    assert [r["time"] for r in wp.front(rows)["c"]] == [1.0, 2.0]
