"""Robot descriptions (YAML and planar URDF), the generic generator, the shipped models and load_model.

docs/models.md. The generic generator's three-link output agrees with the engine's own closed forms; each
shipped model's generated D, C dq + G and contact Jacobians agree with Pinocchio's from the same URDF (when
Pinocchio is installed: ``make bench`` installs it); the compass gait scene walks 10 s passively.
"""
import importlib.util
import math

import numpy as np
import pytest

import biped_sim as bs
from biped_sim.config import models
from biped_sim.engine.compiled import gen
from biped_sim.engine.description import DescriptionError, description_from_dict, description_from_urdf, to_urdf
from biped_sim.engine.generated_model import EngineCannotRun
from biped_sim.engine.model import BipedModel

THREE_LINK = {
    "name": "three_link", "gravity": 9.81,
    "links": {"leg_1": {"parent": "torso", "joint": "hip_1", "length": 1.0, "mass": 5.0, "com": 0.5, "inertia": 0.5},
              "leg_2": {"parent": "torso", "joint": "hip_2", "length": 1.0, "mass": 5.0, "com": 0.5, "inertia": 0.5},
              "torso": {"joint": "torso_pitch", "length": 0.5, "mass": 10.0, "com": 0.25, "inertia": 1.0}},
    "actuated": ["hip_1", "hip_2"],
    "contacts": {"foot_1": {"link": "leg_1", "at": "tip"}, "foot_2": {"link": "leg_2", "at": "tip"}},
    "mirror": [["leg_1", "leg_2"]],
}


def states(n, count=6, seed=3):
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-2, 2, n), rng.uniform(-3, 3, n)) for _ in range(count)]


# ---- the description ---------------------------------------------------------------------------------

def test_the_shipped_three_link_description_is_the_engines_biped():
    d = models.load_description("three_link")
    assert d.structure() == description_from_dict(THREE_LINK).structure()
    assert d.coordinates == ("base_x", "base_y", "hip_1", "hip_2", "torso_pitch")
    assert d.relabeling == (0, 1, 3, 2, 4) and d.contact_mirror == (1, 0)
    R = np.eye(5)[list(d.relabeling)]
    assert np.array_equal(R @ R, np.eye(5))


@pytest.mark.parametrize("name", models.SHIPPED)
def test_each_shipped_yaml_and_urdf_describe_the_same_robot(name):
    yaml_desc = models.load_description(name)
    urdf_desc = models.load_description(str(models.ROBOTS_DIR / f"{name}.urdf"))
    assert urdf_desc.structure() == yaml_desc.structure()
    assert description_from_urdf(to_urdf(yaml_desc), name=name).structure() == yaml_desc.structure()


def _bad(change):
    data = {k: (dict(v) if isinstance(v, dict) else v) for k, v in THREE_LINK.items()}
    data["links"] = {k: dict(v) for k, v in THREE_LINK["links"].items()}
    change(data)
    with pytest.raises(DescriptionError) as e:
        description_from_dict(data, "robot.yaml")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith("robot description robot.yaml: ")
    return msg


def test_a_bad_description_is_refused_in_one_line_that_names_the_field():
    assert "links.leg_1.mass must be >= 0" in _bad(lambda d: d["links"]["leg_1"].update(mass=-1.0))
    assert "links.leg_2.inertia must be a finite number" in _bad(lambda d: d["links"]["leg_2"].update(inertia="x"))
    assert "links.leg_1.parent names no link: 'hip'" in _bad(lambda d: d["links"]["leg_1"].update(parent="hip"))
    assert "actuated names the floating base's angle" in _bad(lambda d: d.update(actuated=["torso_pitch"]))
    assert "mirror [leg_1, leg_2] pairs links that differ in mass" in _bad(
        lambda d: d["links"]["leg_2"].update(mass=4.0))
    assert "contacts.foot_1 has no mirror image" in _bad(
        lambda d: d.update(contacts={"foot_1": {"link": "leg_1", "at": 0.9}, "foot_2": {"link": "leg_2"}}))
    assert "mirror is missing" in _bad(lambda d: d.pop("mirror"))
    assert "field(s) ['colour'] unknown" in _bad(lambda d: d.update(colour="red"))
    assert "exactly one base link" in _bad(lambda d: d["links"]["leg_1"].pop("parent"))


