"""The gait, sweep and basin tools for any robot: the section, the relabeling, stance states and the per-coordinate
columns as functions of the model (issue 31). The three-link biped given as a description must give the
BipedModel's numbers; RABBIT (7 coordinates, knees) has the sizes and the symmetry of its own description."""
import math

import numpy as np
import pytest

import biped_sim as bs
from biped_sim.analysis import gait as G
from biped_sim.config.models import generated_model

BIPED = bs.BipedModel()
THREE_LINK = generated_model("three_link")
RABBIT = bs.load_model("rabbit")


def test_stance_state_of_a_described_robot():
    """stance_state for a GeneratedModel: the three-link description gives the BipedModel's state (both stance
    legs, a foot off the origin); RABBIT's stance foot is at ``foot`` and at rest; a wrong length is one line
    that names the robot's joints."""
    joints, rates, foot = [3.0, 3.4, 0.2], [0.3, -0.5, 0.7], (0.3, -0.1)
    for leg in (1, 2):
        q_b, dq_b = bs.stance_state(BIPED, joints, rates, leg, foot=foot)
        q_g, dq_g = bs.stance_state(THREE_LINK, joints, rates, leg, foot=foot)
        assert np.max(np.abs(q_g - q_b)) < 1e-12 and np.max(np.abs(dq_g - dq_b)) < 1e-12
    for leg in (1, 2):
        q, dq = bs.stance_state(RABBIT, [3.3, 2.9, 0.2, 0.1, 0.1], [1.0, 2.0, 3.0, 4.0, 5.0], leg, foot=foot)
        assert q.shape == dq.shape == (7,) and q[2:].tolist() == [3.3, 2.9, 0.2, 0.1, 0.1]
        assert np.max(np.abs(RABBIT.contact_position(q, leg) - foot)) < 1e-12
        assert np.max(np.abs(RABBIT.contact_velocity(q, dq, leg))) < 1e-12
    with pytest.raises(ValueError) as err:
        bs.stance_state(RABBIT, [3.0, 3.4, 0.2], [0.0, 0.0, 0.0])
    assert str(err.value) == ("joints (q[2:] of rabbit: hip_1, hip_2, knee_1, knee_2, torso_pitch) must have shape "
                              "(5,), got shape (3,)")


def _height_gradient(model, joints, slope):
    """dh/dq[2:], exact: h = n . (p_2 - p_1) with the stance foot pinned, n = (tan(slope), 1)."""
    q, _ = bs.stance_state(model, joints, np.zeros(model.n - 2))
    if isinstance(model, bs.BipedModel):
        J1, J2 = model.foot_jacobian(q, 1), model.foot_jacobian(q, 2)
    else:
        J1, J2 = model.contact_jacobian(q, 1), model.contact_jacobian(q, 2)
    return np.array([math.tan(slope), 1.0]) @ (J2 - J1)[:, 2:]


def test_the_section_of_the_three_link_description_is_the_biped_models():
    """Section point, relabeling rows, height and tangent basis from the description of the three-link biped:
    the BipedModel's (RELABELED_ROWS, h, U) to 1e-12; the basis, by central differences of h (eps = 1e-7),
    to the roundoff of h over eps, and its gradient is the exact one."""
    assert G.section_rows(THREE_LINK) == G.section_rows(BIPED) == G.RELABELED_ROWS == [3, 2, 4, 8, 7, 9]
    assert G.section_size(THREE_LINK) == 6 and G.base_angle_index(THREE_LINK) == G.base_angle_index(BIPED) == 4
    assert G.actuated_coordinates(THREE_LINK) == G.actuated_coordinates(BIPED) == [2, 3]
    rng = np.random.default_rng(31)
    for _ in range(5):
        q, dq = rng.uniform(-1, 1, 5) + [0, 1, math.pi, math.pi, 0], rng.uniform(-2, 2, 5)
        assert np.array_equal(G.section_point(THREE_LINK, q, dq), G.section_point(BIPED, q, dq))
        R_q, R_dq = THREE_LINK.relabel(q, dq)
        assert np.array_equal(G.section_point(BIPED, q, dq), np.concatenate([R_q[2:], R_dq[2:]]))
        z = np.concatenate([q[2:], dq[2:]])
        for slope in (0.0, 0.0525):
            assert abs(G.section_height(THREE_LINK, z[:3], slope) - G.section_height(BIPED, z[:3], slope)) < 1e-12
            U_g, grad_g = G.section_basis(THREE_LINK, z, slope)
            U_b, grad_b = G.section_basis(BIPED, z, slope)
            assert U_g.shape == U_b.shape == (6, 5) and np.allclose(U_g.T @ U_g, np.eye(5), atol=1e-12)
            exact = _height_gradient(BIPED, z[:3], slope)
            assert np.max(np.abs(_height_gradient(THREE_LINK, z[:3], slope) - exact)) < 1e-12
            assert np.max(np.abs(grad_g - exact)) < 1e-8 and np.max(np.abs(grad_b - exact)) < 1e-8
            assert np.max(np.abs(U_g - U_b)) < 1e-8 and np.max(np.abs(U_g[:3].T @ exact)) < 1e-8


