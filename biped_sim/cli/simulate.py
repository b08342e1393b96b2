"""``biped-sim simulate``: one headless run, with the run's figures (hybrid.simulate)."""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from biped_sim.config.controllers import CLI_HELP, chosen_controller, cli_controller, run_without_scene
from biped_sim.config.help_format import HelpFormatter
from biped_sim.engine import compiled_loop
from biped_sim.engine.compiled import WHY_PYTHON
from biped_sim.engine.integrators import FIXED_STEP_METHODS, METHODS
from biped_sim.engine.simulate import simulate


def _floats(n):
    def parse(text):
        try:
            vals = [float(v) for v in text.replace(",", " ").split()]
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {n} numbers, got {text!r}") from None
        if len(vals) != n:
            raise argparse.ArgumentTypeError(f"expected {n} numbers, got {len(vals)} in {text!r}")
        return vals
    return parse


#: the engine options: flag -> (the scene parameter it sets, argparse keywords). The defaults (in the
#: help) apply without --scene; with --scene only the options given replace the scene's values.
OPTIONS = {
    "--method": ("method", dict(choices=METHODS, metavar="METHOD",
                                help=f"integrator: {', '.join(METHODS)} [default: dop853]")),
    "--rtol": ("rtol", dict(type=float, help="relative tolerance (adaptive methods) [default: 1e-9]")),
    "--atol": ("atol", dict(type=float, help="absolute tolerance (adaptive methods) [default: 1e-9]")),
    "--step": ("step", dict(type=float, help=f"step size (s) of {', '.join(FIXED_STEP_METHODS)} [default: 1e-3]")),
    "--control-period": ("control_period", dict(
        type=float, help="hold the torque over this period (s), as the node does [default: continuous feedback]")),
    "--mu": ("mu", dict(type=float, help="friction coefficient [default: enough friction]")),
    "--base": ("base", dict(choices=("floating", "fixed"), help="stance method [default: floating]")),
}
DEFAULTS = dict(method="dop853", rtol=1e-9, atol=1e-9, step=1e-3, base="floating", stance_leg=1, controller="walk")


def scene_overrides(args) -> dict:
    """The scene parameters that the options given with ``--scene`` replace (load_scene's overrides)."""
    out = {name: getattr(args, name) for name, _kw in OPTIONS.values() if getattr(args, name) is not None}
    for option, name in (("q0", "initial_q"), ("dq0", "initial_dq"), ("stance_leg", "initial_stance_leg")):
        if getattr(args, option) is not None:
            out[name] = getattr(args, option)
    if args.duration is not None:
        out["duration"] = float(args.duration)
    return out


def register(sub):
    p = sub.add_parser(
        "simulate", help="run the hybrid simulation headless and print its figures",
        description="Run the hybrid simulation headless and print the run's figures: wall time, "
                    "real-time factor, steps, right-hand-side evaluations, events, constraint drift "
                    "and energy-balance residual. Without --q0/--dq0 it starts on the reference "
                    "walking gait.",
        formatter_class=HelpFormatter)
    p.add_argument("--scene", metavar="NAME|PATH",
                   help="run a scene (msg_configs/NAME.yaml or a YAML path): its initial state, phases, options "
                        "and controller, torques held over its control_period as the node does; --duration, the "
                        "engine options (--method, --rtol, --atol, --step, --mu, --base, --control-period) and "
                        "--q0/--dq0/--stance-leg given with it replace the scene's; --continuous feeds back "
                        "continuously")
    p.add_argument("--continuous", action="store_true",
                   help="with --scene: continuous feedback instead of held torques")
    p.add_argument("--duration", type=float, default=None, help="simulated time (s) [default: 10, or the scene's]")
    p.add_argument("--q0", type=_floats(5), help="initial q = 'x y q1 q2 q3' (m, rad), physical coordinates")
    p.add_argument("--dq0", type=_floats(5), help="initial dq (m/s, rad/s)")
    p.add_argument("--stance-leg", type=int, choices=(0, 1, 2), help="initial stance leg (0: flight) [default: 1]")
    p.add_argument("--controller", metavar="MODULE:ATTR|walk|none",
                   help=CLI_HELP + " [default: walk; with --scene, the scene's]")
    for flag, (name, kw) in OPTIONS.items():
        p.add_argument(flag, dest=name, **kw)
    p.add_argument("--events", action="store_true", help="list every event")
    p.add_argument("--record", nargs="?", const="", default=None, metavar="DIR",
                   help="record the run to a rosbag2/MCAP bag DIR/<scene>-<UTC time>/ (DIR default: bags), run in "
                        "lockstep as the node runs it (control period: --control-period or the scene's, 1 ms "
                        "without); see docs/recording.md")
    p.add_argument("--plot", nargs="?", const="", default=None, metavar="FILE.png",
                   help="write the run's figure (the one biped-sim inspect draws for a bag) to FILE.png "
                        "[default: <scene>.png in the current folder; simulate.png without --scene]")
    p.set_defaults(func=run)


