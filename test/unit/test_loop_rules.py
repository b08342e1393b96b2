"""The hybrid loop's rules written once (biped_sim/engine/loop_rules.py on the state of loop_state.py): the
committed C the compiled loop runs was generated from the current source, the compiled loop has no numerics of
its own for them, and run as Python without Cython installed they give the compiled loop's bits
(docs/engine.md, "The core")."""
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from biped_sim.engine import compiled_loop, loop_state

ROOT = Path(__file__).resolve().parents[2]
ENGINE = ROOT / "biped_sim" / "engine"
sys.path.insert(0, str(ROOT / "tools"))
import generate_loop  # noqa: E402  (tools/ is not a package)


def test_the_committed_c_was_generated_from_the_current_sources():
    """_loop_state.h and .pxd are what loop_state.py declares; _loop_rules.c carries the digest of the
    sources it was made from (regenerate: make generate-loop)."""
    for path, text in generate_loop.state_files().items():
        assert path.read_text() == text, f"{path.name} is stale: run make generate-loop"
    assert generate_loop.committed_digest() == generate_loop.sources_digest(), \
        "_loop_rules.c is stale: run make generate-loop"


def test_a_one_operation_change_of_a_rule_changes_the_digest(tmp_path):
    """The digest covers the rules' text: (t - t_old) * (1 / h) for (t - t_old) / h is a stale C."""
    for name in generate_loop.RULE_SOURCES:
        shutil.copyfile(ENGINE / name, tmp_path / name)
    rules = tmp_path / "loop_rules.py"
    text, line = rules.read_text(), "x: cython.double = (tt - S[T_OLD]) / hi"
    assert text.count(line) == 1
    rules.write_text(text.replace(line, "x: cython.double = (tt - S[T_OLD]) * (1 / hi)"))
    assert generate_loop.sources_digest(tmp_path) != generate_loop.sources_digest(ENGINE)


def test_the_state_is_one_buffer_read_by_offset_and_by_member():
    """The C struct members lie at the offsets the rules index (every field a double, in order)."""
    header = (ENGINE / "_loop_state.h").read_text()
    at = 0
    for field in loop_state.FIELDS:
        assert f"#define LS_{field.name.upper()} {at}\n" in header
        at += math.prod(field.shape)
    assert at == loop_state.SIZE and f"#define LOOP_STATE_SIZE {at}\n" in header
    S = loop_state.new_state(t=1.5, y=[1.0, 2.0])
    assert len(S) == loop_state.SIZE and S[loop_state.T] == 1.5 and S[loop_state.Y + 1] == 2.0
    with pytest.raises(ValueError, match=f"holds {loop_state.NMAX} values"):
        loop_state.new_state(y=[0.0] * (loop_state.NMAX + 1))


def test_the_compiled_loop_has_no_numerics_of_the_rules():
    """_core.c includes the compiled rules (_loop_rules.c) and defines none of the step, the dense
    output, the foot's height, the dip search or brentq itself."""
    core = (ENGINE / "_core.c").read_text()
    assert '#include "_loop_rules.c"' in core
    for name in ("step", "dense", "dense_at", "height_at", "may_dip", "locate_crossing", "ulp", "track_scuff",
                 "swinging_through"):
        assert not re.search(rf"^{name}\(", core, re.M), f"_core.c defines {name}()"
    assert "brentq.c" not in core and "pow(err" not in core


def test_the_scuff_rules_are_written_once():
    """A foot swinging through, a scuff's start, its passing through and its tracking over a step are the rules'
    (loop_rules.py), in no other file of the engine's Python or in _core.c."""
    rules = (ENGINE / "loop_rules.py").read_text()
    assert rules.count("dx > 0.0 and dx + dheight >= 0.0") == 1
    assert rules.count("tt = i * step + t0 if i < 8 else t_end") == 1
    for path in [*ENGINE.glob("*.py"), ENGINE / "_core.c"]:
        if path.name != "loop_rules.py":
            text = path.read_text()
            assert not re.search(r"dx \+ \w*\.?dheight >= 0|foot\[2\] \+ foot\[3\]", text), path.name
            assert "linspace(t0, t_end" not in text and "i * step_t + t0" not in text, path.name


def assert_written_once(formulas, written_again):
    """Each formula is written once in loop_rules.py, and the regular expression written_again (the same rule
    written out by hand) matches no other file of the engine's Python nor _core.c."""
    rules = (ENGINE / "loop_rules.py").read_text()
    for formula in formulas:
        assert rules.count(formula) == 1, formula
    for path in [*ENGINE.glob("*.py"), ENGINE / "_core.c"]:
        if path.name != "loop_rules.py":
            assert not re.search(written_again, path.read_text()), path.name


