"""The sweep and basin maps colour by a measure of the gait (the distance walked), not by the step
count, and tell the basin's fixed point and the refused starts apart from the falls (issue 33)."""
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.image import AxesImage

from biped_sim.analysis import basin as bn, sweep as sw


def _row(a, b, status, impacts, x_end, names=("kp", "kd")):
    return {names[0]: a, names[1]: b, "status": status, "impacts": impacts, "x_end": x_end}


def _rows(names=("kp", "kd")):
    """A 3 x 3 grid whose step counts and distances disagree: quick short steps (many impacts, little
    distance) in one corner, long steps in another; one fall and one refused start."""
    rows = []
    for i, a in enumerate((-1.0, 0.0, 1.0)):
        for j, b in enumerate((-1.0, 0.0, 1.0)):
            status = "completed"
            if (i, j) == (0, 0):
                status = "error"
            elif (i, j) == (2, 2):
                status = "stopped"
            rows.append(_row(a, b, status, impacts=20 - 3 * i - j, x_end=0.5 * i + 0.1 * j + 0.05, names=names))
    return rows


def test_the_map_colours_by_the_distance_walked_not_the_step_count():
    rows = _rows()
    fig = sw.figure(rows, ["kp", "kd"])
    try:
        (image,) = [a for a in fig.axes[0].get_children() if isinstance(a, AxesImage)]
        shown = np.ma.filled(image.get_array().astype(float), np.nan)
        distance = np.array([[np.nan if r["status"] == "error" else r["x_end"] for r in rows[k:k + 3]]
                             for k in (0, 3, 6)])
        steps = np.array([[r["impacts"] for r in rows[k:k + 3]] for k in (0, 3, 6)], dtype=float)
        np.testing.assert_array_equal(shown, distance)
        assert not np.allclose(np.nan_to_num(shown), steps)
        assert "distance walked" in fig.axes[1].get_ylabel()    # the colour bar says what the colour is
    finally:
        plt.close(fig)


def test_the_basin_map_marks_the_fixed_point_and_the_refused_starts_apart_from_the_falls():
    rows = _rows(bn.AXES)
    fig = sw.figure(rows, list(bn.AXES), fixed_point={axis: 0.0 for axis in bn.AXES})
    try:
        ax = fig.axes[0]
        texts = [t.get_text() for t in ax.get_legend().get_texts()]
        assert any(t.startswith("fixed point") for t in texts), texts
        assert any(t.startswith("refused start") for t in texts), texts
        assert any(t.startswith("fell") for t in texts), texts
        lines = {line.get_label(): line for line in ax.get_lines()}
        star = next(v for k, v in lines.items() if k.startswith("fixed point"))
        assert (list(star.get_xdata()), list(star.get_ydata())) == ([1.0], [1.0])   # the centre cell, offsets 0
        refused = next(v for k, v in lines.items() if k.startswith("refused start"))
        fell = next(v for k, v in lines.items() if k.startswith("fell"))
        assert (list(refused.get_xdata()), list(refused.get_ydata())) == ([0], [0])
        assert (list(fell.get_xdata()), list(fell.get_ydata())) == ([2], [2])
        assert refused.get_marker() != fell.get_marker()
    finally:
        plt.close(fig)
