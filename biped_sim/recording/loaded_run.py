"""A recorded run read back into named arrays: :func:`load_run` (``biped_sim.load_run``, docs/recording.md)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from biped_sim.recording import inspect_bag


@dataclass
class RecordedRun:
    """A bag's run as arrays, named as :class:`biped_sim.SimulationResult`'s.

    t (n,) s; q, dq (n, 5) physical coordinates [x, y, q1, q2, q3]; u (n, 2) hip torques (N m);
    stance_leg (n,) 0 in flight, else 1 or 2: one row per ``joint_states`` message. grf (m, 2) [F_x,
    F_y] (N) at grf_t (m,) s: one row per ``ground_reaction`` message (none in flight). impacts: the
    ``impact`` topic's events; events: every engine event (touchdowns, scuffs, liftoffs, pushes, ...)
    in their order, each a dict of typed values (floats, ints, lists of floats; docs/node.md lists
    the keys). params: the run's parameters record (None for a bag not recorded by biped_sim).
    """
    bag: str
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    u: np.ndarray
    stance_leg: np.ndarray
    grf_t: np.ndarray
    grf: np.ndarray
    impacts: list
    events: list
    params: dict | None

    def to_dataframe(self):
        """The samples as a pandas DataFrame indexed by t: x, y, q1, q2, q3, their rates (dx ... dq3),
        u1, u2, stance_leg (the ground force is on its own clock: ``grf_t``, ``grf``)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("RecordedRun.to_dataframe needs pandas: pip install pandas") from None
        names = ["x", "y", "q1", "q2", "q3"]
        cols = {n: self.q[:, i] for i, n in enumerate(names)}
        cols.update({"d" + n: self.dq[:, i] for i, n in enumerate(names)})
        cols.update(u1=self.u[:, 0], u2=self.u[:, 1], stance_leg=self.stance_leg)
        return pd.DataFrame(cols, index=pd.Index(self.t, name="t"))

    to_pandas = to_dataframe


def load_run(bag) -> RecordedRun:
    """Every sample and event of a recorded bag (a bag directory or its .mcap file) as arrays."""
    run = inspect_bag.load_run(bag, max_points=None)
    return RecordedRun(bag=str(bag), t=run["t"], q=run["q"], dq=run["dq"], u=run["u"], stance_leg=run["leg"],
                       grf_t=run["grf_t"], grf=run["grf"], impacts=run["impacts"], events=run["all_events"],
                       params=run["params"])