def test_the_witness_values_are_written_once():
    """A foot's height across the ground (the touchdown witness), a force's normal component (liftoff) and the
    friction-cone margin (slip) are the rules' (loop_rules.py): guards.py and _core.c call them."""
    assert_written_once(("return y + tan_s * x", "return fx * sin_s + fy * cos_s", "return fx * cos_s - fy * sin_s",
                         "return mu * normal - fabs(tangential)"),
                        (r"\* L->(sin|cos)_s|\* L->mu\b|p\[\d\] \+ t \* p\[|\w+\[0\] \* s \+ \w+\[1\] \* c"
                         r"|\w+\[0\] \* c - \w+\[1\] \* s|mu \* normal - (abs|fabs)\(|\w+ \+ t \* \w+x\b"
                         r"|\by \+ tan_slope \* x"))
    from biped_sim.engine import guards as G, loop_rules as rules_py
    ground = G.Ground.of(0.05)
    n, tg = G.normal_tangent([3.0, 100.0], ground)
    assert (n, tg) == (3.0 * ground.sin + 100.0 * ground.cos, 3.0 * ground.cos - 100.0 * ground.sin)
    assert G.slip_guard(n, tg, 0.6) == 0.6 * n - abs(tg)
    S = loop_state.new_state(sin_s=ground.sin, cos_s=ground.cos, mu=0.6)
    assert rules_py.ev_normal_force(S, 3.0, 100.0) == n and rules_py.ev_cone_margin(S, 3.0, 100.0) == 0.6 * n - abs(tg)


def test_arming_and_the_projection_are_written_once():
    """A free foot's arming, the disarming by a reset and the projection onto the pinned stance foot are the
    rules' (loop_rules.py): locator.py, modes.py and _core.c call them. Projected, the stance foot is at its pin
    and at rest."""
    assert_written_once(("return free and height > arm_height", "return height - tan_s * x",
                         "q[1] += pin[1] - ev_ground_y(tan_s, foot[0], foot[1])"),
                        (r"height > (self\.opt\.|L->)arm_height|\+= (L->)?pin\[[01]\] - |-= \w+(\.dheight|\[3\]) - "
                         r"|armed\[0\] = L->armed\[1\] = 0|self\.armed = \[False, False\]"))
    import biped_sim as bs
    from biped_sim.engine import guards as G, modes
    model, slope = bs.BipedModel(), 0.04
    q0, dq0 = bs.stance_state(model, [math.pi + 0.2, math.pi - 0.25, 0.1], [0.3, -0.4, 0.5])
    q, dq = (q0 + [1e-4, -2e-4, 0, 0, 0]).tolist(), (dq0 + [3e-3, 1e-3, 0, 0, 0]).tolist()
    foot = G.foot_states(model, q, dq, math.tan(slope))[0]
    pin = G.foot_xy(model, q0.tolist(), 1)
    qp, dqp, drift, rate = modes.project_onto_pin(q, dq, foot, pin, math.tan(slope))
    assert drift > 1e-4 and rate > 1e-3
    after = G.foot_states(model, qp, dqp, math.tan(slope))[0]
    assert abs(G.foot_xy(model, qp, 1)[0] - pin[0]) < 1e-15 and abs(G.foot_xy(model, qp, 1)[1] - pin[1]) < 1e-15
    assert abs(after.dx) < 1e-15 and abs(after.dheight) < 1e-15


def test_the_invariants_predicates_and_the_thinning_are_written_once():
    """The invariants' predicates (a finite state, a value below zero beyond its tolerance) and the sample's
    thinning are the rules' (loop_rules.py): invariants.py, locator.py, results.py and _core.c call them."""
    assert_written_once(("return value < -tol", "return isfinite(s + sd)",
                         "return appended > 1 and (every == 0 or (appended - 1) % every != 0)"),
                        (r"< -(\w+\.)*(\w+->)?(ground|force|impulse)_tol|>= -(\w+\.)*(ground|force)_tol"
                         r"|isfinite\(sum\(q\)|isfinite\(s \+ sd\)|\(appended - 1\) % \w*\.?every"))
    from biped_sim.engine import results
    samples = results.Samples(keep=3)
    for k in range(8):
        samples.append(float(k), [0.0] * 5, [0.0] * 5, 1, [0.0, 0.0], [0.0, 0.0], 0.0)
    assert samples.n == 4 and list(samples._data[:samples.n, 0]) == [0.0, 3.0, 6.0, 7.0]     # the newest last


def test_the_compiled_rules_touch_no_python_object():
    """The C of every rule (loop_rules.pxd's functions, in _loop_rules.c) calls nothing of Python: no
    object, no exception check (Cython's cdivision and noexcept, the state a double *)."""
    c = (ENGINE / "_loop_rules.c").read_text()
    names = re.findall(r"^cdef (?:public )?\w+ (\w+)\(", (ENGINE / "loop_rules.pxd").read_text(), re.M)
    assert len(names) >= 10
    for name in names:
        head = rf"\n(?:static )?(?:int|long|void|double) (?:__pyx_f_\w+_)?{name}\("
        m = re.search(head + r"(?:double \*|double |int |long )__pyx_v_\w+[^)]*\) {\n(.*?)\n}\n", c, re.S)
        assert m, name
        code = [line for line in m.group(1).splitlines() if not line.lstrip().startswith(("/*", "*"))]
        assert not [line for line in code if re.search(r"PyObject|__Pyx_|PyErr", line)], name


