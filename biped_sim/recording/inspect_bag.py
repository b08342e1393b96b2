"""Look at a recorded run: a text summary and a PNG (``biped-sim inspect``).

Owns the summary (duration, topics with counts and rates, impacts, figures of the run: distance,
speed, step lengths and periods, torques, ground forces, the run's end status) and the figure
(matplotlib, Agg backend): joint angles, ground reaction forces, hip torques, impact markers, and
a stick-figure strip of the gait. Reads the bag with :mod:`biped_sim.recording.bagio`.
"""
from __future__ import annotations

import math

import numpy as np

from biped_sim.config.parameters import method_label
from biped_sim.recording import bagio, messages as M


def load_run(bag) -> dict:
    """Arrays of a bag: t, q, dq, u, leg (joint_states), grf (t, F, leg), impacts, commands, events."""
    topics = bagio.channels(bag)
    t_js = bagio.find_topic(topics, "joint_states")
    t_grf = bagio.find_topic(topics, "ground_reaction")
    t_imp = bagio.find_topic(topics, "impact")
    t_diag = bagio.find_topic(topics, "diagnostics")
    t_cmd = bagio.find_topic(topics, "hip_torque")
    js, grf, impacts, events, cmds = [], [], [], [], []
    counts, first, last = {}, {}, {}
    for topic, typ, t_ns, data in bagio.messages(bag):
        counts[topic] = counts.get(topic, 0) + 1
        first.setdefault(topic, t_ns)
        last[topic] = t_ns
        if topic not in (t_js, t_grf, t_imp, t_diag, t_cmd):
            continue
        msg = bagio.decode(typ, data)
        if topic == t_js:
            js.append(M.joint_state_values(msg))
        elif topic == t_grf:
            grf.append(M.wrench_values(msg))
        elif topic == t_imp:
            impacts.extend(M.event_values(msg))
        elif topic == t_diag:
            events.extend(M.event_values(msg))
        else:
            cmds.append((t_ns, list(msg.data)))
    run = dict(topics=topics, counts=counts, first=first, last=last, impacts=impacts, events=events,
               commands=cmds, cut=bagio.cut_short(bag), being_written=bagio.being_written(bag))
    run["t"] = np.array([j[0] for j in js]) / 1e9
    run["q"] = np.array([j[1] for j in js]).reshape(-1, 5)
    run["dq"] = np.array([j[2] for j in js]).reshape(-1, 5)
    run["u"] = np.array([j[3] for j in js]).reshape(-1, 2)
    run["leg"] = np.array([j[4] for j in js], dtype=int)
    run["grf_t"] = np.array([g[0] for g in grf]) / 1e9
    run["grf"] = np.array([g[1] for g in grf]).reshape(-1, 2)
    try:
        run["params"] = bagio.run_parameters(bag)
    except ValueError:
        run["params"] = None
    return run


def run_model(params):
    """The BipedModel of a run's parameters (the defaults without them)."""
    from biped_sim.engine.model import BipedModel
    if not params:
        return BipedModel()
    return BipedModel(**{k.split(".", 1)[1]: v for k, v in params.items() if k.startswith("model.")})


