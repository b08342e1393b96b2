"""The hybrid loop's state: one declaration of the fields the single-source rules read and write.

Every field is float64 and lives at a fixed offset in one flat buffer ``S``; counters and flags are
floats too (whole numbers, exact below 2^53). From :data:`FIELDS` come

* the offsets, as module constants named like the field in capitals (``T``, ``Y``, ``STAGES``...), which
  the rules (``loop_rules.py``) index ``S`` with when they run as Python;
* ``_loop_state.h`` for C: the same offsets as ``LS_<NAME>`` and the fields as the members of a struct
  of doubles laid out exactly as ``S`` (``LOOP_STATE_MEMBERS``), so that the compiled loop (``_core.c``)
  holds one buffer that it reads by member and the compiled rules read by offset;
* ``_loop_state.pxd`` for Cython: the offsets as C constants of the compiled rules.

Both files are written by ``tools/generate_loop.py`` (``make generate-loop``) and checked against this
declaration by test/unit/test_loop_rules.py. Run as Python, a state is a list of floats
(:func:`new_state`): the interpreter indexes a list faster than a buffer (docs/engine.md, the plan's step 5).

Fields whose size depends on the integrated state have room for ``NMAX`` entries (the floating base's
2 N + 1 for the largest model, N = ``NQ_MAX`` coordinates); a state uses the first ``n_y`` entries of each
(the three-link's floating base 11, its fixed base 7), and a trial step's rows in ``out`` and ``stages`` are
``n_y`` apart (the compiled kernels' rows are the three-link's 11). Fields of q have room for ``NQ_MAX``
coordinates, the first ``n_q`` in use. The scratch fields hold
intermediate results between two calls of the rules and nothing across steps; the touchdown's block at the
end holds the constants of the closed forms an impact evaluates (loop_rules.ev_impact) and its results.
"""
from __future__ import annotations

import math
from array import array
from enum import IntEnum
from typing import NamedTuple

NQ_MAX = 12         # the most coordinates a model may have (q = base x, base y, one angle per link)
NMAX = 2 * NQ_MAX + 1   # the floating base's integrated state: q (N), dq (N), motor work
NU_MAX = NQ_MAX - 3     # the most actuators: one per joint, none on the floating base's three coordinates
MAX_STAGES = 13     # dop853's stages k0..k12 (dopri5 uses k0..k6)
DENSE_WIDTH = 8     # coefficients a dense-output row: dop853's 8 (dopri5 uses 5)
MAX_DEPTH = 30      # the dip search's halvings (grazing.MAX_DEPTH)
CHAIN_MAX = 4       # the links of a contact point's chain, from the floating base to the point (the dip bound's)
TERMS_MAX = 6       # the terms of a link's absolute angle: its joint's coordinate and its ancestors'
CHAIN_WIDTH = 2 + TERMS_MAX     # a chain link's row: its length, its terms' count, the terms
COEF_WIDTH = 2 + CHAIN_MAX      # a row of the dip search's coefficients: base x, base y, each chain link's angle
#: the dimensions above that the rules index the state with; _loop_state.h and .pxd carry them by these names
DIMENSIONS = {"CHAIN_MAX": CHAIN_MAX, "CHAIN_WIDTH": CHAIN_WIDTH, "COEF_WIDTH": COEF_WIDTH}
METHODS = {"dop853": 0, "dopri5": 1}
EVENT_ROOM = 32     # the event records a run may make before the Python code takes them (a step makes at most one)


#: a record's values, in order, with their sizes: a touchdown's (a, b: the old and the new stance leg) and an ended
#: scuff's (a, b: the foot and the stance leg; q and dq at t_deepest, NaN outside the step). q and dq have room for
#: NQ_MAX coordinates, the model's N in use. _loop_state.h carries their offsets from REC_V as REC_TD_<NAME> and
#: REC_SCUFF_<NAME>.
RECORD_VALUES = {
    "TD": (("t", 1), ("q", NQ_MAX), ("dq_minus", NQ_MAX), ("dq_plus", NQ_MAX), ("impulse", 2), ("loss", 1),
           ("lost", 1), ("pin", 2)),
    "SCUFF": (("scuff", 3), ("t_up", 1), ("q", NQ_MAX), ("dq", NQ_MAX)),
}


