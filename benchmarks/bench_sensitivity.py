"""The exact Jacobian of the step map against finite differences: ``python -m benchmarks.bench_sensitivity``.

Owns the timings of issue 32 (no assertions: the machine is shared), each the median of ``repeats``, the
rows of each group measured in alternation:

* the walk scene's gait: the 5 x 5 Jacobian of its step map at the fixed point, exact (``StepMap.jacobian``:
  ``run_jacobian`` on the engine's own accepted steps, engine/variational.py, the default; and the augmented
  system integrated on its own by scipy's solve_ivp, ``integration="solve_ivp"``) against central
  differences (``StepMap.jacobian_fd`` with one step of 1e-6 at the gait's tolerance: 10 runs of the engine,
  the cheapest differences); the row "exact / central differences" is issue 32's first ratio (its goal:
  <= 0.1); and ``Gait.jacobian_fd()``'s defaults (Richardson-extrapolated from two steps, 20 runs at rtol
  1e-12), the check of the exact Jacobian (the solve_ivp row is timed on its own: its 60 ms of Python leave the
  caches cold, which would slow the engine's rows alternated with it by a third);
* one step of the walk gait with its Jacobian (``run_jacobian``, S 10 x 6: the engine's run, then S on its
  steps) against one step without (the engine's run, ``StepMap.run``, on the compiled loop where it is
  built): the row "step with its Jacobian / step" is issue 32's second ratio (its goal: <= 3, n = 10);
  and the same step by scipy's DOP853 on x alone in Python (the right-hand side the solve_ivp path
  integrates, without S);
* the same step's exact Jacobian from the three-link's closed forms (``derivatives(BipedModel)``, the
  default) against the three_link description's generated terms (``run_jacobian(..., derivatives=...)``,
  config/codegen.py's module run in Python), on the engine's steps and by solve_ivp: what the derivatives
  of any described robot cost against hand-kept closed forms of the same robot;
* the variational terms of that step's stance phase alone (its accepted steps as one stack, 12 stages each):
  in C (``variational.steps_transition_c``, engine/_variational.c: under the walking law's compiled derivative
  and under a held torque) against numpy (``variational.steps_transition``), per stage.
"""
from __future__ import annotations

import statistics
import time

import numpy as np

from biped_sim.analysis.gait import RELABELED_ROWS, scene_gait
from biped_sim.config.models import generated_model
from biped_sim.engine import variational
from biped_sim.engine.compiled import IMPLEMENTATION
from biped_sim.engine.dynamics import stance_floating_fast
from biped_sim.engine.model_derivatives import derivatives
from biped_sim.engine.sensitivity import SOLVE_IVP, STEPS, run_jacobian


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


def alternating(fns, repeats):
    """The median seconds of each of ``fns`` (a dict), measured in alternation."""
    times = {k: [] for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t0)
    return {k: statistics.median(v) for k, v in times.items()}


