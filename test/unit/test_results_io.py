"""A run's results seen and loaded: ``SimulationResult.plot()`` and ``simulate --plot`` (the figure
``biped-sim inspect`` draws), ``biped_sim.load_run`` (a bag read back into named arrays) and the
typed values of its impact and event fields."""
from __future__ import annotations

import numpy as np
from PIL import Image

import biped_sim as bs
from biped_sim.cli import main as biped_sim

PANEL_TITLES = ("joint angles", "ground reaction force", "motor torques", "gait")


def distinct_colours(png):
    with Image.open(png) as im:
        pixels = np.asarray(im.convert("RGB")).reshape(-1, 3)
    return len(np.unique(pixels, axis=0))


def test_a_result_plots_the_figure_inspect_draws(tmp_path):
    result = bs.load_scene("walk").simulate(t_final=1.0)
    png = tmp_path / "walk.png"
    fig = result.plot(path=png)
    titles = [ax.get_title(loc="left") for ax in fig.axes]
    assert [any(t.startswith(p) for t in titles) for p in PANEL_TITLES] == [True] * 4, titles
    assert len(fig.axes[0].lines) >= 3 + len(result.impacts)           # q1, q2, q3 and an impact line each
    with Image.open(png) as im:
        assert im.size == (1080, 1080)
    assert distinct_colours(png) > 100                                  # lines drawn, not an empty canvas


def test_the_run_figure_draws_a_described_robot_with_its_names_and_links(tmp_path):
    """RABBIT (7 coordinates, 4 motors, knees): the panels name its joints and motors, each stick figure draws a
    leg as hip - knee - foot and the torso, and an impact is marked at its foot."""
    from biped_sim.engine.figure import impact_foot_x, run_figure
    rabbit = bs.load_model("rabbit")
    t = np.linspace(0.0, 1.0, 20)
    q0 = np.array([0.0, 0.75, 3.3, 2.9, 0.35, 0.1, 0.2])
    q = q0 + np.outer(t, [0.3, 0, 0.1, -0.1, 0.2, 0, 0])
    u = np.outer(np.sin(t), [1.0, -1.0, 0.5, 0.0])
    fig = run_figure(t, q, u, t, np.zeros((20, 2)), [(0.5, 2, q[10])], rabbit, "rabbit", frames=4,
                     path=tmp_path / "rabbit.png")
    labels = [line.get_label() for line in fig.axes[0].lines if not line.get_label().startswith("_")]
    assert labels[:5] == ["hip_1", "hip_2", "knee_1", "knee_2", "torso_pitch"]
    assert [line.get_label() for line in fig.axes[2].lines][:4] == ["hip_1", "hip_2", "knee_1", "knee_2"]
    legs = [line for line in fig.axes[3].lines if len(line.get_xdata()) == 3]    # hip, knee, foot
    assert len(legs) == 2 * 4
    x = impact_foot_x(rabbit, 2, q[10])
    assert np.isclose(x, rabbit.contact_position(q[10], 2)[0])
    assert distinct_colours(tmp_path / "rabbit.png") > 100


def test_simulate_plot_writes_scene_png_in_the_current_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert biped_sim(["simulate", "--scene", "walk", "--duration", "0.6", "--plot"]) == 0
    out = capsys.readouterr().out
    assert f"figure  {tmp_path / 'walk.png'}" in out, out
    assert (tmp_path / "walk.png").stat().st_size > 20_000 and distinct_colours(tmp_path / "walk.png") > 100