#: an event record's row (the state's records, made by the compiled loop, read by compiled_loop.take_records): its kind
#: (Record), the legs a and b, and from REC_V its values (RECORD_VALUES); its width holds the longer kind's values.
#: _loop_state.h and .pxd carry them by these names.
RECORD_ROW = {"REC_KIND": 0, "REC_A": 1, "REC_B": 2, "REC_V": 3,
              "REC_WIDTH": 3 + max(sum(size for _, size in values) for values in RECORD_VALUES.values())}


def _record_offsets():
    out = {}
    for kind, values in RECORD_VALUES.items():
        at = 0
        for name, size in values:
            out[f"REC_{kind}_{name.upper()}"] = at
            at += size
    return out


RECORD_OFFSETS = _record_offsets()


class Field(NamedTuple):
    """A field of the state: its name, its shape (() for a scalar), what it holds."""
    name: str
    shape: tuple
    doc: str


FIELDS = (
    # -- the stepper's method and options
    Field("method", (), "the Runge-Kutta pair: 0 dop853, 1 dopri5 (METHODS)"),
    Field("n_y", (), "entries of y in use (at most NMAX): also the distance of a trial step's rows (out, stages)"),
    Field("n_q", (), "the model's coordinates N, the entries of a field of q in use (at most NQ_MAX)"),
    Field("model_kernels", (), "whose kernels the rules evaluate (loop_kernels): 0 the three-link's closed forms on "
                               "the constants below, k > 0 the generated model registered as k (the Python loop only)"),
    Field("rtol", (), "relative tolerance of the step control"),
    Field("atol", (), "absolute tolerance of the step control"),
    Field("max_step", (), "the largest step size (s)"),
    # -- the events' options and the model's constants they use
    Field("graze_tol", (), "the dip search's depth (m): a dip of the foot deeper than this is found"),
    Field("event_tol", (), "brentq's xtol (s)"),
    Field("l_leg", (), "the leg's length (m)"),
    Field("chain_links", (2,), "per contact point, the links of its chain: those from the floating base's point to "
                               "it that carry it a distance (a link's frame turns with its absolute angle)"),
    Field("chain", (2, CHAIN_MAX, CHAIN_WIDTH), "per contact point, a row per chain link from the base: its length l_k "
                                               "(m), the count of its absolute angle's terms, then each term as "
                                               "+-(the entry of y + 1), + for a joint turning about +y"),
    Field("tan_s", (), "tan(slope) of the ground"),
    Field("sin_s", (), "sin(slope): a force's normal and tangential components on the ground line"),
    Field("cos_s", (), "cos(slope)"),
    Field("mu", (), "the friction coefficient (0 without one: the slip witness is then not a row)"),
    Field("fixed_base", (), "1 when y is the fixed base's (q1, q2, q3, dq..., work): the dip bound's form"),
    Field("front_tol", (), "touchdown_rule front: a swing foot within this of the stance foot counts as behind (m)"),
    Field("scuff_depth", (), "the deepest a scuff may pass under the ground (m)"),
    Field("forward_rule", (), "1 under scuff_rule forward, 0 under behind"),
    Field("k_pos", (32,), "the constants of the closed form foot_positions (BipedModel.k; room for any)"),
    Field("to_power_basis", (8, 8), "dop853's dense row to its power-basis coefficients (integrators)"),
    # -- the options of the compiled loop's steps and events (Options: CompiledStepper writes them)
    Field("max_speed", (), "a rate beyond this is a diverging state (Options.max_speed)"),
    Field("ground_tol", (), "how far a free foot may be under the ground (m)"),
    Field("force_tol", (), "how far the ground may pull or the force leave the cone (N)"),
    Field("arm_height", (), "a foot's touchdown counts once it has been higher than this (m)"),
    Field("has_mu", (), "1 with a friction coefficient (the slip witness is a row)"),
    Field("stop_on_slip", (), "1: a slip stops the run (Options.stop_on_slip)"),
    Field("project", (), "1: the state is projected onto the pin after each step (project_constraints)"),
    Field("check_invariants", (), "1: the invariants are checked after each step and impact"),
    Field("impact_phase", (), "1 when the scene has impacts (\"impact\" in phases)"),
    Field("front_rule", (), "1 under touchdown_rule front"),
    Field("compute_grf", (), "1: the event's sample has its ground force"),
    Field("zeno_interval", (), "impacts closer than this may accumulate (s)"),
    Field("impulse_tol", (), "how far an impact's impulse may pull (N s)"),
    Field("contact_tol", (), "an old stance foot slower than this after an impact stays down (m/s)"),
    Field("max_events", (), "the run stops after this many mode events"),
    # -- the mode: the simulator's, which the compiled loop steps (a touchdown in either loop changes it)
    Field("stance_leg", (), "the stance foot: 1 or 2, 0 in flight (the simulator's stance_leg)"),
    Field("pin", (2,), "where the stance foot is pinned (m; the simulator's pin, not read in flight)"),
    Field("u_hold", (NU_MAX,), "the torque held while the torque law is held, one an actuator (N m)"),
    # -- what an entry point of the compiled loop leaves besides its Outcome
    Field("t_next", (), "period(), periods(): the end of the control period under way (s)"),
    Field("refused_u", (NU_MAX,), "periods() ending TORQUE_CHANGE: the command refused at its period's start, one "
                                  "an actuator (N m)"),
    Field("n_records", (), "the touchdowns and ended scuffs applied in C whose Events the Python code makes "
                           "(records, in order)"),
    Field("why", (), "why the compiled loop handed the last step back (Reason)"),
    Field("end_u", (NU_MAX,), "the step handed back: the torque of its end, one an actuator (N m)"),
    Field("end_F", (2,), "the step handed back: the stance force of its end (N)"),
    # -- the compiled loop's statistics since the Python code last took them (compiled_loop.take_stats)
    Field("steps", (), "the quiet steps accepted in C"),
    Field("max_drift", (), "the largest drift of the stance foot from the pin (m)"),
    Field("max_rate", (), "the largest rate of that drift (m/s)"),
    Field("max_residual", (), "the largest |energy balance residual| (J)"),
    Field("wall_time", (), "the wall time of the control periods run whole in C (Loop.period, s)"),
    # -- the stepper (integrators._ListRungeKutta)
    Field("t", (), "time (s) at the end of the last step"),
    Field("t_bound", (), "the end of the interval the stepper runs to (s)"),
    Field("h_abs", (), "the step size the next step tries (s)"),
    Field("t_old", (), "time at the start of the last step (s)"),
    Field("h", (), "the last step's size (s)"),
    Field("y", (NMAX,), "the state at t"),
    Field("f", (NMAX,), "the right-hand side at (t, y)"),
    Field("y_old", (NMAX,), "the state at t_old"),
    Field("stages", (MAX_STAGES, NMAX), "the last step's stages k0..k12"),
    Field("nfev", (), "right-hand-side evaluations"),
    Field("nrejected", (), "rejected steps"),
    Field("naccepted", (), "accepted steps"),
    Field("dense_ready", (), "1 when dense holds the last step's dense output"),
    Field("dense", (NMAX * DENSE_WIDTH,), "the last step's dense output, a row of DENSE_WIDTH per entry of y"),
    Field("fail_kind", (), "why the last step failed: 1 the step size underflowed, 2 a non-finite state, "
                           "3 the torque law failed (callback_failed)"),
    Field("fail_value", (), "the failure's step size (kind 1) or time (kind 2)"),
    Field("fail_t", (), "the time the failing step started at"),
    Field("callback_failed", (), "1 once the torque law failed inside the right-hand side (the compiled loop)"),
    Field("guard_leg", (), "the foot whose height the root finder and the dip search follow"),
    Field("scuff_trial", (3,), "a scuff followed over a step: t_start, deepest, t_deepest (ev_track_scuff)"),
    Field("deepest_trial", (), "the deepest of any scuff so far, with this step's (ev_track_scuff)"),
    Field("feet", (2, 4), "the feet on the dense output: x, height across the slope, and their rates, a row a foot"),
    # -- the run: the simulator's, its Samples' and its locator's fields that both loops read and write (the
    #    simulator owns the state for its life: compiled_loop.run_state)
    Field("e0", (), "the energy at the run's start (J)"),
    Field("push_work", (), "the kinetic energy pushes added (J)"),
    Field("energy_lost", (), "the energy the impacts took out (J)"),
    Field("sim_t", (), "the simulator's time: its last accepted state's (s)"),
    Field("sim_work", (), "the hip motors' work up to sim_t (J)"),
    Field("sim_h", (), "the step size the next stepper starts with (NaN: none yet, the initial one is computed)"),
    Field("sim_u", (NU_MAX,), "the torque held now, one an actuator (N m)"),
    Field("sim_q", (NQ_MAX,), "q at sim_t, where a quiet period left it (sim_state_unmade)"),
    Field("sim_dq", (NQ_MAX,), "dq at sim_t, alike"),
    Field("sim_state_unmade", (), "1 when sim_q and sim_dq are the simulator's state and its arrays not yet made"),
    Field("mode_begun", (), "1 while the compiled loop's mode was begun (Loop.begin) at the simulator's state: a "
                            "write of the simulator's time, q or dq by the Python code, or its reset to flight, "
                            "clears it, and the next period begins the mode again"),
    Field("control_periods", (), "the control periods begun so far"),
    Field("running", (), "1 while the run's status is running"),
    Field("initial_sample_pending", (), "1 until the first advance redoes the t0 sample under its torque"),
    Field("n_samples", (), "the Samples' rows in use"),
    Field("appended", (), "the samples appended so far"),
    Field("provisional", (), "1 when the newest sample is overwritten by the next (ev_provisional)"),
    Field("every", (), "keep every this many samples (0: only the events' and the last)"),
    Field("last_only", (), "1 when the Samples keep the last sample only (one row)"),
    Field("last_impact", (), "the last impact's time (s): ImpactHistory, a touchdown the loop applies"),
    Field("n_impacts", (), "the impacts so far"),
    Field("recent_impacts", (4,), "the last (up to) 4 impact times, oldest first"),
    Field("n_recent", (), "how many of recent_impacts are in use"),
    Field("mode_events", (), "the events that changed the mode so far (max_events counts them)"),
    Field("ring", (49,), "the times of the last 49 of them, event i at i % 49 (50 within 1e-9 s: an event loop)"),
    Field("n_latched", (), "the guards the locator holds latched (off until positive again: only Python follows)"),
    Field("armed", (2,), "1 for a foot whose touchdown counts (it has been higher than arm_height): EventLocator"),
    Field("scuffing", (2,), "1 for a foot in a scuff (under the ground, passing through it)"),
    Field("scuff", (2, 3), "a foot's scuff: t_start, deepest, t_deepest"),
    Field("deepest_scuff", (), "the deepest dip of any scuff so far (m)"),
    Field("scuffs", (), "the scuffs so far (crossings behind the stance foot that did not touch down)"),
    Field("feet_end_t", (), "the time of feet_end (NaN: none kept): the last step's end, the next one's start"),
    Field("feet_end", (2, 4), "the feet there (x, height, and their rates, a row a foot)"),
    Field("force_end_t", (), "the time of force_end (NaN: none kept)"),
    Field("force_end", (2,), "the stance force there (N)"),
    # -- scratch
    Field("out", (2 * NMAX + 1 + MAX_STAGES * NMAX,), "a trial step: y_new, f_new, err, stages; between steps "
                                                      "the dense state (dense_state)"),
    Field("result", (2,), "a located root, or a dip's bracket"),
    Field("coef", (8, COEF_WIDTH), "the dip search's |power-basis coefficients|, a row a power: the base's x, its y, "
                                   "then the absolute angle of each link of the foot's chain (fixed base: the stance "
                                   "leg's angle, 0, the swing leg's)"),
    Field("coef_links", (), "the chain links of coef's row (its columns from the third)"),
    Field("coef_length", (CHAIN_MAX,), "their lengths l_k (m): from the link's joint to the next joint, or the foot"),
    Field("dip_d", (2, COEF_WIDTH), "the dip search's bounds of each column's first and second derivatives"),
    Field("qs", (NQ_MAX,), "q on the dense output"),
    Field("ps", (4,), "the feet's positions there"),
    Field("stack", (2 * MAX_DEPTH + 4, 5), "the dip search's intervals: a, b, h(a), h(b), depth"),
    # -- touchdown: the impact (loop_rules.ev_impact), the constants of the closed forms it evaluates, its scratch
    Field("k_impact", (32,), "the constants of the closed form impact_map_1 (impact_map_2 takes the same)"),
    Field("k_energy", (32,), "the constants of the closed form energy"),
    Field("k_feet", (32,), "the constants of the closed form foot_kinematics"),
    Field("q_impact", (NQ_MAX,), "q at the impact"),
    Field("dq_minus", (NQ_MAX,), "dq before the impact"),
    Field("dq_plus", (NQ_MAX,), "dq after the impact (the impact map writes it, and the impulse into the next field)"),
    Field("impulse", (2,), "the ground's impulse on the landing foot (N s)"),
    Field("tv", (2,), "T and V (the closed form energy)"),
    Field("energy_before", (), "T + V before the impact (J)"),
    Field("energy_after", (), "T + V after the impact (J)"),
    Field("kinematics", (8,), "foot_kinematics after the impact: p_1, p_2, dp_1/dt, dp_2/dt"),
    Field("feet_after", (2, 4), "the feet after the impact: x, height across the ground, their rates, a row a foot"),
    # -- what the compiled loop applied, for the Python code to make Events of (compiled_loop.take_records)
    Field("records", (EVENT_ROOM, RECORD_ROW["REC_WIDTH"]), "the touchdowns and ended scuffs applied in C, a row "
                                                          "a record (RECORD_ROW), the first n_records in use"),
)

