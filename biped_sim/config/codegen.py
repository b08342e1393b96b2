"""The dynamics of a robot description, derived from its energies with sympy and emitted as Python.

Owns the generic generator: for a :class:`~biped_sim.engine.description.RobotDescription` with N
coordinates, M actuators and L contact points it derives (docs/models.md, "The generated dynamics")

    T = sum_links 1/2 m |v_centre|^2 + 1/2 I w^2,   V = g sum_links m y_centre,
    D = d^2T/d dq^2,  C from the Christoffel symbols of D,  G = dV/dq,  B (a unit column per actuator),
    p_c (each contact point),  J_c = dp_c/dq,  Jdot_c = sum_k dJ_c/dq_k dq_k,

and the derivatives the linearisation of the phases needs (engine/sensitivity.py, docs/gait.md "Derivatives
for any robot"): dD/dq_k, d(C dq + G)/dq and d(C dq + G)/d dq, and per contact dJ_c/dq_k, d(Jdot_c dq)/dq
and d(Jdot_c dq)/d dq,
and writes them as straight-line scalar code with shared subexpressions (``sympy.cse``) into one module
per description, with the description's numbers in it. The three-link biped's engine keeps its own
closed forms (tools/generate_model.py); this generator's three-link output agrees with them to 1e-12
(test/unit/test_robot_models.py). sympy is needed here only: the shipped models' modules are generated
by ``make generate`` (tools/generate_models.py); a user's description on first use (biped_sim.config.models).
"""
from __future__ import annotations

import re

from biped_sim.engine.description import RobotDescription
from biped_sim.engine.generated_model import at_tip as _at_tip, parameter_names

#: bumps when the emitted code changes, so that cached modules of an older generator are rebuilt
GENERATOR_VERSION = 2
#: bumps when the emitted code of the parameters' module (``generate_parameter_source``) changes
PARAMETER_GENERATOR_VERSION = 1


def _sympy():
    try:
        import sympy
    except ImportError:
        return None
    return sympy


