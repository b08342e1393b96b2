"""The generated derivatives of any described robot (config/codegen.py, GeneratedModel's ``*_jacobian``
methods, issue 32): each against central differences of the method it differentiates, for the four shipped
robots, and for the three-link against the closed-form derivatives of ``_gen/derivatives.py``; and the
linearisation of a run from a model's terms (engine/model_derivatives.py): the three-link description's
generated terms give the BipedModel's run Jacobian."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import biped_sim as bs
from biped_sim.analysis.edge_cases import bouncing_landing
from biped_sim.config import models
from biped_sim.control.walking import WalkingController
from biped_sim.engine._gen import closed_forms as cf, derivatives as dgen
from biped_sim.engine.hybrid import HybridSimulator
from biped_sim.engine.model import BipedModel
from biped_sim.engine.model_derivatives import ClosedFormDerivatives, GeneratedDerivatives, derivatives
from biped_sim.engine.sensitivity import Linearization, _Integration, run_jacobian
from biped_sim.engine.simulate import stance_state

ROBOTS = {name: models.generated_model(name) for name in models.SHIPPED}
EPS = 1e-5   # (truncation ~EPS^2 |f'''| / 6, rounding ~1e-16 |f| / EPS: both near 1e-11 of the terms here)


def rel(a, b):
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def central(fun, x, eps=EPS):
    """Central differences of fun at x: the derivative by x_k in the last axis, k = 0.. len(x) - 1."""
    x = np.asarray(x, float)
    return np.stack([(np.asarray(fun(x + eps * e)) - np.asarray(fun(x - eps * e))) / (2 * eps)
                     for e in np.eye(len(x))], axis=-1)


def state(model, rng):
    """A state of ``model`` (a base, joint angles anywhere, rates and torques of walking size)."""
    n, m = model.n, model.B.shape[1]
    q = np.concatenate([[rng.uniform(-0.5, 0.5), rng.uniform(0.5, 1.2)], rng.uniform(-np.pi, np.pi, n - 2)])
    return q, rng.normal(size=n) * 1.5, rng.normal(size=m) * 20


def check_phase_jacobians(model, q, dq, u, tol=1e-7):
    """Every phase Jacobian of ``model`` at (q, dq, u) against central differences of its phase."""
    n = model.n
    A_q, A_dq, A_u = model.flight_dynamics_jacobian(q, dq, u)
    assert rel(A_q, central(lambda v: model.flight_dynamics(v, dq, u), q)) < tol
    assert rel(A_dq, central(lambda v: model.flight_dynamics(q, v, u), dq)) < tol
    assert rel(A_u, central(lambda v: model.flight_dynamics(q, dq, v), u)) < tol
    for contact in (1, 2):
        def stance(q_, dq_, u_):
            return np.concatenate(model.stance_dynamics(q_, dq_, u_, contact))
        A_q, A_dq, A_u, F_q, F_dq, F_u = model.stance_dynamics_jacobian(q, dq, u, contact)
        assert rel(np.vstack([A_q, F_q]), central(lambda v: stance(v, dq, u), q)) < tol
        assert rel(np.vstack([A_dq, F_dq]), central(lambda v: stance(q, v, u), dq)) < tol
        assert rel(np.vstack([A_u, F_u]), central(lambda v: stance(q, dq, v), u)) < tol

        def impact(q_, dq_):
            return np.concatenate(model.impact_map(q_, dq_, contact))
        P_q, P_dq, I_q, I_dq = model.impact_map_jacobian(q, dq, contact)
        assert rel(np.vstack([P_q, I_q]), central(lambda v: impact(v, dq), q)) < tol
        assert rel(np.vstack([P_dq, I_dq]), central(lambda v: impact(q, v), dq)) < tol

        v_q, v_dq = model.contact_velocity_jacobian(q, dq, contact)
        assert rel(v_q, central(lambda v: model.contact_velocity(v, dq, contact), q)) < tol
        assert rel(v_dq, central(lambda v: model.contact_velocity(q, v, contact), dq)) < tol
        assert v_q.shape == v_dq.shape == (2, n)


@pytest.mark.parametrize("name", models.SHIPPED)
def test_each_robots_generated_terms_are_the_derivatives_of_its_terms(name):
    """dD/dq_k, d(C dq + G)/d(q, dq), dJ_c/dq_k, d(Jdot_c dq)/d(q, dq) of the generated module."""
    model = ROBOTS[name]
    rng = np.random.default_rng(7)
    for _ in range(2):
        q, dq, _u = state(model, rng)
        assert rel(np.moveaxis(model.mass_matrix_jacobian(q), 0, -1), central(model.mass_matrix, q)) < 1e-8
        dhq, dhv = model.bias_forces_jacobian(q, dq)
        assert rel(dhq, central(lambda v: model.bias_forces(v, dq), q)) < 1e-8
        assert rel(dhv, central(lambda v: model.bias_forces(q, v), dq)) < 1e-8
        for contact in model.contacts:
            dJ = model.contact_jacobian_jacobian(q, contact)
            assert rel(np.moveaxis(dJ, 0, -1), central(lambda v: model.contact_jacobian(v, contact), q)) < 1e-8
            jb, jbq, jbv = model.contact_bias_jacobian(q, dq, contact)
            assert np.allclose(jb, model.contact_jacobian_dot(q, dq, contact) @ dq, rtol=1e-13, atol=1e-12)
            assert rel(jbq, central(lambda v: model.contact_jacobian_dot(v, dq, contact) @ dq, q)) < 1e-8
            assert rel(jbv, central(lambda v: model.contact_jacobian_dot(q, v, contact) @ v, dq)) < 1e-8


@pytest.mark.parametrize("name", models.SHIPPED)
def test_each_robots_phase_jacobians_are_the_derivatives_of_its_phases(name):
    """Flight, stance on each contact (ddq and F), the impact of each contact and the contact velocity: d/dq,
    d/ddq, d/du against central differences of the method differentiated, to 1e-7 relative."""
    model = ROBOTS[name]
    rng = np.random.default_rng(11)
    for _ in range(2):
        check_phase_jacobians(model, *state(model, rng))


@settings(max_examples=30, deadline=None, derandomize=True)
@given(st.sampled_from(models.SHIPPED), st.integers(0, 2 ** 32 - 1))
def test_the_phase_jacobians_hold_at_any_state(name, seed):
    """The same as a property over states (a base anywhere, joint angles on the whole circle)."""
    model = ROBOTS[name]
    check_phase_jacobians(model, *state(model, np.random.default_rng(seed)))


def test_the_three_link_description_has_the_closed_forms_derivatives():
    """For the three-link biped the generated terms and phase Jacobians are the closed forms' (_gen/derivatives.py,
    engine/sensitivity.py's Linearization) to 1e-10: two derivations of one robot."""
    g, m = ROBOTS["three_link"], BipedModel()
    k = {name: constants(m.p) for name, constants in dgen.CONSTANTS.items()}
    lin = Linearization(m)
    rng = np.random.default_rng(3)
    for _ in range(3):
        q, dq, u = state(g, rng)
        ql, dql = q.tolist(), dq.tolist()
        dD = np.array(dgen.mass_matrix_jacobian(ql, k["mass_matrix_jacobian"])).reshape(5, 5, 5)
        assert rel(g.mass_matrix_jacobian(q), dD) < 1e-10
        dh = np.array(dgen.bias_forces_jacobian(ql, dql, k["bias_forces_jacobian"])).reshape(2, 5, 5)
        assert rel(np.array(g.bias_forces_jacobian(q, dq)), dh) < 1e-10
        for leg in (1, 2):
            dJ = np.array(getattr(dgen, f"foot_jacobian_jacobian_{leg}")(ql, k[f"foot_jacobian_jacobian_{leg}"]))
            assert rel(g.contact_jacobian_jacobian(q, leg), dJ.reshape(5, 2, 5)) < 1e-10
            jb = np.array(getattr(dgen, f"foot_bias_jacobian_{leg}")(ql, dql, k[f"foot_bias_jacobian_{leg}"]))
            assert rel(np.concatenate([a.ravel() for a in g.contact_bias_jacobian(q, dq, leg)]), jb) < 1e-10
            assert rel(g.contact_jacobian(q, leg), np.array(cf.foot_jacobian_1(ql, m.k["foot_jacobian_1"]) if leg == 1
                                                            else cf.foot_jacobian_2(ql, m.k["foot_jacobian_2"])
                                                            ).reshape(2, 5)) < 1e-12
            s, dsq, dsv, dsu, _ = lin.accelerations(q, dq, u, leg)
            A_q, A_dq, A_u, F_q, F_dq, F_u = g.stance_dynamics_jacobian(q, dq, u, leg)
            assert rel(np.vstack([A_q, F_q]), dsq) < 1e-10 and rel(np.vstack([A_dq, F_dq]), dsv) < 1e-10
            assert rel(np.vstack([A_u, F_u]), dsu) < 1e-10
            dqp, imp, Rq, Rv, _ = lin.impact(q, dq, leg)
            P_q, P_dq, _I_q, _I_dq = g.impact_map_jacobian(q, dq, leg)
            assert rel(P_q, Rq) < 1e-10 and rel(P_dq, Rv) < 1e-10
        _s, dsq, dsv, dsu, _ = lin.accelerations(q, dq, u, 0)
        A_q, A_dq, A_u = g.flight_dynamics_jacobian(q, dq, u)
        assert rel(A_q, dsq) < 1e-10 and rel(A_dq, dsv) < 1e-10 and rel(A_u, dsu) < 1e-10