def test_a_non_planar_urdf_is_refused_naming_the_joint():
    urdf = to_urdf(models.load_description("three_link"))
    bad_axis = urdf.replace('<axis xyz="0 1.0 0"/>', '<axis xyz="1 0 0"/>', 1)
    with pytest.raises(DescriptionError, match=r"joint 'hip_1' is not planar: it turns about axis \(1.0 0.0 0.0\)"):
        description_from_urdf(bad_axis)
    bad_rpy = urdf.replace('rpy="0 0.0 0"', 'rpy="0.1 0.0 0"', 1)
    with pytest.raises(DescriptionError, match=r"joint 'hip_1' origin is not planar|joint 'hip_1' is not planar"):
        description_from_urdf(bad_rpy)
    prismatic = urdf.replace('type="revolute"', 'type="prismatic"', 1)
    with pytest.raises(DescriptionError, match="joint 'hip_1' has type 'prismatic'"):
        description_from_urdf(prismatic)


def test_a_broken_urdf_is_refused_in_one_line_naming_the_element():
    urdf = to_urdf(models.load_description("three_link"))
    cases = {
        urdf.replace('<mass value="5.0"/>', '<mass value="heavy"/>', 1): "link 'leg_1' mass value must be a number",
        urdf.replace('<parent link="torso"/>', '', 1): "joint 'hip_1' has no <parent link=...>",
        urdf.replace('<mirror left="leg_1" right="leg_2"/>', ''): "mirror is empty",
        urdf[:200]: "not well-formed XML",
    }
    for text, match in cases.items():
        with pytest.raises(DescriptionError) as e:
            description_from_urdf(text)
        assert match in str(e.value) and "\n" not in str(e.value)


# ---- the generator -----------------------------------------------------------------------------------

def test_the_generic_generators_three_link_agrees_with_the_engines_closed_forms():
    m = BipedModel()
    g = models.generated_model("three_link")
    k = m.k
    for q, dq in states(5):
        ql, dql = q.tolist(), dq.tolist()
        assert np.allclose(g.mass_matrix(q), m.mass_matrix(q), rtol=0, atol=1e-12)
        assert np.allclose(g.coriolis(q, dq), m.coriolis(q, dq), rtol=0, atol=1e-12)
        assert np.allclose(g.gravity(q), m.gravity(q), rtol=0, atol=1e-12)
        assert np.allclose(g.bias_forces(q, dq), m.bias_forces(q, dq), rtol=1e-13, atol=1e-12)
        for leg in (1, 2):
            assert np.allclose(g.contact_position(q, leg), m.foot_position(q, leg), rtol=0, atol=1e-12)
            assert np.allclose(g.contact_jacobian(q, leg), m.foot_jacobian(q, leg), rtol=0, atol=1e-12)
            assert np.allclose(g.contact_jacobian_dot(q, dq, leg), m.foot_jacobian_dot(q, dq, leg), rtol=0, atol=1e-12)
            assert np.allclose(g.contact_velocity(q, dq, leg), m.foot_velocity(q, dq, leg), rtol=0, atol=1e-12)
        assert abs(g.energy(q, dq) - sum(gen.energy(ql, dql, k["energy"]))) < 1e-12 * max(1.0, abs(m.energy(q, dq)))
        assert np.allclose(g.com_position(q), m.com_position(q), rtol=0, atol=1e-12)
        ddq_g, F_g = g.stance_dynamics(q, dq, [1.0, -2.0], 1)
        ddq, F = bs.stance_dynamics(m, q, dq, np.array([1.0, -2.0]), stance_leg=1)
        assert np.allclose(ddq_g, ddq, atol=1e-9) and np.allclose(F_g, F, atol=1e-9)
        dqp_g, L_g = g.impact_map(q, dq, 2)
        dqp, L = bs.impact_map(m, q, dq, impact_leg=2)
        assert np.allclose(dqp_g, dqp, atol=1e-10) and np.allclose(L_g, L, atol=1e-10)
        assert np.array_equal(g.relabel(q, dq)[0], bs.relabel(q, dq)[0])


def test_the_committed_three_link_module_is_what_the_generator_writes():
    pytest.importorskip("sympy")
    from biped_sim.config import codegen
    committed = models.ROBOTS_DIR.parents[1] / "engine" / "_gen" / "models" / "three_link.py"
    assert codegen.generate_source(models.load_description("three_link")) == committed.read_text(), \
        "run make generate (tools/generate_models.py)"


def test_a_users_description_is_generated_once_and_cached(tmp_path, monkeypatch):
    pytest.importorskip("sympy")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    path = tmp_path / "stilts.urdf"
    desc = description_from_dict(dict(THREE_LINK, name="stilts"))
    path.write_text(to_urdf(desc).replace('<mass value="5.0"/>', '<mass value="4.0"/>'))
    m = bs.load_model(str(path))
    cached = list((tmp_path / "biped_sim" / "models").glob("stilts-*.py"))
    assert len(cached) == 1 and m.total_mass == 18.0
    stamp = cached[0].stat().st_mtime_ns
    again = bs.load_model(str(path))
    assert cached[0].stat().st_mtime_ns == stamp
    q = np.array([0.1, 0.9, 3.0, 3.4, 0.1])
    assert np.array_equal(again.mass_matrix(q), m.mass_matrix(q))
    assert m.mass_matrix(q)[0, 0] == 18.0