def _rabbit_double_support(rng):
    """Joints of RABBIT with both feet on flat ground: leg 2 the mirror image of leg 1 about the vertical through
    the hip (femur_2 at pi - d - k, tibia_2 at pi - d, where leg 1 has pi + d and pi + d + k)."""
    d, k, t = rng.uniform(-0.4, 0.4), rng.uniform(0.0, 0.6), rng.uniform(-0.3, 0.3)
    return np.array([math.pi + d - t, math.pi - d - k - t, k, k, t])


def test_rabbits_section_relabeling_and_height():
    """RABBIT: R R = I, the section point of a state with leg 2 in stance is R's stance-1 state (its contact 1
    is the old contact 2, the mirror image), z has 10 entries, the basis is 10 x 9, and h = 0 on the states
    stance_state builds with both feet down (either leg in stance)."""
    R = G.relabeling(RABBIT)
    assert R == (0, 1, 3, 2, 5, 4, 6) and [R[i] for i in R] == list(range(7))
    assert G.section_size(RABBIT) == 10 and G.section_rows(RABBIT) == [3, 2, 5, 4, 6, 10, 9, 12, 11, 13]
    assert G.base_angle_index(RABBIT) == 6 and G.actuated_coordinates(RABBIT) == [2, 3, 4, 5]
    rng = np.random.default_rng(32)
    for _ in range(5):
        joints, rates = _rabbit_double_support(rng), rng.uniform(-2, 2, 5)
        assert abs(G.section_height(RABBIT, joints)) < 1e-12
        q, dq = bs.stance_state(RABBIT, joints, rates, stance_leg=2)     # leg 2 has touched down
        assert np.max(np.abs(RABBIT.contact_position(q, 1)[1])) < 1e-12  # both feet on the ground
        z = G.section_point(RABBIT, q, dq)
        Rq, Rdq = RABBIT.relabel(q, dq)
        assert np.array_equal(z, np.concatenate([Rq[2:], Rdq[2:]]))
        assert np.array_equal(np.concatenate(RABBIT.relabel(Rq, Rdq)), np.concatenate([q, dq]))
        assert np.max(np.abs(RABBIT.contact_position(Rq, 1) - RABBIT.contact_position(q, 2))) < 1e-12
        assert abs(G.section_height(RABBIT, z[:5])) < 1e-12
        q1, dq1 = bs.stance_state(RABBIT, z[:5], z[5:], stance_leg=1)   # the state the step map starts from
        assert np.max(np.abs(q1 - (Rq - [*RABBIT.contact_position(q, 2), 0, 0, 0, 0, 0]))) < 1e-12
        assert np.max(np.abs(dq1 - Rdq)) < 1e-12
        U, grad = G.section_basis(RABBIT, z)
        assert U.shape == (10, 9) and np.allclose(U.T @ U, np.eye(9), atol=1e-12)
        assert np.max(np.abs(grad - _height_gradient(RABBIT, z[:5], 0.0))) < 1e-8


def test_find_gait_takes_a_described_robot():
    """bs.find_gait(model, controller, z0) with a GeneratedModel: z0 sized 2 (n - 2) (a wrong one is one line
    naming RABBIT's joints); the exact Jacobian is at hand for it (no fallback to differences), and the gait of a
    user's law without a ``jacobian`` says its law was differentiated by central differences."""
    def no_torque(t, q, dq, stance_leg):
        return [0.0] * 4
    with pytest.raises(ValueError, match=r"^z0 must be 10 finite numbers, the post-impact state \[hip_1, hip_2, "
                                         r"knee_1, knee_2, torso_pitch, dhip_1, .*\(leg 1 the new stance leg\), "
                                         r"got \[0\.0, 0\.0, 0\.0, 0\.0, 0\.0, 0\.0\]$"):
        bs.find_gait(RABBIT, no_torque, z0=np.zeros(6))
    assert not hasattr(G, "exact_jacobian_unavailable")
    z0 = np.concatenate([_rabbit_double_support(np.random.default_rng(1)), np.zeros(5)])
    g = G.Gait(z=z0, step_length=0.4, step_period=0.5, speed=0.8, cost_of_transport=0.1, motor_work=1.0,
               eigenvalues=np.array([0.5] * 9), residual=1e-12, newton_iterations=3, max_torque=10.0, slope=0.0,
               law_derivative="central differences of the law", step_map=G.StepMap(RABBIT, no_torque))
    text = G.format_gait(g)
    assert ("Jacobian  exact (variational equations and saltation matrix; law derivative: central differences of "
            "the law)") in text
    assert "(hip_1, hip_2, knee_1, knee_2, torso_pitch and their rates after impact, leg 1 the new stance leg)" in text


