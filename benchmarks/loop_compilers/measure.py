"""Measure the loop-compiler candidates of issue 29 on the slice of rules.py: bits, speed and costs.

``python -m benchmarks.loop_compilers.measure`` (about a minute; needs Cython and numba in the venv:
``uv pip install cython numba``) prints the markdown tables that docs/engine.md, "How the compiled loop is
made: the choice", reads. Candidates: ``python`` (rules.py run as Python), ``cython`` (rules.py compiled by
Cython, build.build_cython), ``numba`` (rules.py under numba.njit, numba_binding), beside ``hand C``
(``biped_sim.engine._core.Loop``, today's compiled loop; for the dip search, which it does not expose alone,
the Python engine's ``grazing.dip_bracket``).

Owns measurement only: every figure is a median over repeats in this one process (the first-call and
import latencies in fresh processes), and the tables say which command made them.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time
import timeit
from pathlib import Path

import numpy as np

from benchmarks.loop_compilers import build, rules as R
from biped_sim.engine import grazing, guards as G, integrators
from biped_sim.engine.model import BipedModel

MODEL = BipedModel()
ROOT = Path(__file__).resolve().parents[2]
TPB = integrators._DOP853Interpolant.TO_POWER_BASIS.ravel()
N = R.N


# -- inputs ---------------------------------------------------------------------------------------------------
_WALK = []
_LANDING = []


def walk_states():
    """Stance states (q, dq, stance leg) of the walk scene's first 3 s (its samples), computed once."""
    if not _WALK:
        import biped_sim as bs
        r = bs.load_scene("walk").simulate(t_final=3.0)
        _WALK.extend((r.q[i].copy(), r.dq[i].copy(), int(r.stance_leg[i])) for i in range(len(r.t)) if r.stance_leg[i])
    return _WALK


def landing_states():
    """Indices of the walk states from which one step (0.05 s tried, rtol 1e-9, as walked) carries the swing foot
    through the ground, by the hand C (every second state; computed once)."""
    if not _LANDING:
        for i in range(0, len(walk_states()), 2):
            if hand_outputs(make_case(i, np.zeros(5), (0.0, 0.0), 0.05, 1e-9, 0.0))["_brentq"]:
                _LANDING.append(i)
    return _LANDING


def make_case(i, noise, u, h_abs, tol, slope, graze_tol=1e-10):
    """One input: walk state i (modulo their number) with its velocities moved by ``noise`` (5), a held torque
    u (2), the step size to try, rtol = atol = tol, the ground's slope."""
    states = walk_states()
    q, dq, leg = states[i % len(states)]
    return {"q": q.tolist(), "dq": (dq + np.asarray(noise)).tolist(), "leg": leg, "u": list(u), "h_abs": h_abs,
            "tol": tol, "slope": slope, "graze_tol": graze_tol, "event_tol": 1e-13}


def random_cases(n, seed=0):
    """n inputs from the walk's states: a third as walked, from landing_states() with long steps (0.02 to 0.1 s
    tried, rtol 1e-10 to 1e-8: most carry the swing foot through the ground), a third as walked with any step and
    tolerance (0.1 ms to 0.1 s, 1e-11 to 1e-5), a third with their velocities and torques disturbed."""
    rng = np.random.default_rng(seed)
    cases = []
    for k in range(n):
        long_step, disturbed = k % 3 == 0, k % 3 == 2
        h_abs = float(rng.uniform(0.02, 0.1) if long_step else 10 ** rng.uniform(-4, -1))
        tol = float(10 ** rng.uniform(-10, -8) if long_step else 10 ** rng.uniform(-11, -5))
        i = int(rng.choice(landing_states())) if long_step else int(rng.integers(1 << 20))
        noise, u = rng.normal(0, 0.3 * disturbed, 5), rng.uniform(-20, 20, 2) * disturbed
        slope = 0.0 if long_step else float(rng.uniform(-0.1, 0.1))
        cases.append(make_case(i, noise, u, h_abs, tol, slope, float(10 ** rng.uniform(-12, -6))))
    return cases