@pytest.mark.skipif(not compiled_loop.AVAILABLE, reason=f"no compiled loop: {compiled_loop.WHY_NOT}")
def test_without_cython_the_python_rules_give_the_compiled_bits():
    """In a process where Cython cannot be imported, the rules run as Python through the shim, and the walk
    (held 1 ms and continuous, dop853 and dopri5) gives the compiled loop's bits."""
    script = """
import hashlib, sys
sys.modules["cython"] = None          # as if Cython were not installed
import numpy as np
import biped_sim as bs
from biped_sim.engine import compiled_loop, loop_rules
assert loop_rules.cython.__name__ == "biped_sim.engine._cython_shim", loop_rules.cython
for method in ("dop853", "dopri5"):
    for hold in (True, False):
        r = bs.load_scene("walk").simulate(hold=hold, method=method, t_final=1.2)
        h = hashlib.sha256(b"".join(np.ascontiguousarray(a).tobytes() for a in (r.t, r.q, r.dq, r.u, r.grf)))
        print(compiled_loop.AVAILABLE, len(r.impacts), h.hexdigest())
"""
    runs = {}
    for pure in ("1", "0"):
        out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                             env={**os.environ, "BIPED_SIM_PURE_PYTHON": pure})
        assert out.returncode == 0, out.stderr
        runs[pure] = out.stdout.split("\n")
    assert all(line.startswith("False") for line in runs["1"] if line)
    assert all(line.startswith("True") for line in runs["0"] if line)
    assert [line.split()[1:] for line in runs["1"]] == [line.split()[1:] for line in runs["0"]]
    assert all(int(line.split()[1]) >= 2 for line in runs["1"] if line)      # touchdowns were located



def test_the_impact_and_its_checks_are_written_once():
    """The one-foot impact (the generated impact map, the energy before and after, the feet after) and its checks
    (an impulse that pulls or lies outside the friction cone, the old stance foot moving into the ground or not
    leaving it) are the rules' (loop_rules.ev_impact): resets.py, invariants.py and _core.c's touchdown call them."""
    assert_written_once(("return fabs(tg) - mu * n > tol", "return dheight < tol",
                         "k_impact_map(S, leg, Q_IMPACT, DQ_MINUS, DQ_PLUS)"),
                        (r"k_impact_map_[12]\(|k_energy\(q, dq[mp]\b|fabs\(tg\w*\) > |abs\(tg\) (-|>) mu \* n"
                         r"|\[old - 1\]\.dheight < |\.dheight < rest_tol|\[3\] < (0\b|L->contact_tol)|\bn_imp < 0"))


def test_the_impact_rule_gives_the_impact_map_and_says_which_check_refused():
    """Run as Python, ev_impact gives dynamics.impact_map's dq+ and impulse and the energy's loss, bit for bit, and
    its bits say which assumption the impact violates: none for a foot landing forward on a grippy ground, the
    cone where mu is 0, the pull where the foot is moving up, the old stance foot where it goes on sinking."""
    import numpy as np

    import biped_sim as bs
    from biped_sim.engine import guards as G, loop_rules as rules, resets
    from biped_sim.engine.dynamics import impact_map_fast
    from biped_sim.engine.loop_state import (
        DQ_MINUS,
        DQ_PLUS,
        ENERGY_AFTER,
        ENERGY_BEFORE,
        FEET_AFTER,
        IMPACT_OLD_FOOT_SINKS,
        IMPACT_OUTSIDE_CONE,
        IMPACT_PULLS,
        IMPULSE,
        Q_IMPACT,
    )
    model, ground = bs.BipedModel(), G.Ground.of(0.03)
    q, _ = bs.stance_state(model, [math.pi + 0.25, math.pi - 0.25, 0.1], [0.0, 0.0, 0.0])
    ctrl = bs.WalkingController(model)
    _, dq_walk = ctrl.initial_state()

    def impact(dq, mu, old=1):
        S = resets.touchdown_state(model, ground, mu)
        S[Q_IMPACT:Q_IMPACT + 5], S[DQ_MINUS:DQ_MINUS + 5] = q.tolist(), list(dq)
        return rules.ev_impact(S, 2, old, mu is not None), S

    dq = [0.3, -0.2, *dq_walk[2:].tolist()]
    checks, S = impact(dq, 10.0)
    dq_plus, impulse = impact_map_fast(model, q, np.array(dq), 2)
    assert S[DQ_PLUS:DQ_PLUS + 5] == dq_plus.tolist() and S[IMPULSE:IMPULSE + 2] == impulse.tolist()
    loss = model.energy_fast(q.tolist(), dq) - model.energy_fast(q.tolist(), dq_plus.tolist())
    assert S[ENERGY_BEFORE] - S[ENERGY_AFTER] == loss and loss > 0
    feet = G.foot_states(model, q.tolist(), dq_plus.tolist(), ground.tan)
    assert S[FEET_AFTER:FEET_AFTER + 8] == [v for foot in feet for v in foot]
    n, tg = G.normal_tangent(impulse, ground)
    assert n > 0 and tg != 0
    assert checks == 0 and feet[0].dheight > 0          # the old stance foot leaves the ground
    falling = [0.0, -0.5, 0.0, 0.0, 0.0]                 # the whole robot falling: the old foot keeps sinking
    assert impact(falling, 10.0)[0] == IMPACT_OLD_FOOT_SINKS
    assert impact(dq, 0.0)[0] & IMPACT_OUTSIDE_CONE and not impact(dq, None)[0] & IMPACT_OUTSIDE_CONE
    up = [-v for v in dq]            # the swing foot moving up: the ground would have to pull it down
    assert impact(up, 10.0)[0] & IMPACT_PULLS
    assert not impact(dq, 10.0, old=0)[0] & IMPACT_OLD_FOOT_SINKS        # from flight: no old stance foot


