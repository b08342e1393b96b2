"""``biped-sim gait``: the periodic gait of a scene and the eigenvalues of its Poincare map (gait.py)."""
from __future__ import annotations

import time

from biped_sim.config.controllers import CLI_HELP


def register(sub):
    p = sub.add_parser(
        "gait", help="find the periodic gait of a scene and the eigenvalues of its Poincare map",
        description="With the engine headless (continuous feedback of the scene's walking controller), find "
                    "the fixed point of the step-to-step Poincare map on the post-impact section (Newton's "
                    "method on the section of 2(n-2) - 1 dimensions, 5 for the three-link: the x translation and the "
                    "section constraint removed) and "
                    "print the step length, speed, step period, cost of transport and the eigenvalues of the "
                    "linearised map, its Floquet multipliers (all inside the unit circle: the gait is locally "
                    "stable). The Jacobian is exact by default: the variational equations of the step and the "
                    "saltation matrix of its impact (docs/gait.md).")
    p.add_argument("--scene", default="walk", metavar="NAME|PATH", help="the scene: its controller, or u = 0 "
                   "(the passive gait) for a scene without a walk_controller section (default: walk)")
    p.add_argument("--controller", metavar="MODULE:ATTR|walk|none", help=CLI_HELP + " [default: the scene's]")
    p.add_argument("--jacobian", choices=("exact", "fd"), default="exact",
                   help="the Jacobian of the step map for Newton's method and the eigenvalues: exact (default; "
                        "variational equations and saltation matrix) or fd (central differences of the map, "
                        "Richardson-extrapolated, its runs at rtol 1e-12: Gait.jacobian_fd)")
    p.set_defaults(func=run)


def run(args):
    from biped_sim.analysis.gait import EXACT, FINITE_DIFFERENCES, NoGait, format_gait, scene_gait
    from biped_sim.config.controllers import cli_law
    from biped_sim.config.joints import joint_layout
    from biped_sim.config.scenes import load_scene
    from biped_sim.engine.model import BipedModel
    scene = load_scene(args.scene)
    t0 = time.perf_counter()
    try:
        g = scene_gait(scene, jacobian=EXACT if args.jacobian == "exact" else FINITE_DIFFERENCES,
                       controller=cli_law(args.controller))
    except NoGait as exc:       # an answer, not a usage error: the controller does not walk from this start
        print(f"scene {scene.name}: no periodic gait: {exc}")
        return 1
    print(f"scene {scene.name}: periodic gait (slope {g.slope:g} rad), found in {time.perf_counter() - t0:.2f} s")
    # a described robot's z* is named by its coordinates; the three-link chains (a BipedModel: three_link,
    # compass_gait, three_link_hip_mass) keep q_st, q_sw, q3, the names docs/gait.md uses
    model = g.step_map.model
    print(format_gait(g, None if isinstance(model, BipedModel) else joint_layout(scene.robot).coordinates))
    return 0 if g.stable else 1
