"""The options of a hybrid run (``Options``): which phases, which guards, which tolerances."""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from biped_sim.engine.integrators import ADAPTIVE_METHODS, FIXED_STEP_METHODS, METHODS

PHASES = frozenset({"stance", "impact", "flight"})
#: the scuff rules of touchdown_rule "front": a swing foot under the ground passes through it while it moves
#: forward ("forward"), or wherever it is behind the stance foot ("behind", the compass-gait literature's)
SCUFF_RULES = ("forward", "behind")


@dataclass
class Options:
    base: str = "floating"
    phases: frozenset = PHASES
    touchdown_rule: str = "front"
    # which crossings of the swing foot are scuffs (passes through the ground) under touchdown_rule "front":
    # "forward" those of a foot moving forward (it lands where it does not), "behind" every one behind the
    # stance foot (docs/engine.md "Scuffs")
    scuff_rule: str = "forward"
    scuff_depth: float = math.inf      # m; a scuff deeper than this stops the run (inf: no bound)
    front_tol: float = 1e-5            # m; a touchdown within this of the stance foot's x counts as behind
    stop_on_slip: bool = True
    project_constraints: bool = True
    step: float | None = None          # fixed-step methods: the step size (s)
    max_step: float = np.inf
    slope: float = 0.0                 # ground angle (rad), positive: the ground falls in +x
    arm_height: float = 1e-9           # m above the ground that arms a foot's touchdown guard
    event_tol: float = 1e-13           # s, root-finding tolerance on event times
    graze_tol: float = 1e-10           # m; a dip of a swing foot deeper than this inside a step is found
    simultaneous_tol: float = 1e-9     # s, two touchdowns closer than this are one double touchdown
    contact_tol: float = 1e-6          # m and m/s, initial-state check of the stance foot
    max_events: int = 100_000
    zeno_interval: float = 1e-6        # s; this many impacts in a row closer than it stop the run
    zeno_count: int = 20
    max_speed: float = 1e4             # a velocity entry above this is a diverging state
    ground_tol: float = 1e-9           # m; invariant: no free foot lower than this below the ground
    force_tol: float = 1e-6            # N; invariant: stance normal force and friction margin above -this
    impulse_tol: float = 1e-6          # N s; invariant: every normal impulse of an impact above -this
    check_invariants: bool = True      # check them after every step and reset (docs/engine.md)
    compute_grf: bool = True
    # True: every accepted step; N: every Nth, the event samples and the last; "events": the first,
    # the event samples and the last; False: the last only (a long-running node)
    keep_samples: bool | int | str = True

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
        if self.scuff_rule not in SCUFF_RULES:
            raise ValueError(f"scuff_rule must be one of {', '.join(map(repr, SCUFF_RULES))}, got {self.scuff_rule!r}")
        check_number("slope", self.slope, -math.pi / 2, math.pi / 2, "rad, strictly between -pi/2 and pi/2",
                     open_low=True, open_high=True)
        for name, low, what in (("event_tol", 0.0, "s"), ("contact_tol", 0.0, "m and m/s"),
                                ("front_tol", 0.0, "m"), ("graze_tol", 0.0, "m"),
                                ("zeno_interval", 0.0, "s"), ("max_speed", 0.0, "m/s and rad/s"),
                                ("ground_tol", 0.0, "m"), ("force_tol", 0.0, "N"), ("impulse_tol", 0.0, "N s")):
            check_number(name, getattr(self, name), low, math.inf, what, open_low=True)
        for name, what in (("arm_height", "m"), ("simultaneous_tol", "s")):
            check_number(name, getattr(self, name), 0.0, math.inf, what)
        check_number("scuff_depth", self.scuff_depth, 0.0, math.inf, "m, or inf for no bound", open_low=True,
                     allow_inf=True)
        check_number("max_step", self.max_step, 0.0, math.inf, "s, or inf for no limit", open_low=True,
                     allow_inf=True)
        if self.step is not None:
            check_number("step", self.step, 0.0, math.inf, "s", open_low=True)
        k = self.keep_samples
        if not (isinstance(k, bool) or k == "events" or isinstance(k, numbers.Integral) and k >= 1):
            raise ValueError(f"keep_samples must be True, False, 'events' or a whole number N >= 1 (every Nth "
                             f"sample), got {k!r}")
        for name in ("max_events", "zeno_count"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < 1:
                raise ValueError(f"{name} must be a whole number >= 1, got {v!r}")


def check_number(name, value, low, high, what, open_low=False, open_high=False, allow_inf=False):
    """A ValueError naming ``name`` unless ``value`` is a real number (not a bool) in the range."""
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool)
    if ok:
        v = float(value)
        ok = (math.isfinite(v) or allow_inf and v == math.inf) and (v > low if open_low else v >= low) and (
            v < high if open_high else v <= high)
    if not ok:
        lo = "(" if open_low else "["
        hi = ")" if open_high or high == math.inf else "]"
        raise ValueError(f"{name} must be a number in {lo}{low:g}, {high:g}{hi} ({what}), got {value!r}")


#: the smallest relative tolerance the adaptive methods accept (100 eps, as scipy's solvers)
MIN_RTOL = 100 * np.finfo(float).eps


def check_run_arguments(opt, method, rtol, atol, mu, stance_leg) -> int:
    """A ValueError naming the argument unless the run's method, tolerances, friction and starting
    mode are allowed (with these options); returns stance_leg as an int."""
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if method in FIXED_STEP_METHODS and not opt.step:
        raise ValueError(f"method {method!r} is fixed-step: give step=<seconds>")
    if method in ADAPTIVE_METHODS:
        # below ~100 eps a step's error estimate is roundoff: the tolerance cannot be met
        check_number("rtol", rtol, MIN_RTOL, 1.0,
                     f"relative; double precision delivers no less than {MIN_RTOL:.3g}", open_high=True)
        check_number("atol", atol, 0.0, 1.0, "absolute", open_low=True, open_high=True)
    if mu is not None:
        check_number("mu", mu, 0.0, math.inf, "friction coefficient, or None for enough friction")
    if isinstance(stance_leg, bool) or not isinstance(stance_leg, (int, np.integer)) or stance_leg not in (0, 1, 2):
        raise ValueError(f"stance_leg must be 1, 2 or 0 (flight), got {stance_leg!r}")
    stance_leg = int(stance_leg)
    if stance_leg == 0 and "flight" not in opt.phases:
        raise ValueError("stance_leg=0 starts in flight, but the phases do not include 'flight'")
    if stance_leg != 0 and "stance" not in opt.phases:
        raise ValueError("the phases do not include 'stance': start in flight with stance_leg=0")
    return stance_leg