def recorded_walk(tmp_path, duration="1"):
    """A real bag on disk: ``biped-sim simulate --scene walk --record`` (lockstep, torques held 1 ms)."""
    assert biped_sim(["simulate", "--scene", "walk", "--duration", duration, "--record", str(tmp_path)]) == 0
    (bag,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    return bag


def test_load_run_reads_a_bag_back_into_the_arrays_of_a_result(tmp_path, monkeypatch):
    bag = recorded_walk(tmp_path)
    run = bs.load_run(bag)
    assert isinstance(run, bs.RecordedRun)
    result = bs.load_scene("walk").simulate(t_final=1.0)      # the same run, held torques as recorded
    assert run.t.shape == (1001,) and run.q.shape == run.dq.shape == (1001, 5) and run.u.shape == (1001, 2)
    assert run.grf.shape == (len(run.grf_t), 2) and set(run.stance_leg) <= {0, 1, 2}
    assert np.all(np.diff(run.t) > 0) and run.t[-1] == 1.0
    np.testing.assert_allclose(run.q[0], result.q[0], atol=1e-12)
    assert [e["time"] for e in run.impacts] == [e.time for e in result.impacts]
    assert [e["kind"] for e in run.events] == [e.kind for e in result.events]
    monkeypatch.setitem(__import__("sys").modules, "pandas", None)       # pandas absent: one clear line
    try:
        run.to_dataframe()
        raise AssertionError("to_dataframe without pandas did not raise")
    except ImportError as exc:
        assert "pip install pandas" in str(exc)


STRING_KEYS = {"kind", "warnings", "name", "message"}


def test_a_bags_impact_and_event_fields_are_typed_with_no_nan_strings(tmp_path):
    run = bs.load_run(recorded_walk(tmp_path))
    touchdown = run.impacts[0]
    assert isinstance(touchdown["time"], float) and isinstance(touchdown["foot"], int)
    assert isinstance(touchdown["energy_loss"], float) and touchdown["energy_loss"] > 0
    for key in ("q", "dq_minus", "dq_plus", "impulse"):
        assert isinstance(touchdown[key], list) and all(isinstance(v, float) for v in touchdown[key]), key
    scuffs = [e for e in run.events if e["kind"] == "scuff"]
    assert scuffs, [e["kind"] for e in run.events]             # the walk's swing foot scuffs (forward rule)
    for e in run.events:
        strings = {k: v for k, v in e.items() if isinstance(v, str) and k not in STRING_KEYS}
        assert not strings, (e["kind"], strings)                 # every number parsed, no "[nan, ...]"
        assert "nan" not in repr({k: v for k, v in e.items() if k not in STRING_KEYS}), e
    assert all(e["q"] == [] or len(e["q"]) == 5 for e in scuffs)


def stopped_run(duration=3.0):
    """The passive scene run past its 0.5 s: the robot falls and its impacts accumulate (Zeno, stopped
    at t ~ 1.56 s), its stick figures piled up where it fell."""
    return bs.load_scene("passive").simulate(t_final=duration)


def visible_label_boxes(fig):
    """The window boxes of the gait panel's time labels that are drawn (Agg renderer, after a draw)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    gait = [ax for ax in fig.axes if ax.get_title(loc="left").startswith("gait")][0]
    return [(txt.get_text(), txt.get_window_extent(renderer)) for txt in gait.texts if txt.get_visible()]


def test_the_figure_of_a_stopped_run_says_why_and_when_and_its_time_labels_do_not_overprint(tmp_path):
    result = stopped_run()
    assert result.status == "stopped" and result.events[-1].kind == "zeno"
    fig = result.plot(path=tmp_path / "passive.png")
    title = " ".join(fig.get_suptitle().split())
    assert f"stopped at t = {result.events[-1].time:.6g} s" in title, title
    assert "the impacts accumulate (Zeno behaviour)" in title, title
    boxes = visible_label_boxes(fig)
    assert len(boxes) >= 2 and f"{result.t[-1]:.2f} s" in [text for text, _box in boxes], boxes   # the end's time
    overprinted = [(a, b) for i, (a, box_a) in enumerate(boxes) for b, box_b in boxes[i + 1:] if box_a.overlaps(box_b)]
    assert not overprinted, overprinted


def test_simulate_plot_of_a_recorded_stopped_run_draws_its_samples_and_its_end(tmp_path):
    png = tmp_path / "passive.png"
    assert biped_sim(["simulate", "--scene", "passive", "--duration", "3", "--record", str(tmp_path),
                      "--plot", str(png)]) == 1                               # stopped: exit code 1
    (bag,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    with Image.open(png) as im:       # the time panels (the top 60 %) hold lines of hip 1's colour C0
        top = np.asarray(im.convert("RGB"))[: int(0.6 * im.size[1])].reshape(-1, 3)
    assert np.sum(np.all(top == (31, 119, 180), axis=1)) > 300          # an empty panel: the legend's, ~0
    from biped_sim.recording import inspect_bag
    fig = inspect_bag.plot(bag, tmp_path / "again.png")
    title = " ".join(fig.get_suptitle().split())
    assert "stopped at t = 1.5598" in title and "the impacts accumulate (Zeno behaviour)" in title, title


def test_inspects_readers_give_what_rclpy_gives_in_log_time_order(tmp_path):
    """load_run reads the file in its own order with the CDR readers of recording/cdr.py (no rclpy):
    every state, force and event field is the value rclpy's deserialiser gives, and the run is the
    one read in log-time order (a stopped run: impacts, a scuff, the Zeno stop on /diagnostics)."""
    from biped_sim.recording import bagio, inspect_bag, messages as M
    assert biped_sim(["simulate", "--scene", "passive", "--duration", "3", "--record", str(tmp_path)]) == 1
    (bag,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    readers = {"sensor_msgs/msg/JointState": (M.joint_state_values_cdr, M.joint_state_values),
               "geometry_msgs/msg/WrenchStamped": (M.wrench_values_cdr, M.wrench_values),
               "diagnostic_msgs/msg/DiagnosticArray": (M.event_values_cdr, M.event_values)}
    seen = dict.fromkeys(readers, 0)
    for _topic, typ, _t, data in bagio.messages(bag):
        if typ in readers:
            own, rclpy_values = readers[typ]
            assert own(typ, data) == rclpy_values(bagio.decode(typ, data))
            seen[typ] += 1
    assert seen["sensor_msgs/msg/JointState"] > 1000 and seen["diagnostic_msgs/msg/DiagnosticArray"] >= 7, seen
    in_file_order = inspect_bag.load_run(bag, max_points=None)
    in_log_order = inspect_bag._read_run(bag, None, log_time_order=True)
    for key in ("t", "q", "dq", "u", "leg", "grf_t", "grf"):
        np.testing.assert_array_equal(in_file_order[key], in_log_order[key], err_msg=key)
    for key in ("impacts", "events", "all_events", "counts", "first", "last", "stats", "commands", "params"):
        assert in_file_order[key] == in_log_order[key], key
    assert [e["kind"] for e in in_file_order["all_events"]][-2:] == ["touchdown", "zeno"]


def test_a_bag_whose_states_go_back_in_file_order_is_read_in_log_time_order(tmp_path):
    """A bag of another writer may store a topic's messages out of time order: load_run then reads it
    again in log-time order (the file's order would draw the time series back and forth)."""
    from biped_sim.recording import inspect_bag
    from biped_sim.recording.cdr import StateSerializer
    from biped_sim.recording.messages import JOINT_NAMES
    from biped_sim.recording.recorder import BagRecorder
    serializer = StateSerializer(JOINT_NAMES)
    rec = BagRecorder(tmp_path / "bag")
    rec.add_topic("/joint_states", "sensor_msgs/msg/JointState")
    for t_ns in (2_000_000, 1_000_000, 3_000_000):
        x = t_ns * 1e-9
        rec.write("/joint_states", serializer.joint_state(0, t_ns, "foot_1", [x, 1.0, 3.0, 3.0, 0.0], [0.0] * 5,
                                                         [0.0] * 5), t_ns)
    rec.close()
    run = inspect_bag.load_run(tmp_path / "bag")
    np.testing.assert_array_equal(run["t"], [0.001, 0.002, 0.003])
    assert run["stats"]["q_first"][0] == 0.001 and run["stats"]["q_last"][0] == 0.003