# ---- the run Jacobian from a model's derivatives (model_derivatives.derivatives) ------------------------------

def walk_touchdown_start(model):
    """The walk law's state 80 ms before a touchdown of leg 2 (the step map's last stretch)."""
    q0, dq0 = WalkingController(model).initial_state()
    sim = HybridSimulator(model, q0, dq0, rtol=1e-12, atol=1e-12)
    sim.advance(0.4, controller=WalkingController(model))
    return sim.q.copy(), sim.dq.copy()


STANCE_IMPACT = frozenset({"stance", "impact"})


@pytest.mark.parametrize("case", ["steps", "solve_ivp", "held", "flight"])
def test_the_run_jacobian_from_the_generated_three_link_terms_is_the_closed_forms(case):
    """A run of the BipedModel linearised with the generated terms of the three-link description
    (``derivatives=derivatives(generated_model("three_link"))``, the same robot) gives today's run Jacobian
    (the closed forms') to 1e-9 relative: through a touchdown on the engine's own steps and by solve_ivp, held
    torques, and landings from flight with their liftoffs; and it is the generated terms that were used
    (the two differ in rounding)."""
    m = BipedModel()
    generated = derivatives(ROBOTS["three_link"])
    assert isinstance(generated, GeneratedDerivatives) and isinstance(derivatives(m), ClosedFormDerivatives)
    if case == "flight":
        q0, dq0 = bouncing_landing()
        run = dict(stance_leg=0, u=(0.0, 0.0), phases=frozenset({"stance", "impact", "flight"}))
        t_final = 0.1
    else:
        q0, dq0 = walk_touchdown_start(m)
        run = dict(controller=WalkingController(m), phases=STANCE_IMPACT, end_at_event=(case == "steps"))
        t_final = 0.12
        if case == "solve_ivp":
            run["integration"] = "solve_ivp"
        elif case == "held":
            run["control_period"] = 1e-3
    today = run_jacobian(m, q0, dq0, t_final, **run)
    other = run_jacobian(m, q0, dq0, t_final, derivatives=generated, **run)
    assert other.integration == today.integration == ("steps" if case == "steps" else "solve_ivp")
    assert today.events == other.events and len(today.events) >= 1
    assert rel(other.jacobian, today.jacobian) < 1e-9
    assert not np.array_equal(other.jacobian, today.jacobian)
    if case == "steps":
        assert rel(other.time_derivative, today.time_derivative) < 1e-9