@pytest.fixture(scope="module")
def rabbit_gait():
    return bs.find_gait("rabbit")


def test_rabbits_gait_by_newton_on_the_exact_jacobian(rabbit_gait):
    """bs.find_gait("rabbit"): RABBIT's gait under its law (the law's exact derivative), the period and step length
    of docs/models.md's harness (0.5890 s, 0.3914 m), 9 multipliers; the exact Jacobian at rtol 1e-10 is the one at
    1e-12 to 5e-8 (its error at the gait's tolerance: a last bit moved in the start moves it between 5e-9 and
    1.5e-8). A user's law (the same, without its ``jacobian``) gets central differences of the law and says so."""
    g = rabbit_gait
    assert g.law_derivative == "exact" and g.jacobian_method == G.EXACT and g.residual < 1e-9
    assert abs(g.period - 0.5890) < 5e-5 and abs(g.step_length - 0.3914) < 5e-5
    assert g.multipliers.shape == (9,) and g.stable and abs(g.multipliers[0] - 0.6841) < 1e-4
    assert "Jacobian  exact (variational equations and saltation matrix; law derivative: exact)" in G.format_gait(g)
    smap = g.step_map
    options = {k: v for k, v in smap.kw.items() if k not in ("rtol", "atol", "method", "max_events", "phases")}
    fine = G.StepMap(smap.model, smap.controller, rtol=1e-12, atol=1e-12, **options)
    U, _ = fine.basis(g.z)
    A = fine.jacobian(g.z, U)
    assert np.max(np.abs(A - g.jacobian)) < 5e-8
    ctrl = smap.controller

    def user_law(t, q, dq, stance_leg):
        return ctrl(t, q, dq, stance_leg)
    J, how = G.StepMap(smap.model, user_law, **options).full_jacobian(g.z)
    assert how == "central differences of the law" and J.shape == (10, 10)


def test_rabbits_differences_agree_with_its_exact_jacobian(rabbit_gait):
    """RABBIT's gait: ``jacobian_fd()``'s defaults (central differences of the same step map, Richardson from steps
    of 1e-3 and 5e-4, the runs at rtol 1e-12) agree with the exact Jacobian to 1e-6 relative, in the Jacobian and
    in the multipliers (issue 32's check), which a single step of 1e-6 at the gait's rtol 1e-10 misses by far: the
    step map's own error over the step."""
    g = rabbit_gait
    A_fd = g.jacobian_fd()
    assert np.max(np.abs(A_fd - g.jacobian)) < 1e-6 * np.max(np.abs(g.jacobian))
    fd = np.linalg.eigvals(A_fd)
    assert np.max(np.abs(np.sort_complex(fd) - np.sort_complex(g.multipliers))) < 1e-6 * abs(g.multipliers[0])


def test_sweep_columns_are_sized_from_the_robot(tmp_path):
    """A sweep's per-coordinate columns q_end[i], dq_end[i] run over the robot's n coordinates: a run's row has n
    of each (NaN for a run that did not run: RABBIT's 7, the three-link's 5); a CSV of robots of different sizes
    runs to the largest n and leaves a smaller robot's cells empty; the columns' line names each robot's q."""
    import csv

    from biped_sim.analysis import sweep as sw
    rabbit_start = {"robot": "rabbit", "initial_q": [0.0997086196481708, 0.7935100972856273, 3.241592653589793,
                                                     2.941592653589793, -0.05, 0.5, 0.05], "initial_dq": [0.0] * 7}
    refused = sw.run_one("walk", rabbit_start, 0.1)       # the walk scene's law is the three-link robots'
    assert refused["status"] == "error" and len(refused["q_end"]) == len(refused["dq_end"]) == 7, refused["message"]
    assert sw.run_one("walk", {"robot": "rabbit"}, 0.1)["q_end"] == []    # no initial state of 7: the scene fails
    bad_start = sw.run_one("walk", {"initial_q[1]": -1.0}, 0.1)
    assert bad_start["status"] == "error" and len(bad_start["q_end"]) == 5
    rows = [dict(index=0, robot="three_link", **dict(bad_start, q_end=[0.5] * 5, dq_end=[1.5] * 5)),
            dict(index=1, **{k: v for k, v in refused.items() if k not in ("initial_q", "initial_dq")})]
    out = tmp_path / "mixed.csv"
    sw.write_csv(rows, ["robot"], out)
    with open(out) as f:
        table = list(csv.DictReader(f))
    assert [c for c in table[0] if "q_end[" in c] == [f"q_end[{i}]" for i in range(7)] + [f"dq_end[{i}]" for i in
                                                                                          range(7)]
    assert [table[0][f"q_end[{i}]"] for i in range(7)] == ["0.5"] * 5 + ["", ""]
    assert [table[0][f"dq_end[{i}]"] for i in range(7)] == ["1.5"] * 5 + ["", ""]
    assert [table[1][f"dq_end[{i}]"] for i in range(7)] == ["nan"] * 7
    assert sw.csv_columns(["kp"], 5)[-10:] == [f"q_end[{i}]" for i in range(5)] + [f"dq_end[{i}]" for i in range(5)]
    sw.write_csv([], ["kp"], tmp_path / "none.csv", 7)       # no rows (a sweep stopped at once): the robot's size
    assert (tmp_path / "none.csv").read_text().rstrip().endswith("q_end[6],dq_end[0],dq_end[1],dq_end[2],dq_end[3],"
                                                                   "dq_end[4],dq_end[5],dq_end[6]")
    robots = sw.grid_robots("walk", {"robot": ["three_link", "rabbit", "three_link"], "kp": [1.0, 2.0]})
    assert robots == {"three_link": BIPED_NAMES, "rabbit": RABBIT.coordinates}
    line = sw.columns_line(robots)
    assert line.startswith("q_end[i], dq_end[i] (i = 0..6) are q and dq of three_link: base_x, base_y, hip_1, hip_2, "
                           "torso_pitch; rabbit: base_x, base_y, hip_1, hip_2, knee_1, knee_2, torso_pitch")
    assert "the grid mixes robots of different sizes" in line and "\n" not in line
    assert sw.columns_line(sw.grid_robots("compass_gait", {})) == ("q_end[i], dq_end[i] (i = 0..4) are q and dq of "
                                                                   "compass_gait: base_x, base_y, hip_1, hip_2, "
                                                                   "hip_pitch")


