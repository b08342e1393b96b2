"""The figure of a run (``SimulationResult.plot()`` and ``biped-sim inspect``): joint angles, ground
reaction forces, motor torques, impact markers and a stick-figure strip of the gait, drawn from arrays;
its title says how and when the run ended and, for a run that stopped, why. Any robot is drawn: the
three-link ``BipedModel`` with its panels' names of docs/model.md, a described robot (``GeneratedModel``)
with its coordinates' and actuators' names and its links (:mod:`biped_sim.engine.drawing`).

matplotlib is imported inside :func:`run_figure` only: a run that plots nothing does not pay for its
import, and the engine stays usable without it (it is the ``plot`` extra). The figure is a
``matplotlib.figure.Figure`` made without pyplot: no global backend or figure registry is touched.
"""
from __future__ import annotations

import math
import textwrap

import numpy as np

#: characters a line of the reason under the title holds (the figure is 12 in wide, 12 pt text)
REASON_WIDTH = 110
#: lines of the reason shown at most (the rest is in the summary, the events and the log)
REASON_LINES = 3
#: the height of a line of the title, as a fraction of the figure's (12 pt in a 12 in figure, spaced)
TITLE_LINE = 0.0205


def coordinate_count(model) -> int:
    """N, the length of the model's q (the three-link ``BipedModel``: 5)."""
    return getattr(model, "n", 5)


def impact_foot_x(model, foot, q) -> float:
    """x (m) of the foot that touched down at state ``q`` (nan without a state of the model's size)."""
    from biped_sim.engine.drawing import RobotDrawing
    if q is None or len(q) != coordinate_count(model) or not np.all(np.isfinite(np.asarray(q, dtype=float))):
        return float("nan")
    foot = int(foot) if foot in (1, 2, "1", "2") else 1
    return float(RobotDrawing(model).foot(np.asarray(q, dtype=float), foot)[0])


def panel_series(model):
    """((q index, label, offset) of each angle shown, (u index, label) of each torque) of a model's run: the
    three-link's relative hip angles shown as q - pi and its torso; a described robot's joint angles as they
    are, named by its coordinates and actuators."""
    if not hasattr(model, "description"):
        return ([(2, "hip_1 (q1) - pi", math.pi), (3, "hip_2 (q2) - pi", math.pi), (4, "torso_pitch (q3)", 0.0)],
                [(0, "u1 (hip 1)"), (1, "u2 (hip 2)")])
    angles = [(i, name, 0.0) for i, name in enumerate(model.coordinates) if i >= 2]
    return angles, list(enumerate(model.description.actuated))


def outcome_text(status, time, reason=""):
    """How and when a run ended, and why if it did not complete: "stopped at t = 1.5598 s: <the
    reason's first line, wrapped>" (``time`` nan: no time)."""
    when = f" at t = {time:.6g} s" if time is not None and math.isfinite(time) else ""
    first = (reason or "").strip().splitlines()[0] if (reason or "").strip() else ""
    if status == "completed" or not first:
        return f"{status}{when}"
    lines = textwrap.wrap(f"{status}{when}: {first}", REASON_WIDTH)
    if len(lines) > REASON_LINES:
        lines = lines[:REASON_LINES]
        lines[-1] = lines[-1][:REASON_WIDTH - 4] + " ..."
    return "\n".join(lines)


def thin_labels(ax, labels, pad=2.0):
    """Show only labels that do not overprint: ``labels`` (matplotlib Text, in order of preference) are
    checked when ``ax`` is drawn, once the layout is final, and each one whose box (grown by ``pad``
    pixels) overlaps one shown before it is hidden. Stick figures of a robot that stays in place (a
    fall, a stop) stand on one another and their time labels would."""
    from matplotlib.artist import Artist

    class LabelThinner(Artist):
        def draw(self, renderer):
            shown = []
            for label in labels:
                label.set_visible(True)
                box = label.get_window_extent(renderer).padded(pad)
                if any(box.overlaps(other) for other in shown):
                    label.set_visible(False)
                else:
                    shown.append(box)

    thinner = LabelThinner()
    thinner.set_zorder(-1e9)     # drawn before the labels (an Axes draws its artists by zorder)
    ax.add_artist(thinner)
    return thinner


def _draw_lines(ax, lines, **style):
    """A drawing's :class:`~biped_sim.engine.drawing.Lines`: one polyline, or a segment per pair of points."""
    points = np.asarray(lines.points, dtype=float).reshape(-1, 2)
    if lines.strip:
        if len(points):
            ax.plot(points[:, 0], points[:, 1], **style)
        return
    for a, b in zip(points[0::2], points[1::2]):
        ax.plot([a[0], b[0]], [a[1], b[1]], **style)