def test_the_compass_gaits_step_jacobian_from_its_generated_terms():
    """The compass gait's passive step (slope 0.0525 rad, to its touchdown) linearised with the compass_gait
    description's generated terms is the BipedModel's (its special case) to 1e-9."""
    m = bs.load_model("compass_gait")
    z = np.array([2.92075575, 3.46742955, 0.0, 1.09644226, 0.37368084, 0.0])
    q0, dq0 = stance_state(m, z[:3], z[3:], 1)
    run = dict(u=(0.0, 0.0), slope=0.0525, scuff_rule="behind", end_at_event=True, phases=STANCE_IMPACT)
    today = run_jacobian(m, q0, dq0, 1.0, **run)
    other = run_jacobian(m, q0, dq0, 1.0, derivatives=derivatives(ROBOTS["compass_gait"]), **run)
    assert [kind for _t, kind, _leg in today.events] == ["touchdown"] and other.integration == "steps"
    assert rel(other.jacobian, today.jacobian) < 1e-9 and rel(other.time_derivative, today.time_derivative) < 1e-9


def test_generated_terms_refuse_what_they_cannot_give_in_one_line():
    """A closed forms' parameter name given to generated terms (their names are the description's), another
    robot's terms, the fixed base's derivatives: one line each."""
    m = BipedModel()
    q0, dq0 = walk_touchdown_start(m)
    cases = [
        (dict(derivatives=derivatives(ROBOTS["three_link"]), parameters=("m_torso",)),
         r"unknown parameter 'm_torso': the model's are \['leg_1.mass'"),
        (dict(derivatives=derivatives(ROBOTS["rabbit"])), "derivatives: of a robot with 7 coordinates"),
    ]
    for kwargs, match in cases:
        with pytest.raises(ValueError, match=match) as e:
            run_jacobian(m, q0, dq0, 0.05, controller=WalkingController(m), **kwargs)
        assert "\n" not in str(e.value)
    lin = Linearization(m, derivatives=derivatives(ROBOTS["three_link"]))
    with pytest.raises(ValueError, match="fixed base's derivatives are the three-link's only") as e:
        lin.fixed_base_jacobian(q0[2:], dq0[2:], (0.0, 0.0))
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="no derivatives for a model of type str"):
        derivatives("three_link")