def test_the_stance_start_is_written_once():
    """How a stance starts (the ground pulls: a liftoff at once; outside the friction cone with the slip witness
    watched: a slip at once) is the rule ev_stance_start: hybrid's _check_stance_start and _core.c's touchdown
    (the new stance) and refused_at_start (a period's start) call it."""
    assert_written_once(("if slip_watched and ev_slip_margin(mu, n, tg) < 0.0",),
                        (r"normal_force\(L->S, [\w>-]+\[0\], [\w>-]+\[1\]\) < 0\.0|cone_margin\(L->S, [^)]*\) < 0\.0"
                         r"|slip_guard\(n, tg, self\.mu\) < 0\.0"))
    from biped_sim.engine import loop_rules as rules
    from biped_sim.engine.loop_state import STANCE_HOLDS, STANCE_LIFTS_OFF, STANCE_SLIPS
    assert rules.ev_stance_start(True, 0.5, -1e-12, 0.0) == STANCE_LIFTS_OFF
    assert rules.ev_stance_start(True, 0.5, 100.0, 60.0) == STANCE_SLIPS
    assert rules.ev_stance_start(False, 0.5, 100.0, 60.0) == STANCE_HOLDS        # latched, or no mu
    assert rules.ev_stance_start(True, 0.5, 100.0, 50.0) == STANCE_HOLDS         # on the cone's edge
    assert rules.ev_stance_start(True, 0.0, 0.0, 0.0) == STANCE_HOLDS


def test_the_impact_history_predicates_are_written_once():
    """A gap of a Zeno run, the events' budget, an event loop and impacts that accumulate (the Zeno limit, where a
    crossing is an impact and never a scuff) are the rules' (loop_rules.py): invariants.ImpactHistory,
    HybridSimulator._add_event and _core.c's touchdown and quiet step call them with the history's values."""
    assert_written_once(("return n_before > 0 and t - t_before < interval", "return n_events >= max_events",
                         "return n_events >= 50 and t_last - t_first < 1e-9",
                         "return g0 > g1 and g1 > g2 and g2 <= 0.5 * g0 and t - times[3] < g2"),
                        (r"- (L->)?last_impact < |mode_events \+ 1 >= |>= self\.opt\.max_events"
                         r"|recent\[-1\] - recent\[0\]|ring\[[^]]*\] < 1e-9|g\[0\] > g\[1\] > g\[2\]"
                         r"|g2 <= 0\.5 \* g0|b - a < self\.interval"))
    from biped_sim.engine import loop_rules as rules
    from biped_sim.engine.invariants import ImpactHistory
    assert rules.ev_impacts_close(1, 1.0, 1.0 + 5e-7, 1e-6) and not rules.ev_impacts_close(0, 1.0, 1.0 + 5e-7, 1e-6)
    assert rules.ev_over_budget(10, 10) and not rules.ev_over_budget(9, 10)
    assert rules.ev_event_loop(50, 2.0, 2.0 + 5e-10) and not rules.ev_event_loop(49, 2.0, 2.0)
    assert not rules.ev_event_loop(60, 2.0, 2.0 + 2e-9)
    history = ImpactHistory(zeno_count=3, zeno_interval=1e-3)
    for t in (0.0, 0.4, 0.6, 0.7):              # gaps 0.4, 0.2, 0.1: each at most half the one before
        assert history.record(t) is None
    assert history.accumulating(0.75) and not history.accumulating(0.85)     # sooner than the last gap, or not
    assert not ImpactHistory(3, 1e-3).accumulating(0.75)                    # no impacts yet
    assert [history.record(0.7 + k * 1e-4) for k in (1, 2)] == [None, None]
    assert "3 impacts in a row less than 0.001 s apart" in history.record(0.7 + 3e-4)