def run_figure(t, q, u, grf_t, grf, impacts, model, title, slope=0.0, path=None, frames=14, outcome=None):
    """The figure of a run as a matplotlib Figure; written to ``path`` (PNG) if given.

    t (n,), q (n, N), u (n, M): the samples; grf_t (m,), grf (m, 2): the ground's force on the stance
    foot (nan where a line should break, e.g. in flight); impacts: (time, foot, q) of each touchdown;
    outcome: (status, time, reason) of the run's end, said under the title (:func:`outcome_text`) and,
    for a run that did not complete, marked at its time on the time panels.
    """
    from matplotlib.figure import Figure

    from biped_sim.engine.drawing import RobotDrawing
    t, q, u = np.asarray(t, dtype=float), np.asarray(q, dtype=float), np.asarray(u, dtype=float)
    imp_t = [float(ti) for ti, _foot, _q in impacts]
    stop = None
    if outcome is not None:
        status, end_time, reason = outcome
        title = f"{title}\n{outcome_text(status, end_time, reason)}"
        if status != "completed" and end_time is not None and math.isfinite(end_time):
            stop = (status, float(end_time))
    # fixed margins, the top one for the title's lines: a constrained layout measured every tick
    # label for ~40 % of the drawing time of `biped-sim inspect`
    fig = Figure(figsize=(12, 12))
    top = 1.0 - (0.012 + TITLE_LINE * (title.count("\n") + 1)) - 0.03
    gs = fig.add_gridspec(4, 1, height_ratios=[1.1, 1, 0.8, 1.6], left=0.07, right=0.985, bottom=0.045, top=top,
                          hspace=0.42)
    fig.suptitle(title, fontsize=12, y=0.994, va="top")

    angles, torques = panel_series(model)
    ax = fig.add_subplot(gs[0])
    if len(t):
        for j, (i, name, offset) in enumerate(angles):
            ax.plot(t, q[:, i] - offset, color=f"C{j}", label=name)
    ax.set_ylabel("angle (rad)")
    ax.set_title("joint angles" + (" (relative hip angles shown as q - pi)" if angles[0][2] else ""), fontsize=10,
                 loc="left")

    ax2 = fig.add_subplot(gs[1], sharex=ax)
    if len(grf_t):
        ax2.plot(grf_t, grf[:, 1], color="C3", label="F_y (normal)")
        ax2.plot(grf_t, grf[:, 0], color="C4", label="F_x (tangential)")
    ax2.set_ylabel("force (N)")
    ax2.set_title("ground reaction force on the stance foot", fontsize=10, loc="left")

    ax3 = fig.add_subplot(gs[2], sharex=ax)
    if len(t):
        for j, name in torques:
            ax3.step(t, u[:, j], where="post", color=f"C{j}", label=name)
    ax3.set_ylabel("torque (N m)")
    ax3.set_xlabel("simulated time (s)")
    ax3.set_title("motor torques (held over each control period)", fontsize=10, loc="left")
    for a in (ax, ax2, ax3):
        for i, ti in enumerate(imp_t):
            a.axvline(ti, color="0.5", lw=0.8, ls="--", label="impact" if i == 0 else None)
        if stop is not None:
            a.axvline(stop[1], color="C3", lw=1.5, label=stop[0])
        a.grid(alpha=0.3)
        if a.get_legend_handles_labels()[0]:
            a.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=8, ncol=4, frameon=False)

    ax4 = fig.add_subplot(gs[3])
    ax4.set_title("gait (stick figures at even times; leg 1 blue, leg 2 orange, the body green; x marks impacts)",
                  fontsize=10, loc="left")
    if len(t):
        drawing = RobotDrawing(model)
        idx = np.unique(np.linspace(0, len(t) - 1, frames).round().astype(int))
        xs, ys, labels = [], [], []
        for j, i in enumerate(idx):
            figure = drawing.figure(q[i])
            shade = 0.35 + 0.65 * j / max(len(idx) - 1, 1)
            for k, lines in enumerate(figure.legs):
                _draw_lines(ax4, lines, color=f"C{k}", lw=2, alpha=shade)
            _draw_lines(ax4, figure.body, color="C2", lw=2.5, alpha=shade)
            for lines in (*figure.legs, figure.body):
                xs += [p[0] for p in lines.points]
                ys += [p[1] for p in lines.points]
            ax4.plot(*figure.hip, "o", color="k", ms=3, alpha=shade)
            xs += [figure.hip[0]]
            ys += [figure.hip[1]]
            labels.append((j, t[i], figure))
        top_y = max(ys) + 0.1
        texts = []
        for j, ti, figure in labels:
            x = max((p for lines in (figure.body, *figure.legs) for p in lines.points), key=lambda p: p[1],
                    default=figure.hip)[0]
            texts.append(ax4.text(x, top_y if j % 2 == 0 else top_y + 0.14, f"{ti:.2f} s", ha="center", fontsize=7))
        for _ti, foot, qi in impacts:
            x = impact_foot_x(model, foot, qi)
            if math.isfinite(x):
                ax4.plot(x, -math.tan(slope) * x, "x", color="C3", ms=7)
        lo, hi = min(xs) - 0.2, max(xs) + 0.2
        gx = np.array([lo, hi])
        ax4.plot(gx, -math.tan(slope) * gx, color="0.3", lw=1)
        ax4.set_xlim(lo, hi)
        ax4.set_ylim(min(-0.12, min(ys) - 0.05), top_y + 0.26)
        ax4.set_aspect("equal", adjustable="box")
        ax4.set_xlabel("x (m)")
        ax4.set_ylabel("y (m)")
        # the last frame's time first (where the run ended), then the first, then the rest in order
        thin_labels(ax4, texts[-1:] + texts[:-1])
    if path is not None:
        fig.savefig(path, dpi=90)
    return fig