def test_the_linearization_of_rabbit_is_its_phase_jacobians():
    """What the variational code asks of a GeneratedModel (Linearization's flow, impact, guard, stance tangent)
    at a RABBIT state, against its phase Jacobians and central differences."""
    rabbit = ROBOTS["rabbit"]
    lin = Linearization(rabbit, slope=0.02)
    q, dq, u = state(rabbit, np.random.default_rng(2))
    n = rabbit.n
    for leg in (1, 2, 0):
        f, A, fu, _fp, force = lin.flow(q, dq, u, leg)
        if leg:
            A_q, A_dq, A_u, F_q, F_dq, F_u = rabbit.stance_dynamics_jacobian(q, dq, u, leg)
            assert np.allclose(force[0], rabbit.stance_dynamics(q, dq, u, leg)[1], rtol=1e-12, atol=1e-9)
            assert rel(force[1], np.hstack([F_q, F_dq])) < 1e-12 and rel(force[2], F_u) < 1e-12
        else:
            A_q, A_dq, A_u = rabbit.flight_dynamics_jacobian(q, dq, u)
        assert A.shape == (2 * n, 2 * n) and fu.shape == (2 * n, 4)
        assert rel(A[n:], np.hstack([A_q, A_dq])) < 1e-12 and rel(fu[n:], A_u) < 1e-12
        assert np.array_equal(A[:n], np.hstack([np.zeros((n, n)), np.eye(n)])) and np.array_equal(f[:n], dq)
    for leg in (1, 2):
        dqp, imp, Rq, Rv, _ = lin.impact(q, dq, leg)
        P_q, P_dq, _I_q, _I_dq = rabbit.impact_map_jacobian(q, dq, leg)
        assert rel(Rq, P_q) < 1e-12 and rel(Rv, P_dq) < 1e-12
        g, gx, _ = lin.touchdown_guard(q, leg)
        height = lambda v: np.array([lin.touchdown_guard(v, leg)[0]])   # noqa: E731
        assert rel(gx[:n], central(height, q)[0]) < 1e-8 and not gx[n:].any()
        T = lin.stance_tangent(q, dq, leg)
        assert T.shape == (2 * n, 2 * (n - 2))
        # the stance foot stays put along the tangent: J_c dq and its rate's derivative vanish on it
        J = rabbit.contact_jacobian(q, leg)
        v_q, v_dq = rabbit.contact_velocity_jacobian(q, dq, leg)
        assert np.allclose(J @ T[:n], 0, atol=1e-12) and np.allclose(v_q @ T[:n] + v_dq @ T[n:], 0, atol=1e-12)