#: the codes the touchdown's rules return (loop_rules.py): the bits of an impact's checks (ev_impact,
#: ev_impulse_checks), and how a stance starts (ev_stance_start). _loop_state.h and .pxd carry them by these names.
CODES = {
    "IMPACT_OLD_FOOT_SINKS": 1,     # the old stance foot moves into the ground after the impact
    "IMPACT_PULLS": 2,              # the ground's impulse on a landing foot pulls it (normal < 0)
    "IMPACT_OUTSIDE_CONE": 4,       # it pushes, outside the friction cone (|Lambda_t| > mu Lambda_n)
    "STANCE_HOLDS": 0,              # the ground pushes, inside the cone: the stance goes on
    "STANCE_LIFTS_OFF": 1,          # the ground would pull (normal force < 0): a liftoff at once
    "STANCE_SLIPS": 2,              # the force is outside the friction cone (the slip witness watched): a slip at once
}

#: a sample's row (results.Samples' array, loop_rules.ev_sample_row, the compiled loop's runs): where t, q (5), dq (5),
#: the stance leg, the ground force F (2), the torque u (2) and the energy balance's residual lie, and its width.
#: _loop_state.h and .pxd carry them by these names.
SAMPLE_ROW = {"ROW_T": 0, "ROW_Q": 1, "ROW_DQ": 6, "ROW_LEG": 11, "ROW_F": 12, "ROW_U": 14, "ROW_RESIDUAL": 16,
              "ROW_WIDTH": 17}


