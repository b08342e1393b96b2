"""What a run returns: its discrete events and its samples (``Event``, ``SimulationResult``).

Plain data, filled by :class:`biped_sim.engine.hybrid.HybridSimulator`; the recorder, the node and the
analysis read them.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from biped_sim.engine import loop_rules as rules
from biped_sim.engine.loop_state import (
    APPENDED,
    EVERY,
    LAST_ONLY,
    N_SAMPLES,
    PROVISIONAL,
    ROW_Q,
    ROW_T,
    ROW_WIDTH,
    SAMPLE_ROW,
    new_state,
    sample_row,
)

EVENT_KINDS = ("touchdown", "double_touchdown", "liftoff", "slip", "scuff", "error", "zeno", "push")
IMPACT_KINDS = ("touchdown", "double_touchdown")


@dataclass
class Event:
    """One discrete event. ``q``, ``dq_minus`` and ``dq_plus`` are physical coordinates.

    kind: ``touchdown`` (the impact map was applied to foot ``leg``), ``double_touchdown`` (both
    feet at once; ``leg`` is the new stance foot, ``impulse`` has 4 entries, foot 1 first),
    ``liftoff`` (foot ``leg`` leaves the ground; flight follows), ``slip`` (foot ``leg`` would slip),
    ``scuff`` (foot ``leg`` passed under the ground behind the stance foot, within ``scuff_depth``: a
    report, the mode does not change; ``message`` says when and how deep), ``error`` (the run stopped:
    ``message`` says why), ``zeno`` (impacts accumulate; the run stopped).
    ``push`` (an impulse ``push`` (N s, [x forward, y up]) on the hip, applied as a velocity jump;
    ``leg`` is the stance foot then (0 in flight), ``stance_leg_after`` 0 if it lifted the foot off).
    ``impulse`` is the ground's impulse on the foot (N s), for touchdowns and pushes.
    ``energy_loss`` is the kinetic energy the event took out (J; negative for a push that adds energy).
    ``warnings`` lists violated contact assumptions of an impact (the old stance foot does not leave
    the ground, the impulse is outside the friction cone).
    """
    time: float
    kind: str
    leg: int
    q: np.ndarray
    dq_minus: np.ndarray
    dq_plus: np.ndarray
    impulse: np.ndarray | None = None
    stance_leg_before: int = 0
    stance_leg_after: int = 0
    energy_loss: float = 0.0
    warnings: list = field(default_factory=list)
    message: str = ""
    push: np.ndarray | None = None


@dataclass
class SimulationResult:
    """Samples at every accepted step (and twice at each impact: before and after)."""
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    stance_leg: np.ndarray
    grf: np.ndarray
    u: np.ndarray
    events: list
    stats: dict
    status: str = "completed"     # "completed", "stopped" (a scene's assumption left), "failed"
    message: str = ""
    #: per sample: E - E0 - motor work - work of pushes + energy lost at impacts (J); ~0 up to the integration error
    energy_balance: np.ndarray | None = None
    #: the run's Options (slope, scuff_depth and the tolerances its invariants were checked with)
    options: object = None
    #: the run's BipedModel (the stick figures of :meth:`plot`; None: the default model)
    model: object = None
    #: what ended a run "failed" in its controller: the exception the controller raised (its
    #: ``__traceback__`` reaches the raising line), or a :class:`ControllerError` naming what it returned;
    #: None otherwise
    controller_error: BaseException | None = None

    @classmethod
    def from_samples(cls, samples, events, stats, status, message, options, model=None, controller_error=None):
        """From the simulator's :class:`Samples`."""
        d, r, n, m = samples.rows(), samples.layout, samples.n_q, samples.n_u
        return cls(t=d[:, r["ROW_T"]].copy(), q=d[:, r["ROW_Q"]:r["ROW_Q"] + n].copy(),
                   dq=d[:, r["ROW_DQ"]:r["ROW_DQ"] + n].copy(), stance_leg=d[:, r["ROW_LEG"]].astype(int),
                   grf=d[:, r["ROW_F"]:r["ROW_F"] + 2].copy(), u=d[:, r["ROW_U"]:r["ROW_U"] + m].copy(),
                   events=events, stats=stats, status=status, message=message,
                   energy_balance=d[:, r["ROW_RESIDUAL"]].copy(), options=options, model=model,
                   controller_error=controller_error)

    def plot(self, path=None, title=None, frames=14):
        """The figure ``biped-sim inspect`` draws for a bag (joint angles, ground forces, hip torques,
        impacts, a stick-figure strip of the gait; the title says how and when the run ended and why
        it stopped), as a matplotlib Figure; ``path``: also written there as a PNG. Needs matplotlib
        (the ``plot`` extra), imported here only."""
        from biped_sim.engine.figure import run_figure
        from biped_sim.engine.model import BipedModel
        grf = self.grf.astype(float)
        grf[self.stance_leg == 0] = np.nan          # no stance foot in flight: the lines break there
        impacts = [(e.time, e.leg, e.q) for e in self.impacts]
        slope = float(getattr(self.options, "slope", 0.0) or 0.0)
        if title is None:
            title = f"simulated run: {len(impacts)} impacts"
        return run_figure(self.t, self.q, self.u, self.t, grf, impacts, self.model or BipedModel(), title,
                          slope=slope, path=path, frames=frames, outcome=(self.status, self.end_time, self.message))

    @property
    def end_time(self) -> float:
        """When the run ended (s): the time of the event that stopped it, else of its last sample."""
        stops = [e.time for e in self.events if e.kind in ("error", "zeno")]
        if self.status != "completed" and stops:
            return float(stops[-1])
        return float(self.t[-1]) if len(self.t) else float("nan")

    @property
    def impacts(self):
        return [e for e in self.events if e.kind in IMPACT_KINDS]


