"""A recorded run read back into named arrays: :func:`load_run` (``biped_sim.load_run``, docs/recording.md)."""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from biped_sim.recording import inspect_bag
from biped_sim.recording.bag_robot import is_three_link


@dataclass
class RecordedRun:
    """A bag's run as arrays, named as :class:`biped_sim.SimulationResult`'s, sized by the robot it recorded.

    t (n,) s; q, dq (n, N) the robot's coordinates, named by ``coordinates`` (the three-link biped's
    [base_x, base_y, hip_1, hip_2, torso_pitch], docs/model.md's [x, y, q1, q2, q3]); u (n, M) the motor
    torques (N m), one column per actuated joint named by ``actuators`` (the three-link's hip_1, hip_2);
    effort (n, N) ``joint_states``' effort as recorded (B u: each torque on its joint's column, 0 elsewhere);
    stance_leg (n,) 0 in flight, else the stance foot (1 or 2): one row per ``joint_states`` message. grf
    (m, 2) [F_x, F_y] (N) at grf_t (m,) s: one row per ``ground_reaction`` message (none in flight). impacts:
    the ``impact`` topic's events (their states ``q``, ``dq_minus``, ``dq_plus`` of N); events: every engine
    event (touchdowns, scuffs, liftoffs, pushes, ...) in their order, each a dict of typed values (floats,
    ints, lists of floats; docs/node.md lists the keys). params: the run's parameters record (None for a bag
    not recorded by biped_sim). robot: the run's ``robot`` parameter ("three_link" for a bag that recorded
    none; None for a bag of another program). robot_problem: '' or why the robot could not be loaded (a
    description file that is gone): q and dq are then named by the recorded names, and u has no columns.
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
    robot: str | None
    coordinates: tuple
    actuators: tuple
    effort: np.ndarray
    robot_problem: str = ""

    def to_dataframe(self):
        """The samples as a pandas DataFrame indexed by t: a three-link robot's x, y, q1, q2, q3, their rates
        (dx ... dq3), u1, u2; a described robot's coordinates by name, their rates ``d_<name>``, its torques
        ``u_<actuator>``; then stance_leg (the ground force is on its own clock: ``grf_t``, ``grf``)."""
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("RecordedRun.to_dataframe needs pandas: pip install pandas") from None
        if is_three_link(self.robot, self.coordinates, self.actuators):
            names, rates, torques = ["x", "y", "q1", "q2", "q3"], ["dx", "dy", "dq1", "dq2", "dq3"], ["u1", "u2"]
        else:
            names = list(self.coordinates)
            rates, torques = ["d_" + n for n in names], ["u_" + a for a in self.actuators]
        cols = {n: self.q[:, i] for i, n in enumerate(names)}
        cols.update({n: self.dq[:, i] for i, n in enumerate(rates)})
        cols.update({n: self.u[:, i] for i, n in enumerate(torques)})
        cols.update(stance_leg=self.stance_leg)
        return pd.DataFrame(cols, index=pd.Index(self.t, name="t"))

    to_pandas = to_dataframe


def load_run(bag) -> RecordedRun:
    """Every sample and event of a recorded bag (a bag directory or its .mcap file) as arrays; a bag whose
    robot cannot be loaded is read by the names it recorded, with one warning line that says so."""
    run = inspect_bag.load_run(bag, max_points=None)
    robot = run["robot"]
    if robot.problem:
        warnings.warn(f"{bag}: {robot.problem}", UserWarning, stacklevel=2)
    return RecordedRun(bag=str(bag), t=run["t"], q=run["q"], dq=run["dq"], u=run["u"], stance_leg=run["leg"],
                       grf_t=run["grf_t"], grf=run["grf"], impacts=run["impacts"], events=run["all_events"],
                       params=run["params"], robot=robot.robot, coordinates=robot.coordinates,
                       actuators=robot.actuators, effort=run["effort"], robot_problem=robot.problem)