def plot_path(args):
    """Where ``--plot`` writes the figure (checked before the run, not after it)."""
    if args.plot:
        png = Path(args.plot)
    else:
        png = Path((Path(args.scene).stem if args.scene else "simulate") + ".png")
    if not png.parent.is_dir():
        raise ValueError(f"cannot write the figure {png}: the folder {png.parent} does not exist; "
                         "create it or give another --plot path")
    return png


def controller_name(choice, scene=None) -> str:
    if choice not in (None, "walk", "none"):
        return choice
    if choice == "none" or (scene is not None and scene.controller_params is None):
        return "none (u = 0)"
    return "walk"


def run(args):
    args.controller = cli_controller(args.controller)
    args.plot_png = plot_path(args) if getattr(args, "plot", None) is not None else None
    if args.scene:
        args.scene_overrides = scene_overrides(args)
    else:
        for name, value in DEFAULTS.items():
            if getattr(args, name) is None:
                setattr(args, name, value)
    if args.record is not None:
        from biped_sim.recording.record_run import simulate_recorded
        return _report(simulate_recorded(args), args)
    if args.scene:
        from biped_sim.config.scenes import load_scene
        scene = load_scene(args.scene, overrides=args.scene_overrides)
        given = ", ".join(f"{k} {v}" for k, v in args.scene_overrides.items())
        controller = chosen_controller(args.controller, scene)
        print(f"scene {scene.name} ({scene.path}): phases {sorted(scene.phases)}, base {scene.params['base']}, "
              f"controller {controller_name(args.controller, scene)}"
              + (f"; given on the command line: {given}" if given else ""))
        return _report(scene.simulate(hold=not args.continuous, controller=controller), args)
    if args.duration is None:
        args.duration = 10.0
    model, ctrl, q0, dq0 = run_without_scene(args.controller, args.q0, args.dq0)
    options = dict(base=args.base)
    if args.method in FIXED_STEP_METHODS:
        options["step"] = args.step
    if args.base == "fixed":
        options["phases"] = frozenset({"stance", "impact"})
    result = simulate(model, q0, dq0, args.duration, controller=ctrl,
                      stance_leg=args.stance_leg, rtol=args.rtol, atol=args.atol, method=args.method,
                      control_period=args.control_period, mu=args.mu, **options)
    return _report(result, args)


def _report(result, args):
    print_summary(result)
    if getattr(args, "plot_png", None) is not None:
        bag = result.stats.get("bag")
        if bag is not None:     # a recorded run keeps no samples in memory: its bag has every one
            from biped_sim.recording.inspect_bag import plot
            plot(bag, args.plot_png)
        else:
            result.plot(path=args.plot_png,
                        title=f"{Path(args.scene).stem if args.scene else 'simulate'}: {len(result.impacts)} impacts")
        print(f"{'figure':>23}  {args.plot_png.resolve()}")
    if args.events:
        for e in result.events:
            extra = f" impulse={np.round(e.impulse, 6).tolist()}" if e.impulse is not None else ""
            print(f"  {e.time:14.9f} s  {e.kind:16s} leg {e.leg}{extra} {'; '.join(e.warnings)} {e.message}")
    if result.status == "interrupted":       # a run cut short by a signal: the shell's code for it
        return 128 + int(result.stats.get("interrupted_by", 15))
    return 0 if result.status == "completed" else 1


def print_summary(result):
    s = result.stats
    kinds = {}
    for e in result.events:
        kinds[e.kind] = kinds.get(e.kind, 0) + 1
    rows = [
        ("status", result.status + (f" ({result.message})" if result.message else "")),
        ("method", s["method"]),
        ("generated code", "C (the compiled twin)" if s["generated_code"] == "C" else f"Python ({WHY_PYTHON})"),
        ("hybrid loop", f"C for {s['compiled_loop_steps']} of {s['steps']} steps (the compiled loop)"
         if compiled_loop.AVAILABLE else f"Python ({compiled_loop.WHY_NOT})"),
        ("simulated time", f"{s['simulated_time']:.6g} s"),
        ("wall time", f"{s['wall_time']:.4g} s"),
        ("real-time factor", f"{s['real_time_factor']:.3g}" if math.isfinite(s["real_time_factor"]) else "inf"),
        ("steps (rejected)", f"{s['steps']} ({s['rejected_steps']})"),
        ("rhs evaluations", f"{s['rhs_evaluations']}"),
        ("events", ", ".join(f"{k} {v}" for k, v in kinds.items()) or "none"),
        ("max constraint drift", f"|p_st - c| {s['max_constraint_drift_position']:.3g} m, "
                                 f"|J dq| {s['max_constraint_drift_velocity']:.3g} m/s"),
        ("energy balance residual", f"final {s['energy_balance_residual']:.3g} J, "
                                    f"max {s['max_energy_balance_residual']:.3g} J"),
        ("energy lost at impacts", f"{s['energy_lost_at_impacts']:.6g} J"),
        ("motor work", f"{s['motor_work']:.6g} J"),
    ]
    w = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:>{w}}  {v}")
