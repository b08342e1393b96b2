"""The markers of the robot (recording/markers.py) from known states, and the stick figure they draw."""
from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("visualization_msgs")
from visualization_msgs.msg import Marker  # noqa: E402

from biped_sim.config import parameters as P  # noqa: E402
from biped_sim.config.scenes import load_scene  # noqa: E402
from biped_sim.engine.hybrid import HybridSimulator  # noqa: E402
from biped_sim.engine.model import BipedModel  # noqa: E402
from biped_sim.recording import markers as MK  # noqa: E402

MODEL = BipedModel()
Q = np.array([0.5, np.sqrt(3) / 2, np.radians(150), np.radians(120), np.radians(30)])  # docs/model.md, config 1


def by_id(array):
    return {m.id: m for m in array.markers}


def xz(point):
    assert point.y == 0.0        # the sagittal plane is drawn as x-z
    return np.array([point.x, point.z])


def test_the_stick_figure_is_the_models_feet_hip_and_torso():
    fig = MODEL.stick_figure(Q)
    assert np.array_equal(fig.foot_1, MODEL.foot_position(Q, 1))
    assert np.array_equal(fig.foot_2, MODEL.foot_position(Q, 2))
    assert np.array_equal(fig.hip, Q[:2])
    tip = fig.torso_tip - fig.hip      # l_torso long, at the absolute torso angle q3 from the vertical
    assert math.hypot(*tip) == pytest.approx(MODEL.parameters.l_torso, abs=1e-15)
    assert math.atan2(tip[0], tip[1]) == pytest.approx(Q[4], abs=1e-15)


def test_a_known_stance_state_gives_the_nine_markers_in_world_x_z():
    force, slope = [30.0, 180.0], 0.1
    arr = MK.marker_array(1.25, MODEL.stick_figure(Q), 1, force, slope, flash_at=(0.3, -0.03))
    m = by_id(arr)
    assert sorted(m) == list(range(1, 10))
    for mk in arr.markers:
        assert mk.header.frame_id == "world" and mk.ns == "biped_sim"
        assert (mk.header.stamp.sec, mk.header.stamp.nanosec) == (1, 250_000_000)
        assert mk.action == Marker.ADD
    types = {i: m[i].type for i in m}
    assert types == {MK.LEG_1: Marker.LINE_STRIP, MK.LEG_2: Marker.LINE_STRIP, MK.TORSO: Marker.LINE_STRIP,
                     MK.HIP: Marker.SPHERE, MK.FOOT_1: Marker.SPHERE, MK.FOOT_2: Marker.SPHERE,
                     MK.FORCE: Marker.ARROW, MK.GROUND: Marker.LINE_STRIP, MK.FLASH: Marker.SPHERE}
    hip, f1, f2 = Q[:2], MODEL.foot_position(Q, 1), MODEL.foot_position(Q, 2)
    assert [xz(p).tolist() for p in m[MK.LEG_1].points] == [hip.tolist(), f1.tolist()]
    assert [xz(p).tolist() for p in m[MK.LEG_2].points] == [hip.tolist(), f2.tolist()]
    assert xz(m[MK.TORSO].points[1]).tolist() == MODEL.stick_figure(Q).torso_tip.tolist()
    assert xz(m[MK.FOOT_1].pose.position).tolist() == f1.tolist()
    assert xz(m[MK.FOOT_2].pose.position).tolist() == f2.tolist()
    assert xz(m[MK.HIP].pose.position).tolist() == hip.tolist()
    # the stance foot (1) is marked red and larger, the swing foot grey
    c1, c2 = m[MK.FOOT_1].color, m[MK.FOOT_2].color
    assert (c1.r, c1.g, c1.b) == pytest.approx(MK.STANCE_FOOT_COLOUR[:3])
    assert (c2.r, c2.g, c2.b) == pytest.approx(MK.SWING_FOOT_COLOUR[:3])
    assert m[MK.FOOT_1].scale.x > m[MK.FOOT_2].scale.x
    # the arrow starts at the stance foot; its length is |F| / NEWTONS_PER_METRE, along F
    a, b = (xz(p) for p in m[MK.FORCE].points)
    assert a.tolist() == f1.tolist()
    assert np.linalg.norm(b - a) == pytest.approx(math.hypot(*force) / MK.NEWTONS_PER_METRE, rel=1e-12)
    assert (b - a) / np.linalg.norm(b - a) == pytest.approx(np.array(force) / math.hypot(*force), rel=1e-12)
    # the ground line falls in +x: y = -tan(slope) x, centred under the hip
    g0, g1 = (xz(p) for p in m[MK.GROUND].points)
    assert g0[1] == pytest.approx(-math.tan(slope) * g0[0]) and g1[1] == pytest.approx(-math.tan(slope) * g1[0])
    assert g1[1] < g0[1] and (g0[0] + g1[0]) / 2 == pytest.approx(hip[0])
    # the flash: where asked, with a lifetime
    assert xz(m[MK.FLASH].pose.position).tolist() == [0.3, -0.03]
    assert m[MK.FLASH].lifetime.nanosec == round(MK.FLASH_DURATION * 1e9)