def symbolic(desc: RobotDescription):
    """The symbolic model of ``desc``: a dict of sympy objects (q, dq, D, C, G, B, T, V, feet, J, Jdot, ...)."""
    sp = _sympy()
    n = desc.n
    q = sp.symbols(" ".join(f"q{i}" for i in range(n)), real=True)
    dq = sp.symbols(" ".join(f"dq{i}" for i in range(n)), real=True)
    Q, DQ = sp.Matrix(q), sp.Matrix(dq)

    def num(v):
        return sp.Integer(int(v)) if float(v).is_integer() else sp.Float(repr(float(v)))

    index = {link.name: 2 + i for i, link in enumerate(desc.links)}
    by_name = {link.name: link for link in desc.links}
    frames = {}

    def frame(name):
        """(origin, absolute angle) of a link's frame."""
        if name in frames:
            return frames[name]
        link = by_name[name]
        if link.parent is None:
            o, a = sp.Matrix([q[0], q[1]]), q[index[name]]
        else:
            po, pa = frame(link.parent)
            o = point(po, pa, link.origin)
            a = pa + num(link.sign) * q[index[name]] + num(link.offset)
        frames[name] = (o, a)
        return o, a

    def point(o, a, p):
        px, pz = num(p[0]), num(p[1])
        return o + px * sp.Matrix([sp.cos(a), -sp.sin(a)]) + pz * sp.Matrix([sp.sin(a), sp.cos(a)])

    g = num(desc.gravity)
    T, V = sp.Integer(0), sp.Integer(0)
    total = sp.Integer(0)
    com_sum = sp.zeros(2, 1)
    for link in desc.links:
        o, a = frame(link.name)
        c = point(o, a, link.com)
        m, inertia = num(link.mass), num(link.inertia)
        v = c.jacobian(Q) * DQ
        w = (sp.Matrix([a]).jacobian(Q) * DQ)[0]
        T += sp.Rational(1, 2) * m * (v.T * v)[0] + sp.Rational(1, 2) * inertia * w ** 2
        V += g * m * c[1]
        total += m
        com_sum += m * c
    D = sp.hessian(T, dq).applyfunc(lambda e: sp.trigsimp(sp.expand(e)))
    C = sp.zeros(n, n)
    dD = [[[sp.diff(D[k, j], q[i]) for i in range(n)] for j in range(n)] for k in range(n)]
    for k in range(n):
        for j in range(n):
            C[k, j] = sum(sp.Rational(1, 2) * (dD[k][j][i] + dD[k][i][j] - dD[i][j][k]) * dq[i] for i in range(n))
    G = sp.Matrix([sp.diff(V, c) for c in q])
    B = sp.zeros(n, len(desc.actuated))
    for col, j in enumerate(desc.actuated):
        B[2 + [link.joint for link in desc.links].index(j), col] = 1
    feet = [point(*frame(c.link), c.point) for c in desc.contacts]
    J = [f.jacobian(Q) for f in feet]
    dJ = [[Ji.diff(q[k]) for k in range(n)] for Ji in J]
    Jdot = [sum((dJc[k] * dq[k] for k in range(n)), sp.zeros(2, n)) for dJc in dJ]
    joints = []      # the drawing: each link's joint and tip
    for link in desc.links:
        o, a = frame(link.name)
        joints.append((o, point(o, a, (0.0, link.length))))
    h = C * DQ + G
    Jdot_dq = [Jd * DQ for Jd in Jdot]
    return dict(q=q, dq=dq, T=T, V=V, D=D, C=C, G=G, B=B, h=h, feet=feet, J=J, Jdot=Jdot,
                com=com_sum / total, total_mass=total, segments=joints,
                # the derivatives of the phases (docs/gait.md "Derivatives for any robot"): dD/dq_k, dh/dq and
                # dh/d dq, and per contact dJ_c/dq_k, Jdot_c dq with d(Jdot_c dq)/dq and d(Jdot_c dq)/d dq
                dD=[D.diff(q[k]) for k in range(n)], dh_dq=h.jacobian(Q), dh_ddq=h.jacobian(DQ),
                dJ=dJ, Jdot_dq=Jdot_dq, dJdot_dq=[j.jacobian(Q) for j in Jdot_dq],
                dJdot_ddq=[j.jacobian(DQ) for j in Jdot_dq])


POW2 = re.compile(r"\b([A-Za-z_]\w*)\*\*2\b")


def _py(sp, ex):
    return POW2.sub(r"\1*\1", sp.pycode(ex, fully_qualified_modules=False))


def _function(sp, name, args, outputs, doc, n):
    """A function of straight-line code: unpack q (and dq), shared subexpressions, one returned tuple."""
    flat = []
    for o in outputs:
        flat.extend(list(o) if isinstance(o, sp.MatrixBase) else [o])
    repl, reduced = sp.cse([sp.sympify(e) for e in flat], symbols=sp.numbered_symbols("t"), optimizations="basic")
    lines = [f"def {name}({', '.join(args)}):", f'    """{doc}"""']
    if "q" in args:
        lines.append("    " + ", ".join(f"q{i}" for i in range(n)) + ", = q")
    if "dq" in args:
        lines.append("    " + ", ".join(f"dq{i}" for i in range(n)) + ", = dq")
    lines += [f"    {s} = {_py(sp, e)}" for s, e in repl]
    lines.append("    return (" + ", ".join(_py(sp, r) for r in reduced) + ",)")
    return "\n".join(lines)


