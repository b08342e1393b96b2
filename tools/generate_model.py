#!/usr/bin/env python3
"""Generate biped_sim/engine/_gen/closed_forms.py: closed-form model expressions from the energies (docs/model.md).

Run once whenever the model changes (``make generate``); the package never imports sympy.
Everything is derived from the kinetic and potential energies of docs/model.md:
  T = sum_links 1/2 m |v_centre|^2 + 1/2 I w^2,   V = g sum_links m y_centre,
  D = d^2T/d dq^2,  C from the Christoffel symbols of D,  G = dV/dq,
  p_i = (x + l_leg sin(qi + q3), y + l_leg cos(qi + q3)),  J_i = dp_i/dq,  Jdot_i.
Two stance solvers are emitted as straight-line scalar code:
  * floating base: the KKT system [D -J^T; J 0][ddq; F] = [-C dq - G + B u; -Jdot dq] solved by
    eliminating the constraint rows (J = [I2 | A], so ddq_base = -A ddq_r - Jdot dq, and the three
    remaining equations are projected on the null space of J, which removes F);
  * fixed base: the stance foot is a pin, the chain has the three coordinates (q1, q2, q3),
    D_s, C_s dq_s and G_s come from the chain's own energies, and F is recovered from Newton's law
    for the whole body (F = m_total * (ddp_com + [0, g])).
The impact of one foot, [D -J^T; J 0][dq+; L] = [D dq-; 0], is reduced as floating-base stance is
(dq+ = P v with J P = 0, P^T D P v = P^T D dq-) and emitted the same way (``impact_map_1/2``).
The parameters are arguments of the generated functions, so changing a mass needs no regeneration.
"""
import pathlib
import re

import sympy as sp

OUT = pathlib.Path(__file__).resolve().parent.parent / "biped_sim" / "engine" / "_gen" / "closed_forms.py"

PARAMS = sp.symbols("m_torso I_torso l_torso c_torso m_leg I_leg l_leg c_leg g", real=True)
m_t, I_t, l_t, c_t, m_l, I_l, l_l, c_l, g = PARAMS
x, y, q1, q2, q3 = q = sp.symbols("x y q1 q2 q3", real=True)
dx, dy, dq1, dq2, dq3 = dq = sp.symbols("dx dy dq1 dq2 dq3", real=True)
u1, u2 = u = sp.symbols("u1 u2", real=True)
Q = sp.Matrix(q)
DQ = sp.Matrix(dq)


def point(base, length, angle):
    return base + length * sp.Matrix([sp.sin(angle), sp.cos(angle)])


hip = sp.Matrix([x, y])
links = [  # (mass, inertia, centre, absolute angle)
    (m_l, I_l, point(hip, c_l, q1 + q3), q1 + q3),
    (m_l, I_l, point(hip, c_l, q2 + q3), q2 + q3),
    (m_t, I_t, point(hip, c_t, q3), q3),
]
feet = [point(hip, l_l, q1 + q3), point(hip, l_l, q2 + q3)]
m_total = 2 * m_l + m_t
com = sum((m * p for m, _, p, _ in links), sp.zeros(2, 1)) / m_total


def energies(coords, dcoords, subs):
    T = 0
    V = 0
    for m, I, p, a in links:
        p = p.subs(subs)
        a = a.subs(subs)
        v = p.jacobian(coords) * dcoords
        w = sp.Matrix([a]).jacobian(coords) * dcoords
        T += sp.Rational(1, 2) * m * (v.T * v)[0] + sp.Rational(1, 2) * I * w[0] ** 2
        V += g * m * p[1]
    return sp.simplify(T), sp.simplify(V)


def lagrange(T, V, coords, dcoords):
    """D, C (Christoffel), G of the Lagrangian T - V."""
    n = len(coords)
    D = sp.hessian(T, dcoords).applyfunc(sp.simplify)
    C = sp.zeros(n, n)
    for k in range(n):
        for j in range(n):
            C[k, j] = sum(
                sp.Rational(1, 2) * (sp.diff(D[k, j], coords[i]) + sp.diff(D[k, i], coords[j])
                                     - sp.diff(D[i, j], coords[k])) * dcoords[i]
                for i in range(n))
    C = C.applyfunc(sp.simplify)
    G = sp.Matrix([sp.diff(V, c) for c in coords]).applyfunc(sp.simplify)
    return D, C, G


