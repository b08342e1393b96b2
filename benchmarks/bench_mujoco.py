"""MuJoCo side by side (issue 15): ``python -m benchmarks.bench_mujoco`` (also run by ``make bench``).

The same robot built in MJCF (:func:`biped_mjcf`) and stepped by MuJoCo (``mujoco`` from PyPI, a
benchmark-only dependency that ``make bench`` installs), measured against this engine in one process:

1. the model check, before any timing: MuJoCo's mass matrix (``mj_fullM`` after ``mj_forward``) and
   bias forces (``qfrc_bias``) against ``BipedModel``'s D(q) and C(q, dq) dq + G(q) at random states;
   the benchmark stops there when they differ by more than 1e-9 (relative, max-norm);
2. the walk scene, 10 s, the scene's controller (the computed-torque ``WalkingController``) called
   from Python once per 1 ms control period and held: ``simulate`` at rtol = atol = 1e-9 (dop853,
   its default, and dopri5, the method the scene's ``method: auto`` picks at 1 ms) against a loop of
   ``mj_step`` at timestep 1 ms and at 0.1 ms (10 steps per period); real-time factors from the
   median wall time of repeats that alternate, so that a slow spell of this shared machine hits all;
3. the velocity after a touchdown: MuJoCo put in the exact pre-impact state of a touchdown of the
   engine's walk (both feet on the ground), stepped through the contact with u = 0, against the
   exact post-impact velocity ``dq_plus`` and against the exact run that goes on from it in stance
   on the new foot, also with u = 0 (soft contact is never exact: this measures by how much).

MJCF choices (docs/performance.md, "MuJoCo, side by side"): the model's plane is MuJoCo's x-z plane;
a hinge about +y turned by angle a carries a point at local (0, 0, l) to (l sin a, l cos a), the
model's "0 points up" convention, so that no sign or offset is needed. The hip body carries a slide
along x, a slide along z and the torso hinge (absolute q3); each leg is a child body with a hinge
(q1, q2 relative to the torso). So qpos = [x, y, q3, q1, q2] and q = qpos[Q_FROM_QPOS], the same map
for the velocities. Explicit ``<inertial>`` elements carry the masses, centres and inertias of
docs/model.md (no geom adds mass). The feet are spheres of radius FOOT_RADIUS at the legs' ends,
against a plane lowered by that radius, so that a foot touches when its centre -- the model's point
foot -- is at height 0. Two motors with gear 1 on the leg hinges are the model's B.
"""
from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

from biped_sim.config.scenes import load_scene
from biped_sim.engine.hybrid import HybridSimulator
from biped_sim.engine.model import BipedModel
from biped_sim.engine.simulate import simulate

try:
    import mujoco
except ModuleNotFoundError:   # benchmark-only: `make bench` installs it
    mujoco = None

#: q[i] = qpos[Q_FROM_QPOS[i]] (and dq from qvel alike): MuJoCo's joints are ordered by the body
#: tree, qpos = [x, y, q3, q1, q2], the model's q = [x, y, q1, q2, q3].
Q_FROM_QPOS = (0, 1, 3, 4, 2)
FOOT_RADIUS = 1e-3
MODEL_CHECK_LIMIT = 1e-9
#: the front rule of the engine (touchdown_rule="front") in the MuJoCo loop: the swing foot collides
#: with the ground only when it is this far in front of the stance foot (the nominal step is
#: 2 l_leg sin(step_angle) = 0.40 m). The mid-stance graze that the engine lets pass as a scuff
#: (0.6 mm deep, behind the stance foot) ends a few mm in front of MuJoCo's stance foot, which the
#: soft contact lets sink by about 0.2 mm; colliding there, the robot trips and falls.
LANDING_AHEAD = 0.05


