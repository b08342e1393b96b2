"""A described robot's derivatives by its model parameters (config/codegen.py ``generate_parameter_source``,
engine/model_derivatives.py ``GeneratedDerivatives.parameters``, issue 32): each generated term against central
differences of the robot's symbolic model evaluated with the parameter moved, for RABBIT and the three-link
description; the three-link description's against the BipedModel's closed forms; the names and their refusals;
and a run Jacobian by a parameter through an impact against central differences of runs of robots built from
the description with the parameter moved."""
from dataclasses import replace

import numpy as np
import pytest
import sympy as sp

from biped_sim.config import codegen, models
from biped_sim.engine.generated_model import GeneratedModel
from biped_sim.engine.hybrid import HybridSimulator
from biped_sim.engine.model import BipedModel
from biped_sim.engine.model_derivatives import derivatives
from biped_sim.engine.sensitivity import run_jacobian
from biped_sim.engine.simulate import stance_state


def rel(a, b):
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def numeric_model(desc):
    """(names, values, f): f(q, dq, p) = (D, h, p_c stacked, J_c stacked, Jdot_c dq stacked) of ``desc`` with its
    parameters p as numbers, from the symbolic T, V and contact points (``codegen.parametric``), not differentiated
    by p: the reference the generated derivatives are differenced against."""
    m = codegen.parametric(desc)
    n, q, dq = desc.n, m["q"], m["dq"]
    syms = [m["symbols"][k] for k in m["names"]]
    Q, DQ = sp.Matrix(q), sp.Matrix(dq)
    D = sp.hessian(m["T"], dq)
    h = sp.Matrix([sum((sp.diff(D[k, j], q[i]) - sp.Rational(1, 2) * sp.diff(D[i, j], q[k])) * dq[i] * dq[j]
                       for i in range(n) for j in range(n)) + sp.diff(m["V"], q[k]) for k in range(n)])
    feet = sp.Matrix.vstack(*m["feet"])
    J = feet.jacobian(Q)
    f = sp.lambdify([q, dq, syms], [D, h, feet, J, (J * DQ).jacobian(Q) * DQ], "numpy")
    values = np.array([float(m["numbers"][s]) for s in syms])
    return m["names"], values, lambda q_, dq_, p_: [np.array(v, float) for v in f(q_, dq_, p_)]


@pytest.mark.parametrize("name", ["three_link", "rabbit"])
def test_each_generated_parameter_term_is_the_derivative_by_its_parameter(name):
    """dD/dp, dh/dp, dp_c/dp, dJ_c/dp, d(Jdot_c dq)/dp of every parameter at random states against central
    differences of the symbolic model with p +- h (1e-7 relative); the symbolic model at the description's numbers
    is the generated module's (D, h, p_c)."""
    model = models.generated_model(name)
    deriv = derivatives(model)
    names, p0, f = numeric_model(model.description)
    assert names == deriv.parameter_names == codegen.parameter_names(model.description)
    n, C = model.n, len(model.contacts)
    rng = np.random.default_rng(5)
    for _ in range(2):
        q = np.concatenate([[rng.uniform(-0.5, 0.5), rng.uniform(0.5, 1.2)], rng.uniform(-np.pi, np.pi, n - 2)])
        dq = rng.normal(size=n) * 1.5
        D, h, feet, _J, _Jd = f(q, dq, p0)
        assert rel(D, model.mass_matrix(q)) < 1e-12 and rel(h.ravel(), model.bias_forces(q, dq)) < 1e-12
        assert rel(feet.ravel(), np.concatenate([model.contact_position(q, c) for c in (1, 2)])) < 1e-12
        out = deriv.parameters(q, dq)
        exact = np.concatenate([np.concatenate([out[0][j].ravel(), out[1][:, j]]
                                               + [out[2 + c][j].ravel() for c in range(C)]
                                               + [out[2 + C + c][:, j] for c in range(C)] + [out[-1][:, j]])
                                for j in range(len(names))])
        fd = []
        for j in range(len(names)):
            step = 1e-6 * max(1.0, abs(p0[j]))
            plus, minus = f(q, dq, p0 + step * np.eye(len(p0))[j]), f(q, dq, p0 - step * np.eye(len(p0))[j])
            d = [(a - b) / (2 * step) for a, b in zip(plus, minus)]
            fd.append(np.concatenate([d[0].ravel(), d[1].ravel()] + [d[3][2 * c:2 * c + 2].ravel() for c in range(C)]
                                     + [d[4][2 * c:2 * c + 2].ravel() for c in range(C)] + [d[2].ravel()]))
        assert rel(exact, np.concatenate(fd)) < 1e-7


#: a BipedModel parameter as the three-link description's: the links it moves at once (their derivatives summed)
THREE_LINK = {"m_torso": ["torso.mass"], "I_torso": ["torso.inertia"], "c_torso": ["torso.com_z"],
              "m_leg": ["leg_1.mass", "leg_2.mass"], "I_leg": ["leg_1.inertia", "leg_2.inertia"],
              "l_leg": ["leg_1.length", "leg_2.length"], "c_leg": ["leg_1.com_z", "leg_2.com_z"], "g": ["gravity"]}


