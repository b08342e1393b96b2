"""Drake's CompassGait walking 10 s from its example state (issue 31): run by the Drake venv's Python 3.12.

``.venv-drake/bin/python benchmarks/drake_compass_gait.py [--accuracy A ...] [--repeats R]`` prints one JSON
line per accuracy: the wall time of ``Simulator.AdvanceTo(10)`` (median of the repeats, the simulator built
outside the timing) and every impact: its time and the state just before it, (stance, swing, stancedot,
swingdot) in Drake's angles (from the vertical, foot to hip; the ramp falls in +x). Both accuracy settings
are set, the integrator's (``set_target_accuracy``) and the context's (``SetAccuracy``, which the witness
isolation of the touchdown uses); runge_kutta5, as the issue's figures. Imports pydrake and the standard
library only; benchmarks/bench_drake.py runs it and compares.

``--limit-cycle`` prints instead one JSON line: Drake's passive limit cycle and its multipliers, found on
Drake's own step-to-step map (``step_map``: the simulator from a post-impact state to the next impact and
through Drake's own reset). The section is the post-impact states, stance + swing = 2 slope, coordinates
(stance, stancedot, swingdot); Newton's method on central differences of the map finds the fixed point,
and the multipliers are the eigenvalues of the 3 x 3 Jacobian there (Richardson-extrapolated central
differences: steps h and h / 2).
"""
import argparse
import json
import statistics
import time

import numpy as np
from pydrake.examples import CompassGait, CompassGaitParams
from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator
from pydrake.systems.framework import EventStatus

INITIAL = (0.0, 0.0, 0.4, -2.0)     # Drake's example (stance, swing, stancedot, swingdot)
DURATION = 10.0


def run(accuracy, integrator="runge_kutta5"):
    """(wall s, [(t, stance, swing, stancedot, swingdot) just before each impact])."""
    plant = CompassGait()
    context = plant.CreateDefaultContext()
    plant.get_input_port(0).FixValue(context, [0.0])
    context.get_mutable_continuous_state_vector().SetFromVector(list(INITIAL))
    simulator = Simulator(plant, context)
    ResetIntegratorFromFlags(simulator, integrator, 0.1)
    simulator.get_mutable_integrator().set_target_accuracy(accuracy)
    simulator.get_mutable_context().SetAccuracy(accuracy)
    records = []

    def monitor(c):
        records.append((c.get_time(), c.get_discrete_state_vector().GetAtIndex(0),
                        tuple(c.get_continuous_state_vector().CopyToVector())))
        return EventStatus.Succeeded()
    simulator.set_monitor(monitor)
    simulator.Initialize()
    t0 = time.perf_counter()
    simulator.AdvanceTo(DURATION)
    wall = time.perf_counter() - t0
    # the toe (discrete state) moves at each impact: the step before it ended at the isolated witness time
    impacts = [(a[0],) + a[2] for a, b in zip(records, records[1:]) if b[1] != a[1]]
    return wall, impacts