# ---- floating base (N = 5) -------------------------------------------------------------------
T, V = energies(Q, DQ, {})
D, C, G = lagrange(T, V, q, dq)
B = sp.Matrix([[0, 0], [0, 0], [1, 0], [0, 1], [0, 0]])
J = [f.jacobian(Q) for f in feet]
Jdot = [sp.zeros(2, 5) for _ in feet]
for i in range(2):
    for k in range(5):
        Jdot[i] += sp.diff(J[i], q[k]) * dq[k]
    Jdot[i] = Jdot[i].applyfunc(sp.simplify)
h = (C * DQ + G).applyfunc(sp.simplify)  # bias forces

# floating-base stance on leg 1 by null-space elimination of the KKT system
A = J[0][:, 2:]                     # J_1 = [I2 | A]
gamma = -(Jdot[0] * DQ)             # ddq_base = -A ddq_r + gamma
P = sp.Matrix.vstack(-A, sp.eye(3))  # J_1 P = 0
e = sp.Matrix([gamma[0], gamma[1], 0, 0, 0])
Mr = (P.T * D * P).applyfunc(sp.simplify)
br = (P.T * (B * sp.Matrix(u) - h - D * e))
Fexpr_rows = D[:2, :]                # F = D[:2,:] ddq + h[:2] (B has no rows for x, y)
# the impact of leg 1 reduces the same way: dq+ = P v (J_1 dq+ = 0), Mr v = P^T D dq- (P^T J^T = 0
# removes the impulse), then the impulse from the base rows, J^T = I there: L = D[:2,:] (dq+ - dq-)
br_impact = (P.T * D * DQ).applyfunc(sp.simplify)

# ---- fixed base (N = 3), stance foot of leg 1 pinned at (cx, cy) --------------------------------
cx, cy = sp.symbols("cx cy", real=True)
qs = sp.Matrix([q1, q2, q3])
dqs = sp.Matrix([dq1, dq2, dq3])
hip_s = sp.Matrix([cx, cy]) - l_l * sp.Matrix([sp.sin(q1 + q3), sp.cos(q1 + q3)])
Ts, Vs = energies(qs, dqs, {x: hip_s[0], y: hip_s[1]})
Ds, Cs, Gs = lagrange(Ts, Vs, [q1, q2, q3], [dq1, dq2, dq3])
hs = (Cs * dqs + Gs).applyfunc(sp.simplify)
com_s = com.subs({x: hip_s[0], y: hip_s[1]})
Jc = com_s.jacobian(qs)
# ddp_com = Jc ddq_s + (d/dt Jc) dq_s; (d/dt Jc) dq_s = sum_k d(Jc dq_s)/dq_k dq_k
vc = Jc * dqs
Jcdot_dq = (vc.jacobian(qs) * dqs).applyfunc(sp.simplify)
hip_s_vel = (hip_s.jacobian(qs) * dqs)


# ---- code emission ---------------------------------------------------------------------------
POW2 = re.compile(r"\b([A-Za-z_]\w*)\*\*2\b")


def py(ex):
    # x*x is about twice as fast as x**2 for Python floats
    return POW2.sub(r"\1*\1", sp.pycode(ex, fully_qualified_modules=False))