def generate_source(desc: RobotDescription) -> str:
    """The Python source of the module of ``desc``'s dynamics (no import but math)."""
    sp = _sympy()
    if sp is None:
        raise RuntimeError("generating a robot's dynamics needs sympy: pip install 'biped_sim[models]'")
    s = symbolic(desc)
    n = desc.n
    feet, J, Jdot = s["feet"], s["J"], s["Jdot"]
    DQ = sp.Matrix(s["dq"])
    chunks = [
        _function(sp, "mass_matrix", ["q"], [s["D"]], f"D(q), {n}x{n} row-major.", n),
        _function(sp, "coriolis_matrix", ["q", "dq"], [s["C"]], "C(q, dq) from the Christoffel symbols of D.", n),
        _function(sp, "gravity_vector", ["q"], [s["G"]], "G(q) = dV/dq.", n),
        _function(sp, "bias_forces", ["q", "dq"], [s["h"]], "C(q, dq) dq + G(q).", n),
        _function(sp, "contact_positions", ["q"], feet, "p_c of every contact point, (x, y) each.", n),
        _function(sp, "contact_jacobians", ["q"], J, f"J_c = dp_c/dq of every contact point, 2x{n} row-major each.", n),
        _function(sp, "contact_jacobian_dots", ["q", "dq"], Jdot, f"dJ_c/dt of every contact point, 2x{n} each.", n),
        _function(sp, "contact_velocities", ["q", "dq"], [Ji * DQ for Ji in J], "dp_c/dt of every contact point.", n),
        _function(sp, "mass_matrix_jacobian", ["q"], s["dD"],
                  f"dD/dq_k for k = 0..{n - 1}, each {n}x{n} row-major: [k, i, j], {n ** 3} values.", n),
        _function(sp, "bias_forces_jacobian", ["q", "dq"], [s["dh_dq"], s["dh_ddq"]],
                  f"dh/dq ({n}x{n}), then dh/d dq ({n}x{n}), row-major, h = C dq + G.", n),
        _function(sp, "contact_jacobian_jacobians", ["q"], [m for dJc in s["dJ"] for m in dJc],
                  f"dJ_c/dq_k of every contact point: for each contact, for k = 0..{n - 1}, 2x{n} row-major "
                  f"([c, k, a, j], {2 * n * n} values a contact).", n),
        _function(sp, "contact_bias_jacobians", ["q", "dq"],
                  [m for c in range(len(J)) for m in (s["Jdot_dq"][c], s["dJdot_dq"][c], s["dJdot_ddq"][c])],
                  f"Jdot_c dq (2), d(Jdot_c dq)/dq (2x{n}), d(Jdot_c dq)/d dq (2x{n}) of every contact point, "
                  f"row-major ({2 + 4 * n} values a contact).", n),
        _function(sp, "energy", ["q", "dq"], [s["T"], s["V"]], "(T, V): kinetic and potential energy.", n),
        _function(sp, "com_position", ["q"], [s["com"]], "The centre of mass of the whole robot.", n),
        _function(sp, "segments", ["q"], [p for seg in s["segments"] for pt in seg for p in pt],
                  "Each link's joint and tip, (x, y) each: the drawing.", n),
    ]
    B = [[int(s["B"][i, j]) for j in range(s["B"].shape[1])] for i in range(n)]
    head = [
        f'"""The dynamics of the robot {desc.name!r}, generated from its description by biped_sim.config.codegen.',
        "",
        "Do not edit: regenerate (make generate for a shipped model). Coordinates: "
        + ", ".join(desc.coordinates) + ".",
        '"""',
        "# ruff: noqa",
        "from math import cos, sin",
        "",
        f"NAME = {desc.name!r}",
        f"DIGEST = {desc.digest()!r}",
        f"GENERATOR_VERSION = {GENERATOR_VERSION}",
        f"COORDINATES = {desc.coordinates!r}",
        f"CONTACTS = {tuple(c.name for c in desc.contacts)!r}",
        f"ACTUATED = {desc.actuated!r}",
        f"B = {B!r}",
        f"RELABELING = {desc.relabeling!r}",
        f"CONTACT_MIRROR = {desc.contact_mirror!r}",
        f"TOTAL_MASS = {float(s['total_mass'])!r}",
        f"LINKS = {tuple(link.name for link in desc.links)!r}",
    ]
    return "\n".join(head) + "\n\n\n" + "\n\n\n".join(chunks) + "\n"


