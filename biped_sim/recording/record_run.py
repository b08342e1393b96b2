"""A headless run recorded to a bag, exactly as the node records a ``lockstep`` run.

Owns ``simulate --record``: the engine advances one control period per torque command (the
controller is called at the start of each period and its torques are held, as
``hybrid.simulate(..., control_period=...)`` and the node's lockstep mode do), and every message
the node would publish is written with the node's message functions (:mod:`biped_sim.recording.messages`):
``/hip_torque`` (the command, at the start of its period), ``/impact`` (at the located impact
time), ``/diagnostics`` (other events), then ``/joint_states``, ``/ground_reaction`` (in stance)
and ``/clock`` at the end of the period. The state at t = 0 is written first. ``/markers`` (with
"markers" in ``outputs``) at ``marker_rate`` of simulated time (a headless run has no wall clock to
follow), and at the end, each with the transform world -> hip on ``/tf`` (a 3D view follows the robot).
"""
from __future__ import annotations

import dataclasses
import signal

from biped_sim.recording import messages as M
from biped_sim.recording.cdr import float64_multi_array_data
from biped_sim.recording.markers import TF_TOPIC, TF_TYPE, MarkerStream, hip_transform
from biped_sim.recording.node_run import NodeRun, event_output


def topics_for(params) -> dict:
    """{full topic name: type} that a run with these parameters publishes (and records)."""
    out = {}
    for name in params["outputs"]:
        if name == "impact" and "impact" not in params["phases"]:
            continue
        out["/" + name] = M.TOPIC_TYPES[name]
        if name == "markers":
            out[TF_TOPIC] = TF_TYPE      # the frame that moves with the drawn robot
    out["/diagnostics"] = M.TOPIC_TYPES["diagnostics"]
    out["/hip_torque"] = M.TOPIC_TYPES["hip_torque"]
    return out




def run_recorded(params, controller, recorder, progress=None, build_messages=False, stop=None):
    """Run ``params`` (checked, see parameters.validate) in lockstep; record to ``recorder``.

    ``controller(t, q, dq, stance_leg) -> u`` or None (u = 0); each command goes through the node's
    command check (:class:`~biped_sim.recording.node_run.NodeRun`), as a controller's message would.
    ``recorder`` is a BagRecorder or None (then nothing is written). ``build_messages``: serialise the
    state messages every period also without a recorder, as the node does to publish them (the
    recording benchmark's loop). SIGTERM and SIGINT end the run early (the signal's number is appended
    to ``stop``, a list the caller may pass to tell); the caller closes the recorder. Returns the
    HybridSimulator at the end.
    """
    run = NodeRun(params, labels={name: "/" + name for name in M.TOPIC_TYPES})
    sim = run.sim
    topics = topics_for(params)
    if recorder is not None:
        for name, typ in topics.items():
            recorder.add_topic(name, typ)
    rec = recorder.write if recorder is not None else (lambda *a: None)
    markers = (MarkerStream(sim.model, params["slope"], params["marker_rate"])
               if recorder is not None and "/markers" in topics else None)

    def publish_state():
        # the state messages of the period as the node publishes them: serialised once, recorded in one call
        if build_messages or recorder is not None:
            state = run.state_messages()
            if recorder is not None and state:
                recorder.write_messages(M.to_ns(sim.t), state)
        if markers is not None:
            msg = markers.poll(sim.t, sim, force=not run.running)
            if msg is not None:
                t_ns = M.to_ns(sim.t)
                rec("/markers", msg, t_ns)
                rec(TF_TOPIC, hip_transform(t_ns, markers.hip), t_ns)

    stop = [] if stop is None else stop
    old = {}
    try:
        for signum in (signal.SIGTERM, signal.SIGINT):
            old[signum] = signal.signal(signum, lambda signum, _frame: stop.append(signum))
    except ValueError:  # not the main thread
        pass
    try:
        publish_state()
        while run.running and sim.t < run.duration and not stop:
            if controller is not None:
                u = sim.command(controller)
                if u is None:       # the controller failed: the run ends "failed" with its message
                    break
                if recorder is not None:   # the command as sent (what M.torque_msg(u) serialises to)
                    rec("/hip_torque", float64_multi_array_data(u), M.to_ns(sim.t))
                run.take_command(u)
            elif recorder is not None:
                rec("/hip_torque", float64_multi_array_data(run.u), M.to_ns(sim.t))
            events, _ended = run.advance()
            for ev in events:
                output = event_output(ev)
                if "/" + output in topics:
                    rec("/" + output, M.impact_msg(ev), M.to_ns(ev.time))
            publish_state()
            if progress is not None:
                progress(sim)
    finally:
        for signum, handler in old.items():
            signal.signal(signum, handler)
    return sim


def params_from_args(args):
    """(checked parameters, controller) of a ``biped-sim simulate`` command line (with or without --scene)."""
    from biped_sim.config import parameters as P
    from biped_sim.config.controllers import chosen_controller
    if args.scene:
        from biped_sim.config.scenes import load_scene
        scene = load_scene(args.scene, overrides=getattr(args, "scene_overrides", None))
        params = dict(scene.given)     # (what the file and the overrides set: a described robot takes no model.*)
        params["time_mode"] = "lockstep"
        return P.validate(params), chosen_controller(getattr(args, "controller", None), scene)
    from biped_sim.config.controllers import run_without_scene
    from biped_sim.engine.integrators import FIXED_STEP_METHODS
    _model, controller, q0, dq0 = run_without_scene(args.controller, args.q0, args.dq0)
    values = dict(scene="simulate", time_mode="lockstep", duration=10.0 if args.duration is None else args.duration,
                  initial_q=[float(v) for v in q0], initial_dq=[float(v) for v in dq0],
                  initial_stance_leg=args.stance_leg, method=args.method, rtol=args.rtol, atol=args.atol,
                  control_period=args.control_period or 0.001, mu=args.mu or 0.0, base=args.base,
                  on_slip="stop")
    values["publish_rate"] = 1.0 / values["control_period"]
    if args.method in FIXED_STEP_METHODS:
        values["step"] = args.step
    if args.base == "fixed":
        values["phases"] = ["stance", "impact"]
    return P.validate(values), controller


def simulate_recorded(args):
    """``biped-sim simulate --record [DIR]``: the run in lockstep, recorded to DIR/<scene>-<UTC time>/."""
    from biped_sim.recording.recorder import BagRecorder, default_bag_path
    params, controller = params_from_args(args)
    folder = args.record or params["bag_dir"]
    path = default_bag_path(folder, params["scene"])
    params["bag_dir"] = str(folder)
    rec = BagRecorder(path, parameters=params)
    print(f"recording to {path}", flush=True)
    stop = []
    try:
        sim = run_recorded(params, controller, rec, stop=stop)
    finally:
        rec.close()
    print(f"recorded {sum(rec.message_counts.values())} messages: "
          + ", ".join(f"{k} {v}" for k, v in rec.message_counts.items()))
    result = sim.result()
    result.stats["bag"] = str(path)     # its samples (the simulator kept none): simulate --plot draws them
    if stop and sim.status == "running" and sim.t < params["duration"]:
        # a run cut short by a signal is not "completed": say so (the bag is closed and readable)
        name = signal.Signals(stop[0]).name
        result = dataclasses.replace(
            result, status="interrupted", stats=dict(result.stats, interrupted_by=int(stop[0])),
            message=f"{name} at t = {sim.t:.6g} s of {params['duration']:g} s; the bag {path} is closed and readable")
    return result