def biped_mjcf(model: BipedModel, foot_radius=FOOT_RADIUS, timestep=1e-3) -> str:
    """The MJCF of the three-link biped with ``model``'s constants (see the module docstring)."""
    p = model.parameters

    def leg(i):
        return f"""
      <body name="leg_{i}">
        <joint name="q{i}" type="hinge" axis="0 1 0"/>
        <inertial pos="0 0 {p.c_leg!r}" mass="{p.m_leg!r}" diaginertia="{p.I_leg!r} {p.I_leg!r} {p.I_leg!r}"/>
        <geom name="foot_{i}" type="sphere" size="{foot_radius!r}" pos="0 0 {p.l_leg!r}" contype="1" conaffinity="0"/>
      </body>"""
    # contype/conaffinity: a foot meets the ground, never the other foot; the loop switches a swing
    # foot's contype off and on (LANDING_AHEAD). The inertias about x and z do not enter a planar motion.
    return f"""<mujoco model="biped_sim three-link biped">
  <option timestep="{timestep!r}" gravity="0 0 {-p.g!r}"/>
  <worldbody>
    <geom name="ground" type="plane" size="0 0 1" pos="0 0 {-foot_radius!r}" contype="1" conaffinity="1"/>
    <body name="torso">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="y" type="slide" axis="0 0 1"/>
      <joint name="q3" type="hinge" axis="0 1 0"/>
      <inertial pos="0 0 {p.c_torso!r}" mass="{p.m_torso!r}"
                diaginertia="{p.I_torso!r} {p.I_torso!r} {p.I_torso!r}"/>{leg(1)}{leg(2)}
    </body>
  </worldbody>
  <actuator>
    <motor name="hip_1" joint="q1" gear="1"/>
    <motor name="hip_2" joint="q2" gear="1"/>
  </actuator>
</mujoco>
"""


def mujoco_model(model: BipedModel, timestep=1e-3, foot_radius=FOOT_RADIUS):
    return mujoco.MjModel.from_xml_string(biped_mjcf(model, foot_radius, timestep))


def set_state(mj, data, q, dq):
    """Put MuJoCo in the model's state (q, dq) and run mj_forward."""
    mujoco.mj_resetData(mj, data)
    data.qpos[list(Q_FROM_QPOS)] = q
    data.qvel[list(Q_FROM_QPOS)] = dq
    mujoco.mj_forward(mj, data)


def state_of(data):
    return data.qpos[list(Q_FROM_QPOS)], data.qvel[list(Q_FROM_QPOS)]


def model_check(model: BipedModel, mj, states=20, seed=0):
    """Largest relative differences (max-norm) of MuJoCo's mass matrix and bias forces from D(q) and
    C(q, dq) dq + G(q) at ``states`` random states (angles in [-pi, pi], rates in [-5, 5])."""
    rng = np.random.default_rng(seed)
    data = mujoco.MjData(mj)
    full = np.zeros((mj.nv, mj.nv))
    order = list(Q_FROM_QPOS)
    worst_D = worst_bias = 0.0
    for _ in range(states):
        q = np.concatenate([rng.uniform(-1, 1, 2), rng.uniform(-math.pi, math.pi, 3)])
        dq = rng.uniform(-5, 5, 5)
        set_state(mj, data, q, dq)
        mujoco.mj_fullM(mj, data, full)
        D, bias = model.mass_matrix(q), model.bias_forces(q, dq)
        worst_D = max(worst_D, np.max(np.abs(full[np.ix_(order, order)] - D)) / np.max(np.abs(D)))
        worst_bias = max(worst_bias, np.max(np.abs(data.qfrc_bias[order] - bias)) / np.max(np.abs(bias)))
    return worst_D, worst_bias


