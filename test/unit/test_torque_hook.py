"""The torque-law hook (biped_sim/engine/torque_hook.py): a law given as the address of a C function and
its parameters runs in the compiled loop and gives the run of the same law called back from Python, and
of the Python loop; the walking laws of control/ plug in through it like any other law."""
import ctypes
import math
import re

import numpy as np
import pytest

import biped_sim as bs
from biped_sim.analysis.edge_cases import on_both_loops
from biped_sim.control import walking
from biped_sim.control.walking import PDWalkingController, WalkingController
from biped_sim.engine import compiled_loop
from biped_sim.engine.model import BipedModel
from biped_sim.engine.torque_hook import MAX_PARAMETERS, CompiledLaw, c_prototype

MODEL = BipedModel()

pytestmark = pytest.mark.skipif(not compiled_loop.AVAILABLE, reason=f"no compiled loop: {compiled_loop.WHY_NOT}")


class PDThroughCtypes(PDWalkingController):
    """The PD walking law, offered to the hook as a C function made by ctypes from its Python code (the
    same operations on the same doubles: the same bits), or not offered (``offer=False``: called back).
    ``fail_after``: the C function returns 7 from that time on."""

    def __init__(self, model, offer=True, fail_after=math.inf):
        super().__init__(model)
        self.offer, self.fail_after, self.c_calls = offer, fail_after, 0

        def law(t, q, dq, stance_leg, params, u):
            self.c_calls += 1
            if t >= self.fail_after:
                return 7
            u[0], u[1] = PDWalkingController.__call__(self, t, q[:5], dq[:5], stance_leg)
            return 0
        self._c_law = c_prototype()(law)     # (kept alive as long as the controller)

    def compiled_law(self, model):
        if not self.offer:
            return None
        return CompiledLaw("pd through ctypes", (), ctypes.cast(self._c_law, ctypes.c_void_p).value)


def _walk(ctrl, period, t_final=0.8):
    q0, dq0 = PDWalkingController(MODEL).initial_state()
    return bs.simulate(MODEL, q0, dq0, t_final, controller=ctrl, control_period=period)


@pytest.mark.parametrize("period", [None, 1e-3])
def test_a_law_plugged_in_as_a_c_function_gives_the_run_of_the_law_called_back(period):
    plugged, called = PDThroughCtypes(MODEL), PDThroughCtypes(MODEL, offer=False)
    a, python_loop = on_both_loops(lambda: _walk(plugged, period))
    assert plugged.c_calls > 0 and a.stats["compiled_loop_steps"] > 0
    b = _walk(called, period)
    assert called.c_calls == 0 and b.stats["compiled_loop_steps"] > 0
    assert a.status == b.status == python_loop.status == "completed" and len(a.events) >= 1
    for other in (b, python_loop):    # bit for bit
        assert [(e.kind, e.time) for e in a.events] == [(e.kind, e.time) for e in other.events]
        for field in ("t", "q", "dq", "u", "grf"):
            assert getattr(a, field).tobytes() == getattr(other, field).tobytes(), field
        assert a.stats["rhs_evaluations"] == other.stats["rhs_evaluations"]


@pytest.mark.parametrize("cls", [WalkingController, PDWalkingController])
def test_the_walking_laws_are_c_functions_of_the_hooks_signature(cls):
    ctrl = cls(MODEL, kp=150.0)
    law = ctrl.compiled_law(MODEL)
    assert isinstance(law, CompiledLaw) and law.params[5] == 150.0
    assert law.address == {WalkingController: walking._laws.WALKING_LAW}.get(cls, walking._laws.PD_WALKING_LAW)
    c_law = c_prototype()(law.address)       # called as any C caller of the hook calls it
    params = (ctypes.c_double * len(law.params))(*law.params)
    rng = np.random.default_rng(5)
    for _ in range(50):
        q = (rng.uniform(-1, 1, 5) + [0, 0.9, math.pi, math.pi, 0]).tolist()
        dq = rng.uniform(-4, 4, 5).tolist()
        for leg in (0, 1, 2):
            u = (ctypes.c_double * 2)()
            assert c_law(0.0, (ctypes.c_double * 5)(*q), (ctypes.c_double * 5)(*dq), leg, params, u) == 0
            expected = np.asarray(ctrl(0.0, q, dq, leg), dtype=float)
            assert np.array(u[:]).tobytes() == expected.tobytes(), (q, dq, leg)


@pytest.mark.parametrize("period", [None, 1e-3])
def test_a_compiled_law_that_fails_ends_the_run_failed_naming_the_law(period):
    ctrl = PDThroughCtypes(MODEL, fail_after=0.2)
    r = _walk(ctrl, period)
    assert r.status == "failed", r.message
    assert re.search(r": the torque law pd through ctypes returned 7 at t=0\.2\d* s$", r.message), r.message
    assert 0.15 < r.t[-1] <= 0.2 + 1e-12


def test_a_compiled_law_with_too_many_parameters_is_refused_in_one_line():
    class TooMany(PDThroughCtypes):
        def compiled_law(self, model):
            return super().compiled_law(model)._replace(params=(0.0,) * (MAX_PARAMETERS + 1))
    r = _walk(TooMany(MODEL), None, t_final=0.05)
    assert r.status == "failed" and len(r.t) == 1
    assert r.message.endswith(f"parameters: {MAX_PARAMETERS + 1} values, expected 0 to {MAX_PARAMETERS}")
