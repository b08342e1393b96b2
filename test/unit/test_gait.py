"""The periodic gait of the walk scene: fixed point, figures and Poincare eigenvalues (issue 6)."""
import numpy as np
import pytest

from biped_sim.analysis.gait import StepMap, scene_gait
from biped_sim.cli import main as cli_main
from biped_sim.config.scenes import load_scene


@pytest.fixture(scope="module")
def walk_gait():
    return scene_gait(load_scene("walk"))


def test_walk_has_a_stable_periodic_gait(walk_gait):
    g = walk_gait
    assert g.residual < 1e-8
    assert g.eigenvalues.shape == (5,)              # the 5-dimensional section
    assert np.all(np.abs(g.eigenvalues) < 1.0) and g.stable
    assert 0.3 < g.step_length < 0.5 and 0.4 < g.step_period < 0.6
    assert g.speed == pytest.approx(g.step_length / g.step_period)
    assert 0.0 < g.cost_of_transport < 1.0
    assert g.max_torque < load_scene("walk").controller_params["torque_limit"]


def test_fixed_point_is_on_the_section_and_maps_to_itself(walk_gait):
    s = load_scene("walk")
    smap = StepMap(s.engine_arguments()["model"], s.controller())
    z = walk_gait.z
    assert abs(smap.height(z[0:3])) < 1e-9          # both feet on the ground after the impact
    assert np.linalg.norm(smap(z) - z) < 1e-8


def test_the_simulation_converges_to_the_fixed_point(walk_gait):
    """The headless run (continuous and held torques) settles on the gait that Newton finds."""
    s = load_scene("walk")
    for hold in (False, True):
        r = s.simulate(hold=hold, t_final=10.0 if not hold else 5.0)
        periods = np.diff([e.time for e in r.impacts])
        tol = 2e-3 if not hold else 5e-3
        assert periods[-1] == pytest.approx(walk_gait.step_period, abs=tol)
    # the largest eigenvalue is the rate at which the step period settles
    ratio = np.abs(np.diff(periods[-6:]))
    assert np.all(ratio[1:] <= ratio[:-1] * 1.05)


def test_the_section_removes_the_flow_direction(walk_gait):
    """The full 6 x 6 Jacobian has one more eigenvalue, zero; the other five are those of the section."""
    s = load_scene("walk")
    smap = StepMap(s.engine_arguments()["model"], s.controller())
    z, eps = walk_gait.z, 1e-6
    J = np.column_stack([(smap(z + eps * e) - smap(z - eps * e)) / (2 * eps) for e in np.eye(6)])
    full = np.sort(np.abs(np.linalg.eigvals(J)))
    assert full[0] < 1e-4
    assert np.allclose(full[1:], np.sort(np.abs(walk_gait.eigenvalues)), rtol=1e-3, atol=1e-5)


def test_the_exact_multipliers_agree_with_finite_differences(walk_gait):
    """The walk scene's gait: the exact Jacobian (variational equations, saltation matrix of the impact) and
    central differences of the same step map (``jacobian_fd()``'s defaults: Richardson-extrapolated, the runs at
    rtol 1e-12) give the same multipliers to 1e-6 (issue 32) and the same Jacobian to 2e-8 relative, which a
    single step of 1e-6 at the gait's rtol 1e-10 misses: the step map's own error over the step."""
    g = walk_gait
    assert g.jacobian_method == "exact" and g.jacobian.shape == (5, 5)
    assert np.array_equal(g.multipliers, g.eigenvalues) and g.period == g.step_period and g.fixed_point is g.z
    A_fd = g.jacobian_fd()
    assert np.max(np.abs(g.jacobian - A_fd)) < 2e-8 * np.max(np.abs(g.jacobian))
    fd = np.linalg.eigvals(A_fd)
    assert np.max(np.abs(np.sort_complex(g.multipliers) - np.sort_complex(fd))) < 1e-6


def test_jacobian_fd_refuses_a_bad_step_or_tolerance_in_one_line(walk_gait):
    for kw, words in ((dict(eps=0.0), "eps must be a positive number"), (dict(eps=float("nan")), "eps must be"),
                      (dict(rtol=1e-20), r"rtol must be a number in \[2.22e-14, 1\)"), (dict(rtol="1e-12"), "rtol")):
        with pytest.raises(ValueError, match=f"^jacobian_fd: {words}") as exc:
            walk_gait.jacobian_fd(**kw)
        assert "\n" not in str(exc.value)