def test_in_flight_and_without_an_impact_the_arrow_and_the_flash_are_deleted():
    m = by_id(MK.marker_array(0.5, MODEL.stick_figure(Q), 0, [99.0, 99.0]))
    assert m[MK.FORCE].action == Marker.DELETE and m[MK.FLASH].action == Marker.DELETE
    assert (m[MK.FORCE].type, m[MK.FLASH].type) == (Marker.ARROW, Marker.SPHERE)   # same id, same type
    assert m[MK.FOOT_1].color.r == m[MK.FOOT_2].color.r == pytest.approx(MK.SWING_FOOT_COLOUR[0])
    g0, g1 = (xz(p) for p in m[MK.GROUND].points)
    assert g0[1] == g1[1] == 0.0                      # flat ground at slope 0


def test_the_stream_sends_at_its_rate_and_flashes_each_touchdown():
    """A real walking run advanced period by period, the stream polled on the simulated clock."""
    scene = load_scene("walk")
    sim = HybridSimulator(**scene.engine_arguments(), keep_samples=False)
    ctrl = scene.controller()
    rate = 50.0
    stream = MK.MarkerStream(sim.model, 0.0, rate)
    sent, states = [], []
    while sim.t < 1.0:
        u = sim.command(ctrl)
        sim.advance_period(0.001, u=u)
        arr = stream.poll(sim.t, sim)
        if arr is not None:
            sent.append((sim.t, by_id(arr)))
            states.append((sim.q.copy(), sim.stance_leg))
    touchdowns = [e for e in sim.events if e.kind == "touchdown"]
    assert len(touchdowns) >= 2
    times = np.array([t for t, _ in sent])
    # one array per 1/rate of the clock, plus one at each touchdown (the flash shown at once)
    assert len(sent) == pytest.approx(1.0 * rate + len(touchdowns), abs=2)
    assert np.all(np.diff(times) > 0)
    for ev in touchdowns:
        foot = MODEL.foot_position(ev.q, ev.leg)
        flashing = [t for t, m in sent if m[MK.FLASH].action == Marker.ADD]
        first = next(t for t in flashing if t >= ev.time)
        assert first - ev.time < 0.0011         # the period of the touchdown
        m = dict(sent)[first]
        assert xz(m[MK.FLASH].pose.position) == pytest.approx(foot, abs=1e-12)
        # ... for FLASH_DURATION of the clock, then deleted
        assert all(t - ev.time <= MK.FLASH_DURATION + 0.0011 for t in flashing if t >= ev.time
                   and all(t < e.time for e in touchdowns if e.time > ev.time))
    # each array draws its own state: legs ending at the model's feet, the stance foot red
    for (_t, m), (q, leg) in zip(sent, states):
        assert xz(m[MK.LEG_1].points[1]).tolist() == MODEL.foot_position(q, 1).tolist()
        assert xz(m[MK.LEG_2].points[1]).tolist() == MODEL.foot_position(q, 2).tolist()
        assert m[MK.FOOT_1 if leg == 1 else MK.FOOT_2].color.r == pytest.approx(MK.STANCE_FOOT_COLOUR[0])
    assert {leg for _q, leg in states} == {1, 2}


def test_after_a_restart_the_new_runs_first_state_and_first_touchdown_are_drawn_at_once():
    """The node's ~/reset starts a new simulator: its events count from 0 again."""
    scene = load_scene("walk")
    ctrl = scene.controller()
    stream = MK.MarkerStream(MODEL, 0.0, 1.0)          # 1 Hz: only events and restarts send in between
    for _ in range(2):
        sim = HybridSimulator(**scene.engine_arguments(), keep_samples=False)
        stream.restart()
        assert stream.poll(0.0, sim) is not None                        # the new run's first state
        flashes = []
        while sim.t < 1.0:
            sim.advance_period(0.001, u=sim.command(ctrl))
            arr = stream.poll(0.01 + sim.t, sim)
            if arr is not None and by_id(arr)[MK.FLASH].action == Marker.ADD:
                flashes.append(sim.t)
        first = next(e for e in sim.events if e.kind == "touchdown")
        assert flashes and flashes[0] - first.time < 0.0011               # the first touchdown flashes


def test_markers_is_an_output_and_walk_has_it_a_scene_without_it_builds_no_stream():
    assert "markers" in P.OUTPUTS and "markers" not in P.BY_NAME["outputs"].default
    assert P.BY_NAME["marker_rate"].default == 30.0
    assert "markers" in load_scene("walk").outputs and "markers" in load_scene("slope").outputs
    assert "markers" not in load_scene("stance_fixed").outputs
    # markers need the ground force even where ground_reaction is not published
    params = P.validate(dict(outputs=["joint_states", "markers"]))
    assert P.engine_arguments(params)["compute_grf"] is True
    assert P.engine_arguments(P.validate(dict(outputs=["joint_states"])))["compute_grf"] is False


