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
from biped_sim.recording.bag_robot import bag_robot

#: the most samples of a time series ``load_run`` keeps for the figure (a bag longer than that is
#: thinned evenly: every 2nd, 4th, ... state); the figures of the summary use every state
MAX_POINTS = 5000


class Thinned:
    """Rows of a time series kept for a figure in bounded memory: every ``stride``-th row, at most
    ``capacity``; when full, every second kept row is let go and the stride doubles."""

    def __init__(self, width, capacity=MAX_POINTS):
        self.grows = capacity is None     # None: every row, the array doubled when full (biped_sim.load_run)
        capacity = 1024 if capacity is None else capacity
        self.rows = np.full((max(2, int(capacity)), width), np.nan)   # all of it at once: the same for any bag
        self.n = 0              # rows kept
        self.seen = 0           # rows offered
        self.stride = 1

    def add(self, row):
        if self.seen % self.stride == 0:
            if self.n == len(self.rows) and self.grows:
                self.rows = np.concatenate([self.rows, np.full_like(self.rows, np.nan)])
            elif self.n == len(self.rows):
                half = self.rows[:self.n:2].copy()
                self.n = len(half)
                self.rows[:self.n] = half
                self.stride *= 2
                if self.seen % self.stride:
                    self.seen += 1
                    return
            self.rows[self.n] = row
            self.n += 1
        self.seen += 1

    def array(self):
        return self.rows[:self.n].copy()


def load_run(bag, max_points=MAX_POINTS) -> dict:
    """A bag read as a stream, in memory that does not grow with it: the figures of the summary over
    every state (``stats``), and for the figure at most ``max_points`` samples of each series: t, q,
    dq (n columns), effort (n), u (M: effort at the actuated joints), leg (joint_states), grf (t, F), then
    impacts and events (diagnostics) and the commands' count; ``robot``: the :class:`~biped_sim.recording.
    bag_robot.BagRobot` whose coordinates and actuators the columns are. ``max_points=None`` keeps every
    sample; ``all_events`` lists every engine event (those with a ``kind``) of the impact and diagnostics
    topics in their order."""
    # the file in its own order (no merge of its chunks by time): the same run wherever each topic's
    # messages come in time order, as a recorder writes them; else read again in log-time order
    return _read_run(bag, max_points, log_time_order=False) or _read_run(bag, max_points, log_time_order=True)