def new_state(case):
    """The probe's state array S of a case, before begin()."""
    S = np.zeros(R.SIZE)
    S[0] = case["leg"]
    S[1:3] = case["u"]
    S[3:25] = MODEL.k_stance
    S[25:34] = MODEL.k["foot_positions"]
    S[R.TAN_S] = math.tan(case["slope"])
    S[R.RTOL] = S[R.ATOL] = case["tol"]
    S[R.MAX_STEP] = math.inf
    S[R.GRAZE_TOL] = case["graze_tol"]
    S[R.EVENT_TOL] = case["event_tol"]
    S[R.L_LEG] = MODEL.parameters.l_leg
    S[R.T_BOUND] = 1e9
    S[R.H_ABS] = case["h_abs"]
    S[R.Y:R.Y + N] = case["q"] + case["dq"] + [0.0]
    S[R.TO_POWER_BASIS:R.TO_POWER_BASIS + 64] = TPB
    return S


def hand_loop(case):
    """Today's compiled loop (_core.Loop) at the case's start, as compiled_loop.CompiledStepper builds it."""
    from biped_sim.engine import _core
    loop = _core.Loop()
    loop.set_model(MODEL.k_stance, MODEL.k["foot_kinematics"], MODEL.k["foot_positions"], MODEL.k["energy"],
                   MODEL.k["stance_terms_1"], MODEL.k["impact_map_1"], MODEL.parameters.l_leg)
    loop.set_options(case["tol"], case["tol"], math.inf, 1e4, 1e-9, 1e-6, case["graze_tol"], 1e-9, None, False, False,
                     False, False, case["slope"], TPB.tolist(), 1e-5, math.inf, case["event_tol"], True, True)
    begin_hand(loop, case)
    return loop


def begin_hand(loop, case):
    loop.begin(0, case["leg"], 0.0, 0.0, None, case["u"][0], case["u"][1], 0.0, case["q"] + case["dq"] + [0.0], 1e9,
               case["h_abs"], True)


# -- what each implementation computes on a case ----------------------------------------------------------
def _hex(values):
    return [float(v).hex() for v in values]


def times_in_step(t_old, t):
    return [t_old, t] + [t_old + k * (t - t_old) / 7 for k in range(1, 7)]


def outputs(impl, case):
    """The slice's results on a case by a rules.py implementation (a module): the step, the dense state at 8
    times, both feet's heights there, the swing foot's crossing over the step and over its halves, its dip
    search; as hex strings (bit for bit)."""
    S = new_state(case)
    impl.begin(S)
    rc = impl.step(S)
    out = {"step": [rc]}
    if rc < 0:
        out["step"] += _hex([S[R.FAIL_KIND], S[R.FAIL_VALUE], S[R.FAIL_T]])
        return out
    out["step"] += _hex([S[R.T], S[R.T_OLD], S[R.H], S[R.H_ABS], *S[R.Y:R.Y + N], *S[R.Y_OLD:R.Y_OLD + N],
                         *S[R.F:R.F + N], S[R.NFEV], S[R.NREJECTED], S[R.NACCEPTED]])
    t_old, t = S[R.T_OLD], S[R.T]
    ts = times_in_step(t_old, t)
    out["dense"] = []
    for tt in ts:
        impl.dense_state(S, tt)
        out["dense"] += _hex(S[R.OUT:R.OUT + N])
    out["height"] = _hex([impl.height_at(S, leg, tt) for leg in (1, 2) for tt in ts])
    swing = 3 - case["leg"]
    out["crossing"] = []
    for ta, tb in ((t_old, t), (t_old, ts[5]), (ts[5], t)):
        rc = impl.locate_crossing(S, swing, ta, tb)
        out["crossing"] += [rc] + (_hex([S[R.RESULT]]) if rc == 0 else [])
    h0, h1 = impl.height_at(S, swing, t_old), impl.height_at(S, swing, t)
    rc = impl.may_dip(S, swing, h0, h1)
    out["dip"] = [rc] + (_hex(S[R.RESULT:R.RESULT + 2]) if rc else [])
    out["dip bound"] = _hex([S[R.RESULT + 2]])   # (not in the hand C's results: compared with the Python run)
    return out