def sample_row(n, m) -> dict:
    """SAMPLE_ROW's layout for a robot of n coordinates and m actuators (loop_rules.ev_sample_row_of): t, q (n),
    dq (n), the stance leg, F (2), u (m), the residual; the three-link's (5, 2) is SAMPLE_ROW."""
    q = SAMPLE_ROW["ROW_Q"]
    return {"ROW_T": SAMPLE_ROW["ROW_T"], "ROW_Q": q, "ROW_DQ": q + n, "ROW_LEG": q + 2 * n, "ROW_F": q + 2 * n + 1,
            "ROW_U": q + 2 * n + 3, "ROW_RESIDUAL": q + 2 * n + 3 + m, "ROW_WIDTH": q + 2 * n + 4 + m}


class Outcome(IntEnum):
    """How an entry point of the compiled loop (``run``, ``held``, ``period``, ``periods``, ``step``) ended; what
    it leaves besides is in the state (the samples and their counters, the simulator's time and state,
    t_next, refused_u, n_records and the records, the failure's fail_kind, fail_value, fail_t, a step handed back's
    why, end_u and end_F, the statistics)."""
    DONE = 0            # at its end: the state is the last sample's
    EVENT = 1           # a step taken and not accepted: the Python code handles it (a step handed back)
    NEED_ROOM = 2       # the Samples' array or the event records are full: make room, call again
    FAILED = 3          # the step failed (fail_kind: the step size underflowed, or a non-finite state)
    RAISED = 4          # the torque law failed: Loop.raise_error() raises its exception
    TORQUE_CHANGE = 5   # periods(): the stance guards refuse the next period's command at its start (refused_u)
    DECLINED = 6        # period(): not run, nothing changed: the Python code runs the period
    PYTHON_STEPS = 7    # CompiledStepper.run, never C: the locator holds what only the Python code follows


