"""Re-simulate a recorded run: its torque commands through a fresh engine with its settings.

Owns ``biped-sim resim``. The parameters come from the bag's ``biped_sim`` metadata record; the
engine is built with ``parameters.engine_arguments`` as the node builds it, and advanced the way
the node does: one ``advance_period`` per control period (the engine's one zero-order hold, to
``(k + 1) * control_period``, capped at ``duration``), with the torques of the last valid command
held (the node's checks: two finite values within ``torque_limit``, else rejected or clipped per
``torque_limit_action``). Each recorded ``joint_states`` message is compared with the engine's
state at its stamp, and each recorded impact with the engine's; a lockstep run of the same
version and settings is reproduced exactly (difference 0.0). The pushes of the run (``push`` events
on ``diagnostics``) are applied again at their times, through ``HybridSimulator.push``. A bag
ends at a ``~/reset`` of the node; the run goes on from t = 0 in the next bag, which resim
re-simulates from the scene's initial state as any other (docs/recording.md "Resets").
"""
from __future__ import annotations

import math

from biped_sim.config.parameters import method_label
from biped_sim.recording import bagio, messages as M
from biped_sim.recording.node_run import NodeRun, stale_command


def resim(bag, progress=None) -> dict:
    """Re-simulate ``bag``; returns a report dict (see :func:`format_report`)."""
    from biped_sim.config.parameters import recorded_given, validate
    recorded = bagio.run_parameters(bag)
    try:
        params = validate(recorded_given(recorded))
    except ValueError as exc:       # e.g. its robot, a description file that is gone
        raise ValueError(f"cannot re-simulate {bag}: its recorded parameters are refused here: {exc}") from None
    topics = bagio.channels(bag)
    t_js = bagio.find_topic(topics, "joint_states")
    t_cmd = bagio.find_topic(topics, "hip_torque")
    t_imp = bagio.find_topic(topics, "impact")
    t_diag = bagio.find_topic(topics, "diagnostics")
    if t_js is None:
        raise ValueError(f"{bag} has no joint_states topic to compare with")
    run = NodeRun(params)
    sim = run.sim
    lockstep = params["time_mode"] == "lockstep"
    advance_to = run.advance_to

    rep = dict(bag=str(bag), params=params, commands=0, states=0, max_dq=0.0, max_q=0.0, first=None,
               pushes=0, impacts_recorded=[], status=None, message="", t_end=0.0, t_last_state=-math.inf,
               cut=bagio.cut_short(bag))
    for topic, typ, t_ns, data in bagio.messages(bag, topics=[t for t in (t_js, t_cmd, t_imp, t_diag) if t]):
        msg = bagio.decode(typ, data)
        if topic == t_cmd:
            advance_to(t_ns)
            rep["commands"] += 1
            if lockstep and stale_command(M.answered_ns(msg), t_ns) is not None:
                continue        # the node ignored it: it answers another state than the newest (stale)
            run.take_command(list(msg.data))
        elif topic == t_diag:
            for e in M.event_values(msg):
                if e.get("kind") in ("push", "error") and isinstance(e.get("push"), list):
                    advance_to(e["t_ns"])
                    sim.push(e["push"])
                    rep["pushes"] += 1
        elif topic == t_imp:
            rep["impacts_recorded"].extend(e["time"] for e in M.event_values(msg) if "time" in e)
        else:
            advance_to(t_ns)
            ts, q, dq, _u, _leg = M.joint_state_values(msg)
            rep["states"] += 1
            rep["t_last_state"] = ts / 1e9
            dqe = max(abs(a - b) for a, b in zip(q, sim.q.tolist()))
            dve = max(abs(a - b) for a, b in zip(dq, sim.dq.tolist()))
            if M.to_ns(sim.t) != ts:
                dqe = dve = math.inf   # the engine could not reach that time (it stopped)
            rep["max_q"] = max(rep["max_q"], dqe)
            rep["max_dq"] = max(rep["max_dq"], dve)
            if rep["first"] is None and (dqe != 0.0 or dve != 0.0):
                rep["first"] = dict(topic=topic, index=rep["states"] - 1, t=ts / 1e9, dq=dve, dpos=dqe,
                                    recorded=q, resimulated=sim.q.tolist(), engine_t=sim.t)
            if progress is not None:
                progress(rep)
    rep["impacts_resimulated"] = [e.time for e in sim.events if e.kind in M.IMPACT_KINDS]
    # impacts are compared up to the last state compared: a bag cut short (a killed recording, then
    # recovered) can end between an impact's message and the next state, where resim has not gone
    last = rep["t_last_state"]
    rep["impacts_recorded"] = [t for t in rep["impacts_recorded"] if t <= last]
    rep["impacts_resimulated"] = [t for t in rep["impacts_resimulated"] if t <= last]
    rep["impact_dt"] = (max((abs(a - b) for a, b in zip(rep["impacts_recorded"], rep["impacts_resimulated"])),
                            default=0.0)
                        if len(rep["impacts_recorded"]) == len(rep["impacts_resimulated"]) else math.inf)
    rep["status"], rep["message"], rep["t_end"] = sim.status, sim.message, sim.t
    rep["identical"] = rep["first"] is None and rep["impact_dt"] == 0.0 and rep["states"] > 0
    return rep


def format_report(rep) -> str:
    p = rep["params"]
    lines = [
        f"bag               {rep['bag']}" + (f" ({rep['cut']}: compared up to its last complete chunk; "
                                                 "'biped-sim recover' repairs the file)" if rep.get("cut") else ""),
        f"settings          scene {p['scene']}, time_mode {p['time_mode']}, control_period {p['control_period']:g} s, "
        f"method {method_label(p)}, rtol {p['rtol']:g}, atol {p['atol']:g}, base {p['base']}",
        f"replayed          {rep['commands']} torque commands, {rep['pushes']} pushes, compared {rep['states']} "
        "joint_states "
        f"(to t = {rep['t_end']:.6g} s)",
        f"largest difference  |q| {rep['max_q']:.3g}, |dq| {rep['max_dq']:.3g}",
        f"impacts           recorded {len(rep['impacts_recorded'])}, re-simulated {len(rep['impacts_resimulated'])}, "
        f"largest time difference {rep['impact_dt']:.3g} s",
    ]
    if rep["identical"]:
        lines.append("result            IDENTICAL: the re-simulation reproduces every recorded state bit for bit")
    else:
        f = rep["first"]
        if f is not None:
            lines.append(f"result            DIFFERENT: first at {f['topic']} message #{f['index']} "
                         f"(t = {f['t']:.9f} s): "
                         f"|q| {f['dpos']:.3g}, |dq| {f['dq']:.3g}")
            lines.append(f"  recorded q       {f['recorded']}")
            lines.append(f"  re-simulated q   {f['resimulated']}")
        else:
            lines.append("result            DIFFERENT: the impacts differ (count or time)")
    return "\n".join(lines)