def test_the_three_link_descriptions_parameter_derivatives_are_the_closed_forms():
    """The three-link description's derivatives by its links' parameters, summed over the links a BipedModel
    parameter moves (m_leg: both legs' masses), are the closed forms' (_gen/derivatives.py) to 1e-10."""
    closed, generated = derivatives(BipedModel()), derivatives(models.generated_model("three_link"))
    rng = np.random.default_rng(7)
    for _ in range(2):
        q = np.array([0.2, 0.9, np.pi + rng.uniform(-1, 1), np.pi + rng.uniform(-1, 1), rng.uniform(-0.5, 0.5)])
        dq = rng.normal(size=5)
        a, b = closed.parameters(q.tolist(), dq.tolist()), generated.parameters(q, dq)
        for name, links in THREE_LINK.items():
            i = closed.parameter_names.index(name)
            js = [generated.parameter_names.index(link) for link in links]
            for axis, (x, y) in zip((0, 1, 0, 0, 1, 1, 1), zip(a, b)):
                mine = np.take(y, js, axis=axis).sum(axis=axis)
                theirs = np.take(x, i, axis=axis)
                assert np.allclose(mine, theirs, rtol=0, atol=1e-10 * max(1.0, np.abs(x).max())), (name, axis)


def test_parameter_names_and_refusals_are_one_line_each():
    """RABBIT's names (a length only where a contact point or a child's joint is at the tip); a wrong name is
    refused listing them; a length on the stance foot's chain from a start in stance is refused (it moves the
    initial state's stance foot)."""
    rabbit = models.generated_model("rabbit")
    names = derivatives(rabbit).parameter_names
    assert names[:5] == ("femur_1.mass", "femur_1.inertia", "femur_1.com_x", "femur_1.com_z", "femur_1.length")
    assert "torso.length" not in names and "tibia_1.length" in names and names[-1] == "gravity" and len(names) == 25
    scene = __import__("biped_sim").load_scene("rabbit")
    q0, dq0 = scene.params["initial_q"], scene.params["initial_dq"]
    for parameters, match in ((("femur_1.mas",), r"unknown parameter 'femur_1.mas': the model's are \['femur_1.mass'"),
                              (("torso.mass", "tibia_1.length"),
                               r"parameters \['tibia_1.length'\]: a run that starts in stance cannot")):
        with pytest.raises(ValueError, match=match) as e:
            run_jacobian(rabbit, q0, dq0, 0.01, controller=scene.controller(), parameters=parameters)
        assert "\n" not in str(e.value)


def test_the_shipped_parameters_module_is_the_generators_and_is_used(tmp_path, monkeypatch):
    """make generate writes the shipped robots' <name>_parameters.py (here three_link's, the generator's output
    as committed), and a run Jacobian reads it rather than generating one into the cache."""
    from pathlib import Path
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    desc = models.load_description("three_link")
    module = models.parameters_module(desc)
    assert module.__name__ == "biped_sim.engine._gen.models.three_link_parameters"
    assert Path(module.__file__).read_text() == codegen.generate_parameter_source(desc)
    assert not (tmp_path / "biped_sim").exists()


def test_a_users_description_gets_its_parameters_module_on_the_first_request(tmp_path, monkeypatch, capsys):
    """Loading a user's description generates its dynamics only; its first derivatives by parameters generate
    <name>-<digest>-g<V>-p<V>_parameters.py into the cache (said on stderr), a second model reads it unchanged; the
    derivative by the torso's mass (the legs' masses moved) is the three-link's."""
    import yaml
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    data = yaml.safe_load(models.description_path("three_link").read_text())
    data["name"] = "stilts"
    for leg in ("leg_1", "leg_2"):
        data["links"][leg]["mass"] = 4.0
    path = tmp_path / "stilts.yaml"
    path.write_text(yaml.safe_dump(data))
    cache = tmp_path / "biped_sim" / "models"
    model = models.generated_model(str(path))
    assert list(cache.glob("*_parameters.py")) == []
    q, dq = np.array([0.1, 0.9, 3.0, 3.4, 0.1]), np.array([0.3, -0.2, 1.0, -0.5, 0.2])
    mine = derivatives(model).parameters(q, dq)
    made = list(cache.glob("stilts-*-p*_parameters.py"))
    said = capsys.readouterr().err
    assert len(made) == 1 and "generated the derivatives by model parameters of robot 'stilts'" in said
    stamp = made[0].stat().st_mtime_ns
    again = derivatives(models.generated_model(str(path))).parameters(q, dq)
    assert made[0].stat().st_mtime_ns == stamp and all(np.array_equal(a, b) for a, b in zip(mine, again))
    three = derivatives(models.generated_model("three_link"))
    j = three.parameter_names.index("torso.mass")
    assert np.allclose(mine[0][j], three.parameters(q, dq)[0][j], rtol=0, atol=1e-12)


