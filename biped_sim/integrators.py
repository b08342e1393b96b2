"""One-step integrators with dense output, in the style of scipy's ``OdeSolver``.

Owns the numerical integration of one continuous phase (no physics, no events): a stepper has
``t``, ``y``, ``step()`` (one accepted step, or a failure with a message), ``dense_output()`` over
the last step, and counters ``nfev``, ``naccepted``, ``nrejected``. The hybrid engine
(``hybrid.py``) locates guards on the dense output and restarts a stepper after every reset.

Methods (``make_stepper(name, ...)``):
  * ``dop853``   adaptive explicit Runge-Kutta 8(5,3) of Dormand and Prince with its 7th-order
                 dense output (coefficients from scipy); the default. Same algorithm as
                 ``solve_ivp(method="DOP853")`` with less overhead per stage.
  * ``rk4``      classical fixed-step Runge-Kutta (what a real-time loop runs); cubic Hermite
                 dense output from the end-point derivatives.
  * ``semi_implicit_euler``  fixed-step symplectic Euler (velocities first): the cheap baseline.
  * ``radau``, ``bdf``       implicit methods for stiff cases (scipy's ``Radau`` and ``BDF``).
  * ``scipy_dop853``, ``scipy_rk45``  scipy's explicit solvers, for comparison.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import BDF, DOP853 as _ScipyDOP853, RK45, Radau
from scipy.integrate._ivp import dop853_coefficients as _dop  # coefficient tables only

FIXED_STEP_METHODS = ("rk4", "semi_implicit_euler")
ADAPTIVE_METHODS = ("dop853", "radau", "bdf", "scipy_dop853", "scipy_rk45")
METHODS = ADAPTIVE_METHODS + FIXED_STEP_METHODS


class StepFailure(RuntimeError):
    """The integrator cannot continue (step size underflow, non-finite state, solver failure)."""


class _Stepper:
    #: True when the last right-hand-side evaluation of ``step()`` is at the new (t, y)
    last_eval_at_end = True

    def __init__(self, fun, t0, y0, t_bound):
        self.fun = fun
        self.nfev = 0
        self.naccepted = 0
        self.nrejected = 0
        self.restart(t0, y0, t_bound)

    def restart(self, t0, y0, t_bound, h=None):
        self.t = float(t0)
        self.y = np.array(y0, dtype=float)
        self.t_bound = float(t_bound)
        self.t_old = self.t
        self.y_old = self.y


class DOP853Stepper(_Stepper):
    """Dormand-Prince 8(5,3), the algorithm of scipy's DOP853 (Hairer's step control).

    The twelve stages are combined with one small matrix product each; the three extra stages of
    the dense output are computed only when ``dense_output()`` is asked for, which the hybrid
    engine does only in steps where a guard may have crossed.
    """
    A = _dop.A[:_dop.N_STAGES, :_dop.N_STAGES]
    Bw = _dop.B
    C = _dop.C[:_dop.N_STAGES]
    E3 = _dop.E3
    E5 = _dop.E5
    D = _dop.D
    A_EXTRA = _dop.A[_dop.N_STAGES + 1:]
    # constant per class, not per stepper: the node builds a stepper every control period
    _rows = [_dop.A[s, :s].copy() for s in range(_dop.N_STAGES)]
    _E53 = np.vstack([_dop.E5, _dop.E3])
    C_EXTRA = _dop.C[_dop.N_STAGES + 1:]
    SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
    ERROR_EXPONENT = -1.0 / 8.0

    def __init__(self, fun, t0, y0, t_bound, rtol=1e-9, atol=1e-9, h0=None, max_step=np.inf):
        self.rtol, self.atol, self.max_step = rtol, atol, max_step
        self.h_abs = h0
        super().__init__(fun, t0, y0, t_bound)

    def restart(self, t0, y0, t_bound, h=None):
        super().restart(t0, y0, t_bound)
        self.f = np.asarray(self.fun(self.t, self.y), dtype=float)
        self.nfev += 1
        self.K = np.empty((_dop.N_STAGES_EXTENDED, self.y.size))
        if h is not None:
            self.h_abs = h
        if self.h_abs is None:
            self.h_abs = self._initial_step()
        self.h_abs = min(self.h_abs, self.max_step)
        self._dense = None

    def _initial_step(self):
        # Hairer, Norsett & Wanner, Solving ODEs I, II.4 (as in scipy's select_initial_step)
        y, f = self.y, self.f
        scale = self.atol + np.abs(y) * self.rtol
        d0 = np.sqrt(np.mean((y / scale) ** 2))
        d1 = np.sqrt(np.mean((f / scale) ** 2))
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, abs(self.t_bound - self.t)) or 1e-6
        f1 = self.fun(self.t + h0, y + h0 * f)
        self.nfev += 1
        d2 = np.sqrt(np.mean(((f1 - f) / scale) ** 2)) / h0
        if d1 <= 1e-15 and d2 <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
        return min(100 * h0, h1)

    def step(self):
        # K holds the stages already scaled by h (K[s] = h f_s): every stage is then one dot
        # product with a pre-sliced row of A and one addition, the fewest numpy calls per stage
        t, y, K, fun, rows, C = self.t, self.y, self.K, self.fun, self._rows, self.C
        remaining = self.t_bound - t
        if remaining <= 0:
            return
        min_step = 10 * np.spacing(t) + 1e-300
        h_abs = min(self.h_abs, self.max_step)
        rejected = False
        dot, multiply = np.dot, np.multiply
        while True:
            if h_abs < min_step:
                raise StepFailure(f"step size {h_abs:.3g} s fell below the smallest step at t={t:.9g} s "
                                  "(the dynamics are too stiff or singular for an explicit method)")
            h = h_abs
            if h >= remaining:
                h = remaining
                h_abs = remaining
            multiply(self.f, h, out=K[0])
            for s in range(1, 12):
                multiply(fun(t + C[s] * h, y + dot(rows[s], K[:s])), h, out=K[s])
            y_new = y + dot(self.Bw, K[:12])
            f_new = fun(t + h, y_new)
            multiply(f_new, h, out=K[12])
            self.nfev += 12
            scale = self.atol + np.maximum(np.abs(y), np.abs(y_new)) * self.rtol
            e = dot(self._E53, K[:13]) / scale       # rows: h * err5, h * err3 (scaled)
            n5, n3 = (e * e).sum(axis=1)
            # scipy's |h| n5 / sqrt((n5 + 0.01 n3) n) with n5, n3 of the unscaled stages
            err = 0.0 if n5 == 0.0 and n3 == 0.0 else n5 / math.sqrt((n5 + 0.01 * n3) * scale.size)
            if err < 1.0:
                if not np.isfinite(y_new).all():
                    raise StepFailure(f"the state became non-finite at t={t + h:.9g} s")
                factor = self.MAX_FACTOR if err == 0.0 else min(self.MAX_FACTOR, self.SAFETY * err ** self.ERROR_EXPONENT)
                if rejected:
                    factor = min(1.0, factor)
                self.h_abs = h_abs * factor
                break
            if not math.isfinite(err):
                h_abs *= self.MIN_FACTOR
            else:
                h_abs *= max(self.MIN_FACTOR, self.SAFETY * err ** self.ERROR_EXPONENT)
            rejected = True
            self.nrejected += 1
        self.naccepted += 1
        self.t_old, self.y_old, self.f_old, self.h = t, y, self.f, h
        self.t = t + h if h < remaining else self.t_bound
        self.y, self.f = y_new, np.asarray(f_new, dtype=float)
        self._dense = None

    def dense_output(self):
        if self._dense is None:
            K, h, t0, y0 = self.K, self.h, self.t_old, self.y_old
            for s, (a, c) in enumerate(zip(self.A_EXTRA, self.C_EXTRA), start=13):
                np.multiply(self.fun(t0 + c * h, y0 + np.dot(a[:s], K[:s])), h, out=K[s])
            self.nfev += 3
            F = np.empty((_dop.INTERPOLATOR_POWER, self.y.size))
            dy = self.y - y0
            F[0] = dy
            F[1] = K[0] - dy
            F[2] = 2 * dy - (K[12] + K[0])
            F[3:] = self.D @ K
            self._dense = _DOP853Interpolant(t0, self.t, y0, F[::-1].copy())
        return self._dense


class _DOP853Interpolant:
    def __init__(self, t_old, t, y_old, F_reversed):
        self.t_old, self.t, self.y_old, self.F = t_old, t, y_old, F_reversed
        self.h = t - t_old

    def __call__(self, t):
        x = (t - self.t_old) / self.h
        y = np.zeros_like(self.y_old)
        for i, f in enumerate(self.F):
            y += f
            y *= x if i % 2 == 0 else 1.0 - x
        return y + self.y_old


class _HermiteInterpolant:
    """Cubic Hermite interpolant from the end values and derivatives of one step."""

    def __init__(self, t0, t1, y0, y1, f0, f1):
        self.t_old, self.t = t0, t1
        self.y0, self.y1, self.f0, self.f1 = y0, y1, f0, f1
        self.h = t1 - t0

    def __call__(self, t):
        s = (t - self.t_old) / self.h
        h00 = (1 + 2 * s) * (1 - s) ** 2
        h10 = s * (1 - s) ** 2
        h01 = s * s * (3 - 2 * s)
        h11 = s * s * (s - 1)
        return h00 * self.y0 + h10 * self.h * self.f0 + h01 * self.y1 + h11 * self.h * self.f1


class _FixedStepper(_Stepper):
    def __init__(self, fun, t0, y0, t_bound, h):
        if not h or h <= 0:
            raise ValueError(f"a fixed-step method needs a positive step size, got {h!r}")
        self.h_fixed = float(h)
        super().__init__(fun, t0, y0, t_bound)

    def restart(self, t0, y0, t_bound, h=None):
        super().restart(t0, y0, t_bound)
        self.f = np.asarray(self.fun(self.t, self.y), dtype=float)
        self.nfev += 1

    def step(self):
        remaining = self.t_bound - self.t
        if remaining <= 0:
            return
        # a step that would end within 1e-9 h of the bound ends on it (no sliver steps)
        h = remaining if remaining <= self.h_fixed * (1 + 1e-9) else self.h_fixed
        y_new = self._advance(self.t, self.y, self.f, h)
        if not np.isfinite(y_new).all():
            raise StepFailure(f"the state became non-finite at t={self.t + h:.9g} s (step {h:.3g} s too large?)")
        self.t_old, self.y_old, self.f_old, self.h = self.t, self.y, self.f, h
        self.t = self.t + h if h < remaining else self.t_bound
        self.y = y_new
        self.f = np.asarray(self.fun(self.t, y_new), dtype=float)
        self.nfev += 1
        self.naccepted += 1

    def dense_output(self):
        return _HermiteInterpolant(self.t_old, self.t, self.y_old, self.y, self.f_old, self.f)


class RK4Stepper(_FixedStepper):
    def _advance(self, t, y, f, h):
        fun = self.fun
        k2 = fun(t + 0.5 * h, y + 0.5 * h * f)
        k3 = fun(t + 0.5 * h, y + 0.5 * h * k2)
        k4 = fun(t + h, y + h * k3)
        self.nfev += 3
        return y + (h / 6.0) * (f + 2.0 * k2 + 2.0 * k3 + k4)


class SemiImplicitEulerStepper(_FixedStepper):
    """Symplectic Euler for y = [q (n), dq (n), extra...]: dq first, then q with the new dq.

    ``n`` is the number of positions; entries after 2n (quadratures such as the work of the
    motors) advance with explicit Euler.
    """

    def __init__(self, fun, t0, y0, t_bound, h, n):
        self.n = n
        super().__init__(fun, t0, y0, t_bound, h)

    def _advance(self, t, y, f, h):
        n = self.n
        y_new = y + h * f
        y_new[:n] = y[:n] + h * y_new[n:2 * n]
        return y_new


class ScipyStepper(_Stepper):
    """A scipy ``OdeSolver`` (Radau, BDF, DOP853, RK45) behind the same interface."""
    last_eval_at_end = False
    CLASSES = {"radau": Radau, "bdf": BDF, "scipy_dop853": _ScipyDOP853, "scipy_rk45": RK45}

    def __init__(self, method, fun, t0, y0, t_bound, rtol, atol, h0=None, max_step=np.inf):
        self.cls = self.CLASSES[method]
        self.rtol, self.atol, self.max_step, self.h0 = rtol, atol, max_step, h0
        self._nfev_done = 0
        self._njev_done = 0
        super().__init__(fun, t0, y0, t_bound)

    def restart(self, t0, y0, t_bound, h=None):
        super().restart(t0, y0, t_bound)
        if hasattr(self, "solver"):
            self._nfev_done += self.solver.nfev
        kw = dict(rtol=self.rtol, atol=self.atol, max_step=self.max_step)
        if h is not None or self.h0 is not None:
            kw["first_step"] = min(h or self.h0, max(t_bound - t0, 1e-15))
        self.solver = self.cls(self.fun, self.t, self.y, self.t_bound, **kw)

    @property
    def nfev(self):
        return self._nfev_done + (self.solver.nfev if hasattr(self, "solver") else 0)

    @nfev.setter
    def nfev(self, value):
        pass

    @property
    def h_abs(self):
        return getattr(self.solver, "h_abs", None) if hasattr(self, "solver") else None

    def step(self):
        if self.t >= self.t_bound:
            return
        msg = self.solver.step()
        if self.solver.status == "failed":
            raise StepFailure(f"{self.cls.__name__} failed at t={self.solver.t:.9g} s: {msg}")
        if not np.isfinite(self.solver.y).all():
            raise StepFailure(f"the state became non-finite at t={self.solver.t:.9g} s")
        self.naccepted += 1
        self.t_old, self.y_old = self.t, self.y
        self.t, self.y = self.solver.t, self.solver.y.copy()

    def dense_output(self):
        return self.solver.dense_output()


def make_stepper(method, fun, t0, y0, t_bound, rtol=1e-9, atol=1e-9, step=None, n_positions=None,
                 h0=None, max_step=np.inf):
    """The stepper for ``method`` (see the module doc); ``step`` is the fixed-step size."""
    if method == "dop853":
        return DOP853Stepper(fun, t0, y0, t_bound, rtol, atol, h0=h0, max_step=max_step)
    if method == "rk4":
        return RK4Stepper(fun, t0, y0, t_bound, step)
    if method == "semi_implicit_euler":
        return SemiImplicitEulerStepper(fun, t0, y0, t_bound, step, n_positions)
    if method in ScipyStepper.CLASSES:
        return ScipyStepper(method, fun, t0, y0, t_bound, rtol, atol, h0=h0, max_step=max_step)
    raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