def test_the_compiled_loop_reads_no_python_attribute_by_name():
    """_core.c reads and writes the run's fields in the state (the simulator's, which its Samples and its locator
    view: loop_state.py) and takes the samples' array as an argument, so that renaming a Python attribute cannot
    break the compiled loop at run time: no attribute of a Python object is read, written or called by name."""
    core = (ENGINE / "_core.c").read_text()
    by_name = re.findall(r"PyObject_(?:Get|Set|Has|Del)Attr\w*|PyObject_CallMethod\w*|PyUnicode_InternFromString"
                         r"|_PyObject_\w*Id\b", core)
    assert by_name == []


def test_the_control_periods_rules_are_written_once():
    """The control period under way at t (a bisection: a run may start late) and when it ends are the rules'
    (loop_rules.py): HybridSimulator.advance_period and _core.c's periods and period call them."""
    assert_written_once(("if (k + 1) * period > t:", "if t_final > 0 and t_next >= t_final - 1e-9 * period:"),
                        r"\(\w+ \+ 1\) \* period <= t|>= t_final - 1e-9 \* period")
    from biped_sim.engine import loop_rules as rules
    assert rules.ev_period_index(0.3, 0.1, 0) == 2          # 3 * 0.1 > 0.3 in floating point: period 2 is under way
    assert rules.ev_period_index(1e5, 1e-3, 7) == 100000000 and rules.ev_period_index(0.05, 0.1, 4) == 4
    assert rules.ev_period_index(2.0 ** 60, 1.0, 0) == -1   # refused: beyond 2^53 periods
    assert rules.ev_period_end(2, 0.1, 0.0) == 3 * 0.1 and rules.ev_period_end(9, 0.1, 1.0 + 1e-12) == 1.0 + 1e-12


def test_the_divergence_check_is_written_once():
    """A diverging state (a speed beyond max_speed) is the rules' (loop_rules.py): HybridSimulator._integrate and
    _core.c's quiet step call it."""
    assert_written_once(("return top > max_speed",), r"max\(map\(abs, dq\)\)|top <= L->max_speed|fabs\(dq\[i\]\) > top")
    from biped_sim.engine import loop_rules as rules
    assert rules.ev_diverging([0.0, -2.0, 1.0, 0.5, 0.0], 5, 1.5) and not rules.ev_diverging([1.5, -1.5], 2, 1.5)
    assert not rules.ev_diverging([0.0, 0.0, 0.0, 0.0, 2.0], 4, 1.5)      # the first n entries only


def test_the_energy_balance_residual_is_written_once():
    """The energy balance's residual is the rules' (loop_rules.py): HybridSimulator._record and _core.c's quiet step
    and touchdown (before and after the impact) call it."""
    assert_written_once(("return energy - e0 - work - push_work + energy_lost",),
                        r"S\[E0\] - |- E0 - w\b|- e0 - |- push_work \+ ")
    from biped_sim.engine import loop_rules as rules
    assert rules.ev_energy_residual(10.0, 9.0, 0.75, 0.5, 0.25) == 0.0
    assert rules.ev_energy_residual(1.0, 0.1, 0.2, 0.3, 0.0) == ((1.0 - 0.1) - 0.2) - 0.3   # in this order


def test_the_runs_running_maxima_are_written_once():
    """The run's statistics (the largest constraint drift, its rate, |residual|) are kept by the rules'
    (loop_rules.py) running maximum: HybridSimulator._project and _record and _core.c's quiet steps call it."""
    assert_written_once(("return v if v > m else m",),
                        r"\bmax\(s\[\"max_|\bmax\(self\._stats\[|(drift|rate|residual) > L->max_|fabs\(res_e\) > ")
    from biped_sim.engine import loop_rules as rules
    assert rules.ev_running_max(1.0, 2.0) == 2.0 and rules.ev_running_max(2.0, 1.0) == 2.0
    assert rules.ev_running_max(1.0, math.nan) == 1.0     # as max(m, v)


def test_what_a_sample_holds_is_written_once():
    """A sample's row (t, q, dq, the stance leg, F, u, the residual) is composed by the rules (loop_rules.py):
    results.Samples.append and _core.c's quiet step and touchdown call it."""
    assert_written_once(("row[ROW_Q + 2 * n + 3 + m] = residual",),
                        r"\[t, \*q, \*dq|\brows?\[1[1-6]\] = |rows\[(1[7-9]|2\d|3[0-3])\] = ")
    import numpy as np

    from biped_sim.engine.results import Samples
    samples = Samples()
    samples.append(0.5, np.arange(5.0), [5.0, 6.0, 7.0, 8.0, 9.0], 2, [10.0, 11.0], [12.0, 13.0], 14.0)
    assert samples.rows().tolist() == [[0.5, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 2.0, 10.0, 11.0, 12.0,
                                        13.0, 14.0]]
    wide = Samples(n=7, m=4)        # a described robot's (RABBIT's): 7 coordinates, 4 actuators
    wide.append(0.5, np.arange(7.0), np.arange(7.0, 14.0), 1, [20.0, 21.0], [30.0, 31.0, 32.0, 33.0], 40.0)
    assert wide.rows().tolist() == [[0.5, *range(14), 1.0, 20.0, 21.0, 30.0, 31.0, 32.0, 33.0, 40.0]]
    assert wide.last()[4:] == ([20.0, 21.0], [30.0, 31.0, 32.0, 33.0], 40.0)


