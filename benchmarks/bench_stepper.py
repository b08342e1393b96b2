"""Bare stepper cost: biped_sim DOP853Stepper against scipy.integrate.DOP853 on an 11-state oscillator.

Each is driven with the right-hand side in the form it takes (ours: lists; scipy: arrays), so the
figures are the steppers' own overhead plus a near-free right-hand side.
"""
import time

import numpy as np
from scipy.integrate import DOP853

from biped_sim.engine.integrators import DOP853Stepper

ZEROS = [0.0] * 9


def f_list(t, y):
    return [y[1], -y[0]] + ZEROS


def f_array(t, y):
    return np.array([y[1], -y[0]] + ZEROS)


y0 = [1.0, 0.0] + ZEROS
for name, mk in [("ours", lambda: DOP853Stepper(f_list, 0, y0, 200.0, 1e-10, 1e-10)),
                 ("scipy", lambda: DOP853(f_array, 0, np.array(y0), 200.0, rtol=1e-10, atol=1e-10))]:
    best = 1e9
    for _ in range(3):
        s = mk()
        t0 = time.perf_counter()
        n = 0
        while s.t < 200.0:
            s.step()
            n += 1
        best = min(best, time.perf_counter() - t0)
    print(name, n, "steps", s.nfev, "nfev", "%.1f us/step" % (best / n * 1e6), "%.2f us/eval" % (best / s.nfev * 1e6))
