"""The compiled twin of the closed forms (biped_sim/_cmodel.c, chosen by biped_sim/closed_form.py):
built, generated from the current _generated.py, and bit for bit the Python code's results."""
import inspect
import json
import os
import random
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from biped_sim import _generated, closed_form
from biped_sim.model import BipedModel

ROOT = Path(__file__).resolve().parents[1]
RUNTIME = [n for n, f in vars(_generated).items()
           if inspect.isfunction(f) and not n.endswith("_constants")]


def twin():
    from biped_sim import _cmodel
    return _cmodel


def test_the_compiled_twin_is_built_and_chosen():
    assert closed_form.IMPLEMENTATION == "C", closed_form.WHY_PYTHON
    for name in RUNTIME:
        assert getattr(closed_form.gen, name) is getattr(twin(), name)


def test_the_committed_c_source_is_generated_from_the_current_python():
    out = subprocess.run([sys.executable, str(ROOT / "tools" / "generate_c.py"), "--check"],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def _arguments(name, rng, model):
    """Random arguments of one run-time function: leg angles over several turns, rates to 20 rad/s."""
    params = list(inspect.signature(getattr(_generated, name)).parameters)
    n = 3 if name.startswith("fixed_base") else 5
    sizes = {"q": n, "qs": n, "dq": n, "dqs": n, "u": 2}
    scale = {"q": 8.0, "qs": 8.0, "dq": 20.0, "dqs": 20.0, "u": 300.0}
    return [[rng.uniform(-scale[p], scale[p]) for _ in range(sizes[p])] if p != "k" else model.k[name]
            for p in params]


def _bits(value):
    """The exact result: types and every float's bits."""
    if isinstance(value, (list, tuple)):
        return (type(value).__name__, [_bits(v) for v in value])
    return (type(value).__name__, float(value).hex())


@pytest.mark.parametrize("name", RUNTIME)
def test_every_function_returns_the_python_bits(name):
    rng = random.Random(name)
    for model in (BipedModel(), BipedModel(m_leg=3.7, l_leg=0.83, I_torso=1.9, g=1.62)):
        for _ in range(400):
            args = _arguments(name, rng, model)
            assert _bits(getattr(twin(), name)(*args)) == _bits(getattr(_generated, name)(*args)), args


def test_bad_arguments_raise_what_the_python_code_raises():
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


WALK = """
import json, sys
import numpy as np
from biped_sim import closed_form
from biped_sim.control import WalkingController
from biped_sim.hybrid import simulate
from biped_sim.model import BipedModel
model = BipedModel()
ctrl = WalkingController(model)
q0, dq0 = ctrl.initial_state()
r = simulate(model, q0, dq0, 1.6, controller=ctrl)
print(json.dumps({"implementation": closed_form.IMPLEMENTATION,
                  "t": [v.hex() for v in r.t.tolist()],
                  "state": [v.hex() for v in np.concatenate([r.q, r.dq], axis=1).ravel().tolist()],
                  "grf": [v.hex() for v in r.grf.ravel().tolist()],
                  "events": [(e.kind, e.leg, e.time.hex()) for e in r.events]}))
"""


def test_a_walk_in_pure_python_equals_the_compiled_walk_bit_for_bit():
    runs = {}
    for forced in ("python", ""):
        env = dict(os.environ, BIPED_SIM_CLOSED_FORM=forced)
        out = subprocess.run([sys.executable, "-c", WALK], capture_output=True, text=True, env=env, cwd=ROOT)
        assert out.returncode == 0, out.stderr
        runs[forced] = json.loads(out.stdout)
    python, compiled = runs["python"], runs[""]
    assert (python.pop("implementation"), compiled.pop("implementation")) == ("Python", "C")
    assert sum(kind == "touchdown" for kind, _, _ in compiled["events"]) >= 2
    assert python == compiled
