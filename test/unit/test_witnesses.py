"""The witnesses (biped_sim/engine/witnesses.py): each guard is one row (name, direction, value, reset,
the invariants it protects); ``witnesses(mode)`` gives a mode's rows; one rule, ``loop_rules.ev_triggered``, decides a
crossing in both loops; a new guard is one new row."""
import math
import re
from pathlib import Path

import numpy as np
import pytest

import biped_sim as bs
from biped_sim.control.walking import PDWalkingController
from biped_sim.engine import witnesses as W
from biped_sim.engine.results import Event

ENGINE = Path(W.__file__).resolve().parent
MODEL = bs.BipedModel()


@pytest.mark.parametrize("stance_leg, armed, phases, mu, expected", [
    (1, [False, True], {"stance", "impact"}, None, [("touchdown", 2), ("liftoff", 1)]),
    (2, [True, False], {"stance", "impact"}, 0.6, [("touchdown", 1), ("liftoff", 2), ("slip", 2)]),
    (1, [False, False], {"stance", "impact"}, 0.6, [("liftoff", 1), ("slip", 1)]),
    (1, [False, True], {"stance"}, None, [("liftoff", 1)]),
    (0, [True, True], {"stance", "impact", "flight"}, 0.6, [("touchdown", 1), ("touchdown", 2)]),
    (0, [False, True], {"stance", "impact", "flight"}, None, [("touchdown", 2)]),
])
def test_a_modes_witnesses_are_rows_with_a_name_direction_value_reset_and_invariants(stance_leg, armed, phases, mu,
                                                                                      expected):
    rows = W.witnesses(stance_leg, armed, phases, mu)
    assert [(w.name, w.leg) for w in rows] == expected
    invariants = (ENGINE / "invariants.py").read_text()
    for w in rows:
        assert w.direction == W.POSITIVE_THEN_NON_POSITIVE and callable(w.kind.value) and callable(w.kind.reset)
        assert w.kind.invariants and all(f"invariant '{name}'" in invariants for name in w.kind.invariants)


def test_triggered_is_positive_then_non_positive():
    assert W.triggered(1.0, 0.0) and W.triggered(1e-300, -2.0)
    assert not W.triggered(0.0, -1.0) and not W.triggered(1.0, 1e-300) and not W.triggered(-1.0, 1.0)
    assert not W.triggered(math.nan, -1.0) and not W.triggered(1.0, math.nan)      # as C's comparisons
    with pytest.raises(ValueError, match="direction"):
        W.triggered(1.0, 0.0, "non-positive then positive")


def test_positive_then_non_positive_is_written_once_in_loop_rules():
    """The crossing test is one rule, loop_rules.ev_triggered: witnesses.triggered calls it as Python, the
    compiled loop calls its compiled C; neither writes the test again."""
    python = [(p.name, m.group(0)) for p in sorted(ENGINE.glob("*.py"))
              for m in re.finditer(r"\w+ > 0 and \w+ <= 0", p.read_text())]
    hand_c = re.findall(r"\w+ > 0 && \w+ <= 0", (ENGINE / "_core.c").read_text())
    assert python == [("loop_rules.py", "w0 > 0 and w1 <= 0")]
    assert hand_c == [] and "ev_triggered(" in (ENGINE / "_core.c").read_text()
    assert W.triggered(1.0, -0.0) and not W.triggered(-0.0, -1.0)


def _hip_height(ctx, leg, t, q, dq, force_at, feet=None, F=None):
    return q[1] - 0.985


def _stop_low(ctx, t, q, dq, legs, stance_leg):
    ev = Event(t, "hip_low", stance_leg, np.array(q), np.array(dq), np.array(dq), None, stance_leg, stance_leg,
               message=f"the hip went below 0.985 m at t={t:.9g} s")
    return ev, ev.message


def test_a_new_guard_is_one_new_row(monkeypatch):
    q0, dq0 = PDWalkingController(MODEL).initial_state()

    def walk():
        return bs.simulate(MODEL, q0, dq0, 1.5, controller=PDWalkingController(MODEL))
    before = walk()
    monkeypatch.setitem(W.KINDS, "hip_low", W.WitnessKind(
        "hip_low", W.POSITIVE_THEN_NON_POSITIVE, _hip_height, _stop_low, ("feet at or above the ground",),
        lambda stance_leg, armed, phases, mu: (stance_leg,) if stance_leg else ()))
    r = walk()
    assert r.status == "stopped" and r.message.startswith("the hip went below 0.985 m at t=")
    assert r.stats["compiled_loop_steps"] == 0      # a witness the compiled loop does not know: the Python loop
    ev = r.events[-1]
    assert ev.kind == "hip_low" and abs(ev.q[1] - 0.985) < 1e-9 and ev.time == r.t[-1]
    assert r.q[-2, 1] > 0.985 and r.q[0, 1] < 0.985     # it crossed going down (it started below, rose above)
    # the run is the one without the witness until then
    assert [(e.kind, e.time) for e in before.events if e.time < ev.time] == [(e.kind, e.time) for e in r.events[:-1]]
    n = len(r.t) - 1
    assert np.array_equal(before.t[:n], r.t[:n]) and np.array_equal(before.q[:n], r.q[:n])