def solve_sym3(M, b):
    """x of [[M0 M1 M2][M1 M3 M4][M2 M4 M5]] x = b (symmetric positive definite) by LDL^T, as a list
    of (name, expression) steps: three divisions and about twenty products, about half the
    operations of the adjugate (the right-hand side runs this ~10^4 times a simulated second)."""
    M0, M1, M2, M3, M4, M5 = M
    l10, l20, l21, d1, d2, z1, z2 = sp.symbols("l10 l20 l21 d1 d2 z1 z2")
    x = sp.symbols("a1 a2 a3")
    return [(l10, M1 / M0), (l20, M2 / M0), (d1, M3 - l10 * M1), (l21, (M4 - l20 * M1) / d1),
            (d2, M5 - l20 * M2 - l21 * l21 * d1), (z1, b[1] - l10 * b[0]), (z2, b[2] - l20 * b[0] - l21 * z1),
            (x[2], z2 / d2), (x[1], z1 / d1 - l21 * x[2]), (x[0], b[0] / M0 - l10 * x[1] - l20 * x[2])]


def _symbols(names):
    return list(sp.symbols(" ".join(names)))


REDUCED_TERMS = _symbols("M00 M01 M02 M11 M12 M22 b0 b1 b2 A00 A01 A02 A10 A11 A12".split())
BASE_ROW_TERMS = _symbols("m Dbr00 Dbr01 Dbr02 Dbr10 Dbr11 Dbr12".split())   # m_total, D_br
g0, g1, hb0, hb1 = _symbols("g0 g1 hb0 hb1".split())
STANCE_TERMS = REDUCED_TERMS + [g0, g1] + BASE_ROW_TERMS + [hb0, hb1]
IMPACT_TERMS = REDUCED_TERMS + BASE_ROW_TERMS


def base_rows(vb, vr):
    """The base rows of D times a vector (vb, vr) split in base and joints: m_total vb + D_br vr (D_bb = m_total I2)."""
    m, Dbr00, Dbr01, Dbr02, Dbr10, Dbr11, Dbr12 = BASE_ROW_TERMS
    return [m * vb[0] + Dbr00 * vr[0] + Dbr01 * vr[1] + Dbr02 * vr[2],
            m * vb[1] + Dbr10 * vr[0] + Dbr11 * vr[1] + Dbr12 * vr[2]]


def reduced_solve(base_offset, swap):
    """The reduced floating-base KKT solution (see the module doc): the joint part a = (a1, a2, a3) from
    Mr a = b, then the base part from the constraint rows, a_base = base_offset - A a. Returns (steps,
    a_base, a, the vector (a_base, a) in relabeled order (q1 <-> q2) if ``swap``, for leg 2)."""
    M00, M01, M02, M11, M12, M22, b0, b1, b2, A00, A01, A02, A10, A11, A12 = REDUCED_TERMS
    a1, a2, a3, ax, ay = sp.symbols("a1 a2 a3 ax ay")
    steps = solve_sym3([M00, M01, M02, M11, M12, M22], [b0, b1, b2])
    steps += [(ax, base_offset[0] - A00 * a1 - A01 * a2 - A02 * a3),
              (ay, base_offset[1] - A10 * a1 - A11 * a2 - A12 * a3)]
    return steps, [ax, ay], [a1, a2, a3], [ax, ay, a2, a1, a3] if swap else [ax, ay, a1, a2, a3]


def stance_solve(swap=False):
    """Stance: a = ddq_r, the base from gamma, then F from the base rows of D ddq + h = J^T F + B u (J^T = I)."""
    steps, ab, ar, ddq = reduced_solve((g0, g1), swap)
    F = base_rows(ab, ar)
    return steps, (ddq, [F[0] + hb0, F[1] + hb1])


def impact_solve(swap=False):
    """Impact: a = dq+_r, the base from J dq+ = 0, then the impulse of the ground on the foot from the base
    rows of D (dq+ - dq-) = J^T L (J^T = I), on the differences: L = m_total (dq+_b - dq-_b) + D_br (dq+_r - dq-_r)."""
    steps, (ax, ay), (a1, a2, a3), dq_plus = reduced_solve((0, 0), swap)
    return steps, (dq_plus, base_rows([ax - dx, ay - dy], [a1 - dq1, a2 - dq2, a3 - dq3]))


FIXED_TERMS = _symbols("D00 D01 D02 D11 D12 D22 r0 r1 r2".split())


