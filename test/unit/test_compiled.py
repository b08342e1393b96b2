"""The compiled twin of the generated code (biped_sim/engine/_gen/_cmodel.c, chosen by biped_sim/engine/compiled.py):
built, generated from the current sources, and bit for bit the Python code's results."""
import inspect
import json
import math
import os
import random
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from biped_sim.engine import compiled
from biped_sim.engine._gen import closed_forms as _generated, rk_steps as _rk_steps
from biped_sim.engine.model import BipedModel

ROOT = Path(__file__).resolve().parents[2]
CLOSED_FORMS = [n for n, f in vars(_generated).items() if inspect.isfunction(f) and not n.endswith("_constants")]
STEPS = [n for n, f in vars(_rk_steps).items() if inspect.isfunction(f) and re.fullmatch(r"\w+_step_\d+", n)]
DENSE = [n for n, f in vars(_rk_steps).items() if inspect.isfunction(f) and re.fullmatch(r"\w+_dense_\d+", n)]


def twin():
    """The twin, or a skip: without it there is nothing to compare (the test above fails then)."""
    if compiled.IMPLEMENTATION != "C":
        pytest.skip(f"no compiled twin to compare: {compiled.WHY_PYTHON}")
    from biped_sim.engine._gen import _cmodel
    return _cmodel


def test_the_compiled_twin_is_built_and_chosen():
    assert compiled.IMPLEMENTATION == "C", compiled.WHY_PYTHON
    for name in CLOSED_FORMS:
        assert getattr(compiled.gen, name) is getattr(twin(), name)
    assert sorted(STEPS) == [f"{method}_step_{n}" for method in ("dop853", "dopri5") for n in ("11", "15", "7", "9")]
    for table in (compiled.rk.DOP853_STEPS, compiled.rk.DOPRI5_STEPS):
        assert all(step is getattr(twin(), step.__name__) for step in table.values())


