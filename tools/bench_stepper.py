"""Bare stepper cost: biped_sim DOP853Stepper against scipy.integrate.DOP853 on an 11-state oscillator (same steps)."""
import numpy as np, time
from scipy.integrate import DOP853
from biped_sim.integrators import DOP853Stepper
def f(t, y): return np.array([y[1], -y[0]] + [0.0]*9)
y0 = np.r_[1.0, 0.0, np.zeros(9)]
for name, mk in [("ours", lambda: DOP853Stepper(f, 0, y0, 200.0, 1e-10, 1e-10)), ("scipy", lambda: DOP853(f, 0, y0, 200.0, rtol=1e-10, atol=1e-10))]:
    best = 1e9
    for _ in range(3):
        s = mk(); t0 = time.perf_counter(); n=0
        while s.t < 200.0: s.step(); n+=1
        best = min(best, time.perf_counter()-t0)
    print(name, n, "steps", s.nfev, "nfev", "%.1f us/step" % (best/n*1e6), "%.2f us/eval" % (best/s.nfev*1e6))
t0=time.perf_counter()
for _ in range(10000): f(0, y0)
print("rhs %.2f us" % ((time.perf_counter()-t0)/10000*1e6))
