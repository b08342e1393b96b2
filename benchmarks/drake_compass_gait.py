"""Drake's CompassGait walking 10 s from its example state (issue 31): run by the Drake venv's Python 3.12.

``.venv-drake/bin/python benchmarks/drake_compass_gait.py [--accuracy A ...] [--repeats R]`` prints one JSON
line per accuracy: the wall time of ``Simulator.AdvanceTo(10)`` (median of the repeats, the simulator built
outside the timing) and every impact: its time and the state just before it, (stance, swing, stancedot,
swingdot) in Drake's angles (from the vertical, foot to hip; the ramp falls in +x). Both accuracy settings
are set, the integrator's (``set_target_accuracy``) and the context's (``SetAccuracy``, which the witness
isolation of the touchdown uses); runge_kutta5, as the issue's figures. Imports pydrake and the standard
library only; benchmarks/bench_drake.py runs it and compares.
"""
import argparse
import json
import statistics
import time

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


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--accuracy", type=float, nargs="+", default=[1e-4, 1e-6, 1e-8, 1e-10, 1e-12])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    p = CompassGaitParams()
    for accuracy in args.accuracy:
        runs = [run(accuracy) for _ in range(args.repeats)]
        print(json.dumps(dict(accuracy=accuracy, wall_s=statistics.median(w for w, _ in runs),
                              impacts=runs[0][1], slope=p.slope(), mass_hip=p.mass_hip(), mass_leg=p.mass_leg(),
                              length_leg=p.length_leg(), center_of_mass_leg=p.center_of_mass_leg(),
                              gravity=p.gravity())), flush=True)


if __name__ == "__main__":
    main()
