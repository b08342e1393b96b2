"""The options of a hybrid run (``Options``): which phases, which guards, which tolerances."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PHASES = frozenset({"stance", "impact", "flight"})


@dataclass
class Options:
    base: str = "floating"
    phases: frozenset = PHASES
    touchdown_rule: str = "front"
    stop_on_slip: bool = True
    project_constraints: bool = True
    step: float | None = None          # fixed-step methods: the step size (s)
    max_step: float = np.inf
    slope: float = 0.0                 # ground angle (rad), positive: the ground falls in +x
    arm_height: float = 1e-9           # m above the ground that arms a foot's touchdown guard
    event_tol: float = 1e-13           # s, root-finding tolerance on event times
    simultaneous_tol: float = 1e-9     # s, two touchdowns closer than this are one double touchdown
    contact_tol: float = 1e-6          # m and m/s, initial-state check of the stance foot
    max_events: int = 100_000
    zeno_interval: float = 1e-6        # s; this many impacts in a row closer than it stop the run
    zeno_count: int = 20
    max_speed: float = 1e4             # a velocity entry above this is a diverging state
    max_penetration: float = 0.05      # m; a free foot this deep below the ground: the robot fell
                                       # or a touchdown was missed (checked when impacts are modelled)
    compute_grf: bool = True
    keep_samples: bool = True          # False: keep only the last sample (a long-running node)

    def check(self):
        if self.base not in ("floating", "fixed"):
            raise ValueError(f"base must be 'floating' or 'fixed', got {self.base!r}")
        unknown = set(self.phases) - PHASES
        if unknown or "stance" not in self.phases and "flight" not in self.phases:
            raise ValueError(f"phases must be a subset of {sorted(PHASES)} with stance or flight, "
                             f"got {sorted(self.phases)}")
        if self.base == "fixed" and "flight" in self.phases:
            raise ValueError("the fixed-base method has no flight phase: use base='floating' or drop 'flight'")
        if self.touchdown_rule not in ("front", "any"):
            raise ValueError(f"touchdown_rule must be 'front' or 'any', got {self.touchdown_rule!r}")