def main():
    repeats = 7
    g = scene_gait("walk")
    smap, z = g.step_map, g.fixed_point
    U, _ = smap.basis(z)
    q, dq = smap.state(z)
    kw = smap.kw

    def exact(integration, terms=None):
        run_jacobian(smap.model, q, dq, 5.0, controller=smap.controller, end_at_event=True, integration=integration,
                     derivatives=terms, **kw)
    # (solve_ivp's 60 ms of Python leave the caches cold for whatever runs next: measured alone, not in alternation
    # with the engine's rows, which it would slow by a third)
    m = alternating({"exact": lambda: smap.jacobian(z, U),
                     "fd": lambda: smap.jacobian_fd(z, U, 1e-6, rtol=kw["rtol"], extrapolate=False),
                     "fd_check": lambda: g.jacobian_fd()}, repeats)
    m.update(alternating({"exact_ivp": lambda: U.T @ run_jacobian(smap.model, q, dq, 5.0, controller=smap.controller,
                                                                  end_at_event=True, integration=SOLVE_IVP,
                                                                  **kw).jacobian[RELABELED_ROWS] @ U}, repeats))
    print(f"walk gait (generated code {IMPLEMENTATION}; law derivative: {g.law_derivative}), 5 x 5 Jacobian of the "
          f"step map, medians of {repeats}:")
    print(f"  exact on the engine's steps      {m['exact'] * 1e3:8.2f} ms")
    print(f"  exact by solve_ivp               {m['exact_ivp'] * 1e3:8.2f} ms")
    print(f"  central differences (10 runs)    {m['fd'] * 1e3:8.2f} ms")
    print(f"  jacobian_fd() (20 runs, rtol 1e-12) {m['fd_check'] * 1e3:5.2f} ms")
    print(f"  exact / central differences      {m['exact'] / m['fd']:8.2f}     (solve_ivp's: "
          f"{m['exact_ivp'] / m['fd']:.2f}; issue 32's goal: <= 0.1)")
    print(f"  exact / jacobian_fd()            {m['exact'] / m['fd_check']:8.2f}")
    s = alternating({"with": lambda: exact(STEPS), "engine": lambda: smap.run(z),
                     "python": lambda: plain_step_in_python(smap, z, kw["rtol"], kw["atol"])}, repeats)
    print("one step of the walk gait (n = 10 states, S 10 x 6):")
    print(f"  with its Jacobian                {s['with'] * 1e3:8.2f} ms")
    print(f"  without, on the engine           {s['engine'] * 1e3:8.2f} ms")
    print(f"  without, scipy DOP853 in Python  {s['python'] * 1e3:8.2f} ms")
    print(f"  step with its Jacobian / step    {s['with'] / s['engine']:8.2f}     (issue 32's goal: <= 3)")
    terms = derivatives(generated_model("three_link"))
    d = alternating({"closed": lambda: exact(STEPS), "generated": lambda: exact(STEPS, terms),
                     "closed_ivp": lambda: exact(SOLVE_IVP), "generated_ivp": lambda: exact(SOLVE_IVP, terms)}, repeats)
    print("one step of the walk gait with its Jacobian, by whose derivatives (the same robot):")
    print(f"  closed forms, engine's steps     {d['closed'] * 1e3:8.2f} ms")
    print(f"  generated terms, engine's steps  {d['generated'] * 1e3:8.2f} ms   ({d['generated'] / d['closed']:.2f} x)")
    print(f"  closed forms, solve_ivp          {d['closed_ivp'] * 1e3:8.2f} ms")
    print(f"  generated terms, solve_ivp       {d['generated_ivp'] * 1e3:8.2f} ms   "
          f"({d['generated_ivp'] / d['closed_ivp']:.2f} x)")
    r = run_jacobian(smap.model, q, dq, 5.0, controller=smap.controller, end_at_event=True, **kw)
    res = r.simulator.result()
    # the stance phase's accepted steps, the last one to the touchdown, as run_jacobian takes them
    idx, H = variational.phase_steps(res.t, res.stance_leg, 1, 0.0, r.t)
    t0, X0 = res.t[idx], np.hstack([res.q, res.dq])[idx]
    deriv = derivatives(smap.model)
    law = variational.compiled_law(deriv, smap.controller, None)
    held = ("held", np.zeros(2))
    fns = {"numpy": lambda: variational.steps_transition(deriv, smap.controller, None, t0, X0, H, 1)}
    if law is not None:
        fns["c"] = lambda: variational.steps_transition_c(deriv, law, t0, X0, H, 1)
        fns["c_held"] = lambda: variational.steps_transition_c(deriv, held, t0, X0, H, 1)
    v = dict(dict.fromkeys(("c", "c_held"), float("nan")), **alternating(fns, repeats))
    stages = 12 * len(H)
    print(f"the variational terms of the step's {len(H)} steps ({stages} stages), per stage"
          + ("" if law is not None else f" (no C: {variational.WHY_NOT_C})") + ":")
    print(f"  in C, the walking law's derivative {v['c'] / stages * 1e6:6.2f} us")
    print(f"  in C, a held torque                {v['c_held'] / stages * 1e6:6.2f} us")
    print(f"  numpy stacks                       {v['numpy'] / stages * 1e6:6.2f} us")
    return dict(exact_s=m["exact"], exact_solve_ivp_s=m["exact_ivp"], fd_s=m["fd"], fd_check_s=m["fd_check"],
                step_with_jacobian_s=s["with"],
                engine_step_s=s["engine"], python_step_s=s["python"], closed_forms_step_jacobian_s=d["closed"],
                generated_step_jacobian_s=d["generated"], closed_forms_solve_ivp_s=d["closed_ivp"],
                generated_solve_ivp_s=d["generated_ivp"], c_stage_s=v["c"] / stages,
                c_held_stage_s=v["c_held"] / stages, numpy_stage_s=v["numpy"] / stages)


if __name__ == "__main__":
    main()