def test_the_compass_gaits_differences_agree_with_its_exact_jacobian():
    """The compass gait's step map has a large third derivative (a single step of 1e-3 is far off):
    ``jacobian_fd()``'s defaults (Richardson from steps of 1e-3 and 5e-4) agree with the exact Jacobian to 1e-7
    relative and in the legs' three multipliers to 1e-6 (issue 32's check); the torso rotor's two are a Jordan
    block at 1, which rounding splits by the square root of an error in A, so they are checked to be at 1."""
    from biped_sim.analysis.gait import compass_gait
    g = compass_gait()
    A_fd = g.jacobian_fd()
    assert np.max(np.abs(A_fd - g.jacobian)) < 1e-7 * np.max(np.abs(g.jacobian))
    fd = np.linalg.eigvals(A_fd)
    by_distance_to_1 = sorted(fd, key=lambda m: abs(m - 1.0))
    assert np.allclose(by_distance_to_1[:2], 1.0, atol=1e-5)
    legs = sorted(g.multipliers, key=lambda m: abs(m - 1.0))[2:]
    for m in legs:
        assert min(abs(f - m) for f in by_distance_to_1[2:]) < 1e-6 * np.max(np.abs(g.multipliers))


def test_find_gait_takes_a_scene_name_or_a_model_and_controller(walk_gait):
    import biped_sim as bs
    s = load_scene("walk")
    kw = s.engine_arguments()
    g = bs.find_gait(kw["model"], s.controller(), z0=walk_gait.z, touchdown_rule=kw["touchdown_rule"],
                     jacobian="central differences")
    assert g.jacobian_method == "central differences"
    assert np.allclose(g.fixed_point, walk_gait.fixed_point, atol=1e-8)
    assert np.allclose(g.multipliers, walk_gait.multipliers, atol=1e-6)
    with pytest.raises(ValueError, match="needs a controller"):
        bs.find_gait(kw["model"])


def test_scene_without_impacts_is_refused():
    with pytest.raises(ValueError, match="needs the 'impact' phase"):
        scene_gait(load_scene("stance_fixed"))


def test_a_step_with_the_legs_together_is_no_gait():
    """The passive scene without torque has no gait: its steps end with the swing foot on the ground where the
    stance foot is (the legs together, q_st = q_sw), which is no step: NoGait in one line, not a 'fixed point'
    of zero length and period (which Newton's method on the exact Jacobian otherwise reaches)."""
    from biped_sim.analysis.gait import NoGait
    from biped_sim.config.controllers import no_torque
    with pytest.raises(NoGait, match="the legs together"):
        scene_gait(load_scene("passive"), controller=no_torque)


def test_cli_gait(capsys):
    assert cli_main(["gait", "--scene", "slope"]) == 0
    out = capsys.readouterr().out
    for word in ("step length", "speed", "step period", "cost of transport", "eigenvalues", "stable  yes",
                 "Jacobian  exact"):
        assert word in out
    assert cli_main(["gait", "--scene", "slope", "--jacobian", "fd"]) == 0
    assert "Jacobian  central differences" in capsys.readouterr().out


def test_the_compass_gait_has_the_reference_multipliers():
    """The passive compass gait (Drake's CompassGait defaults) as a special case of the model: its multipliers
    -0.2022161 +- 0.5434150j and 0.1313867 (issue 32's reference, 7 digits), and the torso rotor's two at 1."""
    from biped_sim.analysis.gait import compass_gait
    g = compass_gait()
    assert g.residual < 1e-9 and g.law_derivative == "central differences of the law"
    legs = sorted(g.multipliers, key=lambda m: abs(m - 1.0))[2:]
    reference = [-0.2022161 + 0.5434150j, -0.2022161 - 0.5434150j, 0.1313867]
    for r in reference:
        assert min(abs(m - r) for m in legs) < 1e-7
    assert np.allclose(sorted(g.multipliers, key=lambda m: abs(m - 1.0))[:2], 1.0, atol=1e-5)


def test_the_gait_moves_with_the_controller_gains_as_its_exact_derivative_says(walk_gait):
    """Gait.derivatives: the fixed point's and the period's derivatives by the walking law's gains, exact,
    against central differences of the fixed points Newton finds with each gain moved (to 1e-5 relative:
    Newton's residual, ~1e-12, over the step); l_leg, which moves the section, is refused."""
    import copy

    from biped_sim.analysis.gait import find_gait
    g = walk_gait
    d = g.derivatives(["controller.step_angle", "controller.kp", "m_torso"])
    assert d.fixed_point.shape == (6, 3) and d.period.shape == (3,) and d.gain_derivative == "exact"
    s = load_scene("walk")
    kw = s.engine_arguments()
    for j, (name, eps) in enumerate((("step_angle", 1e-5), ("kp", 1e-2))):
        found = []
        for sign in (1, -1):
            c = copy.copy(g.step_map.controller)
            setattr(c, name, getattr(c, name) + sign * eps)
            found.append(find_gait(kw["model"], c, z0=g.z, touchdown_rule=kw["touchdown_rule"], tol=1e-12,
                                   warmup_steps=0))
        dz = (found[0].z - found[1].z) / (2 * eps)
        dT = (found[0].period - found[1].period) / (2 * eps)
        assert np.max(np.abs(d.fixed_point[:, j] - dz)) < 1e-5 * np.max(np.abs(dz))
        assert abs(d.period[j] - dT) < 1e-5 * abs(dT)
    with pytest.raises(ValueError, match="l_leg moves the section"):
        g.derivatives(["l_leg"])