def fixed_solve():
    steps = solve_sym3(FIXED_TERMS[0:6], FIXED_TERMS[6:9])
    return steps, (list(sp.symbols("a1 a2 a3")),)


def split_constant(ex, const):
    """(constant part, rest) of a sum: the parameter-only terms of an Add, to be hoisted."""
    if not isinstance(ex, sp.Add):
        return None, ex
    c = [a for a in ex.args if a.free_symbols <= const and not a.is_number]
    if len(c) < 2 and not (c and not isinstance(c[0], sp.Symbol)):
        return None, ex
    return sp.Add(*c), sp.Add(*[a for a in ex.args if a not in c])


#: sin and cos of the three angles, named: every sin or cos of a sum of angles is expanded into them, so a
#: function calls sincos three times at most (the stance right-hand side called it on q1 + q3, q2 + q3
#: and q3, and cos on q1 - q2 and q1: five libm calls, a third of the compiled loop's time)
ONE_ANGLE = {f(a): sp.Symbol(f"{'s' if f is sp.sin else 'c'}_{a}") for a in (q1, q2, q3) for f in (sp.sin, sp.cos)}


def one_angle_trig(ex):
    """``ex`` with its sines and cosines in terms of the ``ONE_ANGLE`` names."""
    ex = ex.replace(lambda e: isinstance(e, (sp.sin, sp.cos)) and isinstance(e.args[0], sp.Add), sp.expand_trig)
    return ex.xreplace(ONE_ANGLE)


def name_square_bases(ex, names, bound):
    """``ex`` with the base of every square of a sum or product bound to a new name first (appended to
    ``bound`` as (name, base)): ``t*t`` instead of ``(a + b)**2``, which CPython's float power computes
    with libm's pow (the compiled twin calls the same pow to keep the bits: tens of ns against a product)."""
    if ex.is_Pow and ex.exp == 2 and not ex.base.is_Atom:
        s = next(names)
        bound.append((s, name_square_bases(ex.base, names, bound)))
        return s ** 2
    return ex.func(*[name_square_bases(a, names, bound) for a in ex.args]) if ex.args else ex


def fn(name, unpack, outputs, doc, names=None, tail=None):
    """Two functions of straight-line scalar code with shared subexpressions.

    ``<name>_constants(p)`` computes, once per model, every subexpression that depends on the
    parameters only (also the parameter-only terms of sums); ``<name>(..., k)`` takes that tuple,
    so the hot path repeats none of it. With ``names`` and ``tail`` (a function giving (steps,
    returned)), the outputs are bound to those names and the steps follow: outputs that are a
    number or a symbol are substituted, so a zero entry costs nothing.
    """
    flat = []
    for o in outputs:
        flat.extend(list(o) if isinstance(o, sp.MatrixBase) else [o])
    flat = [one_angle_trig(sp.sympify(e)) for e in flat]
    repl, reduced = sp.cse(flat, symbols=sp.numbered_symbols("t"), optimizations="basic")
    const = set(PARAMS)
    hoisted, body = [], []
    extra = sp.numbered_symbols("kc")

    def hoist(ex):
        c, rest = split_constant(ex, const)
        if c is None:
            return ex
        s = next(extra)
        const.add(s)
        hoisted.append((s, c))
        return rest + s

    for sym, ex in repl:
        if ex.free_symbols <= const:
            const.add(sym)
            hoisted.append((sym, ex))
        else:
            body.append((sym, hoist(ex)))
    reduced = [hoist(r) for r in reduced]
    squares, unsquared = sp.numbered_symbols("sq"), []
    for sym, ex in body:
        ex = name_square_bases(ex, squares, unsquared)
        unsquared.append((sym, ex))
    reduced = [name_square_bases(r, squares, unsquared) for r in reduced]
    body = unsquared
    knames = [str(s) for s in PARAMS] + [str(s) for s, _ in hoisted]
    args = [u.split(" = ")[1] for u in unpack] + ["k"]
    lines = [f"def {name}_constants(p):",
             f'    """Parameter-only subexpressions of {name}."""',
             "    " + ", ".join(str(s) for s in PARAMS) + " = p"]
    lines += [f"    {s} = {py(ex)}" for s, ex in hoisted]
    lines.append("    return (" + ", ".join(knames) + ",)")
    lines += ["", "", f"def {name}({', '.join(args)}):", f'    """{doc}"""']
    lines += ["    " + u for u in unpack]
    used = set().union(*(ex.free_symbols for _, ex in body), *(r.free_symbols for r in reduced))
    lines += [f"    {v} = {py(f)}" for f, v in ONE_ANGLE.items() if v in used]
    lines.append("    " + ", ".join(knames) + " = k")
    lines += [f"    {s} = {py(ex)}" for s, ex in body]
    if tail is None:
        lines.append("    return (" + ", ".join(py(r) for r in reduced) + ",)")
    else:
        atoms = {}
        for n, r in zip(names, reduced):
            if r.is_Atom or (isinstance(r, sp.Mul) and len(r.args) == 2 and r.args[0] == -1 and r.args[1].is_Atom):
                atoms[n] = r          # substituted below instead of bound
            else:
                lines.append(f"    {n} = {py(r)}")
        steps, returned = tail()
        for n, ex in steps:
            lines.append(f"    {n} = {py(ex.subs(atoms))}")
        out = ["[" + ", ".join(py(sp.sympify(e).subs(atoms)) for e in part) + "]" for part in returned]
        lines.append("    return " + ", ".join(out))
    NAMES.append(name)
    return "\n".join(lines)


