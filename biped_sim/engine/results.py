"""What a run returns: its discrete events and its samples (``Event``, ``SimulationResult``).

Plain data, filled by :class:`biped_sim.engine.hybrid.HybridSimulator`; the recorder, the node and the
analysis read them.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

EVENT_KINDS = ("touchdown", "double_touchdown", "liftoff", "slip", "scuff", "error", "zeno")
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
    ``impulse`` is the ground's impulse on the foot (N s), for touchdowns only.
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
    #: per sample: E - E0 - motor work + energy lost at impacts (J); ~0 up to the integration error
    energy_balance: np.ndarray | None = None
    #: the run's Options (slope, scuff_depth and the tolerances its invariants were checked with)
    options: object = None

    @classmethod
    def from_samples(cls, samples, events, stats, status, message, options):
        """From the simulator's samples: tuples (t, q, dq, stance_leg, F, u, energy-balance residual)."""
        columns = list(zip(*samples)) if samples else [()] * 7
        return cls(t=np.array(columns[0]), q=np.array(columns[1]), dq=np.array(columns[2]),
                   stance_leg=np.array(columns[3], dtype=int), grf=np.array(columns[4]), u=np.array(columns[5]),
                   events=events, stats=stats, status=status, message=message,
                   energy_balance=np.array(columns[6]), options=options)

    @property
    def impacts(self):
        return [e for e in self.events if e.kind in IMPACT_KINDS]


class SimulationError(RuntimeError):
    pass


class SceneAssumptionError(SimulationError):
    """The physics left the scene's declared phases: the run stops (status "stopped")."""