# ---- the derivatives by the model's parameters (a second module per robot, generated on request) ----------

def parametric(desc: RobotDescription):
    """``desc``'s T, V and contact points with its model parameters (``parameter_names``) as sympy symbols: a dict
    (q, dq, names, symbols {name: symbol}, numbers {symbol: the description's value}, T, V, feet)."""
    sp = _sympy()
    n = desc.n
    names = parameter_names(desc)
    symbol = {name: sp.Symbol("P_" + re.sub(r"\W", "_", name), real=True) for name in names}
    values = {}
    for link in desc.links:
        values[f"{link.name}.mass"], values[f"{link.name}.inertia"] = link.mass, link.inertia
        values[f"{link.name}.com_x"], values[f"{link.name}.com_z"] = link.com
        values[f"{link.name}.length"] = link.length
    values["gravity"] = desc.gravity

    def num(v):
        return sp.Integer(int(v)) if float(v).is_integer() else sp.Float(repr(float(v)))

    numbers = {symbol[k]: num(values[k]) for k in names}
    q = sp.symbols(" ".join(f"q{i}" for i in range(n)), real=True)
    dq = sp.symbols(" ".join(f"dq{i}" for i in range(n)), real=True)
    Q, DQ = sp.Matrix(q), sp.Matrix(dq)
    index = {link.name: 2 + i for i, link in enumerate(desc.links)}
    by_name = {link.name: link for link in desc.links}
    frames = {}

    def on_link(link, p):
        """A point of ``link``'s frame, its z the symbol of the link's length when it is the tip."""
        if _at_tip(link, p) and f"{link.name}.length" in symbol:
            return num(p[0]), symbol[f"{link.name}.length"]
        return num(p[0]), num(p[1])

    def point(o, a, p):
        px, pz = p
        return o + px * sp.Matrix([sp.cos(a), -sp.sin(a)]) + pz * sp.Matrix([sp.sin(a), sp.cos(a)])

    def frame(name):
        if name in frames:
            return frames[name]
        link = by_name[name]
        if link.parent is None:
            o, a = sp.Matrix([q[0], q[1]]), q[index[name]]
        else:
            po, pa = frame(link.parent)
            o = point(po, pa, on_link(by_name[link.parent], link.origin))
            a = pa + num(link.sign) * q[index[name]] + num(link.offset)
        frames[name] = (o, a)
        return o, a

    T, V = sp.Integer(0), sp.Integer(0)
    for link in desc.links:
        o, a = frame(link.name)
        c = point(o, a, (symbol[f"{link.name}.com_x"], symbol[f"{link.name}.com_z"]))
        m, inertia = symbol[f"{link.name}.mass"], symbol[f"{link.name}.inertia"]
        v = c.jacobian(Q) * DQ
        w = (sp.Matrix([a]).jacobian(Q) * DQ)[0]
        T += sp.Rational(1, 2) * m * (v.T * v)[0] + sp.Rational(1, 2) * inertia * w ** 2
        V += symbol["gravity"] * m * c[1]
    feet = [point(*frame(c.link), on_link(by_name[c.link], c.point)) for c in desc.contacts]
    return dict(q=q, dq=dq, names=names, symbols=symbol, numbers=numbers, T=T, V=V, feet=feet)