NAMES = []
STANCE_OUTPUTS = [Mr[0, 0], Mr[0, 1], Mr[0, 2], Mr[1, 1], Mr[1, 2], Mr[2, 2], br, A, gamma, m_total,
                  Fexpr_rows[:, 2:], h[:2, 0]]
IMPACT_OUTPUTS = STANCE_OUTPUTS[:6] + [br_impact, A, m_total, Fexpr_rows[:, 2:]]
UQ = "x, y, q1, q2, q3 = q"
UDQ = "dx, dy, dq1, dq2, dq3 = dq"
UU = "u1, u2 = u"
chunks = [
    fn("mass_matrix", [UQ], [D], "D(q), 5x5 row-major (25 values)."),
    fn("coriolis_matrix", [UQ, UDQ], [C], "C(q, dq) from the Christoffel symbols of D, row-major."),
    fn("gravity_vector", [UQ], [G], "G(q) = dV/dq."),
    fn("bias_forces", [UQ, UDQ], [h], "C(q, dq) dq + G(q)."),
    fn("foot_positions", [UQ], [feet[0], feet[1]], "p_1 (2), then p_2 (2)."),
    fn("foot_jacobian_1", [UQ], [J[0]], "J_1 = dp_1/dq, 2x5 row-major."),
    fn("foot_jacobian_2", [UQ], [J[1]], "J_2 = dp_2/dq, 2x5 row-major."),
    fn("foot_jacobian_dot_1", [UQ, UDQ], [Jdot[0]], "dJ_1/dt, 2x5 row-major."),
    fn("foot_jacobian_dot_2", [UQ, UDQ], [Jdot[1]], "dJ_2/dt, 2x5 row-major."),
    fn("foot_kinematics", [UQ, UDQ], [feet[0], feet[1], J[0] * DQ, J[1] * DQ],
       "p_1 (2), p_2 (2), dp_1/dt (2), dp_2/dt (2)."),
    fn("energy", [UQ, UDQ], [T, V], "(T, V): kinetic and potential energy."),
    fn("com_position", [UQ], [com], "Centre of mass of the whole robot."),
    fn("stance_terms_1", [UQ, UDQ, UU], STANCE_OUTPUTS,
       "Floating-base KKT (leg 1 on the ground), reduced: Mr (6 upper), br (3), A (6), gamma (2), "
       "m_total (1; D_bb = m_total I2), D_br (6), h_b (2)."),
    fn("stance_floating_1", [UQ, UDQ, UU], STANCE_OUTPUTS,
       "Floating-base KKT (leg 1 on the ground) solved: (ddq (5), F (2)) as lists.",
       names=STANCE_TERMS, tail=stance_solve),
    # stance on leg 2 is stance on leg 1 of the relabeled state R x (the legs are identical): the
    # same code reading q1 <-> q2 and u1 <-> u2 swapped, and returning ddq relabeled back
    fn("stance_floating_2", ["x, y, q2, q1, q3 = q", "dx, dy, dq2, dq1, dq3 = dq", "u2, u1 = u"], STANCE_OUTPUTS,
       "Floating-base KKT (leg 2 on the ground) solved: (ddq (5), F (2)) as lists.",
       names=STANCE_TERMS, tail=lambda: stance_solve(swap=True)),
    # the impact of a foot, the same reduction (see impact_solve); leg 2 by relabeling as for stance. The
    # impulse is in world axes, so it is not swapped
    fn("impact_map_1", [UQ, "dx, dy, dq1, dq2, dq3 = dqm"], IMPACT_OUTPUTS,
       "Rigid impact of foot 1 (KKT [D -J^T; J 0][dq+; L] = [D dq-; 0], reduced): (dq+ (5), impulse of the "
       "ground on the foot (2), N s) as lists.", names=IMPACT_TERMS, tail=impact_solve),
    fn("impact_map_2", ["x, y, q2, q1, q3 = q", "dx, dy, dq2, dq1, dq3 = dqm"], IMPACT_OUTPUTS,
       "Rigid impact of foot 2 (impact_map_1 of the relabeled state): (dq+ (5), impulse (2)) as lists.",
       names=IMPACT_TERMS, tail=lambda: impact_solve(swap=True)),
    # split in two so that the right-hand side evaluates only the accelerations; the force (from the
    # centre of mass) is needed only where a guard or an output asks for it
    fn("fixed_base_dynamics_1", ["q1, q2, q3 = qs", "dq1, dq2, dq3 = dqs", UU],
       [Ds[0, 0], Ds[0, 1], Ds[0, 2], Ds[1, 1], Ds[1, 2], Ds[2, 2], sp.Matrix([u1, u2, 0]) - hs],
       "Fixed-base chain pinned at the foot of leg 1: ddq_s (3) of D_s ddq_s = B_s u - C_s dq_s - G_s.",
       names=FIXED_TERMS, tail=fixed_solve),
    fn("fixed_base_kinematics_1", ["q1, q2, q3 = qs", "dq1, dq2, dq3 = dqs"],
       [Jc, Jcdot_dq, -l_l * sp.Matrix([sp.sin(q1 + q3), sp.cos(q1 + q3)]), hip_s_vel],
       "Fixed-base chain pinned at the foot of leg 1: J_com (6), Jdot_com dq_s (2), hip minus foot (2), "
       "hip velocity (2)."),
]
header = '''"""GENERATED by tools/generate_model.py from the energies of docs/model.md -- do not edit.

Straight-line scalar closed forms. Each ``f(..., k)`` takes ``k = f_constants(p)``, computed once
per model from the parameter tuple p = (m_torso, I_torso, l_torso, c_torso, m_leg, I_leg, l_leg,
c_leg, g).
"""
from math import sin, cos

PARAMETER_NAMES = ("m_torso", "I_torso", "l_torso", "c_torso", "m_leg", "I_leg", "l_leg", "c_leg", "g")
'''
footer = "\n\nCONSTANTS = {" + ", ".join(f"{n!r}: {n}_constants" for n in NAMES) + "}\n"
OUT.write_text(header + "\n\n" + "\n\n\n".join(chunks) + footer)
print(f"wrote {OUT}")