class _HandStep:
    """The hand C loop's last step as grazing.dip_bracket reads a stepper (its dense output's rows)."""

    def __init__(self, loop):
        self.t, self.t_old = loop.state()[:2]
        self.rows = [tuple(r) for r in loop.dense_rows()]

    def dense_output(self):
        return integrators._DOP853Interpolant(self.t_old, self.t, self.rows)


def hand_outputs(case):
    """outputs() by today's code: _core.Loop's step, dense_at and locate_crossing; the heights by
    guards.foot_height on its dense output; the dip search by grazing.dip_bracket (the Python engine)."""
    loop = hand_loop(case)
    fail = loop.step()
    if fail is not None:
        return {"step": [-1] + _hex(fail)}
    t, t_old, h, h_abs, y, y_old, f, nfev, nrejected, naccepted = loop.state()
    out = {"step": [0] + _hex([t, t_old, h, h_abs, *y, *y_old, *f, nfev, nrejected, naccepted])}
    ts = times_in_step(t_old, t)
    out["dense"] = [v for tt in ts for v in _hex(loop.dense_at(tt))]
    tan = math.tan(case["slope"])

    def height(leg, tt):
        return G.foot_height(MODEL, np.array(loop.dense_at(tt)[:5]), leg, tan)
    out["height"] = _hex([height(leg, tt) for leg in (1, 2) for tt in ts])
    swing = 3 - case["leg"]
    out["crossing"] = []
    for ta, tb in ((t_old, t), (t_old, ts[5]), (ts[5], t)):
        root = loop.locate_crossing(swing, ta, tb)
        out["crossing"] += [-1] if root is None else [0] + _hex([root])
    h0, h1 = height(swing, t_old), height(swing, t)
    bracket = grazing.dip_bracket(_HandStep(loop), None, lambda tt: height(swing, tt), swing, case["leg"], False,
                                  MODEL.parameters.l_leg, tan, h0, h1, case["graze_tol"])
    out["dip"] = [0] if bracket is None else [1] + _hex(bracket)
    # (not compared: how much of the slice the case exercised) brentq's iterations ran; a dip between two
    # ends above the ground was found
    out["_brentq"] = loop.locate_crossing(swing, t_old, t) not in (None, t_old, t)
    out["_dip"] = bracket is not None and h0 > 0 and h1 > 0
    return out


def implementations(with_cython=True, with_numba=True):
    """{name: rules module} of the candidates this machine can build, and {name: why not} of the others."""
    impls, missing = {"python": R}, {}
    if with_cython:
        try:
            impls["cython"] = build.build_cython()[0]
        except (ImportError, OSError, subprocess.CalledProcessError) as e:
            missing["cython"] = f"{type(e).__name__}: {e}"
    try:
        impls["translator"] = build.build_translated()[0]
    except (OSError, subprocess.CalledProcessError) as e:
        missing["translator"] = f"{type(e).__name__}: {e}"
    if with_numba:
        try:
            from benchmarks.loop_compilers import numba_binding
            impls["numba"] = numba_binding.load(build.build_glue_so()[0])
        except (ImportError, OSError, subprocess.CalledProcessError) as e:
            missing["numba"] = f"{type(e).__name__}: {e}"
    return impls, missing