class Record(IntEnum):
    """The kinds of the state's event records (RECORD_ROW): what the loop applied, whose Events the Python code
    makes."""
    SCUFF_ENDED = 1
    TOUCHDOWN = 2


class Reason(IntEnum):
    """Why the compiled loop handed a step back to the Python code (the state's ``why``)."""
    DIVERGING = 1               # a rate beyond max_speed
    CROSSING_IN_PYTHON = 2      # a touchdown crossing brentq gives up on, or touchdown_rule "any"
    TOUCHDOWN_WHILE_SCUFFING = 3
    LIFTOFF = 4                 # the liftoff witness triggered
    SLIP = 5                    # the slip witness triggered
    FOOT_PUSHED_IN = 6          # a resting free foot pushed into the ground
    SCUFF_LEAVES_MODEL = 7      # a scuff that stops passing through, or deeper than scuff_depth
    NON_FINITE = 8              # invariant: a non-finite state
    FOOT_BELOW_GROUND = 9       # invariant: a free foot below the ground
    GROUND_PULLS = 10           # invariant: the normal force beyond force_tol below zero
    OUTSIDE_CONE = 11           # invariant: the force outside the cone (stop_on_slip)
    LAW_FAILED = 12             # the torque law failed in the step
    CALLED_BACK_LAW = 13        # a touchdown under a Python controller
    IMPACTS_CLOSE = 14          # a touchdown within zeno_interval of the last impact
    MAX_EVENTS = 15             # a touchdown that reaches max_events
    EVENT_LOOP = 16             # a touchdown that makes 50 mode events within 1e-9 s
    OLD_FOOT_SINKS = 18         # after the impact the old stance foot moves into the ground
    IMPULSE_CHECK = 19          # the impulse pulls, or lies outside the friction cone
    OLD_FOOT_STAYS = 20         # the old stance foot stays on the ground (check_invariants)
    STANCE_REFUSED = 21         # the new stance starts with the ground pulling or outside the cone
    ACCUMULATING = 22           # a crossing behind the stance foot while the impacts accumulate (Zeno)