def test_the_docs_table_has_the_multipliers_of_every_shipped_gait():
    """docs/gait.md's table of the shipped gaits (tools/docs_figures.py gait) has a row for every scene with a
    gait, the compass gait's included (no torque), whose multipliers are the ones its command finds, and no row
    for a scene without one."""
    import re
    from pathlib import Path

    from biped_sim.config.controllers import no_torque
    from biped_sim.config.scenes import available_scenes
    page = (Path(__file__).resolve().parents[2] / "docs" / "gait.md").read_text()
    table = page.split("<!-- docs-figures: multipliers -->")[1].split("<!-- /docs-figures -->")[0]
    rows = {m[1]: m for m in re.finditer(r"^\| (\w+) \| `biped-sim gait --scene \1( --controller none)?` \| "
                                         r"([^|]+) \|", table, re.M)}
    for name in available_scenes():
        scene = load_scene(name)
        passive = scene.controller_params is None
        try:
            g = scene_gait(scene, controller=no_torque if passive else None)
        except ValueError:
            assert name not in rows
            continue
        assert bool(rows[name][2]) == passive
        printed = [complex(v.replace(" ", "")) for v in rows[name][3].split(", ")]
        assert np.max(np.abs(np.sort_complex(printed) - np.sort_complex(g.multipliers))) < 1e-6
    assert "compass_gait" in rows


def test_the_stable_line_says_what_the_multipliers_say(walk_gait):
    """format_gait's last line: 'yes (all inside ...)' for a stable gait, 'NO (not all inside ...)' when a
    multiplier is on or outside the unit circle (the compass gait's neutral rotor)."""
    from dataclasses import replace

    from biped_sim.analysis.gait import format_gait
    assert format_gait(walk_gait).splitlines()[-1].split(None, 1)[1].startswith("yes (all inside the unit circle")
    neutral = replace(walk_gait, eigenvalues=np.array([1.0000002, 0.9999998, 0.5, 0.1, 0.01]))
    last = format_gait(neutral).splitlines()[-1]
    assert "NO (not all inside the unit circle: max |lambda| = 1.0000)" in last, last
    # the two at 1 are named apart: the legs' gait is stable, the family along the rotor neutral
    assert "; 2 at 1 (neutral: the gaits form a family along them" in last, last
    assert "the other 3 inside: max |lambda| = 0.5000" in last, last


def test_a_scene_without_controller_has_the_passive_gait(capsys):
    """A scene without a walk_controller section runs with u = 0, so its gait is the passive one:
    bs.find_gait("compass_gait") and 'biped-sim gait --scene compass_gait' find the compass gait's limit cycle
    (the legs' multipliers of issue 32's reference), the law's derivative exact (zero); the passive scene's
    steps end with the legs together: no gait, in one line."""
    import biped_sim as bs
    from biped_sim.analysis.gait import NoGait
    g = bs.find_gait("compass_gait")
    assert g.law_derivative == "exact" and abs(g.period - 0.734460621336) < 1e-8
    for r in (-0.2022161 + 0.5434150j, 0.1313867):
        assert min(abs(m - r) for m in g.multipliers) < 1e-6
    with pytest.raises(NoGait, match="the legs together"):
        scene_gait(load_scene("passive"))
    assert cli_main(["gait", "--scene", "compass_gait"]) == 1     # the torso rotor's neutral multipliers at 1
    out = capsys.readouterr().out
    assert "step period  0.7345 s" in out and "law derivative: exact" in out, out


def test_the_derivatives_of_a_gait_with_a_neutral_direction():
    """The compass gait's torso rotor angle is neutral (a multiplier at 1): its gaits are a family along the null
    space n of I - A. Gait.derivatives gives the member without a component along n, which central differences
    of Newton's fixed points confirm once their own component along n is removed; and the period's."""
    import biped_sim as bs
    g = bs.find_gait("compass_gait")
    d = g.derivatives(["m_leg"])
    U, _ = g.step_map.basis(g.z)
    A = U.T @ g.step_map.full_jacobian(g.z)[0] @ U
    n = U @ np.linalg.svd(np.eye(5) - A)[2][-1]           # the neutral direction on the section
    assert abs(n @ d.fixed_point[:, 0]) < 1e-9 and d.neutral == 1
    e = 1e-3
    gp, gm = (bs.find_gait(load_scene("compass_gait", overrides={"model.m_leg": 5.0 + s * e})) for s in (1, -1))
    fd = (gp.fixed_point - gm.fixed_point) / (2 * e)
    fd -= n * (n @ fd)
    assert np.allclose(d.fixed_point[:, 0], fd, rtol=0, atol=3e-6), (d.fixed_point[:, 0], fd)
    assert abs(d.period[0] - (gp.period - gm.period) / (2 * e)) < 1e-6


