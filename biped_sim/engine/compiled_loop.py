"""The choice of hybrid loop, and the compiled loop's stepper.

The choice (:func:`covers`): a mode runs on the compiled loop (``_core.c``) when it is floating-base stance,
stepped by dop853 or dopri5, with no ``on_step`` observer, every witness of the model one that the loop decides
(``witnesses.all_compiled``), and the extension was built from the current generated kernels; its torque
comes through the hook (:mod:`~biped_sim.engine.torque_hook`). Else, and always with
``BIPED_SIM_PURE_PYTHON=1``, the Python loop of ``hybrid.py`` runs, the readable reference. Both give the same
run (test/unit/test_compiled_loop.py).

A described robot (a GeneratedModel with compiled kernels, :func:`why_not_described`): the compiled loop runs its
floating-base stance in C on its kernels' C entry points (``Loop.set_kernels``), with the same rules and their
sizes from the model: the steps, the quiet steps and their samples, the touchdowns it applies, the control periods
(a Python controller called from C, or the node's M torques). A compiled law is the three-link's
(:attr:`CompiledStepper.described`).

The stepper (:class:`CompiledStepper`): the interface of ``integrators._ListRungeKutta`` over the simulator's
state (``loop_state.py``; :func:`run_state`), which the C ``Loop`` reads and writes in place. Its entry points
return an :class:`~biped_sim.engine.loop_state.Outcome`; a step in which anything but a quiet step may happen
comes back taken and not accepted (EVENT), and ``hybrid.HybridSimulator._integrate`` handles it as any step.
"""
from __future__ import annotations

import numpy as np

from biped_sim.engine import grazing, integrators, loop_kernels, loop_rules as rules, model_kernels
from biped_sim.engine.compiled import _compiled_twin
from biped_sim.engine.loop_state import (
    DENSE,
    END_F,
    END_U,
    H_ABS,
    MAX_DRIFT,
    MAX_RATE,
    MAX_RESIDUAL,
    MAX_STEP,
    METHODS,
    MODE_BEGUN,
    N_RECORDS,
    N_Y,
    NACCEPTED,
    NFEV,
    NQ_MAX,
    NREJECTED,
    REC_A,
    REC_B,
    REC_KIND,
    REC_V,
    REC_WIDTH,
    RECORD_OFFSETS,
    RECORD_VALUES,
    RECORDS,
    REFUSED_U,
    STEPS,
    T_NEXT,
    WALL_TIME,
    Y_OLD,
    F,
    Outcome,
    Record,
    Y,
    new_state,
    put,
    write,
)
from biped_sim.engine.model import BipedModel
from biped_sim.engine.modes import checked_torques, controller_failure
from biped_sim.engine.results import ControllerError
from biped_sim.engine.torque_hook import hook_argument, law_in_mode, reference_law
from biped_sim.engine.witnesses import all_compiled


def _compiled_core():
    """(the _core module or None, why not)."""
    twin, why = _compiled_twin()
    if twin is None:
        return None, why
    try:
        from biped_sim.engine import _core
    except ImportError:
        return None, ("the compiled loop biped_sim/engine/_core was not built: install gcc and the Python headers, "
                      "then make venv")
    if _core.KERNELS_SHA256 != twin.SOURCE_SHA256:
        return None, "the compiled loop is older than the generated code; rebuild it: make venv"
    # a compiled law's failure ends the run "failed", and a Python controller's alike
    _core.set_python_checks(ControllerError, controller_failure, checked_torques, np.ndarray)
    return _core, ""


_core, WHY_NOT = _compiled_core()
#: True when the compiled loop runs the modes it covers (``WHY_NOT`` says why it does not)
AVAILABLE = _core is not None
#: False makes every mode run in the Python loop (with the compiled twin of the generated code): the
#: benchmarks compare the two loops this way
enabled = True


#: why a described robot (a GeneratedModel) runs in the Python loop: it has no compiled kernels (model_kernels), or
#: no generated step of its size; why_not_described(model) says which in one line
WHY_NOT_GENERATED = "a described robot without compiled kernels, or without a generated step of its size"

#: the sizes of y (2 N + 1 for N coordinates) the compiled loop has generated steps for (tools/generate_rk.py's
#: UNROLLED; loop_kernels.k_step)
STEPPED_SIZES = (9, 11, 15)


def why_not_described(model):
    """"" when the compiled loop steps the described robot ``model`` (a GeneratedModel), else why not in one line:
    its whole run is then the Python loop's."""
    if _core is None:
        return WHY_NOT
    size = 2 * model.n + 1
    if size not in STEPPED_SIZES:
        return (f"robot {model.name!r} ({model.n} coordinates) runs in the Python loop: the compiled loop has no "
                f"generated step for a state of {size} entries (9, 11 or 15)")
    if model_kernels.compiled_kernels(model) is None:
        return f"robot {model.name!r} runs in the Python loop: it has no compiled kernels (model_kernels)"
    return ""