def test_the_foxglove_layout_shows_the_markers_and_plots_topics_the_node_publishes():
    import json
    from pathlib import Path
    layout = json.loads((Path(__file__).resolve().parents[2] / "foxglove" / "biped_sim_layout.json").read_text())
    panels = layout["configById"]

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])
    assert sorted(leaves(layout["layout"])) == sorted(panels)          # every panel placed, none missing
    assert panels["3D!biped"]["topics"]["/markers"]["visible"] is True
    topics = {"/" + k for k in P.OUTPUTS if k != "clock"} | {"/diagnostics"}
    used = {p["value"].split(".")[0] for k, c in panels.items() if k.startswith("Plot!") for p in c["paths"]}
    used |= {c["topicPath"] for k, c in panels.items() if k.startswith("RawMessages!")}
    assert used <= topics and {"/joint_states", "/ground_reaction", "/impact"} <= used


# -- issue 31, item 3: any chain drawn from its description -------------------------------------------------
RABBIT_Q = np.array([0.1, 0.75, 3.3, 2.9, 0.35, 0.1, 0.2])   # knees bent, the torso leaning forward


def forward_kinematics(desc, q):
    """{link: (joint, tip)} from the description's conventions (docs/models.md), written here from them: a
    link's absolute angle is its parent's + axis * q_joint + offset (the base's: its own), its joint sits
    at ``origin`` in the parent's frame, its tip ``length`` along its z axis (sin a, cos a)."""
    index = {link.name: 2 + i for i, link in enumerate(desc.links)}
    by_name = {link.name: link for link in desc.links}
    out = {}

    def place(name):
        if name in out:
            return out[name]
        link = by_name[name]
        if link.parent is None:
            angle, joint = link.sign * q[index[name]] + link.offset, np.array(q[:2], dtype=float)
        else:
            p_joint, _p_tip, p_angle = place(link.parent)
            ox, oz = link.origin
            joint = p_joint + ox * np.array([math.cos(p_angle), -math.sin(p_angle)]) + \
                oz * np.array([math.sin(p_angle), math.cos(p_angle)])
            angle = p_angle + link.sign * q[index[name]] + link.offset
        tip = joint + link.length * np.array([math.sin(angle), math.cos(angle)])
        out[name] = (joint, tip, angle)
        return out[name]
    for link in desc.links:
        place(link.name)
    return {name: (joint, tip) for name, (joint, tip, _angle) in out.items()}


def test_rabbit_is_drawn_from_its_descriptions_links_a_polyline_hip_knee_foot_per_leg():
    """No simulation: RABBIT (five links, knees) at a given q; each marker's points against forward
    kinematics written in this test from the description."""
    from biped_sim.config.models import load_model
    from biped_sim.engine.drawing import RobotDrawing
    rabbit = load_model("rabbit")
    fk = forward_kinematics(rabbit.description, RABBIT_Q)
    m = by_id(MK.marker_array(0.5, RobotDrawing(rabbit).figure(RABBIT_Q), 1, [10.0, 300.0]))
    assert sorted(m) == list(range(1, 10))
    for mid, side in ((MK.LEG_1, "1"), (MK.LEG_2, "2")):
        femur, tibia = fk[f"femur_{side}"], fk[f"tibia_{side}"]
        assert m[mid].type == Marker.LINE_STRIP and len(m[mid].points) == 3       # hip - knee - foot
        for got, want in zip(m[mid].points, (femur[0], femur[1], tibia[1])):
            np.testing.assert_allclose(xz(got), want, rtol=0, atol=1e-14)
        np.testing.assert_allclose(femur[1], tibia[0], atol=1e-15)                 # the knee joins them
        np.testing.assert_allclose(xz(m[MK.FOOT_1 if side == "1" else MK.FOOT_2].pose.position), tibia[1],
                                   atol=1e-14)
    torso = fk["torso"]
    np.testing.assert_allclose([xz(p) for p in m[MK.TORSO].points], [torso[0], torso[1]], rtol=0, atol=1e-14)
    np.testing.assert_allclose(xz(m[MK.HIP].pose.position), RABBIT_Q[:2], atol=0)
    knee_to_foot = np.linalg.norm(xz(m[MK.LEG_1].points[2]) - xz(m[MK.LEG_1].points[1]))
    assert knee_to_foot == pytest.approx(0.4, abs=1e-14)
    arrow = m[MK.FORCE]                                          # the force arrow starts at the stance foot
    np.testing.assert_allclose(xz(arrow.points[0]), fk["tibia_1"][1], atol=1e-14)


def test_the_three_link_markers_are_unchanged_by_the_chain_drawing():
    from biped_sim.engine.drawing import RobotDrawing
    via_stick = MK.marker_array(1.25, MODEL.stick_figure(Q), 2, [5.0, 150.0], 0.03, flash_at=(0.3, -0.03))
    via_chain = MK.marker_array(1.25, RobotDrawing(MODEL).figure(Q), 2, [5.0, 150.0], 0.03, flash_at=(0.3, -0.03))
    assert via_stick == via_chain
    leg1 = by_id(via_chain)[MK.LEG_1]
    assert leg1.type == Marker.LINE_STRIP and [xz(p).tolist() for p in leg1.points] == [
        Q[:2].tolist(), MODEL.foot_position(Q, 1).tolist()]