def walk_mujoco(mj, controller, q0, dq0, t_final, control_period=1e-3):
    """The walk in MuJoCo: ``controller(t, q, dq, stance_leg)`` once per control period, held over
    its mj_steps; returns (touchdowns, lowest hip height, final q).

    The stance leg given to the controller is the foot that last landed in front of the other, as
    the engine's touchdown_rule="front" has it: a swing foot leaves collision once it has lifted
    off behind the stance foot, and comes back LANDING_AHEAD in front of it. The feet's positions
    (``geom_xpos``) are those of the last step's start, where MuJoCo found that step's contacts."""
    data = mujoco.MjData(mj)
    mj.geom_contype[:] = 1
    set_state(mj, data, q0, dq0)
    substeps = round(control_period / mj.opt.timestep)
    feet = (mj.geom("foot_1").id, mj.geom("foot_2").id)
    contype, xpos, qpos, qvel, ctrl = mj.geom_contype, data.geom_xpos, data.qpos, data.qvel, data.ctrl
    step = mujoco.mj_step
    leg, touchdowns, lowest_hip = 1, 0, math.inf
    for k in range(round(t_final / control_period)):
        stance, swing = feet[leg - 1], feet[2 - leg]
        if xpos[swing, 0] > xpos[stance, 0] + LANDING_AHEAD:
            contype[swing] = 1
            if xpos[swing, 2] < 0.0:       # in contact: the foot's centre below the top of the plane
                leg, touchdowns = 3 - leg, touchdowns + 1
        elif contype[swing] and xpos[swing, 2] > 0.0:
            contype[swing] = 0             # lifted off behind the stance foot: no scuffs
        p, v = qpos.tolist(), qvel.tolist()
        lowest_hip = min(lowest_hip, p[1])
        ctrl[:] = controller(k * control_period, [p[0], p[1], p[3], p[4], p[2]], [v[0], v[1], v[3], v[4], v[2]], leg)
        step(mj, data, substeps)
    mj.geom_contype[:] = 1
    return touchdowns, lowest_hip, state_of(data)[0]


def bench_walk(repeats=5, t_final=10.0, timesteps=(1e-3, 1e-4)):
    """Real-time factors of the walk scene (see the module docstring), alternating repeats."""
    scene = load_scene("walk")
    kw = scene.simulate_kwargs(hold=True)
    model, controller, period = kw["model"], kw["controller"], kw["control_period"]
    q0, dq0 = np.asarray(kw["q0"], float), np.asarray(kw["dq0"], float)
    runs, outcome = {}, {}
    for method in ("dop853", "dopri5"):
        def run(method=method):
            r = simulate(model, q0, dq0, t_final, controller=controller, control_period=period, method=method)
            return len(r.impacts), float(np.min(r.q[:, 1])), r.q[-1], r.status
        runs[f"biped_sim simulate, {method}, rtol=atol=1e-9"] = run
    for dt in timesteps:
        mj = mujoco_model(model, timestep=dt)

        def run(mj=mj):
            return (*walk_mujoco(mj, controller, q0, dq0, t_final, period), "")
        runs[f"MuJoCo mj_step, timestep {dt * 1e3:g} ms ({round(period / dt)} a period)"] = run

    # your own law as a plain Python function (the same law, no compiled form): called once a period by both
    def plain(t, q, dq, leg):
        return controller(t, q, dq, leg)

    def run_plain():
        r = simulate(model, q0, dq0, t_final, controller=plain, control_period=period, method="dopri5")
        return len(r.impacts), float(np.min(r.q[:, 1])), r.q[-1], r.status
    runs[PLAIN_SIMULATE] = run_plain
    mj_plain = mujoco_model(model, timestep=timesteps[0])
    runs[PLAIN_MUJOCO] = lambda: (*walk_mujoco(mj_plain, plain, q0, dq0, t_final, period), "")

    def controller_alone():
        q, dq = q0.tolist(), dq0.tolist()
        for k in range(round(t_final / period)):
            controller(k * period, q, dq, 1)
        return 0, math.nan, q0, "(the floor of any loop that calls it)"
    runs["the controller alone, as often (same state)"] = controller_alone
    walls = {name: [] for name in runs}
    for _ in range(repeats):
        for name, run in runs.items():
            t0 = time.perf_counter()
            outcome[name] = run()
            walls[name].append(time.perf_counter() - t0)
    rtf = {name: t_final / statistics.median(w) for name, w in walls.items()}
    print(f"\n== walk scene, {t_final:g} s, WalkingController every {period * 1e3:g} ms and held (median of {repeats}, "
          "alternating; MuJoCo's loop calls it from Python, simulate's compiled loop computes the same law "
          "in C, bit for bit) ==")
    print(f"  {'':52s} {'wall s':>7s} {'RTF':>7s}  touchdowns  lowest hip  final x")
    for name in runs:
        n, low, q_end, status = outcome[name]
        if math.isnan(low):
            print(f"  {name:52s} {statistics.median(walls[name]):7.3f} {rtf[name]:7.1f}  {status}")
        else:
            print(f"  {name:52s} {statistics.median(walls[name]):7.3f} {rtf[name]:7.1f}  {n:10d}  {low:10.3f}  "
                  f"{q_end[0]:7.3f} {status}")
    print(f"  mj_step alone at 1 ms: {mj_step_us(model, q0, dq0):.1f} us per call; the controller alone: "
          f"{statistics.median(walls[list(runs)[-1]]) / round(t_final / period) * 1e6:.1f} us per call")
    mj_name = next(n for n in runs if n.startswith("MuJoCo"))
    for name in runs:
        if name.startswith("biped_sim") and name != PLAIN_SIMULATE:
            print(f"  RTF ratio {name.split(',')[1].strip()} / MuJoCo 1 ms: {rtf[name] / rtf[mj_name]:.2f} "
                  f"(issue 15 goal >= 5)")
    print(f"  the law as a plain Python function: RTF ratio simulate (dopri5) / MuJoCo 1 ms, both calling it: "
          f"{rtf[PLAIN_SIMULATE] / rtf[PLAIN_MUJOCO]:.2f}")
    return rtf, outcome


