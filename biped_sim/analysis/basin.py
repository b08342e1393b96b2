"""The basin of attraction of a scene's periodic gait, on a 2-D slice of initial states: a sweep.

Owns the slice: the fixed point z* of the step-to-step map (:func:`biped_sim.analysis.gait.scene_gait`,
post-impact, stance leg 1 with its foot at the origin), and around it a grid of post-impact joint
rates, the stance-leg rate dq_st and the torso rate dq3 moved by up to +-span, the configuration
kept at z*. For any robot these are the rates of q[2] (the stance leg's hip in stance-1 labels:
hip_1) and of the floating base link's angle (the torso's, ``torso_pitch``; the compass gait's
``hip_pitch``). Each point becomes a consistent initial state (the base velocity that keeps the stance
foot at rest, :func:`biped_sim.engine.simulate.stance_state`), given to the sweep as whole
``initial_q`` / ``initial_dq`` overrides, so that every run is a plain
``load_scene(scene, overrides=...).simulate(...)`` and a row of :func:`biped_sim.analysis.sweep.sweep`.
The runs use continuous feedback (``hold=False``), the feedback ``biped-sim gait`` finds z* with.
"""
from __future__ import annotations

import numpy as np

from biped_sim.analysis.gait import NoGait, base_angle_index, scene_gait
from biped_sim.analysis.sweep import sweep
from biped_sim.config.scenes import load_scene
from biped_sim.engine.simulate import stance_state

AXES = ("d_dq_stance", "d_dq_torso")


def basin(scene, span=(1.0, 2.0), num=11, duration=None, workers=None, backend="process", progress=None,
          controller=None, **run):
    """(gait, rows): the gait of ``scene`` and one sweep row per point of the slice, each with the
    point's offsets from z* as ``d_dq_stance`` and ``d_dq_torso`` (rad/s), in row-major order
    (d_dq_stance slowest). ``span`` = the largest offsets (rad/s), ``num`` points along each axis.
    ``controller``: yours instead of the scene's (an object, a class or factory, or ``"MODULE:ATTR"``)."""
    if isinstance(num, bool) or not isinstance(num, int) or num < 2:
        raise ValueError(f"num must be an integer >= 2 (points along each axis), got {num!r}")
    spans = [float(s) for s in span]
    if len(spans) != 2 or any(not s > 0 for s in spans):
        raise ValueError(f"span must be two positive rates (rad/s), got {span!r}")
    s = load_scene(scene)
    try:
        gait = scene_gait(s, controller=controller)
    except NoGait as exc:
        raise NoGait(f"scene {s.name!r} has no periodic gait to take the basin of: {exc}") from None
    offsets = [[a * (2 * i - (num - 1)) / (num - 1) for i in range(num)] for a in spans]
    q0, points, initial_dq = slice_states(s.engine_arguments()["model"], gait.z, offsets)
    grid = {"initial_stance_leg": [1], "initial_q": [q0.tolist()], "initial_dq": initial_dq}
    if controller is not None:
        run = dict(run, controller=controller)
    rows = sweep(scene, grid, duration=duration, workers=workers, backend=backend, progress=progress,
                 **dict(dict(hold=False), **run))
    for row, (d_st, d_torso) in zip(rows, points):
        row[AXES[0]], row[AXES[1]] = d_st, d_torso
    return gait, rows


def slice_states(model, z, offsets):
    """(q0, points, initial_dq): the slice's consistent initial states around the section point z (2 (n - 2)
    numbers, ``gait.section_point``) of ``model``: q0 the configuration of z, stance leg 1 with its foot at the
    origin; for each (d_st, d_torso) of the product of ``offsets`` (row-major, d_st slowest) the point and the
    physical dq with the rate of q[2] moved by d_st and the base link's angle rate by d_torso."""
    m = model.n - 2
    torso = base_angle_index(model) - 2
    q0, _ = stance_state(model, z[0:m], z[m:2 * m], stance_leg=1)
    points, initial_dq = [], []
    for d_st in offsets[0]:
        for d_torso in offsets[1]:
            delta = np.zeros(m)
            delta[0], delta[torso] = d_st, d_torso
            _, dq = stance_state(model, z[0:m], z[m:2 * m] + delta, stance_leg=1)
            points.append((d_st, d_torso))
            initial_dq.append(dq.tolist())
    return q0, points, initial_dq


def walked(rows, min_steps) -> np.ndarray:
    """True where a run completed with at least ``min_steps`` impacts."""
    return np.array([r["status"] == "completed" and r["impacts"] >= min_steps for r in rows])