def summary(bag, run=None) -> str:
    run = run or load_run(bag)
    t0 = min(run["first"].values(), default=0)
    t1 = max(run["last"].values(), default=0)
    p = run["params"] or {}
    lines = [f"bag         {bag}"]
    if run.get("being_written"):
        lines.append(f"file        BEING RECORDED right now ({run['cut']}): this is the run so far")
    elif run.get("cut"):
        where = run["cut"].removeprefix("cut short")      # " at N bytes (why)", in capitals to be seen
        lines.append(f"file        CUT SHORT{where}: this is the run up to its last complete chunk, not the whole "
                     f"run; run 'biped-sim recover {bag}' to repair the file")
    lines += [f"run         scene {p.get('scene', '?')}, time_mode {p.get('time_mode', '?')}, control_period "
              f"{p.get('control_period', float('nan')):g} s, method {method_label(p)}"
              if p else "run         NOT RECORDED BY biped_sim (no biped_sim parameters record): its topics only",
              f"duration    {(t1 - t0) / 1e9:.6g} s of simulated time (t = {t0 / 1e9:.6g} .. {t1 / 1e9:.6g} s)",
              "topics"]
    for topic in sorted(run["counts"]):
        n = run["counts"][topic]
        span = (run["last"][topic] - run["first"][topic]) / 1e9
        rate = f"{(n - 1) / span:9.1f} Hz" if n > 1 and span > 0 else " " * 12
        lines.append(f"  {topic:22s} {run['topics'].get(topic, '?'):38s} {n:8d}  {rate}")
    imps = run["impacts"]
    lines.append(f"impacts     {len(imps)}" + (": " + ", ".join(
        f"t={e['time']:.4f} s foot {e['foot']}" for e in imps[:8]) + (" ..." if len(imps) > 8 else "") if imps else ""))
    t, q = run["t"], run["q"]
    if len(t):
        dist = q[-1, 0] - q[0, 0]
        span = t[-1] - t[0]
        lines.append(f"distance    {dist:.4g} m in {span:.4g} s (mean speed {dist / max(span, 1e-12):.3g} m/s), "
                     f"hip height {q[:, 1].min():.3g} .. {q[:, 1].max():.3g} m")
        if len(imps) >= 2:
            ti = np.array([e["time"] for e in imps])
            xs = np.array([_foot_x(e, p) for e in imps])
            lines.append(f"steps       period {np.mean(np.diff(ti)):.4g} s (min {np.min(np.diff(ti)):.4g}, max "
                         f"{np.max(np.diff(ti)):.4g}), length {np.mean(np.diff(xs)):.4g} m")
        if run["u"].size:
            u = run["u"]
            u1, u2 = np.abs(u[:, 0]).max(), np.abs(u[:, 1]).max()
            lines.append(f"torques     |u1| max {u1:.4g} N m, |u2| max {u2:.4g} N m, "
                         f"rms {math.sqrt(float(np.mean(u ** 2))):.4g} N m")
        if len(run["grf"]):
            F = run["grf"]
            lines.append(f"ground      normal force {F[:, 1].min():.4g} .. {F[:, 1].max():.4g} N, "
                         f"max |F_t / F_n| {np.max(np.abs(F[:, 0]) / np.maximum(np.abs(F[:, 1]), 1e-12)):.3g}")
        loss = sum(e.get("energy_loss", 0.0) or 0.0 for e in imps if isinstance(e.get("energy_loss"), float))
        if imps:
            lines.append(f"energy      {loss:.4g} J lost in impacts")
    if run["commands"]:
        lines.append(f"commands    {len(run['commands'])} on hip_torque")
    pushes = [e for e in run["events"] if e.get("kind") == "push"]
    if pushes:
        lines.append(f"pushes      {len(pushes)}: " + ", ".join(
            f"t={e['time']:.4f} s P={e['push']} N s" for e in pushes[:4]) + (" ..." if len(pushes) > 4 else ""))
    for e in run["events"]:      # a ~/reset of the node: this bag starts or ends there (docs/recording.md)
        if e.get("name") == "biped_sim/reset":
            lines.append(f"reset       {e.get('message')}")
    ends = [e for e in run["events"] if e.get("name", "").endswith("/run") or e.get("level", 0) >= 2]
    if ends:
        e = ends[-1]
        lines.append(f"end         {e.get('name')}: {e.get('message')}")
    return "\n".join(lines)


def _foot_x(e, params):
    q = e.get("q")
    if not isinstance(q, list) or len(q) != 5:
        return float("nan")
    foot = int(e["foot"]) if e.get("foot") in (1, 2, "1", "2") else 1
    return float(run_model(params).foot_position(np.array(q), foot)[0])