PLAIN_SIMULATE = "biped_sim simulate, dopri5, the law as plain Python"
PLAIN_MUJOCO = "MuJoCo mj_step 1 ms, the law as plain Python"


def mj_step_us(model, q0, dq0, steps=100, repeats=7):
    """mj_step's own cost, median per call: ``steps`` steps from (q0, dq0) with u = 0, each repeat anew."""
    mj = mujoco_model(model)
    data = mujoco.MjData(mj)
    walls = []
    for _ in range(repeats):
        set_state(mj, data, q0, dq0)
        t0 = time.perf_counter()
        mujoco.mj_step(mj, data, steps)
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls) / steps * 1e6


def exact_touchdown(scene, which=-1):
    """A touchdown Event of the engine's walk scene (rtol = atol = 1e-12, the last one by default)."""
    r = scene.simulate(rtol=1e-12, atol=1e-12, method="dop853")
    return [e for e in r.events if e.kind == "touchdown"][which]


def post_impact_errors(model, event, timestep, solref=None, horizon=0.1):
    """MuJoCo from (event.q, event.dq_minus), u = 0, stepped ``horizon`` s through the contact.

    Returns rows (t, dq - dq_plus and dq - dq_exact(t) as relative (max-norm, 2-norm) pairs, the new
    stance foot's speed and height), where dq_exact(t) is the exact run going on from dq_plus in
    stance on the new foot with u = 0."""
    mj = mujoco_model(model, timestep=timestep)
    if solref is not None:
        mj.geom_solref[:] = solref
    data = mujoco.MjData(mj)
    set_state(mj, data, event.q, event.dq_minus)
    exact = HybridSimulator(model, event.q, event.dq_plus, stance_leg=event.leg, rtol=1e-12, atol=1e-12,
                            phases={"stance", "impact"})
    rows = []
    for k in range(1, round(horizon / timestep) + 1):
        mujoco.mj_step(mj, data)
        q, dq = state_of(data)
        exact.advance(k * timestep, u=(0.0, 0.0))
        rows.append((k * timestep, relative_errors(dq, event.dq_plus), relative_errors(dq, exact.dq),
                     float(np.linalg.norm(model.foot_velocity(q, dq, event.leg))),
                     float(model.foot_position(q, event.leg)[1])))
    return rows