def test_without_sympy_a_new_description_says_what_to_install_in_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setitem(__import__("sys").modules, "sympy", None)
    path = tmp_path / "bot.yaml"
    path.write_text(__import__("yaml").safe_dump(dict(THREE_LINK, name="bot")))
    with pytest.raises(ValueError) as e:
        bs.load_model(str(path))
    assert "pip install 'biped_sim[models]'" in str(e.value) and "\n" not in str(e.value)


# ---- load_model and the scenes -----------------------------------------------------------------------

def test_load_model_names():
    assert repr(bs.load_model("three_link")) == repr(BipedModel())
    cg = bs.load_model("compass_gait")
    assert isinstance(cg, BipedModel) and cg.parameters.I_leg == 0.0 and cg.parameters.c_torso == 0.0
    assert cg.total_mass == 20.0
    hm = bs.load_model("three_link_hip_mass")
    assert isinstance(hm, BipedModel) and hm.total_mass == 35.0
    rabbit = bs.load_model("rabbit")
    assert rabbit.n == 7 and rabbit.contacts == ("foot_1", "foot_2") and rabbit.B.shape == (7, 4)
    assert rabbit.total_mass == pytest.approx(12.0 + 2 * 6.8 + 2 * 3.2)
    with pytest.raises(ValueError, match="unknown model 'rabit'; shipped: three_link, compass_gait"):
        bs.load_model("rabit")


def test_the_generated_three_link_special_cases_agree_with_their_BipedModels():
    """compass_gait and three_link_hip_mass: the description (hip mass on its own link, point masses) and the
    BipedModel the engine runs are one robot."""
    for name in ("compass_gait", "three_link_hip_mass"):
        g, m = models.generated_model(name), bs.load_model(name)
        for q, dq in states(5, 3):
            assert np.allclose(g.mass_matrix(q), m.mass_matrix(q), rtol=0, atol=1e-12), name
            assert np.allclose(g.bias_forces(q, dq), m.bias_forces(q, dq), rtol=1e-13, atol=1e-11), name


def test_what_needs_the_three_link_closed_forms_refuses_rabbit_in_one_line():
    """The engine runs RABBIT (test_generic_engine.py); what reads the three-link biped's closed forms (p, k:
    the sensitivity, the compiled walking law) refuses it in one line."""
    rabbit = bs.load_model("rabbit")
    q = [0.0, 0.8, 3.3, 2.9, 0.1, 0.2, 0.0]
    with pytest.raises(EngineCannotRun, match="'rabbit' .7 coordinates. has no three-link closed forms") as e:
        rabbit.p  # noqa: B018 (the attribute the three-link's tools read first)
    assert "\n" not in str(e.value)
    ddq, F = rabbit.stance_dynamics(q, [0.1] * 7, [0.0] * 4, "foot_1")   # its dynamics are there
    assert np.all(np.isfinite(ddq)) and F[1] > 0


def test_a_point_mass_link_is_accepted_where_D_stays_positive_definite():
    BipedModel(I_leg=0.0)
    BipedModel(I_torso=0.0)
    with pytest.raises(ValueError, match="I_torso = 0 and c_torso = 0"):
        BipedModel(I_torso=0.0, c_torso=0.0)


def test_the_compass_gait_scene_walks_10_s_passively_with_14_impacts():
    scene = bs.load_scene("compass_gait")
    r = scene.simulate()
    assert r.status == "completed" and scene.controller() is None
    assert [e.kind for e in r.impacts] == ["touchdown"] * 14
    assert [e.leg for e in r.impacts] == [2, 1] * 7
    steps = np.diff([e.time for e in r.impacts])
    # the passive limit cycle's step (0.734460621336 s, the independent computation)
    assert abs(steps[-1] - 0.734460621336) < 1e-4
    # stancedot just after the last impact is the limit cycle's, 1.092866810580 rad/s
    last = r.impacts[-1]
    assert abs(last.dq_plus[2] - 1.092866810580) < 1e-3
    assert r.impacts[0].time == pytest.approx(0.41722729, abs=1e-6)


# ---- Pinocchio, from the same URDF ---------------------------------------------------------------------

def _pinocchio_model(urdf_path):
    pin = pytest.importorskip("pinocchio")
    root = pin.JointModelComposite(3)
    root.addJoint(pin.JointModelPX())
    root.addJoint(pin.JointModelPZ())
    root.addJoint(pin.JointModelRY())
    model = pin.buildModelFromUrdf(str(urdf_path), root)
    model.gravity.linear = np.array([0.0, 0.0, -models.load_description(urdf_path.stem).gravity])
    return pin, model


