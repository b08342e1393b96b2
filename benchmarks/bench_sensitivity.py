"""The exact Jacobian of the step map against finite differences: ``python -m benchmarks.bench_sensitivity``.

Owns the timings of issue 32 (no assertions: the machine is shared), each the median of ``repeats``:

* the walk scene's gait: the 5 x 5 Jacobian of its step map at the fixed point, exact
  (``StepMap.jacobian``: one run of the variational equations with the saltation matrix of the impact)
  against central differences (``StepMap.jacobian_fd``: 10 runs of the engine);
* one step of the walk gait with its Jacobian (``run_jacobian``: the engine's run, then the augmented
  system (x, S) with S 10 x 6, integrated by scipy's DOP853 in Python) against one step without (the
  engine's run, ``StepMap.run``, on the compiled loop where it is built) and against the same step by the
  same integrator without S (scipy's DOP853 on x alone, the same right-hand side in Python): the first
  ratio is what a user pays, the second what the variational equations cost in one machinery.
"""
from __future__ import annotations

import statistics
import time

import numpy as np

from biped_sim.analysis.gait import scene_gait
from biped_sim.engine.compiled import IMPLEMENTATION
from biped_sim.engine.dynamics import stance_floating_fast
from biped_sim.engine.sensitivity import run_jacobian


def median_seconds(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def plain_step_in_python(smap, z, rtol, atol):
    """The step from z by scipy's DOP853 on x alone (stance on leg 1 to the touchdown of leg 2)."""
    from scipy.integrate import solve_ivp
    model, law = smap.model, smap.controller
    q, dq = smap.state(z)

    def rhs(t, x):
        ql, dql = x[:5].tolist(), x[5:].tolist()
        ddq, _F = stance_floating_fast(model, ql, dql, list(law(t, ql, dql, 1)), 1)
        return np.concatenate([x[5:], ddq])

    def touchdown(t, x):
        return model.foot_position(x[:5], 2)[1]      # (the walk scene's ground is flat)

    touchdown.terminal, touchdown.direction = False, -1
    return solve_ivp(rhs, (0.0, 0.6), np.concatenate([q, dq]), method="DOP853", rtol=rtol, atol=atol,
                     events=touchdown, dense_output=True)


def main():
    repeats = 5
    g = scene_gait("walk")
    smap, z = g.step_map, g.fixed_point
    U, _ = smap.basis(z)
    exact = median_seconds(lambda: smap.jacobian(z, U), repeats)
    fd = median_seconds(lambda: smap.jacobian_fd(z, U), repeats)
    print(f"walk gait (generated code {IMPLEMENTATION}; law derivative: {g.law_derivative}): 5 x 5 Jacobian of the "
          f"step map exact {exact * 1e3:.1f} ms, central differences {fd * 1e3:.1f} ms "
          f"(exact / differences = {exact / fd:.2f}; issue 32's goal: <= 0.1)")
    q, dq = smap.state(z)
    kw = smap.kw
    with_jacobian = median_seconds(lambda: run_jacobian(smap.model, q, dq, 5.0, controller=smap.controller,
                                                        end_at_event=True, **kw), repeats)
    engine_step = median_seconds(lambda: smap.run(z), repeats)
    python_step = median_seconds(lambda: plain_step_in_python(smap, z, kw["rtol"], kw["atol"]), repeats)
    print(f"one step of the walk gait (n = 10 states, S 10 x 6): with its Jacobian {with_jacobian * 1e3:.1f} ms, "
          f"without on the engine {engine_step * 1e3:.2f} ms (ratio {with_jacobian / engine_step:.1f}), "
          f"without by the same Python DOP853 {python_step * 1e3:.1f} ms (ratio {with_jacobian / python_step:.1f}); "
          "issue 32's goal: <= 3")
    return dict(exact_s=exact, fd_s=fd, step_with_jacobian_s=with_jacobian, engine_step_s=engine_step,
                python_step_s=python_step)


if __name__ == "__main__":
    main()