def relative_errors(v, ref):
    d = np.asarray(v) - np.asarray(ref)
    return float(np.max(np.abs(d)) / np.max(np.abs(ref))), float(np.linalg.norm(d) / np.linalg.norm(ref))


def bench_post_impact(model, timesteps=(1e-3, 1e-4), report_at=(0.002, 0.005, 0.01, 0.02, 0.05, 0.1),
                      settled_below=0.05):
    """The table of the module docstring's item 3: one row per (timestep, solref)."""
    event = exact_touchdown(load_scene("walk"))
    landing_speed = float(np.linalg.norm(model.foot_velocity(event.q, event.dq_minus, event.leg)))
    mj = mujoco_model(model)
    print(f"\n== velocity after a touchdown (the last of the walk scene, t = {event.time:.4f} s, foot {event.leg} "
          f"lands at {landing_speed:.3f} m/s), u = 0 ==")
    print(f"  MuJoCo's defaults: solref {mj.geom_solref[0].tolist()}, solimp {mj.geom_solimp[0].tolist()}, "
          f"friction {mj.geom_friction[0, 0]:g}, {mujoco.mjtCone(mj.opt.cone).name}, "
          f"{mujoco.mjtIntegrator(mj.opt.integrator).name}; "
          "(2 dt, 1): the stiffest time constant MuJoCo advises")
    print(f"  relative velocity errors, max-norm/2-norm: 'settled' is the first step where the new stance foot's speed "
          f"is below {settled_below:.0%} of its landing speed,\n  dq_plus the exact impact map's velocity, "
          "exact(t) the exact run on from dq_plus (stance on the new foot); rebound: the foot's greatest height "
          "after its first contact")
    times = "".join(f"{f'vs exact({t * 1e3:g} ms)':>17s}" for t in report_at)
    print(f"  {'timestep':>8s} {'solref':>12s} {'settled':>8s} {'vs dq_plus':>12s} {'vs exact':>12s}{times}  rebound")
    out = {}
    for dt in timesteps:
        for solref in (None, (2 * dt, 1.0)):
            rows = post_impact_errors(model, event, dt, solref)
            out[(dt, solref)] = rows
            first_contact = next((i for i, r in enumerate(rows) if r[4] < 0.0), 0)
            rebound = max(r[4] for r in rows[first_contact:])
            rebound = f"{rebound * 1e3:.2f} mm" if rebound > 0.0 else "none"
            settled = next((r for r in rows if r[3] < settled_below * landing_speed), None)
            pair = "{0:.2g}/{1:.2g}".format
            at = "".join(f"{pair(*next(r[2] for r in rows if abs(r[0] - t) < dt / 2)):>17s}" for t in report_at)
            head = f"{dt * 1e3:6g}ms {'default' if solref is None else f'({solref[0]:g}, 1)':>12s}"
            if settled is None:
                print(f"  {head} {'no':>8s} {'':12s} {'':12s}{at}  {rebound}")
            else:
                print(f"  {head} {f'{settled[0] * 1e3:.1f}ms':>8s} {pair(*settled[1]):>12s} {pair(*settled[2]):>12s}"
                      f"{at}  {rebound}")
    return event, out


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_mujoco", description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats of each walk (alternating)")
    args = parser.parse_args(argv)
    if mujoco is None:
        print("mujoco is not installed: skipped (`make bench` installs it)")
        return 0
    model = BipedModel()
    print(f"MuJoCo {mujoco.__version__} side by side with biped_sim (python -m benchmarks.bench_mujoco)")
    err_D, err_bias = model_check(model, mujoco_model(model))
    print(f"\n== model check, 20 random states: MuJoCo's mj_fullM vs D(q) {err_D:.2g}, qfrc_bias vs C dq + G "
          f"{err_bias:.2g} (relative, max-norm; limit {MODEL_CHECK_LIMIT:g}) ==")
    if max(err_D, err_bias) > MODEL_CHECK_LIMIT:
        print("  the MJCF is not the model: nothing timed")
        return 1
    bench_walk(repeats=args.repeats)
    bench_post_impact(model)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