def compare_bits(impls, cases):
    """{name: {part: mismatching cases}} against the hand C (its Python engine for the dip; the Python run of
    rules.py for the dip's bound, which neither gives), and how much of the slice the cases exercised."""
    mismatches = {name: {} for name in impls}
    seen = {"brentq roots": 0, "dips between ends above": 0, "failed steps": 0, "steps with rejections": 0}
    for case in cases:
        ref = hand_outputs(case)
        seen["brentq roots"] += ref.get("_brentq", False)
        seen["dips between ends above"] += ref.get("_dip", False)
        seen["failed steps"] += ref["step"][0] < 0
        seen["steps with rejections"] += ref["step"][0] == 0 and float.fromhex(ref["step"][-2]) > 0
        python = outputs(R, case)
        for name, impl in impls.items():
            got = outputs(impl, case) if name != "python" else python
            for part in got:      # against the hand C; what it does not give, against the Python run
                if got[part] != (ref[part] if part in ref else python[part]):
                    mismatches[name][part] = mismatches[name].get(part, 0) + 1
    return mismatches, seen


# -- speed ----------------------------------------------------------------------------------------------------
def _median_ns(fn, number, repeat=7, setup=None):
    kw = {"setup": setup} if setup else {}
    return statistics.median(timeit.repeat(fn, number=number, repeat=repeat, **kw)) / number * 1e9