def covers(sim, controller):
    """The torque law when the compiled loop can run the simulator's current mode, else None. A described robot's
    mode: held or a Python controller (a compiled law is the three-link's)."""
    if (_core is None or not enabled or sim._loop is None or not sim.stance_leg or sim.opt.base != "floating"
            or sim.method not in METHODS or sim.on_step is not None or not all_compiled()):
        return None
    law = law_in_mode(controller, sim.model)
    if sim.p is None and law[0] not in ("held", "callback"):
        return None
    return law


def new_loop(model):
    """A C ``Loop`` with the model's closed-form constants."""
    loop = _core.Loop()
    loop.set_model(model.k_stance, model.k["foot_kinematics"], model.k["foot_positions"], model.k["energy"],
                   model.k["stance_terms_1"], model.k["impact_map_1"], model.parameters.l_leg)
    return loop


def run_state(model):
    """(S, loop): the state a simulator owns for its life (``loop_state.py``'s fields) and the C ``Loop`` made
    over it: with the compiled loop built, the Loop's own memory as a memoryview of doubles (the simulator, its
    Samples and its locator read and write what the loop reads and writes); else a list of floats and None.
    A described robot's (a GeneratedModel) names its kernels (model_kernels); its Loop takes its steps on its
    kernels' C entry points (Loop.set_kernels), where it has them and a generated step of its size
    (why_not_described); else it is a list and None, and the Python loop runs it."""
    fields = dict(n_q=model.n, **grazing.chain_fields(model))
    if not isinstance(model, BipedModel):
        k = loop_kernels.register(model)
        if why_not_described(model):
            return new_state(model_kernels=k, **fields), None
        loop = _core.Loop()
        loop.set_kernels(model_kernels.compiled_kernels(model).KERNEL_TABLE, list(model.actuated_indices), model.name)
        return write(memoryview(loop).cast("d"), model_kernels=k, **fields), loop
    if _core is None:
        return new_state(**fields), None
    loop = new_loop(model)
    return write(memoryview(loop).cast("d"), **fields), loop


def take_records(S, n=5):
    """The touchdowns and ended scuffs the compiled loop applied, in order, from the state's records (RECORD_ROW,
    RECORD_VALUES; q and dq of n entries), as tuples: (TOUCHDOWN, t, old leg, new leg, q, dq-, dq+, impulse, energy
    loss, energy lost so far, pin) or (SCUFF_ENDED, foot, stance leg, [t_start, deepest, t_deepest], t_up, q, dq);
    then none are left."""
    out = []
    for i in range(int(S[N_RECORDS])):
        r = RECORDS + REC_WIDTH * i
        kind, a, b = int(S[r + REC_KIND]), int(S[r + REC_A]), int(S[r + REC_B])
        values = [S[r + REC_V + at:r + REC_V + at + (n if size == NQ_MAX else size)].tolist()
                  for at, size in _VALUE_SLICES["TD" if kind == Record.TOUCHDOWN else "SCUFF"]]
        if kind == Record.TOUCHDOWN:
            (t,), q, dq_minus, dq_plus, impulse, (loss,), (lost,), pin = values
            out.append((kind, t, a, b, q, dq_minus, dq_plus, impulse, loss, lost, tuple(pin)))
        else:
            scuff, (t_up,), q, dq = values
            out.append((kind, a, b, scuff, t_up, q, dq))
    S[N_RECORDS] = 0.0
    return out


def take_stats(S):
    """(steps, max drift, max drift rate, max |residual|, wall time of the periods run whole in C) of the compiled
    loop since the last call, from the state; then zero."""
    stats = int(S[STEPS]), S[MAX_DRIFT], S[MAX_RATE], S[MAX_RESIDUAL], S[WALL_TIME]
    for at in (STEPS, MAX_DRIFT, MAX_RATE, MAX_RESIDUAL, WALL_TIME):
        S[at] = 0.0
    return stats


#: where a record's values lie from REC_V (loop_state.RECORD_VALUES): (offset, size) each
_VALUE_SLICES = {kind: [(RECORD_OFFSETS[f"REC_{kind}_{name.upper()}"], size) for name, size in values]
                 for kind, values in RECORD_VALUES.items()}