def test_newton_does_not_wander_along_a_neutral_direction():
    """Newton's steps on the compass gait, whose rotor angle is neutral (A - I singular): the least-norm step
    keeps the rotor angle where the start has it (0) and converges, at a tight tolerance, to issue 32's
    reference limit cycle."""
    import biped_sim as bs
    g = bs.find_gait("compass_gait", tol=1e-11)
    assert abs(g.fixed_point[2]) < 1e-9 and g.residual < 1e-11
    # the legs' angle just after touchdown: 2 stance - 2 slope of issue 32's reference (stance = -0.218774617980)
    assert abs(g.fixed_point[0] - g.fixed_point[1] - (2 * -0.218774617980 - 2 * 0.0525)) < 1e-9
    assert abs(g.period - 0.734460621336) < 1e-10


def test_basin_of_a_scene_without_a_gait_says_so_in_one_line(tmp_path, capsys):
    """biped-sim basin of the passive scene (u = 0: its steps end with the legs together) names the scene and
    says it has no periodic gait, one line, exit 2, before any run."""
    assert cli_main(["basin", "passive", "-o", str(tmp_path / "basin.csv"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scene 'passive' has no periodic gait to take the basin of: " in err[0], err
    assert not (tmp_path / "basin.csv").exists()


def test_a_scenes_gait_takes_its_scuff_rules():
    """scene_gait runs the step map under the scene's scuff_rule and scuff_depth, as the scene's runs: the
    compass gait scene with scuff_rule 'behind' is compass_gait()'s gait, and a scuff_depth the mid-stance
    scuff exceeds stops every step (no gait)."""
    from biped_sim.analysis.gait import NoGait, compass_gait
    g = scene_gait(load_scene("compass_gait", overrides={"scuff_rule": "behind"}))
    assert g.step_map.kw["scuff_rule"] == "behind"
    assert abs(g.period - compass_gait().period) < 1e-9
    with pytest.raises(NoGait):
        scene_gait(load_scene("compass_gait", overrides={"scuff_depth": 1e-4}))


def test_the_compass_gaits_multipliers_along_its_slope_reach_the_period_doubling():
    """gaits_along on a scene without a controller (u = 0, the scene's scuff rules): the compass gait continued
    down steeper slopes, one real multiplier past -1 between 0.075 and 0.0775 rad (a period doubling)."""
    from biped_sim.analysis.gait import gaits_along
    (_, g0, why0), (_, g1, why1), (_, g2, why2) = gaits_along("compass_gait", "slope", [0.0525, 0.075, 0.0775])
    assert g0 is not None and g1 is not None and g2 is not None, (why0, why1, why2)
    assert abs(g0.period - 0.734460621336) < 1e-8
    legs = [np.sort_complex(g.multipliers[np.abs(g.multipliers - 1.0) > 1e-3]) for g in (g1, g2)]
    assert -1.0 < legs[0][0].real < -0.85 and abs(legs[0][0].imag) < 1e-12
    assert -1.1 < legs[1][0].real < -1.0 and abs(legs[1][0].imag) < 1e-12


def test_gait_derivatives_take_one_name_as_a_string(walk_gait):
    d = walk_gait.derivatives("controller.kp")
    assert d.parameters == ("controller.kp",) and d.period.shape == (1,)
    assert d.period[0] == walk_gait.derivatives(["controller.kp"]).period[0]


def test_newton_that_does_not_converge_is_no_gait_and_a_bad_start_is_named():
    """find_gait returns a gait only where Newton's method reached tol: one iteration from the walk scene's start
    is NoGait naming the residual; a z0 of another length, and tol or max_iter out of range, are one line."""
    import biped_sim as bs
    from biped_sim.analysis.gait import NoGait
    with pytest.raises(NoGait, match=r"did not converge in 1 iterations: \|P\(z\) - z\| = "):
        bs.find_gait("walk", max_iter=1)
    for kwargs, message in ((dict(z0=[1.0, 2.0, 3.0]), r"z0 must be 6 finite numbers.*got \[1.0, 2.0, 3.0\]"),
                            (dict(tol=-1.0), "tol must be a positive number"),
                            (dict(max_iter=0), "max_iter a positive integer")):
        with pytest.raises(ValueError, match=message):
            bs.find_gait("walk", **kwargs)