def test_the_torques_check_is_written_once():
    """Two torques are taken where they and their sum are finite, by the rules' check (loop_rules.py):
    modes.two_finite_floats (a law's command, a held torque) and _core.c's two_finite and two_finite_array call it."""
    assert_written_once(("return isfinite(u0 + u1)",), r"isfinite\(u0 \+ u1\)|isfinite\(out\[0\] \+ out\[1\]\)")
    from biped_sim.engine import loop_rules as rules
    from biped_sim.engine.modes import two_finite_floats
    assert rules.ev_finite_torques(1.0, -2.0) and not rules.ev_finite_torques(1e308, 1e308)
    assert not rules.ev_finite_torques(math.inf, -math.inf) and not rules.ev_finite_torques(math.nan, 0.0)
    assert two_finite_floats((1e308, 1e308)) is None and two_finite_floats([1.0, 2]) == [1.0, 2.0]


def test_whether_another_control_period_runs_is_written_once():
    """A run of control periods goes on before t_final and before a push due at t_stop (within 1e-9 period): the
    rules' (loop_rules.py), which HybridSimulator.advance_periods and _core.c's periods call."""
    assert_written_once(("return t < t_final and t_stop > t + 1e-9 * period",), r"t_stop > (self|L->)\.?t \+ tol")
    from biped_sim.engine import loop_rules as rules
    assert rules.ev_next_period_runs(0.0, 1.0, math.inf, 1e-3)
    assert not rules.ev_next_period_runs(1.0, 1.0, math.inf, 1e-3)         # t_final reached
    assert not rules.ev_next_period_runs(0.5 - 1e-13, 1.0, 0.5, 1e-3)      # the push is due: within 1e-12 s
    assert rules.ev_next_period_runs(0.5 - 1e-11, 1.0, 0.5, 1e-3)


def test_counting_a_change_of_mode_is_written_once():
    """A change of mode is counted, and the time 49 events before the next one read, on the state's ring by the
    rules (loop_rules.py): HybridSimulator._add_event and _core.c's touchdown call them."""
    assert_written_once(("S[RING + m % 49] = t",), r"% 49\] = |\[RING \+ |ring\[")
    from biped_sim.engine import loop_rules as rules
    S = loop_state.new_state()
    for i in range(60):
        assert rules.ev_ring_oldest(S) == (float(i - 49) if i >= 49 else 0.0)
        rules.ev_count_mode_event(S, float(i))
    assert S[loop_state.MODE_EVENTS] == 60


def test_counting_an_impact_is_written_once():
    """An impact is counted in the state's impact history (the last one, their count, the last four) by the rules
    (loop_rules.py): ImpactHistory.record and _core.c's touchdown call it."""
    assert_written_once(("S[RECENT_IMPACTS + n - 1] = t",), r"RECENT_IMPACTS \+ n - 1\] = |recent_impacts\[[^]]*\] = "
                                                           r"|n_impacts\+\+|last_impact = t")
    from biped_sim.engine import loop_rules as rules
    S = loop_state.new_state()
    for t in (1.0, 2.0, 3.0, 4.0, 5.0, 6.0):
        rules.ev_count_impact(S, t)
    R = loop_state.RECENT_IMPACTS
    assert S[R:R + 4] == [3.0, 4.0, 5.0, 6.0] and S[loop_state.N_RECENT] == 4
    assert S[loop_state.N_IMPACTS] == 6 and S[loop_state.LAST_IMPACT] == 6.0


def test_the_motor_power_is_written_once():
    """The motors' power u . (dq1, dq2), the motor work's integrand, is the rules' (loop_rules.py): the Python modes'
    right-hand sides (modes.py) and _core.c's call it."""
    assert_written_once(("return u[0] * dq1 + u[1] * dq2",), r"u\[0\] \* \w+\[\d\] \+ u\[1\] \* \w+\[\d\]")
    from biped_sim.engine import loop_rules as rules
    assert rules.ev_motor_power([2.0, -3.0], 0.5, 0.25) == 0.25


def test_where_a_sample_goes_is_written_once():
    """The row a new sample takes (the only one, the provisional one's, or a new one) is the rules' (loop_rules.py):
    results.Samples.append and _core.c's quiet steps call it."""
    assert_written_once(("return n - 1",), r"last_only \? 0 : |elif S\[PROVISIONAL\]:\n\s+n -= 1")
    from biped_sim.engine import loop_rules as rules
    assert [rules.ev_sample_slot(5, p, o) for p, o in ((False, False), (True, False), (True, True))] == [5, 4, 0]