# ---- derivatives for the linearisation (engine/sensitivity.py) ----------------------------------------
# The partial derivatives of the terms of the KKT system [D -J^T; J 0][ddq; F] = [-h + B u; -Jdot dq]
# (h = C dq + G), of the fixed-base chain's D_s ddq_s = B_s u - h_s, and of the feet, with respect to
# q, dq and the parameters; engine/sensitivity.py differentiates the KKT solutions with them. A separate
# file: the compiled twin (tools/generate_c.py) covers closed_forms.py only, and none of these is on the
# compiled loop's path.
NAMES.clear()
jdq = [(Jdot[i] * DQ).applyfunc(sp.simplify) for i in range(2)]
PARAMETER_AXES = sp.Matrix(PARAMS)


def by_coordinate(M, coords):
    """dM/dc for each c of coords, stacked (c-major, each row-major)."""
    return [M.diff(c) for c in coords]


deriv_chunks = [
    fn("mass_matrix_jacobian", [UQ], by_coordinate(D, q),
       "dD/dq_k for k = 0..4 (x, y, q1, q2, q3), each 5x5 row-major (125 values)."),
    fn("bias_forces_jacobian", [UQ, UDQ], [h.jacobian(Q), h.jacobian(DQ)],
       "dh/dq (5x5), then dh/ddq (5x5), row-major, h = C dq + G (50 values)."),
    fn("foot_jacobian_jacobian_1", [UQ], by_coordinate(J[0], q), "dJ_1/dq_k for k = 0..4, each 2x5 row-major."),
    fn("foot_jacobian_jacobian_2", [UQ], by_coordinate(J[1], q), "dJ_2/dq_k for k = 0..4, each 2x5 row-major."),
    fn("foot_bias_jacobian_1", [UQ, UDQ], [jdq[0], jdq[0].jacobian(Q), jdq[0].jacobian(DQ)],
       "Jdot_1 dq (2), d(Jdot_1 dq)/dq (2x5), d(Jdot_1 dq)/ddq (2x5), row-major."),
    fn("foot_bias_jacobian_2", [UQ, UDQ], [jdq[1], jdq[1].jacobian(Q), jdq[1].jacobian(DQ)],
       "Jdot_2 dq (2), d(Jdot_2 dq)/dq (2x5), d(Jdot_2 dq)/ddq (2x5), row-major."),
    fn("fixed_base_jacobian_1", ["q1, q2, q3 = qs", "dq1, dq2, dq3 = dqs"],
       [Ds, hs] + by_coordinate(Ds, qs) + [hs.jacobian(qs), hs.jacobian(dqs)],
       "Fixed-base chain pinned at the foot of leg 1: D_s (3x3), h_s = C_s dq_s + G_s (3), dD_s/dq_s,k for "
       "k = 0..2 (each 3x3), dh_s/dq_s (3x3), dh_s/ddq_s (3x3), row-major."),
    fn("parameter_jacobian", [UQ, UDQ],
       by_coordinate(D, PARAMS) + [h.jacobian(PARAMETER_AXES)]
       + [J[i].diff(p_) for i in range(2) for p_ in PARAMS]
       + [jdq[i].jacobian(PARAMETER_AXES) for i in range(2)]
       + [sp.Matrix.vstack(feet[0], feet[1]).jacobian(PARAMETER_AXES)],
       "Derivatives with respect to the parameters p (PARAMETER_NAMES order, 9): dD/dp_j (9 x 25), dh/dp (5x9), "
       "dJ_1/dp_j (9 x 10), dJ_2/dp_j (9 x 10), d(Jdot_1 dq)/dp (2x9), d(Jdot_2 dq)/dp (2x9), d(p_1, p_2)/dp (4x9); "
       "row-major."),
]
OUT_DERIVATIVES = OUT.with_name("derivatives.py")
deriv_header = header.replace("Straight-line scalar closed forms.", "Partial derivatives of the closed forms\n"
                              "(engine/sensitivity.py assembles the phases' Jacobians from them).")
deriv_footer = "\n\nCONSTANTS = {" + ", ".join(f"{n!r}: {n}_constants" for n in NAMES) + "}\n"
OUT_DERIVATIVES.write_text(deriv_header + "\n\n" + "\n\n\n".join(deriv_chunks) + deriv_footer)
print(f"wrote {OUT_DERIVATIVES}")