def moved(desc, name, value):
    """``desc`` with the parameter ``name`` at ``value`` (a length moves what is at the link's tip with it)."""
    if name == "gravity":
        return replace(desc, gravity=value)
    link_name, what = name.split(".")
    links = []
    for link in desc.links:
        if link.name == link_name:
            old = link.length
            link = {"mass": lambda: replace(link, mass=value), "inertia": lambda: replace(link, inertia=value),
                    "com_x": lambda: replace(link, com=(value, link.com[1])),
                    "com_z": lambda: replace(link, com=(link.com[0], value)),
                    "length": lambda: replace(link, length=value)}[what]()
        links.append(link)
    contacts = desc.contacts
    if what == "length":
        links = [replace(k, origin=(0.0, value)) if k.parent == link_name and k.origin == (0.0, old) else k
                 for k in links]
        contacts = tuple(replace(c, point=(0.0, value)) if c.link == link_name and c.point == (0.0, old) else c
                         for c in contacts)
    return replace(desc, links=tuple(links), contacts=contacts)


def test_rabbits_run_jacobian_by_a_model_parameter_through_an_impact(tmp_path, monkeypatch):
    """RABBIT under its law (its own model kept) from 30 ms before a touchdown of foot 2 to 70 ms after it: the run
    Jacobian by femur_2.length (it moves tibia_2's joint and foot 2: the flows, the touchdown guard, the impact)
    against central differences of the runs of robots generated from the description with it moved (1e-7)."""
    import biped_sim as bs
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    scene = bs.load_scene("rabbit")
    kw = scene.engine_arguments()
    model, ctrl = kw["model"], scene.controller()
    options = dict(slope=kw["slope"], touchdown_rule=kw["touchdown_rule"], scuff_rule=kw["scuff_rule"],
                   scuff_depth=kw["scuff_depth"], phases=frozenset({"stance", "impact"}))
    sim = HybridSimulator(model, scene.params["initial_q"], scene.params["initial_dq"], rtol=1e-12, atol=1e-12,
                          **options)
    sim.advance(0.56, controller=ctrl)
    q0, dq0 = sim.q.copy(), sim.dq.copy()
    name, t_final = "femur_2.length", 0.1
    r = run_jacobian(model, q0, dq0, t_final, controller=ctrl, parameters=(name,), directions=np.zeros((14, 0)),
                     **options)
    assert [(kind, leg) for _t, kind, leg in r.events] == [("touchdown", 2)] and r.jacobian.shape == (14, 1)

    def end(value):
        desc = moved(model.description, name, value)
        other = GeneratedModel(desc, models.dynamics_module(desc))
        s = HybridSimulator(other, q0, dq0, stance_leg=1, rtol=1e-12, atol=1e-12, **options)
        s.advance(t_final, controller=ctrl)
        assert s.status == "running", s.message
        return np.concatenate([s.q, s.dq])

    value, step = 0.4, 1e-6     # (truncation 1e-5 relative at a step of 1e-4, so ~1e-9 here)
    fd = (end(value + step) - end(value - step)) / (2 * step)
    assert rel(r.jacobian[:, 0], fd) < 1e-7, rel(r.jacobian[:, 0], fd)


def test_the_compass_gait_descriptions_run_jacobian_by_its_parameters_on_the_engine_steps(tmp_path, monkeypatch):
    """The compass gait's description passive down 0.0525 rad, its step's touchdown, impact and 0.1 s of the next
    stance, linearised on the engine's own steps (the parameters' terms on a stack of points): the run Jacobian by
    leg_2.com_z, leg_2.mass and gravity against central differences of runs of the robots generated with each moved
    (1e-7)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    model = models.generated_model("compass_gait")
    z = np.array([2.92075575, 3.46742955, 0.0, 1.09644226, 0.37368084, 0.0])
    q0, dq0 = stance_state(model, z[:3], z[3:], 1, foot=(0.0, 0.0))
    options = dict(slope=0.0525, scuff_rule="behind", phases=frozenset({"stance", "impact"}))
    names, t_final = ("leg_2.com_z", "leg_2.mass", "gravity"), 0.85
    r = run_jacobian(model, q0, dq0, t_final, u=(0.0, 0.0), parameters=names, directions=np.zeros((2 * model.n, 0)),
                     **options)
    assert [(kind, leg) for _t, kind, leg in r.events] == [("touchdown", 2)] and r.integration == "steps"

    def end(name, value):
        desc = moved(model.description, name, value)
        s = HybridSimulator(GeneratedModel(desc, models.dynamics_module(desc)), q0, dq0, stance_leg=1, rtol=1e-12,
                            atol=1e-12, **options)
        s.advance(t_final, u=(0.0, 0.0))
        assert s.status == "running", s.message
        return np.concatenate([s.q, s.dq])

    for j, (name, value) in enumerate(zip(names, (0.5, 5.0, 9.81))):
        step = 1e-6 * value
        fd = (end(name, value + step) - end(name, value - step)) / (2 * step)
        assert rel(r.jacobian[:, j], fd) < 1e-7, (name, rel(r.jacobian[:, j], fd))