def test_the_energy_an_impact_takes_is_written_once():
    """The energy an impact took (T + V before minus after) is the rules' (loop_rules.py): resets.touchdown_reset
    and _core.c's touchdown call it on the state ev_impact wrote."""
    assert_written_once(("return S[ENERGY_BEFORE] - S[ENERGY_AFTER]",),
                        r"S\[ENERGY_BEFORE\] - S\[ENERGY_AFTER\]|energy_before - L->energy_after")
    from biped_sim.engine import loop_rules as rules
    S = loop_state.new_state()
    S[loop_state.ENERGY_BEFORE], S[loop_state.ENERGY_AFTER] = 10.0, 9.25
    assert rules.ev_impact_loss(S) == 0.75


def test_whether_a_time_lies_in_the_last_step_is_written_once():
    """Whether an ended scuff's deepest point lies in the last step (its state then recorded from the dense output)
    is the rules' (loop_rules.py): EventLocator._scuff_event and _core.c's quiet step call it."""
    assert_written_once(("return t_old <= tt and tt <= t",), r"t_old <= \w+(\[\d\])? (<=|&& )")
    from biped_sim.engine import loop_rules as rules
    assert rules.ev_within_step(1.0, 2.0, 1.0) and rules.ev_within_step(1.0, 2.0, 2.0)
    assert not rules.ev_within_step(1.0, 2.0, 0.5) and not rules.ev_within_step(1.0, 2.0, math.nan)


def test_the_carried_step_size_is_written_once():
    """The step size a mode starts with, the one carried over capped by max_step, is the rules' (loop_rules.py):
    the Python steppers' restart, the compiled stepper's start and _core.c's carry_step call it."""
    assert_written_once(("return max_step if max_step < h else h",),
                        r"\bmin\(S\[H_ABS\], self\.max_step\)|MAX_STEP\] if S\[MAX_STEP\] < |max_step < h \?")
    from biped_sim.engine import loop_rules as rules
    assert rules.rk_carried_step(1e-3, math.inf) == 1e-3 and rules.rk_carried_step(1e-3, 1e-4) == 1e-4


def test_the_feet_layout_and_the_new_pin_are_written_once():
    """How the feet's states are laid out from their kinematics (per foot x, height across the ground, their rates)
    and the pin taken from the feet's positions are the rules' (loop_rules.py): guards.foot_states, ev_impact,
    guards.foot_xy and _core.c's feet() and touchdown() call them. The layout is the kinematics' across the slope."""
    assert_written_once(("ft[j + 1] = ev_across(", "point[0] = p[2 * leg - 2]"),
                        r"ev_across\(\w+, p\[\d\]|across\(t, p\dx|FEET_AFTER \+ 4 \* i|\[0\] = p\[2 \* \w+ - 2\]"
                        r"|return p\[2 \* leg - 2\]")
    import biped_sim as bs
    from biped_sim.engine import guards as G
    from biped_sim.engine.compiled import gen
    model, tan_s = bs.BipedModel(), math.tan(0.04)
    q, dq = [0.1, 0.2, math.pi + 0.2, math.pi - 0.25, 0.1], [0.3, -0.1, 0.3, -0.4, 0.5]
    p1x, p1y, p2x, p2y, v1x, v1y, v2x, v2y = gen.foot_kinematics(q, dq, model.k["foot_kinematics"])
    assert G.foot_states(model, q, dq, tan_s) == ((p1x, p1y + tan_s * p1x, v1x, v1y + tan_s * v1x),
                                                  (p2x, p2y + tan_s * p2x, v2x, v2y + tan_s * v2x))
    assert G.foot_xy(model, q, 2) == (p2x, p2y) and G.foot_xy(model, q, 1) == (p1x, p1y)


def test_the_energy_lost_so_far_is_written_once():
    """The running sum of the energy the impacts took out is the rules' (loop_rules.py): HybridSimulator._take_impact
    and _core.c's touchdown() call it."""
    assert_written_once(("return energy_lost + loss",), r"energy_lost \+= |energy_lost \+ loss")
    from biped_sim.engine import loop_rules as rules
    assert rules.ev_energy_lost_after(1.5, 0.25) == 1.75


def test_how_a_scuff_starts_is_written_once():
    """A scuff's start (its row t_start, deepest, t_deepest and the count of the scuffs) is the rules'
    (loop_rules.py): EventLocator._is_scuff and _core.c's quiet step call it."""
    assert_written_once(("scuff[i + 1] = 0.0",),
                        r"scuffs\+\+|scuffs \+= 1|\[t_root, 0\.0, t_root\]|\[0\] = scuff\[2\] = t_root")
    from biped_sim.engine import loop_rules as rules
    S = loop_state.new_state()
    assert rules.ev_start_scuff(S, loop_state.SCUFF + 3, 0.5, 2) == 3
    assert S[loop_state.SCUFF + 3:loop_state.SCUFF + 6] == [0.5, 0.0, 0.5]