def _read_run(bag, max_points, log_time_order):
    """:func:`load_run`, reading the messages in log-time order or in the file's order; None if, in the
    file's order, a topic's messages go back in time."""
    topics = bagio.channels(bag)
    t_js = bagio.find_topic(topics, "joint_states")
    t_grf = bagio.find_topic(topics, "ground_reaction")
    t_imp = bagio.find_topic(topics, "impact")
    t_diag = bagio.find_topic(topics, "diagnostics")
    t_cmd = bagio.find_topic(topics, "hip_torque")
    try:
        params = bagio.run_parameters(bag)
    except ValueError:
        params = None
    # the rows' columns: the robot the bag recorded, named as its first joint_states names its coordinates
    robot = js = None
    grf = Thinned(3, max_points)
    impacts, events, all_events, commands = [], [], [], 0
    counts, first, last = {}, {}, {}
    st = dict(n=0, q_first=None, q_last=None, t_first=None, t_last=None, hip_min=math.inf, hip_max=-math.inf,
              u_max=[], u_sq=0.0, fn_min=math.inf, fn_max=-math.inf, ratio=0.0, n_grf=0)
    for topic, typ, t_ns, data in bagio.messages(bag, log_time_order=log_time_order):
        if topic in last:
            if t_ns < last[topic]:
                return None
            counts[topic] += 1
        else:
            counts[topic], first[topic] = 1, t_ns
        last[topic] = t_ns
        if topic not in (t_js, t_grf, t_imp, t_diag):
            if topic == t_cmd:
                commands += 1
            continue
        if topic == t_js:
            if robot is None:
                robot = bag_robot(params, M.joint_state_names_cdr(typ, data))
                n, slots = robot.n, robot.slots
                js = Thinned(1 + 3 * n + 1, max_points)      # t, q, dq, effort, leg
                unknown, none = [math.nan] * n, [0.0] * n
                y = min(1, n - 1)         # base_y (the hip's height), where there is one
                st["u_max"] = [0.0] * len(slots)
            ts, q, dq, eff, leg = M.joint_state_fields_cdr(typ, data)
            # a message of another length than the names (another program's bag) is cut or padded to them
            q, dq, eff = (q + unknown)[:n], (dq + unknown)[:n], (eff + none)[:n]
            js.add([ts / 1e9, *q, *dq, *eff, leg])
            if st["n"] == 0:
                st["q_first"], st["t_first"] = q, ts / 1e9
            st["q_last"], st["t_last"], st["n"] = q, ts / 1e9, st["n"] + 1
            st["hip_min"], st["hip_max"] = min(st["hip_min"], q[y]), max(st["hip_max"], q[y])
            u_max, sq = st["u_max"], 0.0
            for k, i in enumerate(slots):
                v = eff[i]
                u_max[k] = max(u_max[k], abs(v))
                sq += v * v
            st["u_sq"] += sq
        elif topic == t_grf:
            ts, (fx, fy), _leg = M.wrench_values_cdr(typ, data)
            grf.add([ts / 1e9, fx, fy])
            st["n_grf"] += 1
            st["fn_min"], st["fn_max"] = min(st["fn_min"], fy), max(st["fn_max"], fy)
            st["ratio"] = max(st["ratio"], abs(fx) / max(abs(fy), 1e-12))
        elif topic == t_imp:
            values = M.event_values_cdr(typ, data)
            impacts.extend(values)
            all_events.extend((t_ns, e) for e in values if "kind" in e)
        else:
            values = M.event_values_cdr(typ, data)
            events.extend(e for e in values if _kept_event(e))
            all_events.extend((t_ns, e) for e in values if "kind" in e)
    all_events.sort(key=lambda item: item[0])       # stable: log-time order, ties in the file's order
    all_events = [e for _t, e in all_events]
    run = dict(topics=topics, counts=counts, first=first, last=last, impacts=impacts, events=events,
               all_events=all_events,
               commands=commands, stats=st, cut=bagio.cut_short(bag), being_written=bagio.being_written(bag))
    if robot is None:           # no joint_states: the recorded robot's layout names the (empty) columns
        robot = bag_robot(params, ())
        js = Thinned(1 + 3 * robot.n + 1, max_points)
        st["u_max"] = [0.0] * len(robot.slots)
    n = robot.n
    rows = js.array()
    run["t"], run["q"], run["dq"] = rows[:, 0], rows[:, 1:1 + n], rows[:, 1 + n:1 + 2 * n]
    run["effort"] = rows[:, 1 + 2 * n:1 + 3 * n]
    run["u"] = run["effort"][:, list(robot.slots)]
    run["leg"] = rows[:, 1 + 3 * n].astype(int)
    rows = grf.array()
    run["grf_t"], run["grf"] = rows[:, 0], rows[:, 1:3]
    run["params"], run["robot"] = params, robot
    return run