class CompiledStepper(integrators._OnState):
    """The stepper of a mode the compiled loop runs (the interface of ``integrators._ListRungeKutta``): its
    fields (``t``, ``y``, ``t_old``, ``y_old``, ``f``, ``h``, ``h_abs``, ``t_bound``, the counters) are views of
    the simulator's state, which the C ``Loop`` steps in place; so are the locator's armed feet, its scuffs and
    the step end's feet and force."""
    takes_lists = True

    def _entries(at, doc):
        """A field of the state (a memoryview) as a list of its n_y entries in use."""
        return property(lambda self: self.S[at:at + int(self.S[N_Y])].tolist(), lambda self, v: put(self.S, at, v),
                        doc=doc)

    y = _entries(Y, "the state at t: q, dq, the motors' work")
    y_old = _entries(Y_OLD, "the state at t_old")
    f = _entries(F, "the right-hand side at (t, y)")
    del _entries

    def __init__(self, sim):
        self.sim = sim
        self.loop, self.S = sim._loop, sim.S
        opt, ground = sim.opt, sim.ground
        write(self.S, rtol=sim.rtol, atol=sim.atol, max_step=opt.max_step, max_speed=opt.max_speed,
              ground_tol=opt.ground_tol, force_tol=opt.force_tol, graze_tol=opt.graze_tol, arm_height=opt.arm_height,
              has_mu=sim.mu is not None, mu=0.0 if sim.mu is None else sim.mu, stop_on_slip=opt.stop_on_slip,
              project=opt.project_constraints, check_invariants=opt.check_invariants,
              impact_phase="impact" in opt.phases, sin_s=ground.sin, cos_s=ground.cos, tan_s=ground.tan,
              to_power_basis=integrators._DOP853Interpolant.TO_POWER_BASIS.ravel().tolist(), front_tol=opt.front_tol,
              scuff_depth=opt.scuff_depth, event_tol=opt.event_tol, front_rule=opt.touchdown_rule == "front",
              forward_rule=opt.scuff_rule == "forward", compute_grf=opt.compute_grf, zeno_interval=opt.zeno_interval,
              impulse_tol=opt.impulse_tol, contact_tol=opt.contact_tol, max_events=opt.max_events)
        self.rtol, self.atol, self.method = sim.rtol, sim.atol, sim.method
        self.ERROR_ORDER = 7 if sim.method == "dop853" else 4
        #: a described robot's: a compiled law is the three-link's (command: the Python code computes it)
        self.described = sim.p is None
        self._m = sim._m

    def start(self, t_bound, law, reset_counters):
        """Begin the mode at the simulator's state, as ``make_stepper`` would build a new stepper: the
        torque law, f at the start, the carried-over step size (or the initial one)."""
        sim, S = self.sim, self.S
        write(S, method=METHODS[self.method], u_hold=sim._u, t=sim.t,     # (the stance leg and pin: the state's)
              y=sim.q.tolist() + sim.dq.tolist() + [sim.work], t_bound=t_bound)
        if sim._h is not None:     # (the carried-over step size, as _ListRungeKutta.restart caps it)
            S[H_ABS] = rules.rk_carried_step(sim._h, S[MAX_STEP])
        if reset_counters:
            S[NFEV] = S[NREJECTED] = S[NACCEPTED] = 0.0
        self.loop.begin(hook_argument(law))
        self._dense = None
        if sim._h is None:
            h0 = integrators.initial_step(self.loop.rhs, self.t, self.y, self.f, t_bound, self.rtol, self.atol,
                                          self.ERROR_ORDER)
            S[NFEV] += 1
            S[NACCEPTED] = 0.0
            S[H_ABS] = rules.rk_carried_step(h0, S[MAX_STEP])

    def step(self):
        """One step taken in C and handled by the Python code (the simulator's view of its end's
        evaluation set, as the right-hand side's sink does)."""
        self._handed(self._raise_failure(self.loop.step()))

    def run(self, t_end):
        """The quiet steps to ``t_end`` in C: an :class:`~biped_sim.engine.loop_state.Outcome`, DONE (at t_end:
        the simulator's state is the last sample's), EVENT (a step taken, not accepted: the Python code handles
        it), or PYTHON_STEPS (the locator holds a latched guard or two scuffs, which only the Python code
        follows: step in Python)."""
        sim = self.sim
        if sim.locator.python_only():
            return Outcome.PYTHON_STEPS
        while True:      # NEED_ROOM: make_room makes it, _after_run takes the events
            sim._samples.make_room()
            outcome = self._after_run(self.loop.run(t_end, sim._samples._data))
            if outcome != Outcome.NEED_ROOM:
                return outcome

    def command(self, controller):
        """The control period's command of a compiled law at the simulator's state, computed in C (the
        law's own torques bit for bit), or None where the Python controller must be called."""
        law = reference_law(controller, self.sim.model)
        if law is None or self.described or not self.S[MODE_BEGUN] or self.sim._stepper is not self:
            return None
        return self.loop.law_torque(hook_argument(law))

    def can_run_periods(self):
        """Whether ``periods`` can run now: the simulator's state is the loop's, and the locator holds
        nothing only the Python code follows."""
        return bool(self.S[MODE_BEGUN]) and not self.sim.locator.python_only()

    def periods(self, period, law, t_final, t_stop):
        """Control periods held, as ``advance_period`` would run them, each command computed at its period's
        start: by a compiled law in C (``law`` a CompiledLaw), or by a Python controller (``law`` the
        controller), called from C once a period and checked as ``modes.checked_command`` checks it; the
        periods run in C
        until ``t_final`` or a push due at ``t_stop``: (outcome, t_next, refused), DONE when they all ran,
        TORQUE_CHANGE before a period whose command (``refused``) the stance guards refuse at its start (not
        begun: ``advance_period`` runs it with that command), else the outcome of the step handed back in the
        period ending at ``t_next`` (``can_run_periods`` first)."""
        sim = self.sim
        sim._samples.make_room()
        outcome = self._after_run(self.loop.periods(law if callable(law) else hook_argument(law), period, t_final,
                                                    t_stop, sim._samples._data))
        S = self.S
        t_next = S[T_NEXT]
        if outcome == Outcome.NEED_ROOM:      # the period in progress goes on in run(), which makes room
            return self.run(t_next), t_next, None
        return outcome, t_next, S[REFUSED_U:REFUSED_U + self._m].tolist() if outcome == Outcome.TORQUE_CHANGE else None

    def held_period(self, t_end):
        """A control period under the held torque ``sim._u`` in the mode the loop is in, started and run
        in one call (``None`` when the simulator's state is not the loop's: then ``start`` and ``run``)."""
        sim = self.sim
        if not self.S[MODE_BEGUN] or sim.locator.python_only():
            return None
        # (no room made first: a full array comes back NEED_ROOM before a step, and run() goes on)
        return self.finish_held(self.loop.held(t_end, sim._samples._data), t_end)

    def finish_held(self, outcome, t_end):
        """The outcome of a held period's run (``held``, ``period``) that came back with ``outcome``."""
        outcome = self._after_run(outcome)
        return self.run(t_end) if outcome == Outcome.NEED_ROOM else outcome

    def _after_run(self, outcome):
        """A run's outcome (its samples are written, the Samples' counters and the simulator's time, work, step
        size and state set in the state): the Events of what the loop applied, then the outcome's own
        handling."""
        sim = self.sim
        if self.S[N_RECORDS]:
            sim._loop_records(take_records(self.S, sim.n))
        if self._raise_failure(outcome) == Outcome.EVENT:     # (its start's feet and force: the state's)
            self._handed(outcome)
        return outcome

    def _raise_failure(self, outcome):
        """``outcome``, unless it is RAISED (the torque law's exception, after the steps accepted before it) or
        FAILED (the step's :class:`~biped_sim.engine.integrators.StepFailure`)."""
        if outcome == Outcome.RAISED:
            self.loop.raise_error()
        if outcome == Outcome.FAILED:
            raise integrators.state_failure(self.S)
        return outcome

    def _handed(self, outcome):
        """A step taken in C and handed to the Python code: its dense output made anew when asked, the torque
        and force of its end the simulator's last evaluation's."""
        self._dense = None
        S = self.S
        self.sim._last_u, self.sim._last_F = S[END_U:END_U + self._m].tolist(), S[END_F:END_F + 2].tolist()

    def replace_y(self, y):
        self.y = y

    def dense_output(self):
        if self._dense is None:
            self.loop.dense()
            S, width = self.S, 8 if self.method == "dop853" else 5
            rows = [S[DENSE + width * i:DENSE + width * (i + 1)].tolist() for i in range(int(S[N_Y]))]
            cls = integrators._DOP853Interpolant if self.method == "dop853" else integrators._DOPRI5Interpolant
            self._dense = cls(self.t_old, self.t, rows)
        return self._dense

    def height_crossing(self, leg, ta, tb):
        """Where foot ``leg``'s height crosses zero in [ta, tb] on the last step (``guards.locate_crossing``'s
        brentq, run in C on the same dense output: the same root), or None to find it in Python."""
        return self.loop.locate_crossing(leg, ta, tb)

    def dense_at(self, t):
        """The dense output at t, from C (the interpolant's own arithmetic: the same bits)."""
        return self.loop.dense_at(t)