class SimulationError(RuntimeError):
    pass


class SceneAssumptionError(SimulationError):
    """The physics left the scene's declared phases: the run stops (status "stopped")."""


class ControllerError(SimulationError):
    """The controller failed: it raised (the exception is this one's ``__cause__``, with its traceback), or
    returned anything but two finite real numbers. The run ends "failed"."""


class Samples:
    """A run's samples in one flat float array that grows by doubling: a row a sample,
    ``[t, q (5), dq (5), stance_leg, F (2), u (2), energy-balance residual]`` (17 floats, 136 bytes;
    a tuple of lists and arrays took about 870); for a robot of ``n`` coordinates and ``m`` actuators q and dq
    have n entries and u m (``loop_state.sample_row``).

    ``keep``: True keeps every sample; an int N keeps every Nth (the first, the N+1st, ...), the samples
    of each event (before and after its reset) and the last one; ``"events"`` keeps only the first, the
    event samples and the last one;
    False keeps the last sample only (a node that runs for hours). The newest sample is always the
    last row: one that will not be kept is overwritten by the next (``provisional``).

    The counters are fields of the hybrid state ``S`` (the simulator's, which the compiled loop writes samples
    with: loop_state.py's n_samples, appended, provisional, every, last_only); by default a state of its own."""
    WIDTH = ROW_WIDTH

    def __init__(self, keep=True, S=None, n=5, m=2):
        self.S = new_state() if S is None else S
        self.n_q, self.n_u = n, m
        self.layout = SAMPLE_ROW if (n, m) == (5, 2) else sample_row(n, m)
        self.WIDTH = self.layout["ROW_WIDTH"]
        self.keep = keep
        self.every = 1 if keep is True else 0 if keep is False or keep == "events" else keep
        self.S[LAST_ONLY] = float(keep is False)
        self._data = np.empty((256 if keep is not False else 1, self.WIDTH))
        self.n = 0
        self.appended = 0
        self.provisional = False

    n = property(lambda self: int(self.S[N_SAMPLES]), lambda self, v: self.S.__setitem__(N_SAMPLES, v),
                 doc="the rows in use")
    appended = property(lambda self: int(self.S[APPENDED]), lambda self, v: self.S.__setitem__(APPENDED, v),
                        doc="the samples appended so far")
    every = property(lambda self: int(self.S[EVERY]), lambda self, v: self.S.__setitem__(EVERY, v),
                     doc="every how many samples one is kept (0: only the events' and the last)")
    provisional = property(lambda self: bool(self.S[PROVISIONAL]),
                           lambda self, v: self.S.__setitem__(PROVISIONAL, float(v)),
                           doc="the newest sample is overwritten by the next")

    def append(self, t, q, dq, leg, F, u, residual):
        S = self.S
        n = rules.ev_sample_slot(int(S[N_SAMPLES]), S[PROVISIONAL] != 0.0, self.keep is False)
        if n == len(self._data):
            self.grow()
        row = [0.0] * self.WIDTH        # (a list filled, then copied into the array: faster than the array's items)
        if self.WIDTH == ROW_WIDTH:
            rules.ev_sample_row(row, t, q, dq, leg, F, u, residual)
        else:
            rules.ev_sample_row_of(row, t, q, dq, self.n_q, leg, F, u, self.n_u, residual)
        self._data[n] = row
        S[N_SAMPLES] = n + 1
        S[APPENDED] += 1
        # the first sample (the initial state) is always kept
        S[PROVISIONAL] = float(rules.ev_provisional(int(S[APPENDED]), int(S[EVERY])))

    def grow(self):
        """Twice the room (the compiled loop writes into ``_data`` directly and asks for this when full)."""
        self._data = np.concatenate([self._data, np.empty_like(self._data)])

    def make_room(self):
        """Room for two more samples (an impact's) before the compiled loop writes into ``_data``."""
        if self.keep is not False and self.n + 2 > len(self._data):
            self.grow()

    def keep_last(self):
        """Keep the newest sample (an event's) whatever ``keep`` thins out."""
        self.provisional = False

    def pop(self):
        self.n -= 1
        self.appended -= 1
        self.provisional = False

    def last(self):
        """(t, q, dq, stance_leg, F, u, residual) of the last sample: arrays q, dq; lists F, u."""
        r, o, n = self._data[self.n - 1], self.layout, self.n_q
        dq, f, u = o["ROW_DQ"], o["ROW_F"], o["ROW_U"]
        return (float(r[ROW_T]), r[ROW_Q:ROW_Q + n].copy(), r[dq:dq + n].copy(), int(r[o["ROW_LEG"]]),
                r[f:f + 2].tolist(), r[u:u + self.n_u].tolist(), float(r[o["ROW_RESIDUAL"]]))

    def set_last_in_flight(self):
        """The last sample is a flight sample (a stance that ended the instant it began)."""
        f = self.layout["ROW_F"]
        self._data[self.n - 1, self.layout["ROW_LEG"]] = 0
        self._data[self.n - 1, f:f + 2] = 0.0

    def last_force(self):
        f = self.layout["ROW_F"]
        return self._data[self.n - 1, f:f + 2].tolist()

    def rows(self):
        return self._data[:self.n]

    def __len__(self):
        return self.n