def _size(shape):
    return math.prod(shape)


def _offsets():
    out, at = {}, 0
    for field in FIELDS:
        out[field.name.upper()] = at
        at += _size(field.shape)
    return out, at


OFFSETS, SIZE = _offsets()
SIZES = {field.name: _size(field.shape) for field in FIELDS}    # the values a field holds
globals().update(OFFSETS)       # T, Y, STAGES, ...: the offsets the rules index S with when they run as Python
globals().update(CODES)
globals().update(SAMPLE_ROW)
globals().update(RECORD_ROW)
globals().update(RECORD_OFFSETS)


def put(S, at, values):
    """Write ``values`` into ``S`` from the offset ``at`` (S a list, or the compiled loop's memoryview of doubles,
    which takes a slice as a buffer)."""
    S[at:at + len(values)] = values if type(S) is list else array("d", values)


def new_state(**values) -> list:
    """A state as a list of SIZE floats, zero but for ``values`` (as :func:`write` takes them)."""
    return write([0.0] * SIZE, **values)


def write(S, **values):
    """Write ``values`` into the state S by field name (a float, a bool, or a sequence of floats filling the field
    from its start); returns S."""
    for name, value in values.items():
        at = OFFSETS[name.upper()]
        if isinstance(value, (int, float)):
            S[at] = float(value)
        else:
            value = [float(v) for v in value]
            size = SIZES[name]
            if len(value) > size:
                raise ValueError(f"the state's field {name} holds {size} values, got {len(value)}")
            if type(S) is list:
                S[at:at + len(value)] = value
            else:
                put(S, at, value)
    return S