def rabbit_before_touchdown():
    """RABBIT on foot 1 (pinned at the origin), foot 2 3 cm up and ahead, falling forward with no torque: foot 2
    lands 0.205 s later (normal impulse 2.7 N s, the stance force positive to the end)."""
    rabbit = ROBOTS["rabbit"]
    q = np.array([0.0, 0.0, np.pi + 0.25, np.pi - 0.3, 0.05, -0.3, 0.05])
    q[:2] -= rabbit.contact_position(q, 1)
    dq = np.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0])
    dq[:2] = -rabbit.contact_jacobian(q, 1)[:, 2:] @ dq[2:]
    return rabbit, q, dq


def test_rabbits_run_jacobian_through_a_touchdown():
    """The variational equations and the saltation matrix of the run code (sensitivity._Integration, as
    run_jacobian drives it) on RABBIT's generated terms: from a stance state on foot 1 through the touchdown
    and impact of foot 2 and 30 ms of stance on it, against central differences of the same hybrid map
    (scipy's DOP853 on GeneratedModel.stance_dynamics to the foot's crossing, GeneratedModel.impact_map),
    to 1e-7 relative; so too the state just after the impact and the touchdown's time."""
    from scipy.integrate import solve_ivp

    rabbit, q0, dq0 = rabbit_before_touchdown()
    n, u = rabbit.n, np.zeros(4)

    def flow(leg):
        return lambda t, x: np.concatenate([x[n:], rabbit.stance_dynamics(x[:n], x[n:], u, leg)[0]])

    def height_2(t, x):
        return rabbit.contact_position(x[:n], 2)[1]
    height_2.terminal, height_2.direction = True, -1

    def hybrid(x0, t_end):
        """(touchdown time, state just after the impact, state at t_end on foot 2)."""
        a = solve_ivp(flow(1), (0.0, 1.0), x0, method="DOP853", rtol=1e-12, atol=1e-12, events=height_2)
        te, x = a.t_events[0][0], a.y_events[0][0]
        plus = np.concatenate([x[:n], rabbit.impact_map(x[:n], x[n:], 2)[0]])
        b = solve_ivp(flow(2), (te, t_end), plus, method="DOP853", rtol=1e-12, atol=1e-12)
        return te, plus, b.y[:, -1]

    x0 = np.concatenate([q0, dq0])
    te, plus, end = hybrid(x0, 1.0)
    assert 0.2 < te < 0.21 and rabbit.impact_map(plus[:n], x0[n:], 2)[1][1] != 0
    t_end = te + 0.03
    lin = Linearization(rabbit)
    T = lin.stance_tangent(q0, dq0, 1)          # 14 x 10: the joint angles and rates, foot 1 kept in place
    m = T.shape[1]
    Su, Sp = np.zeros((4, m)), np.zeros((0, m))
    integ = _Integration(lin, None, u, None, False, (), 1e-12, 1e-12)
    t, x, S = integ._piece(0.0, te, x0, T, Su, Sp, 1, guard=("touchdown", 2))
    x_plus, S_plus, leg, dtau = integ._event(t, x, S, Su, Sp, 1, "touchdown", 2, last=True)
    _x, S_jump, leg, _ = integ._event(t, x, S, Su, Sp, 1, "touchdown", 2, last=False)
    t1, x_end, S_end = integ._piece(t, t_end, x_plus, S_jump, Su, Sp, leg)
    assert leg == 2 and abs(t - te) < 1e-12 and np.allclose(x_plus, plus, rtol=0, atol=1e-10)

    eps = 1e-6
    runs = [(hybrid(x0 + eps * d, t_end), hybrid(x0 - eps * d, t_end)) for d in T.T]
    fd_time = np.array([(a[0] - b[0]) / (2 * eps) for a, b in runs])
    fd_plus = np.column_stack([(a[1] - b[1]) / (2 * eps) for a, b in runs])
    fd_end = np.column_stack([(a[2] - b[2]) / (2 * eps) for a, b in runs])
    assert rel(dtau, fd_time) < 1e-7
    assert rel(S_plus, fd_plus) < 1e-7
    assert rel(S_end, fd_end) < 1e-7