def plot(bag, png, run=None, frames=14):
    """Write the figure of a run to ``png``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    run = run or load_run(bag)
    t, q, u = run["t"], run["q"], run["u"]
    p = run["params"] or {}
    model = run_model(p)
    imp_t = [e["time"] for e in run["impacts"]]
    fig = plt.figure(figsize=(12, 12), constrained_layout=True)
    gs = fig.add_gridspec(4, 1, height_ratios=[1.1, 1, 0.8, 1.6])
    title = f"{p.get('scene', bag)}: {p.get('time_mode', '')} run, {len(imp_t)} impacts"
    fig.suptitle(title, fontsize=13)

    ax = fig.add_subplot(gs[0])
    if len(t):
        for i, (name, c) in enumerate([("hip_1 (q1)", "C0"), ("hip_2 (q2)", "C1")]):
            ax.plot(t, q[:, 2 + i] - math.pi, color=c, label=f"{name} - pi")
        ax.plot(t, q[:, 4], color="C2", label="torso_pitch (q3)")
    ax.set_ylabel("angle (rad)")
    ax.set_title("joint angles (relative hip angles shown as q - pi)", fontsize=10, loc="left")

    ax2 = fig.add_subplot(gs[1], sharex=ax)
    if len(run["grf_t"]):
        gt, F = run["grf_t"], run["grf"]
        gap = np.concatenate([[False], np.diff(gt) > 1.5 * np.median(np.diff(gt))]) if len(gt) > 2 else None
        Fx, Fy = F[:, 0].copy(), F[:, 1].copy()
        if gap is not None:   # break the lines across flight phases (no message in flight)
            Fx[gap], Fy[gap] = np.nan, np.nan
        ax2.plot(gt, Fy, color="C3", label="F_y (normal)")
        ax2.plot(gt, Fx, color="C4", label="F_x (tangential)")
    ax2.set_ylabel("force (N)")
    ax2.set_title("ground reaction force on the stance foot", fontsize=10, loc="left")

    ax3 = fig.add_subplot(gs[2], sharex=ax)
    if len(t):
        ax3.step(t, u[:, 0], where="post", color="C0", label="u1 (hip 1)")
        ax3.step(t, u[:, 1], where="post", color="C1", label="u2 (hip 2)")
    ax3.set_ylabel("torque (N m)")
    ax3.set_xlabel("simulated time (s)")
    ax3.set_title("hip torques (held over each control period)", fontsize=10, loc="left")
    for a in (ax, ax2, ax3):
        for i, ti in enumerate(imp_t):
            a.axvline(ti, color="0.5", lw=0.8, ls="--", label="impact" if i == 0 else None)
        a.grid(alpha=0.3)
        a.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=8, ncol=4, frameon=False)

    ax4 = fig.add_subplot(gs[3])
    ax4.set_title("gait (stick figures at even times; leg 1 blue, leg 2 orange, torso green; x marks impacts)",
                  fontsize=10, loc="left")
    if len(t):
        idx = np.unique(np.linspace(0, len(t) - 1, frames).round().astype(int))
        slope = float(p.get("slope", 0.0) or 0.0)
        xs = []
        for j, i in enumerate(idx):
            qi = q[i]
            hip = qi[:2]
            shade = 0.35 + 0.65 * j / max(len(idx) - 1, 1)
            for leg, c in ((1, "C0"), (2, "C1")):
                foot = model.foot_position(qi, leg)
                ax4.plot([hip[0], foot[0]], [hip[1], foot[1]], color=c, lw=2, alpha=shade)
                xs += [foot[0]]
            top = model.stick_figure(qi).torso_tip
            ax4.plot([hip[0], top[0]], [hip[1], top[1]], color="C2", lw=2.5, alpha=shade)
            ax4.plot(*hip, "o", color="k", ms=3, alpha=shade)
            ax4.text(top[0], 1.62 if j % 2 == 0 else 1.76, f"{t[i]:.2f} s", ha="center", fontsize=7)
            xs += [hip[0], top[0]]
        for e in run["impacts"]:
            x = _foot_x(e, p)
            if math.isfinite(x):
                ax4.plot(x, -math.tan(slope) * x, "x", color="C3", ms=7)
        lo, hi = min(xs) - 0.2, max(xs) + 0.2
        gx = np.array([lo, hi])
        ax4.plot(gx, -math.tan(slope) * gx, color="0.3", lw=1)
        ax4.set_xlim(lo, hi)
        ax4.set_ylim(-0.12, 1.88)
        ax4.set_aspect("equal", adjustable="box")
        ax4.set_xlabel("x (m)")
        ax4.set_ylabel("y (m)")
    fig.savefig(png, dpi=90)
    plt.close(fig)
    return png