def _kept_event(e) -> bool:
    """The diagnostics the summary reports (pushes, resets, the run's end and errors): a run's
    periodic status messages are not kept."""
    name = e.get("name", "")
    return e.get("kind") == "push" or name == "biped_sim/reset" or name.endswith("/run") or e.get("level", 0) >= 2


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
              + (f", robot {p['robot']}" if p.get("robot", "three_link") != "three_link" else "")
              if p else "run         NOT RECORDED BY biped_sim (no biped_sim parameters record): its topics only",
              f"duration    {(t1 - t0) / 1e9:.6g} s of simulated time (t = {t0 / 1e9:.6g} .. {t1 / 1e9:.6g} s)",
              "topics"]
    robot = run["robot"]
    if robot.problem:
        lines.insert(-2, f"robot       {robot.problem}")
    for topic in sorted(run["counts"]):
        n = run["counts"][topic]
        span = (run["last"][topic] - run["first"][topic]) / 1e9
        rate = f"{(n - 1) / span:9.1f} Hz" if n > 1 and span > 0 else " " * 12
        lines.append(f"  {topic:22s} {run['topics'].get(topic, '?'):38s} {n:8d}  {rate}")
    imps = run["impacts"]
    lines.append(f"impacts     {len(imps)}" + (": " + ", ".join(
        f"t={e['time']:.4f} s foot {e['foot']}" for e in imps[:8]) + (" ..." if len(imps) > 8 else "") if imps else ""))
    st = run["stats"]
    if st["n"]:
        dist = st["q_last"][0] - st["q_first"][0]
        span = st["t_last"] - st["t_first"]
        height = "hip height" if robot.three_link else robot.coordinates[1] if robot.n > 1 else ""  # the base's y
        lines.append(f"distance    {dist:.4g} m in {span:.4g} s (mean speed {dist / max(span, 1e-12):.3g} m/s)"
                     + (f", {height} {st['hip_min']:.3g} .. {st['hip_max']:.3g} m" if height else ""))
        if len(imps) >= 2:
            model = _model_or_none(robot)
            ti = np.array([e["time"] for e in imps])
            xs = np.array([_foot_x(e, model) for e in imps])
            lines.append(f"steps       period {np.mean(np.diff(ti)):.4g} s (min {np.min(np.diff(ti)):.4g}, max "
                         f"{np.max(np.diff(ti)):.4g}), length {np.mean(np.diff(xs)):.4g} m")
        names = ("u1", "u2") if robot.three_link else robot.actuators
        if names:
            lines.append("torques     " + ", ".join(f"|{name}| max {v:.4g} N m" for name, v in zip(names, st["u_max"]))
                         + f", rms {math.sqrt(st['u_sq'] / (len(names) * st['n'])):.4g} N m")
        if st["n_grf"]:
            lines.append(f"ground      normal force {st['fn_min']:.4g} .. {st['fn_max']:.4g} N, "
                         f"max |F_t / F_n| {st['ratio']:.3g}")
        loss = sum(e.get("energy_loss", 0.0) or 0.0 for e in imps if isinstance(e.get("energy_loss"), float))
        if imps:
            lines.append(f"energy      {loss:.4g} J lost in impacts")
    if run["commands"]:
        lines.append(f"commands    {run['commands']} on hip_torque")
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


def _model_or_none(robot):
    """The bag's robot's model, or None when it cannot be loaded (the summary says why on its robot line)."""
    try:
        return robot.model()
    except ValueError:
        return None


def _foot_x(e, model):
    from biped_sim.engine.figure import impact_foot_x
    return math.nan if model is None else impact_foot_x(model, e.get("foot"), e.get("q"))


def plot(bag, png, run=None, frames=14):
    """Write the figure of a run to ``png`` (:func:`biped_sim.engine.figure.run_figure`, fed the bag's arrays);
    returns the matplotlib Figure."""
    from biped_sim.engine.figure import run_figure
    run = run or load_run(bag)
    p = run["params"] or {}
    gt, F = run["grf_t"], run["grf"].copy()
    if len(gt) > 2:    # break the lines across flight phases (no message in flight)
        F[np.concatenate([[False], np.diff(gt) > 1.5 * np.median(np.diff(gt))])] = np.nan
    impacts = [(e["time"], e.get("foot"), e.get("q")) for e in run["impacts"]]
    title = f"{p.get('scene', bag)}: {p.get('time_mode', '')} run, {len(impacts)} impacts"
    return run_figure(run["t"], run["q"], run["u"], gt, F, impacts, run["robot"].model(), title,
                      slope=float(p.get("slope", 0.0) or 0.0), path=png, frames=frames, outcome=run_end(run))


def run_end(run):
    """(status, time, reason) of a bag's run: its final ``biped_sim/run`` status (the node's), else the
    last error it recorded (an engine stop: ``error``, ``zeno``), else completed or cut short by its
    last state against the run's ``duration``."""
    ends = [e for e in run["events"] if e.get("name", "").endswith("/run") or e.get("level", 0) >= 2]
    t_last = float(run["t"][-1]) if len(run["t"]) else math.nan
    if ends:
        e = ends[-1]
        status = e.get("status") if isinstance(e.get("status"), str) else "stopped"
        time = e.get("time")
        time = float(time) if isinstance(time, (int, float)) else e.get("t_ns", math.nan) / 1e9
        reason = str(e.get("message", ""))
        return status, time, reason.removeprefix(f"{status}: ")
    duration = (run["params"] or {}).get("duration")
    if run.get("cut"):
        return "cut short", t_last, str(run["cut"])
    if isinstance(duration, (int, float)) and duration > 0 and t_last < duration - 1e-9:
        return "ended", t_last, f"the bag ends before the run's duration {duration:g} s"
    return "completed", t_last, ""