BIPED_NAMES = ("base_x", "base_y", "hip_1", "hip_2", "torso_pitch")


def test_the_basin_slice_of_any_robot():
    """The basin's initial states around z*: the three-link description's are the BipedModel's; RABBIT's keep
    contact 1 at the origin and at rest, with the offsets on the rates of hip_1 and of torso_pitch only."""
    from biped_sim.analysis.basin import slice_states
    z = np.array([2.79198, 3.190733, 0.150236, 0.635243, 0.467154, 0.307487])
    offsets = [[-1.0, 0.0, 1.0], [-2.0, 2.0]]
    q_b, points_b, dq_b = slice_states(BIPED, z, offsets)
    q_g, points_g, dq_g = slice_states(THREE_LINK, z, offsets)
    assert points_b == points_g == [(a, b) for a in offsets[0] for b in offsets[1]]
    assert np.max(np.abs(q_b - q_g)) < 1e-12 and np.max(np.abs(np.array(dq_b) - dq_g)) < 1e-12
    zr = np.concatenate([_rabbit_double_support(np.random.default_rng(3)), [0.6, 0.4, -0.2, 0.1, 0.3]])
    q0, points, initial_dq = slice_states(RABBIT, zr, offsets)
    assert np.max(np.abs(RABBIT.contact_position(q0, 1))) < 1e-12 and len(initial_dq) == 6
    for (d_st, d_torso), dq in zip(points, initial_dq):
        assert np.max(np.abs(RABBIT.contact_velocity(q0, dq, 1))) < 1e-12
        assert np.allclose(np.array(dq[2:]) - zr[5:], [d_st, 0.0, 0.0, 0.0, d_torso], atol=1e-15)


def test_cli_sweep_and_gait_name_the_robots_coordinates(tmp_path, capsys):
    """biped-sim sweep's last line names the CSV's q_end[i], dq_end[i] by the scene robot's coordinates (the
    compass gait's base angle is hip_pitch)."""
    from biped_sim.cli import main as cli_main
    out = tmp_path / "cg.csv"
    assert cli_main(["sweep", "compass_gait", "--set", "slope=0.0525", "--duration", "0.2", "--workers", "1",
                     "--no-progress", "-o", str(out)]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last == ("q_end[i], dq_end[i] (i = 0..4) are q and dq of compass_gait: base_x, base_y, hip_1, hip_2, "
                    "hip_pitch")
    assert out.read_text().splitlines()[0].endswith(",q_end[0],q_end[1],q_end[2],q_end[3],q_end[4],dq_end[0],"
                                                    "dq_end[1],dq_end[2],dq_end[3],dq_end[4]")
    assert cli_main(["gait", "--scene", "compass_gait"]) == 1      # (the free hip link's multipliers at 1)
    text = capsys.readouterr().out      # a three-link chain (a BipedModel) keeps the names docs/gait.md uses
    assert "(q_st, q_sw, q3, dq_st, dq_sw, dq3 after impact)" in text and "step period  0.7345 s" in text