def test_the_committed_c_source_is_generated_from_the_current_python():
    out = subprocess.run([sys.executable, str(ROOT / "tools" / "generate_c.py"), "--check"],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def _arguments(name, rng, model):
    """Random arguments of one closed form: angles over several turns, rates to 20 rad/s."""
    params = list(inspect.signature(getattr(_generated, name)).parameters)
    n = 3 if name.startswith("fixed_base") else 5
    sizes = {"q": n, "qs": n, "dq": n, "dqm": n, "dqs": n, "u": 2}
    scale = {"q": 8.0, "qs": 8.0, "dq": 20.0, "dqm": 20.0, "dqs": 20.0, "u": 300.0}
    return [[rng.uniform(-scale[p], scale[p]) for _ in range(sizes[p])] if p != "k" else model.k[name]
            for p in params]


def _bits(value):
    """The exact result: types and every float's bits."""
    if isinstance(value, (list, tuple)):
        return (type(value).__name__, [_bits(v) for v in value])
    return (type(value).__name__, float(value).hex())


@pytest.mark.parametrize("name", CLOSED_FORMS)
def test_every_closed_form_returns_the_python_bits(name):
    rng = random.Random(name)
    for model in (BipedModel(), BipedModel(m_leg=3.7, l_leg=0.83, I_torso=1.9, g=1.62)):
        for _ in range(400):
            args = _arguments(name, rng, model)
            assert _bits(getattr(twin(), name)(*args)) == _bits(getattr(_generated, name)(*args)), args


def _oscillators(n):
    """A nonlinear right-hand side on lists (coupled pendulums), recording what it is given."""
    seen = []

    def fun(t, y):
        seen.append((type(y), len(y)))
        return [y[(i + 1) % n] if i % 2 == 0 else -math.sin(y[i - 1]) + 0.3 * math.cos(t) * y[(i + 2) % n]
                for i in range(n)]
    return fun, seen


@pytest.mark.parametrize("name", STEPS)
def test_every_unrolled_step_returns_the_python_bits(name):
    n = int(name.rsplit("_", 1)[1])
    rng = random.Random(name)
    for _ in range(200):
        ys = [rng.uniform(-3, 3) for _ in range(n)]
        t, h, tol = rng.uniform(0, 10), 10 ** rng.uniform(-5, -0.5), 10 ** rng.uniform(-13, -5)
        outs = []
        for module in (_rk_steps, twin()):
            fun, seen = _oscillators(n)
            k0 = fun(t, ys)
            y_new, k_last, err, stages = getattr(module, name)(fun, t, ys, k0, h, tol, tol)
            assert stages[0] is k0 and stages[-1] is k_last   # the right-hand side's own results
            outs.append((_bits(y_new), _bits(k_last), _bits(err), _bits(stages), seen))
        assert outs[0] == outs[1]


@pytest.mark.parametrize("name", DENSE)
def test_every_dense_output_returns_the_python_bits(name):
    n = int(name.rsplit("_", 1)[1])
    rng = random.Random(name)
    method = name.split("_")[0]
    for _ in range(100):
        ys = [rng.uniform(-3, 3) for _ in range(n)]
        t, h = rng.uniform(0, 10), 10 ** rng.uniform(-5, -0.5)
        outs = []
        for module in (_rk_steps, twin()):
            fun, seen = _oscillators(n)
            k0 = fun(t, ys)
            y_new, _, _, stages = getattr(module, f"{method}_step_{n}")(fun, t, ys, k0, h, 1e-9, 1e-9)
            if method == "dop853":
                rows = getattr(module, name)(fun, t, h, ys, y_new, *[stages[j] for j in _rk_steps.DOP853_DENSE_STAGES])
            else:
                rows = getattr(module, name)(ys, *stages)
            outs.append((_bits(rows), seen))
        assert outs[0] == outs[1]


def test_bad_arguments_and_failing_right_hand_sides_raise_what_the_python_code_raises():
    k = BipedModel().k["stance_floating_1"]
    q, dq, u = [0.5, 0.86, 2.6, 2.1, 0.5], [0.0] * 5, [0.0, 0.0]
    for args, error in [((q[:4], dq, u, k), ValueError), ((q, dq, [0.0], k), ValueError),
                        ((q, dq, u, k[:-1]), ValueError), ((1.0, dq, u, k), TypeError),
                        ((q[:4] + ["x"], dq, u, k), TypeError), ((q, dq, u), TypeError)]:
        for module in (_generated, twin()):
            with pytest.raises(error):
                module.stance_floating_1(*args)
    # numpy arrays and their float64 entries are taken as the Python code takes them
    assert _bits(twin().stance_floating_1(np.array(q), np.array(dq), np.array(u), k)) == \
        _bits(_generated.stance_floating_1(q, dq, u, k))

    class Stop(Exception):
        pass

    calls = []

    def fails_at_third(t, y):
        calls.append(t)
        if len(calls) == 3:
            raise Stop("from the right-hand side")
        return [0.0] * 7
    for module in (_rk_steps, twin()):
        with pytest.raises(Stop, match="from the right-hand side"):
            module.dop853_step_7(fails_at_third, 0.0, [0.0] * 7, [0.0] * 7, 0.1, 1e-9, 1e-9)
        calls.clear()
        with pytest.raises(ValueError):   # a right-hand side of the wrong length
            module.dopri5_step_7(lambda t, y: [0.0] * 6, 0.0, [0.0] * 7, [0.0] * 7, 0.1, 1e-9, 1e-9)
        with pytest.raises(TypeError):
            module.dopri5_step_7(lambda t, y: None, 0.0, [0.0] * 7, [0.0] * 7, 0.1, 1e-9, 1e-9)


def test_a_step_holds_no_reference_after_it_returns_or_fails():
    fun, _ = _oscillators(11)
    ys = [0.1] * 11
    k0 = fun(0.0, ys)
    before = sys.getrefcount(fun), sys.getrefcount(k0)
    for _ in range(1000):
        twin().dop853_step_11(fun, 0.0, ys, k0, 0.01, 1e-9, 1e-9)
        with pytest.raises(ZeroDivisionError):
            twin().dop853_step_11(lambda t, y: [1.0 / 0.0], 0.0, ys, k0, 0.01, 1e-9, 1e-9)
    assert (sys.getrefcount(fun), sys.getrefcount(k0)) == before


WALK = """
import json
import numpy as np
from biped_sim.engine import compiled
from biped_sim.control.walking import WalkingController, PDWalkingController
from biped_sim.engine.simulate import simulate
from biped_sim.engine.model import BipedModel
model = BipedModel()
out = {"implementation": compiled.IMPLEMENTATION}
for method, ctrl in (("dop853", WalkingController(model)), ("dopri5", PDWalkingController(model))):
    q0, dq0 = ctrl.initial_state()
    r = simulate(model, q0, dq0, 1.6, controller=ctrl, method=method)
    out[method] = {"t": [v.hex() for v in r.t.tolist()],
                   "state": [v.hex() for v in np.concatenate([r.q, r.dq], axis=1).ravel().tolist()],
                   "grf": [v.hex() for v in r.grf.ravel().tolist()],
                   "events": [(e.kind, e.leg, e.time.hex()) for e in r.events]}
print(json.dumps(out))
"""


def test_a_walk_in_pure_python_equals_the_compiled_walk_bit_for_bit():
    twin()
    runs = {}
    for forced in ("1", ""):
        env = dict(os.environ, BIPED_SIM_PURE_PYTHON=forced)
        out = subprocess.run([sys.executable, "-c", WALK], capture_output=True, text=True, env=env, cwd=ROOT)
        assert out.returncode == 0, out.stderr
        runs[forced] = json.loads(out.stdout)
    python, compiled_run = runs["1"], runs[""]
    assert (python.pop("implementation"), compiled_run.pop("implementation")) == ("Python", "C")
    for method in ("dop853", "dopri5"):
        assert sum(kind == "touchdown" for kind, _, _ in compiled_run[method]["events"]) >= 2, method
        assert python[method] == compiled_run[method], method
