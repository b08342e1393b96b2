"""When a controller fails: its exception kept with its traceback on the result and re-raised on request
(on both loops and in pure Python), anything but two finite real numbers named on every path, and a wrong
signature refused by every entry point of the simulator before anything runs."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import biped_sim as bs
from biped_sim.analysis.edge_cases import on_both_loops
from biped_sim.control.walking import PDWalkingController
from biped_sim.engine import hybrid
from biped_sim.engine.results import ControllerError

MODEL = bs.BipedModel()
PD = PDWalkingController(MODEL)
Q0, DQ0 = PD.initial_state()
RAISING_LINE = next(i for i, line in enumerate(Path(__file__).read_text().splitlines(), 1)
                    if line.strip().startswith("raise RuntimeError(\"my controller broke\")"))


class BreaksAt:
    """The PD walking law until ``t_break``, then an exception (the one raised kept in ``raised``)."""

    def __init__(self, t_break=0.3):
        self.t_break, self.raised = t_break, []

    def __call__(self, t, q, dq, stance_leg):
        if t > self.t_break:
            try:
                raise RuntimeError("my controller broke")
            except RuntimeError as exc:
                self.raised.append(exc)
                raise
        return PD(t, q, dq, stance_leg)


def _last_frame(exc):
    tb = exc.__traceback__
    while tb.tb_next is not None:
        tb = tb.tb_next
    return tb.tb_frame.f_code.co_filename, tb.tb_lineno


@pytest.mark.parametrize("period", [None, 1e-3], ids=["continuous", "held 1 ms"])
def test_a_raising_controller_keeps_its_exception_and_traceback(period):
    def run():
        ctrl = BreaksAt()
        r = bs.simulate(MODEL, Q0, DQ0, 0.5, controller=ctrl, control_period=period)
        return r, ctrl.raised
    (a, raised_a), (b, raised_b) = on_both_loops(run)
    for r, raised in ((a, raised_a), (b, raised_b)):
        assert r.status == "failed" and r.events[-1].kind == "error"
        assert "the controller raised RuntimeError at t=" in r.message and "my controller broke" in r.message
        assert f"{__file__}:{RAISING_LINE} in __call__" in r.message, r.message
        assert r.controller_error is raised[-1]            # the exception itself, not a copy
        assert _last_frame(r.controller_error) == (__file__, RAISING_LINE)
    assert (a.message, a.t[-1]) == (b.message, b.t[-1])


PURE_PYTHON_RUN = f"""
import json, sys
sys.path.insert(0, {str(Path(__file__).parent)!r})
from biped_sim.engine import compiled_loop
from test_controller_errors import BreaksAt, MODEL, Q0, DQ0, _last_frame
import biped_sim as bs
assert not compiled_loop.AVAILABLE
try:
    bs.simulate(MODEL, Q0, DQ0, 0.5, controller=BreaksAt(), control_period=1e-3, on_controller_error="raise")
except RuntimeError as exc:
    print(json.dumps([exc.result.status, exc.result.message, list(_last_frame(exc))]))