def step_map(x, accuracy, slope, max_time=5.0):
    """(the post-impact state (stance, swing, stancedot, swingdot) after the next impact, the step's duration)
    on Drake's simulator from the post-impact state ``x``. The monitor stops the run at the end of the step
    that the touchdown's witness function truncated (the collision guard 2 slope - stance - swing has
    reached 0, the swing leg in front); the simulator then holds the witnessed reset as its pending event,
    which the next AdvanceTo applies first, before integrating 1e-12 s (a shift of the state by about 2e-12,
    the same for every run)."""
    plant = CompassGait()
    context = plant.CreateDefaultContext()
    plant.get_input_port(0).FixValue(context, [0.0])
    context.get_mutable_continuous_state_vector().SetFromVector(list(x))
    simulator = Simulator(plant, context)
    ResetIntegratorFromFlags(simulator, "runge_kutta5", 0.1)
    simulator.get_mutable_integrator().set_target_accuracy(accuracy)
    simulator.get_mutable_context().SetAccuracy(accuracy)

    def monitor(c):
        stance, swing = c.get_continuous_state_vector().CopyToVector()[:2]
        if c.get_time() > 0.0 and 2 * slope - stance - swing <= 0.0 and swing < stance:
            return EventStatus.ReachedTermination(plant, "touchdown")
        return EventStatus.Succeeded()
    simulator.set_monitor(monitor)
    simulator.Initialize()
    status = simulator.AdvanceTo(max_time)
    if status.reason() != status.ReturnReason.kReachedTerminationCondition:
        raise RuntimeError(f"no touchdown within {max_time} s from {list(x)}")
    t_impact = context.get_time()
    toe = context.get_discrete_state_vector().GetAtIndex(0)
    simulator.clear_monitor()
    simulator.AdvanceTo(t_impact + 1e-12)
    if context.get_discrete_state_vector().GetAtIndex(0) == toe:
        raise RuntimeError("Drake's reset was not applied after the touchdown")
    return np.array(context.get_continuous_state_vector().CopyToVector()), t_impact


def limit_cycle(accuracy, h=1e-4, tol=1e-11, max_iter=10):
    """Drake's passive limit cycle: dict(fixed_point, period, multipliers (re, im), residual, iterations)."""
    slope = CompassGaitParams().slope()

    def full(z):        # section coordinates -> Drake's state
        return np.array([z[0], 2 * slope - z[0], z[1], z[2]])

    def P(z):
        x, _t = step_map(full(z), accuracy, slope)
        return np.array([x[0], x[2], x[3]])

    def jacobian(z):
        def central(e):
            return np.column_stack([(P(z + e * d) - P(z - e * d)) / (2 * e) for d in np.eye(3)])
        return (4 * central(h / 2) - central(h)) / 3

    z = np.array([-0.2208, 1.0964, 0.3737])     # near the limit cycle (the stance leg behind the hip)
    iterations = 0
    while iterations < max_iter:
        iterations += 1
        r = P(z) - z
        if np.linalg.norm(r) < tol:
            break
        z = z + np.linalg.solve(jacobian(z) - np.eye(3), -r)
    x, period = step_map(full(z), accuracy, slope)
    eig = np.linalg.eigvals(jacobian(z))
    eig = eig[np.argsort(-np.abs(eig))]
    return dict(accuracy=accuracy, step=h, fixed_point=full(z).tolist(), period=period,
                residual=float(np.linalg.norm(np.array([x[0], x[2], x[3]]) - z)), iterations=iterations,
                multipliers=[[float(e.real), float(e.imag)] for e in eig])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--accuracy", type=float, nargs="+", default=[1e-4, 1e-6, 1e-8, 1e-10, 1e-12])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--limit-cycle", action="store_true",
                        help="Drake's passive limit cycle and its multipliers at each accuracy instead")
    parser.add_argument("--step", type=float, default=1e-4, help="central differences' step (--limit-cycle)")
    args = parser.parse_args()
    if args.limit_cycle:
        for accuracy in args.accuracy:
            t0 = time.perf_counter()
            d = limit_cycle(accuracy, h=args.step)
            d["wall_s"] = time.perf_counter() - t0
            print(json.dumps(d), flush=True)
        return
    p = CompassGaitParams()
    for accuracy in args.accuracy:
        runs = [run(accuracy) for _ in range(args.repeats)]
        print(json.dumps(dict(accuracy=accuracy, wall_s=statistics.median(w for w, _ in runs),
                              impacts=runs[0][1], slope=p.slope(), mass_hip=p.mass_hip(), mass_leg=p.mass_leg(),
                              length_leg=p.length_leg(), center_of_mass_leg=p.center_of_mass_leg(),
                              gravity=p.gravity())), flush=True)


if __name__ == "__main__":
    main()