def test_a_scuff_under_way_at_the_start_is_the_rules():
    """A start whose free foot lies under the ground where its crossing would be a scuff begins as a scuff: the
    rule (loop_rules.ev_scuff_under_way, which EventLocator's start calls) arms and flags the foot, begins its row
    at t0 with the start's depth as its deepest dip, counts it and raises deepest_scuff to it."""
    from biped_sim.engine import loop_rules as rules
    S = loop_state.new_state()
    S[loop_state.SCUFFS], S[loop_state.DEEPEST_SCUFF] = 2.0, 1e-3
    rules.ev_scuff_under_way(S, 2, 0.25, 4e-3)
    assert S[loop_state.ARMED:loop_state.ARMED + 2] == [0.0, 1.0]
    assert S[loop_state.SCUFFING:loop_state.SCUFFING + 2] == [0.0, 1.0]
    assert S[loop_state.SCUFF + 3:loop_state.SCUFF + 6] == [0.25, 4e-3, 0.25]
    assert (S[loop_state.SCUFFS], S[loop_state.DEEPEST_SCUFF]) == (3.0, 4e-3)


def test_the_step_ends_cache_is_written_once():
    """The feet and the stance force kept at a step's end for the next step's start (their layout in the state, with
    their times) are the rules' (loop_rules.py): EventLocator.locate, its setters and _core.c's cache_step_end call
    them."""
    assert_written_once(("S[FEET_END + k] = ft[i + k]", "S[FORCE_END + 1] = fy"),
                        r"put\(\w+(\.S)?, FEET_END,|S\[FORCE_END\], S\[FORCE_END \+ 1\] = |memcpy\(L->feet_end,"
                        r"|L->force_end\[\d\] = ")
    from biped_sim.engine import loop_rules as rules
    S = loop_state.new_state()
    rules.ev_keep_feet_end(S, 0.5, [9.0, *range(8)], 1)
    rules.ev_keep_force_end(S, 0.25, 3.0, 4.0)
    assert S[loop_state.FEET_END:loop_state.FEET_END + 8] == list(range(8)) and S[loop_state.FEET_END_T] == 0.5
    assert S[loop_state.FORCE_END:loop_state.FORCE_END + 2] == [3.0, 4.0] and S[loop_state.FORCE_END_T] == 0.25


def test_the_sample_rows_layout_is_declared_once():
    """A sample row's layout (where t, q, dq, the leg, F, u and the residual lie, and its width) is declared once
    (loop_state.SAMPLE_ROW, generated into _loop_state.h): ev_sample_row, results.Samples and _core.c's runs
    (the rows they copy, the last sample's q and dq read back) use its names."""
    assert re.search(r'"ROW_WIDTH": 17\b', (ENGINE / "loop_state.py").read_text())
    written_again = r"\b17 \*|[*+=] 17\b|\[1:6\]|\[6:11\]|row\[1\d\] = |\[34\]"
    for path in [*ENGINE.glob("*.py"), ENGINE / "_core.c"]:
        if path.name != "loop_state.py":
            assert not re.search(written_again, path.read_text()), path.name
    from biped_sim.engine import loop_rules as rules, results
    row = [0.0] * loop_state.ROW_WIDTH
    rules.ev_sample_row(row, 0.5, [1.0, 2.0, 3.0, 4.0, 5.0], [6.0, 7.0, 8.0, 9.0, 10.0], 2, [11.0, 12.0], [13.0, 14.0],
                        15.0)
    samples = results.Samples()
    samples.append(0.5, [1.0, 2.0, 3.0, 4.0, 5.0], [6.0, 7.0, 8.0, 9.0, 10.0], 2, [11.0, 12.0], [13.0, 14.0], 15.0)
    t, q, dq, leg, F, u, residual = samples.last()
    assert [t, *q, *dq, leg, *F, *u, residual] == row == [0.5, *range(1, 11), 2, *range(11, 16)]


def test_forgetting_and_finding_the_step_ends_cache_is_written_once():
    """Whether the feet and the force kept are of the step's start, and their forgetting on a reset (NaN times),
    are the rules' (loop_rules.py): EventLocator.locate, its setters and _core.c's quiet step and touchdown() call
    them."""
    assert_written_once(("S[FEET_END_T] = NAN", "return S[FORCE_END_T] == t"),
                        r"(feet|force)_end_t = |(feet|force)_end_t == |S\[(FEET|FORCE)_END_T\] == "
                        r"|S\[(FEET|FORCE)_END_T\] = math\.nan")
    from biped_sim.engine import loop_rules as rules
    S = loop_state.new_state()
    rules.ev_keep_feet_end(S, 0.5, [0.0] * 8, 0)
    rules.ev_keep_force_end(S, 0.5, 1.0, 2.0)
    assert rules.ev_feet_kept_at(S, 0.5) and rules.ev_force_kept_at(S, 0.5) and not rules.ev_feet_kept_at(S, 0.25)
    rules.ev_forget_feet_end(S)
    rules.ev_forget_force_end(S)
    assert math.isnan(S[loop_state.FEET_END_T]) and math.isnan(S[loop_state.FORCE_END_T])
    assert not rules.ev_feet_kept_at(S, 0.5) and not rules.ev_force_kept_at(S, 0.5)