"""


def test_a_raising_controller_in_pure_python_is_re_raised_with_its_traceback():
    out = subprocess.run([sys.executable, "-c", PURE_PYTHON_RUN], capture_output=True, text=True, timeout=120,
                         env=dict(os.environ, BIPED_SIM_PURE_PYTHON="1"))
    assert out.returncode == 0, out.stderr
    status, message, frame = json.loads(out.stdout)
    assert status == "failed" and f"{__file__}:{RAISING_LINE} in __call__" in message
    assert frame == [__file__, RAISING_LINE]


@pytest.mark.parametrize("period", [None, 1e-3], ids=["continuous", "held 1 ms"])
def test_on_controller_error_raise_re_raises_it_after_the_run_with_the_result(period):
    ctrl = BreaksAt()
    with pytest.raises(RuntimeError, match="my controller broke") as info:
        bs.simulate(MODEL, Q0, DQ0, 0.5, controller=ctrl, control_period=period, on_controller_error="raise")
    assert info.value is ctrl.raised[-1]
    r = info.value.result
    assert r.status == "failed" and r.controller_error is info.value and 0.25 < r.t[-1] <= 0.3 + 1e-3
    assert _last_frame(info.value) == (__file__, RAISING_LINE)
    # a scene passes it through; a run that does not fail returns its result
    scene = bs.load_scene("walk")
    with pytest.raises(RuntimeError, match="my controller broke"):
        scene.simulate(controller=BreaksAt(0.05), t_final=0.2, on_controller_error="raise")
    assert scene.simulate(t_final=0.1, on_controller_error="raise").controller_error is None
    with pytest.raises(ValueError, match="on_controller_error must be one of 'fail', 'raise', got 'rise'"):
        bs.simulate(MODEL, Q0, DQ0, 0.1, controller=ctrl, on_controller_error="rise")


BAD_LATE = ["12", [float("nan"), 0.0], (0.5, True), np.array([1.0, np.inf]), [1e308, 1e308], None, 1 + 2j]


@pytest.mark.parametrize("period", [None, 1e-3], ids=["continuous", "held 1 ms"])
@pytest.mark.parametrize("bad", BAD_LATE, ids=repr)
def test_a_bad_return_mid_run_fails_naming_it_on_every_path(bad, period):
    """From 0.2 s on, when the periods (held) or the evaluations (continuous) run in the compiled loop, the
    controller returns anything but two finite real numbers: the run fails, naming it, on both loops."""
    def mine(t, q, dq, leg):
        return bad if t > 0.2 else PD(t, q, dq, leg)
    a, b = on_both_loops(lambda: bs.simulate(MODEL, Q0, DQ0, 0.3, controller=mine, control_period=period))
    for r in (a, b):
        assert r.status == "failed" and f"the controller returned {bad!r} at t=" in r.message, r.message
        assert "two finite torques" in r.message
        assert isinstance(r.controller_error, ControllerError) and str(r.controller_error) in r.message
    assert (a.message, a.t.tobytes()) == (b.message, b.t.tobytes())
    with pytest.raises(ControllerError, match="the controller returned"):
        bs.simulate(MODEL, Q0, DQ0, 0.3, controller=mine, control_period=period, on_controller_error="raise")


def two_arguments(t, q):
    return [0.0, 0.0]


@pytest.mark.parametrize("entry", ["advance", "advance_period", "advance_periods", "command"])
def test_a_wrong_signature_never_runs_on_the_simulators_entry_points(entry, monkeypatch):
    sim = bs.HybridSimulator(MODEL, Q0, DQ0)
    sim.advance_period(1e-3, u=[0.0, 0.0])
    t, n = sim.t, len(sim.result().t)
    call = {"advance": lambda c: sim.advance(0.1, controller=c),
            "advance_period": lambda c: sim.advance_period(1e-3, controller=c),
            "advance_periods": lambda c: sim.advance_periods(1e-3, c, 0.1),
            "command": lambda c: sim.command(c)}[entry]
    with pytest.raises(ValueError, match=r"two_arguments cannot be called as controller\(t, q, dq, stance_leg\)"):
        call(two_arguments)
    assert (sim.status, sim.t, len(sim.result().t)) == ("running", t, n)
    # each controller object is checked once
    checks = []
    monkeypatch.setattr(hybrid, "check_controller", lambda c: checks.append(c) or c)
    for _ in range(3):
        call(PD)
    assert checks == [PD] and sim.status == "running"


class FailingCompiledLaw:
    """A compiled law (a ctypes C function through the torque-law hook) that returns 7 from ``t_fail`` on, and
    u = 0 before; its Python call, the same law, for the Python loop."""

    def __init__(self, t_fail=0.01):
        import ctypes

        from biped_sim.engine.torque_hook import c_prototype
        self.t_fail = t_fail

        def law(t, q, dq, stance_leg, params, u):
            if t >= self.t_fail:
                return 7
            u[0], u[1] = 0.0, 0.0
            return 0
        self._c_law = c_prototype()(law)
        self.address = ctypes.cast(self._c_law, ctypes.c_void_p).value

    def compiled_law(self, model):
        from biped_sim.engine.torque_hook import CompiledLaw
        return CompiledLaw("fails at t_fail", (), self.address)

    def __call__(self, t, q, dq, stance_leg):
        if t >= self.t_fail:
            raise RuntimeError("the torque law returned 7")
        return [0.0, 0.0]


@pytest.mark.skipif(not hybrid.compiled_loop.AVAILABLE, reason="no compiled loop")
def test_a_compiled_law_that_fails_ends_the_run_failed_on_every_entry_point():
    """Its failure is a ControllerError on the result (and raised on request), also where advance_period
    computes the command in C (it escaped the simulator)."""
    law = FailingCompiledLaw()
    sim = bs.HybridSimulator(MODEL, Q0, DQ0)
    for _ in range(30):
        sim.advance_period(1e-3, controller=law)
    r = sim.result()
    assert r.status == "failed" and r.message.endswith("the torque law fails at t_fail returned 7 at t=0.01 s")
    assert isinstance(r.controller_error, ControllerError) and str(r.controller_error) in r.message
    for period in (None, 1e-3):
        r = bs.simulate(MODEL, Q0, DQ0, 0.05, controller=law, control_period=period)
        assert r.status == "failed" and "the torque law fails at t_fail returned 7" in r.message, r.message
        assert isinstance(r.controller_error, ControllerError)
        with pytest.raises(ControllerError, match="returned 7"):
            bs.simulate(MODEL, Q0, DQ0, 0.05, controller=law, control_period=period, on_controller_error="raise")