def speed(impls, n_steps=100):
    """ns per call of each part of the slice, called from Python (the compiled candidates' steps also inside
    compiled code, ``steps(S, n)``), on one case of the walk with a crossing in its first step; and of a call
    that does nothing (``steps(S, 0)``; the hand C's ``Loop.counts()``): the price of the entry alone."""
    case = crossing_case()
    rows = {}
    for name, impl in list(impls.items()) + [("hand C", None)]:
        r = rows[name] = {}
        if impl is None:
            loop = hand_loop(case)
            r["a call doing nothing"] = _median_ns(loop.counts, 20000)
            r["step (from Python)"] = _median_ns(lambda: [loop.step() for _ in range(n_steps)], 1,
                                                 setup=lambda: begin_hand(loop, case)) / n_steps
            begin_hand(loop, case)
            loop.step()
            t_old, t = loop.state()[1], loop.state()[0]
            tm = 0.5 * (t_old + t)
            r["dense state (11)"] = _median_ns(lambda: loop.dense_at(tm), 2000)
            swing = 3 - case["leg"]
            r["locate_crossing"] = _median_ns(lambda: loop.locate_crossing(swing, t_old, t), 200)
            tan = math.tan(case["slope"])
            step = _HandStep(loop)

            def height(tt):
                return G.foot_height(MODEL, np.array(loop.dense_at(tt)[:5]), swing, tan)
            h0, h1 = height(t_old), height(t)
            r["may_dip (Python engine)"] = _median_ns(
                lambda: grazing.dip_bracket(step, None, height, swing, case["leg"], False, MODEL.parameters.l_leg, tan,
                                            h0, h1, case["graze_tol"]), 20)
            continue
        S0 = new_state(case)
        impl.begin(S0)
        S = S0.copy()
        def reset(S=S, S0=S0):
            np.copyto(S, S0)
        r["a call doing nothing"] = _median_ns(lambda: impl.steps(S, 0), 20 if name == "python" else 20000)
        r["step (from Python)"] = _median_ns(lambda: [impl.step(S) for _ in range(n_steps)], 1,
                                             setup=reset) / n_steps
        if name != "python":
            r["step (in compiled code)"] = _median_ns(lambda: impl.steps(S, n_steps), 1, setup=reset) / n_steps
        reset()
        impl.step(S)
        t_old, t = S[R.T_OLD], S[R.T]
        tm = 0.5 * (t_old + t)
        k = 20 if name == "python" else 2000
        r["dense state (11)"] = _median_ns(lambda: impl.dense_state(S, tm), k)
        swing = 3 - case["leg"]
        r["locate_crossing"] = _median_ns(lambda: impl.locate_crossing(S, swing, t_old, t), k // 10)
        h0, h1 = impl.height_at(S, swing, t_old), impl.height_at(S, swing, t)
        r["may_dip"] = _median_ns(lambda: impl.may_dip(S, swing, h0, h1), k // 10)
    return rows


def python_state_kinds():
    """us per call of rules.py run as Python on the state as a numpy array and as a list (the fallback without a
    compiler may keep its state in either: indexing a list is several times cheaper in the interpreter)."""
    case = crossing_case()
    S0 = new_state(case)
    R.begin(S0)
    rows = {}
    for kind in ("numpy array", "list"):
        S = S0.copy() if kind == "numpy array" else S0.tolist()
        row = rows[kind] = {"step": _median_ns(lambda: R.step(S), 20, repeat=5) / 1e3}
        S = S0.copy() if kind == "numpy array" else S0.tolist()
        R.step(S)
        t_old, t = S[R.T_OLD], S[R.T]
        row["dense state (11)"] = _median_ns(lambda: R.dense_state(S, 0.5 * (t_old + t)), 100, repeat=5) / 1e3
        row["locate_crossing"] = _median_ns(lambda: R.locate_crossing(S, 3 - case["leg"], t_old, t), 10, repeat=5) / 1e3
    return rows


def crossing_case():
    """A walk state whose first step carries the swing foot through the ground (a crossing to locate), with
    a dip search that halves its intervals (graze_tol small, both ends' heights used as given)."""
    for i in range(len(walk_states())):
        case = make_case(i, np.zeros(5), (0.0, 0.0), 0.05, 1e-9, 0.0, graze_tol=1e-12)
        out = hand_outputs(case)
        if out["_brentq"]:
            return case
    raise RuntimeError("no walk state crosses the ground in one step")


# -- the torque-law hook and what numba changes ----------------------------------------------------------------
def _law(y):
    return -10.0 * y[2] - 1.0 * y[7], -10.0 * y[3] - 1.0 * y[8]


def _raising_law(y):
    raise ValueError("a law that fails")


def hook_speed(n=20000):
    """ns per call of a torque law through each candidate's hook: a compiled law by its address (glue_so.c's
    so_pd_law), a Python callable; and whether the Python law's exception reaches the caller."""
    import ctypes
    so, _ = build.build_glue_so()
    lib = ctypes.CDLL(str(so))
    address = ctypes.cast(lib.so_pd_law, ctypes.c_void_p).value
    p, y, u = np.array([10.0, 1.0]), np.arange(11.0) / 10, np.zeros(2)
    rows = {}
    try:
        cy = build.build_cython(source="hooks")[0]
        rows["cython"] = {"compiled law": _median_ns(lambda: cy.run_compiled_law(address, p, y, u, n), 1) / n,
                          "Python law": _median_ns(lambda: cy.run_python_law(_law, y, u, n), 1) / n,
                          "exception reaches the caller": _raises(lambda: cy.run_python_law(_raising_law, y, u, 1))}
    except (ImportError, OSError, subprocess.CalledProcessError) as e:
        rows["cython"] = {"skipped": f"{type(e).__name__}: {e}"}
    try:
        import numba
    except ImportError as e:
        rows["numba"] = {"skipped": str(e)}
        return rows
    law_c = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p)(address)

    @numba.njit
    def run_compiled_law(law, p, y, u, n):      # a C law: a ctypes function object, an argument
        total = 0.0
        for _ in range(n):
            law(p.ctypes.data, y.ctypes.data, u.ctypes.data)
            total += u[0]
        return total

    def python_law_runner(law):
        # a Python law: only in object mode, and only a global of the compiled function (not an argument)
        @numba.njit
        def run(y, u, n):
            total = 0.0
            for _ in range(n):
                with numba.objmode(a="float64", b="float64"):
                    a, b = law(y)
                u[0], u[1] = a, b
                total += u[0]
            return total
        return run
    run_python_law, run_raising_law = python_law_runner(_law), python_law_runner(_raising_law)
    run_compiled_law(law_c, p, y, u, 1), run_python_law(y, u, 1)
    rows["numba"] = {"compiled law": _median_ns(lambda: run_compiled_law(law_c, p, y, u, n), 1) / n,
                     "Python law": _median_ns(lambda: run_python_law(y, u, n // 10), 1) / (n // 10),
                     "exception reaches the caller": _raises(lambda: run_raising_law(y, u, 1))}
    return rows


def _cell(v):
    return f"{v:,.1f} ns" if isinstance(v, float) else str(v)


def _raises(fn):
    try:
        fn()
    except ValueError as e:
        return str(e) == "a law that fails"
    return False


def numba_pow_differs(n=20000, seed=1):
    """How many of n math.pow(b, k) with k an int (0..7) and b in (0, 1) numba computes with other bits than
    Python (it multiplies for an int exponent; Python and C call libm's pow)."""
    import numba
    pow_nb = numba.njit(lambda b, k: math.pow(b, k))
    rng = np.random.default_rng(seed)
    return sum(pow_nb(b, k) != math.pow(b, k) for b, k in zip(rng.uniform(0, 1, n).tolist(),
                                                                 rng.integers(0, 8, n).tolist()))


# -- costs ------------------------------------------------------------------------------------------------------
def _fresh(code):
    """Run code in a fresh interpreter of this venv; its last stdout line as JSON."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True, cwd=ROOT)
    return json.loads(r.stdout.strip().splitlines()[-1])


FIRST_CALLS = """
import json, time
t0 = time.perf_counter()
import numpy as np
from benchmarks.loop_compilers import build, measure as M
t_import = time.perf_counter()
{load}
t_load = time.perf_counter()
case = M.crossing_case()
S = M.new_state(case)
t_case = time.perf_counter()
impl.begin(S); impl.step(S); impl.dense_state(S, S[M.R.T])
impl.locate_crossing(S, 3 - case["leg"], S[M.R.T_OLD], S[M.R.T])
impl.may_dip(S, 3 - case["leg"], 1.0, 1.0)
t_first = time.perf_counter()
print(json.dumps({{"load": t_load - t_import, "first calls": t_first - t_case}}))
"""


def first_call_latency():
    """Seconds to load each compiled candidate and to make its first call of every part (fresh processes;
    numba with cache=True twice: the second run loads the cache)."""
    so = build.BUILD / "libglue.so"
    loads = {
        "cython": "import importlib.util, sysconfig\n"
                  "spec = importlib.util.spec_from_file_location('rules_cy', build.BUILD / ('rules_cy' + "
                  "sysconfig.get_config_var('EXT_SUFFIX')))\n"
                  "impl = importlib.util.module_from_spec(spec); spec.loader.exec_module(impl)",
        "numba": f"from benchmarks.loop_compilers import numba_binding\nimpl = numba_binding.load({str(so)!r})",
        "numba cache=True (cold)": f"from benchmarks.loop_compilers import numba_binding\n"
                                   f"impl = numba_binding.load({str(so)!r}, cache=True)",
        "numba cache=True (warm)": f"from benchmarks.loop_compilers import numba_binding\n"
                                   f"impl = numba_binding.load({str(so)!r}, cache=True)",
    }
    _clear_numba_cache()
    return {name: _fresh(FIRST_CALLS.format(load=load)) for name, load in loads.items()}


def _clear_numba_cache():
    for pattern in ("rules*.nb[ic]", "numba_binding*.nb[ic]"):
        for p in (Path(__file__).parent / "__pycache__").glob(pattern):
            p.unlink()


def import_seconds(module, repeat=5):
    """Median seconds of ``import module`` in a fresh interpreter (minus an empty one's start)."""
    code = f"import time; t0 = time.perf_counter(); import {module}; print(time.perf_counter() - t0)"
    runs = [float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
            for _ in range(repeat)]
    return statistics.median(runs)


def installed_mb(*dists):
    """Installed size (MB) of distributions, from their RECORD files."""
    from importlib.metadata import distribution
    total = 0
    for name in dists:
        d = distribution(name)
        total += sum((d.locate_file(f).stat().st_size for f in d.files if d.locate_file(f).exists()), 0)
    return total / 1e6


def build_costs():
    """Build seconds and sizes: Cython (translate + cc), the translator (translate + cc), the glue library, and
    today's _core.c with the same flags."""
    _, cy_times, cy_lines = build.build_cython(reuse=False)
    _, tr_times, tr_lines = build.build_translated()
    _, glue_s = build.build_glue_so()
    hand_s = []
    for _ in range(3):
        t0 = time.perf_counter()
        build._cc([*build.CFLAGS, "-shared", "-I", __import__("sysconfig").get_paths()["include"], "-I",
                   str(build.ENGINE), str(build.ENGINE / "_core.c"), "-o", str(build.BUILD / "hand_core.so")])
        hand_s.append(time.perf_counter() - t0)
    so = next(build.BUILD.glob("rules_cy.*.so"))
    return {"cython translate s": cy_times["cython"], "cython cc s": cy_times["cc"], "cython C lines": cy_lines,
            "cython .so kB": so.stat().st_size / 1e3, "translator s": tr_times["translate"],
            "translator cc s": tr_times["cc"], "translator C lines": tr_lines,
            "translator .so kB": next(build.BUILD.glob("rules_tr.*.so")).stat().st_size / 1e3, "glue .so s": glue_s,
            "hand _core.c cc s": statistics.median(hand_s),
            "hand .so kB": (build.BUILD / "hand_core.so").stat().st_size / 1e3}


# -- the report -------------------------------------------------------------------------------------------------
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=300, help="random inputs compared bit for bit")
    ap.add_argument("--no-costs", action="store_true", help="skip the build and first-call measurements")
    args = ap.parse_args(argv)
    impls, missing = implementations()
    for name, why in missing.items():
        print(f"loop_compilers: {name} skipped ({why})")
    mismatches, seen = compare_bits(impls, random_cases(args.cases))
    print(f"\nbits on {args.cases} random inputs ({seen}), mismatching cases per part against the hand C:")
    for name, parts in mismatches.items():
        print(f"  {name}: {parts or 'none'}")
    rows = speed(impls)
    parts = sorted({p for r in rows.values() for p in r}, key=lambda p: list(rows["hand C"]).index(p)
                   if p in rows["hand C"] else 10)
    print("\n| ns per call | " + " | ".join(rows) + " |")
    print("|---" * (len(rows) + 1) + "|")
    for p in parts:
        print(f"| {p} | " + " | ".join(f"{r[p]:,.0f}" if p in r else "-" for r in rows.values()) + " |")
    print("\nrules.py as Python, us per call:", json.dumps(
        {k: {kk: round(vv, 1) for kk, vv in v.items()} for k, v in python_state_kinds().items()}))
    hooks = hook_speed()
    print("\n| torque-law hook | " + " | ".join(hooks) + " |")
    print("|---" * (len(hooks) + 1) + "|")
    for what in ("compiled law", "Python law", "exception reaches the caller"):
        print(f"| {what} | " + " | ".join(_cell(h.get(what, h.get("skipped"))) for h in hooks.values()) + " |")
    if "numba" in impls:
        print(f"numba: math.pow(float, int) differs from Python's in {numba_pow_differs()} of 20000 calls")
    if args.no_costs:
        return
    print("\nbuild:", json.dumps({k: round(v, 2) for k, v in build_costs().items()}))
    print("first calls (s, fresh processes):", json.dumps(
        {k: {kk: round(vv, 3) for kk, vv in v.items()} for k, v in first_call_latency().items()}))
    print("import (s):", json.dumps({m: round(import_seconds(m), 3) for m in ("numba", "cython", "numpy")}))
    print("installed MB:", json.dumps({"numba + llvmlite": round(installed_mb("numba", "llvmlite"), 1),
                                       "cython (build only)": round(installed_mb("cython"), 1)}))


if __name__ == "__main__":
    main()