def symbolic_parameters(desc: RobotDescription):
    """The derivatives by each of ``parameter_names(desc)``, p, of D, h = C dq + G, p_c, J_c and Jdot_c dq, with
    the description's numbers substituted after differentiating: a dict of lists over p (dD, dh, dp_c, dJ_c,
    dJdot_dq; the contact terms per contact). T and V are built with the parameters as symbols (``parametric``);
    h and Jdot_c dq are linear in (T, V) and in p_c, so their derivatives are those of dT/dp, dV/dp and dp_c/dp."""
    sp = _sympy()
    m = parametric(desc)
    n, names, symbol, numbers = desc.n, m["names"], m["symbols"], m["numbers"]
    q, dq, T, V, feet = m["q"], m["dq"], m["T"], m["V"], m["feet"]
    Q, DQ = sp.Matrix(q), sp.Matrix(dq)

    def sub(e):
        return e.xreplace(numbers)

    out = dict(names=names, dD=[], dh=[], dfeet=[], dJ=[], dJdot_dq=[])
    for name in names:
        s = symbol[name]
        Tp, Vp = sp.expand(sub(sp.diff(T, s))), sub(sp.diff(V, s))
        Dp = sp.hessian(Tp, dq)
        dDp = [Dp.diff(q[k]) for k in range(n)]
        # h_k = sum_ij (dD_kj/dq_i - 1/2 dD_ij/dq_k) dq_i dq_j + dV/dq_k (C from the Christoffel symbols of D)
        hp = sp.Matrix([sum((dDp[i][k, j] - sp.Rational(1, 2) * dDp[k][i, j]) * dq[i] * dq[j]
                            for i in range(n) for j in range(n)) + sp.diff(Vp, q[k]) for k in range(n)])
        out["dD"].append(Dp)
        out["dh"].append(hp)
        dfeet, dJ, dJd = [], [], []
        for f in feet:
            fp = sub(sp.diff(f, s))
            Jp = fp.jacobian(Q)
            dfeet.append(fp)
            dJ.append(Jp)
            dJd.append((Jp * DQ).jacobian(Q) * DQ)
        out["dfeet"].append(dfeet)
        out["dJ"].append(dJ)
        out["dJdot_dq"].append(dJd)
    return out


def generate_parameter_source(desc: RobotDescription) -> str:
    """The Python source of the module of ``desc``'s derivatives by its model parameters (``parameter_names``):
    one function ``parameter_jacobian(q, dq)`` (no import but math)."""
    sp = _sympy()
    if sp is None:
        raise RuntimeError("generating a robot's parameter derivatives needs sympy: pip install 'biped_sim[models]'")
    s = symbolic_parameters(desc)
    n, names, C = desc.n, s["names"], len(desc.contacts)
    P = len(names)
    flat = []
    for p in range(P):
        flat += list(s["dD"][p])
    flat += [s["dh"][p][i] for i in range(n) for p in range(P)]
    for c in range(C):
        for p in range(P):
            flat += list(s["dJ"][p][c])
    for c in range(C):
        flat += [s["dJdot_dq"][p][c][a] for a in range(2) for p in range(P)]
    for c in range(C):
        flat += [s["dfeet"][p][c][a] for a in range(2) for p in range(P)]
    doc = (f"dD/dp [p, i, j] ({P}x{n}x{n}), dh/dp [i, p] ({n}x{P}), per contact dJ_c/dp [p, a, j] ({P}x2x{n}), "
           f"per contact d(Jdot_c dq)/dp [a, p] (2x{P}), per contact dp_c/dp [a, p] (2x{P}); p in PARAMETER_NAMES' "
           "order, h = C dq + G.")
    head = [
        f'"""The derivatives of the robot {desc.name!r}\'s dynamics by its model parameters, generated from its',
        "description by biped_sim.config.codegen.generate_parameter_source.",
        "",
        "Do not edit: regenerate (make generate for a shipped model).",
        '"""',
        "# ruff: noqa",
        "from math import cos, sin",
        "",
        f"NAME = {desc.name!r}",
        f"DIGEST = {desc.digest()!r}",
        f"GENERATOR_VERSION = {GENERATOR_VERSION}",
        f"PARAMETER_GENERATOR_VERSION = {PARAMETER_GENERATOR_VERSION}",
        f"PARAMETER_NAMES = {names!r}",
        f"CONTACTS = {tuple(c.name for c in desc.contacts)!r}",
    ]
    body = _function(sp, "parameter_jacobian", ["q", "dq"], flat, doc, n)
    return "\n".join(head) + "\n\n\n" + body + "\n"