def test_rabbits_dop853_steps_are_differentiated_as_they_stand():
    """variational.steps_transition on RABBIT (n = 7, M = 4): each DOP853 step's Phi is the derivative of its end
    state by its start (central differences of the step itself, 1e-7), under a held torque and under a law
    without a ``jacobian`` (its central differences inside, M x 2n)."""
    from biped_sim.engine import variational
    from biped_sim.engine.sensitivity import LAW_FD, LAW_NONE

    rabbit, q0, dq0 = rabbit_before_touchdown()
    deriv = derivatives(rabbit)
    X0 = np.array([np.concatenate([q0, dq0]), np.concatenate([q0, dq0 + 0.1])])
    t0, H = np.array([0.0, 0.01]), np.array([0.004, 0.007])

    def posture(t, q, dq, stance_leg):       # a PD law on the four joints, no derivative given
        return -50.0 * (q[2:6] - np.array([np.pi + 0.2, np.pi - 0.2, 0.1, -0.2])) - 5.0 * dq[2:6]

    for controller, u_held, how in ((None, np.array([5.0, -3.0, 2.0, 1.0]), LAW_NONE), (posture, None, LAW_FD)):
        X1, Phi, _G, got, _ = variational.steps_transition(deriv, controller, u_held, t0, X0, H, 1)
        assert got == how and Phi.shape == (2, 14, 14)
        for p in range(2):
            def step(x):
                return variational.steps_transition(deriv, controller, u_held, t0[p:p + 1], x[None], H[p:p + 1],
                                                    1)[0][0]
            assert rel(Phi[p], central(step, X0[p], eps=1e-6)) < 1e-7


def test_a_users_description_is_generated_with_its_derivatives_not_taken_from_an_older_cache(tmp_path, monkeypatch):
    """A user's description (a three-link on stilts) is generated with the derivative terms on first use, and a
    module an older generator cached for it (without them) is not used: the generator's version keys the cache."""
    pytest.importorskip("sympy")
    import re
    from pathlib import Path

    import yaml

    from biped_sim.config import codegen
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    data = yaml.safe_load(models.description_path("three_link").read_text())
    data["name"] = "stilts"
    data["links"]["leg_1"]["length"] = data["links"]["leg_2"]["length"] = 1.2
    data["links"]["torso"]["mass"] = 12.0
    path = tmp_path / "stilts.yaml"
    path.write_text(yaml.safe_dump(data))
    desc = models.load_description(str(path))
    # (an older generator's module of this description: the shipped three-link's without the derivative terms,
    # under this description's digest; its numbers do not matter, as it must not be read)
    shipped = Path(ROBOTS["three_link"].module.__file__).read_text()
    older = re.sub(r"\n\n\ndef (mass_matrix_jacobian|bias_forces_jacobian|contact_jacobian_jacobians|"
                   r"contact_bias_jacobians)\(.*?(?=\n\n\ndef )", "", shipped, flags=re.S)
    older = re.sub(r"DIGEST = '\w+'", f"DIGEST = {desc.digest()!r}", older)
    assert "def mass_matrix_jacobian" not in older and "def mass_matrix(" in older
    models.cache_dir().mkdir(parents=True)
    (models.cache_dir() / f"stilts-{desc.digest()}-g{codegen.GENERATOR_VERSION - 1}.py").write_text(
        older.replace(f"GENERATOR_VERSION = {codegen.GENERATOR_VERSION}", f"GENERATOR_VERSION = "
                      f"{codegen.GENERATOR_VERSION - 1}"))
    stilts = bs.load_model(str(path))
    assert stilts.module.GENERATOR_VERSION == codegen.GENERATOR_VERSION >= 2
    assert len(list(models.cache_dir().glob("stilts-*.py"))) == 2
    check_phase_jacobians(stilts, *state(stilts, np.random.default_rng(5)))