@pytest.mark.skipif(importlib.util.find_spec("pinocchio") is None,
                    reason="Pinocchio (pip package pin) is not installed: make bench installs it")
@pytest.mark.parametrize("name", models.SHIPPED)
def test_the_generated_dynamics_agree_with_pinocchio_from_the_same_urdf(name):
    urdf = models.ROBOTS_DIR / f"{name}.urdf"
    ours = models.generated_model(str(urdf))
    pin, model = _pinocchio_model(urdf)
    data = model.createData()
    desc = ours.description
    # our coordinates in Pinocchio's q/v: the root composite is (x, z, base angle), then each joint's index
    idx = [0, 1] + [model.idx_vs[model.getJointId(link.joint)] if link.parent else 2 for link in desc.links]
    for q, dq in states(ours.n, 5, seed=11):
        qp, vp = np.zeros(model.nq), np.zeros(model.nv)
        qp[idx], vp[idx] = q, dq
        D = pin.crba(model, data, qp)
        D = np.triu(D) + np.triu(D, 1).T
        assert np.allclose(ours.mass_matrix(q), D[np.ix_(idx, idx)], rtol=0, atol=1e-12), name
        h = pin.rnea(model, data, qp, vp, np.zeros(model.nv))
        assert np.allclose(ours.bias_forces(q, dq), h[idx], rtol=0, atol=1e-12 * max(1.0, abs(h).max())), name
        pin.forwardKinematics(model, data, qp, vp, np.zeros(model.nv))
        pin.computeJointJacobians(model, data, qp)
        pin.updateFramePlacements(model, data)
        for contact in desc.contacts:
            fid = model.getFrameId(contact.name)
            J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[[0, 2]][:, idx]
            p = data.oMf[fid].translation[[0, 2]]
            # Jdot dq is the contact point's acceleration at ddq = 0 (Pinocchio's classical acceleration;
            # its Jacobian time variation is that of the spatial Jacobian, another quantity)
            a0 = pin.getFrameClassicalAcceleration(model, data, fid, pin.LOCAL_WORLD_ALIGNED).linear[[0, 2]]
            assert np.allclose(ours.contact_position(q, contact.name), p, rtol=0, atol=1e-12), name
            assert np.allclose(ours.contact_jacobian(q, contact.name), J, rtol=0, atol=1e-12), name
            assert np.allclose(ours.contact_jacobian_dot(q, dq, contact.name) @ dq, a0, rtol=0, atol=1e-12), name
    assert math.isfinite(ours.energy(q, dq))


# ---- Drake, side by side (benchmarks/bench_drake.py) -------------------------------------------------------

DRAKE_PYTHON = models.ROBOTS_DIR.parents[2] / ".venv-drake" / "bin" / "python"


@pytest.mark.skipif(not DRAKE_PYTHON.exists(), reason="no .venv-drake (make venv-drake installs drake 1.58)")
def test_the_compass_gait_scene_meets_drakes_impacts():
    import json
    import subprocess
    out = subprocess.run([str(DRAKE_PYTHON), str(models.ROBOTS_DIR.parents[2] / "benchmarks" / "drake_compass_gait.py"),
                          "--accuracy", "1e-12", "--repeats", "1"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    drake = np.array(json.loads(out.stdout)["impacts"])
    from benchmarks.bench_drake import drake_angles
    kw = bs.load_scene("compass_gait").simulate_kwargs()
    kw.update(rtol=1e-12, atol=1e-12)
    ours = np.array([drake_angles(e) for e in bs.simulate(**kw).impacts])
    assert ours.shape == drake.shape == (14, 5)
    assert np.abs(ours[:, 0] - drake[:, 0]).max() < 1e-9
    assert np.abs(ours[:, 1:] - drake[:, 1:]).max() < 1e-9


def test_a_description_path_that_is_a_folder_or_another_format_is_named_so(tmp_path):
    """bs.load_model of a folder says it is a folder (not 'does not exist'), and of a file of another format
    (an SDF) names the formats it reads, each in one line; a missing file 'does not exist'."""
    import biped_sim as bs
    sdf = tmp_path / "robot.sdf"
    sdf.write_text("<sdf version='1.9'><model name='biped'/></sdf>\n")
    for path, message in ((tmp_path, "is a folder: give a .yaml or .urdf file in it"),
                          (sdf, "a description is a .yaml, .yml or .urdf file, not .sdf"),
                          (tmp_path / "none.urdf", "does not exist")):
        with pytest.raises(ValueError, match=message) as exc:
            bs.load_model(str(path))
        assert "\n" not in str(exc.value)