# -- the generated declarations for C and Cython (tools/generate_loop.py writes them) ----------------------
def c_header() -> str:
    """_loop_state.h: the offsets and the struct members of the state, for the compiled loop."""
    lines = ["/* The hybrid loop's state (biped_sim/engine/loop_state.py, written by tools/generate_loop.py: do not",
             " * edit). LOOP_STATE_MEMBERS are the fields as doubles in the order of the offsets LS_*, so that a",
             " * union of double S[LOOP_STATE_SIZE] with a struct of these members reads the same memory both ways. */",
             "#ifndef BIPED_SIM_LOOP_STATE_H", "#define BIPED_SIM_LOOP_STATE_H", "",
             f"#define LOOP_STATE_SIZE {SIZE}", f"#define LS_NMAX {NMAX}", f"#define LS_NQ_MAX {NQ_MAX}",
             f"#define LS_MAX_DEPTH {MAX_DEPTH}",
             *[f"#define LS_{name} {value}" for name, value in DIMENSIONS.items()],
             f"#define LS_EVENT_ROOM {EVENT_ROOM}"]
    lines += [f"#define LS_{name} {at}" for name, at in OFFSETS.items()]
    lines += [f"#define {name} {code}" for name, code in CODES.items()]
    lines += [f"#define {name} {at}" for name, at in SAMPLE_ROW.items()]
    lines += [f"#define {name} {at}" for name, at in RECORD_ROW.items()]
    lines += [f"#define {name} {at}" for name, at in RECORD_OFFSETS.items()]
    lines += ["", "/* Outcome, Record and Reason (loop_state.py) */"]
    for enum, prefix in ((Outcome, "OUTCOME"), (Record, "RECORD"), (Reason, "WHY")):
        lines += [f"#define {prefix}_{member.name} {member.value}" for member in enum]
    lines += ["", "/* the right-hand side f(ctx, t, y) -> dy the generated steps take, and a guard's value at t: the",
              " * functions the rules take as arguments */",
              "typedef int (*rhs_t)(void *ctx, double t, const double *y, double *dy);",
              "typedef double (*guard_t)(double *S, void *ctx, double t);",
              "/* the feet at t into S[LS_FEET] */",
              "typedef void (*feet_t)(double *S, void *ctx, double t);",
              "", "#define LOOP_STATE_MEMBERS \\"]
    for field in FIELDS:
        dims = "".join(f"[{d}]" for d in field.shape)
        lines.append(f"    double {field.name}{dims};  /* {field.doc.replace('*/', '* /')} */ \\")
    lines[-1] = lines[-1][:-2]
    lines += ["", "#endif", ""]
    return "\n".join(lines)


def cython_pxd() -> str:
    """_loop_state.pxd: the offsets as C constants of the compiled rules (from _loop_state.h)."""
    lines = ["# The hybrid loop's state's offsets for the compiled rules (biped_sim/engine/loop_state.py, written by",
             "# tools/generate_loop.py: do not edit).",
             'cdef extern from "_loop_state.h":', "    enum:",
             '        SIZE "LOOP_STATE_SIZE"', '        NMAX "LS_NMAX"', '        NQ_MAX "LS_NQ_MAX"',
             *[f'        {name} "LS_{name}"' for name in DIMENSIONS],
             '        MAX_DEPTH "LS_MAX_DEPTH"',
             '        EVENT_ROOM "LS_EVENT_ROOM"']
    lines += [f'        {name} "LS_{name}"' for name in OFFSETS]
    lines += [f'        {name} "{name}"' for name in CODES]
    lines += [f'        {name} "{name}"' for name in SAMPLE_ROW]
    lines += [f'        {name} "{name}"' for name in RECORD_ROW]
    lines.append("")
    return "\n".join(lines)
