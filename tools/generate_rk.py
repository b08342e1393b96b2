#!/usr/bin/env python3
"""Generate biped_sim/engine/_gen/rk_steps.py: one step of each explicit Runge-Kutta pair, unrolled over lists.

Run whenever a tableau changes (never, in practice; ``make generate`` runs it). The coefficients
are scipy's (the public class attributes of ``scipy.integrate.DOP853`` and ``RK45``):
Dormand-Prince 8(5,3) as in scipy's ``DOP853`` and
Dormand-Prince 5(4) as in scipy's ``RK45``, with the same error norms and step control.

Why generated and unrolled: the engine's states have 7 or 11 entries, and for vectors that short
every numpy call costs more than the arithmetic it does. Each step comes in a generic form (one
list comprehension per stage, the zero entries of the tableau left out, h folded into the
combination) and, for the engine's sizes, a fully unrolled form where every entry is its own local
(no comprehension, no zip): the right-hand side then takes and returns lists, with no array
conversion at all.
"""
import pathlib

from scipy.integrate import DOP853, RK45  # their public coefficient tables

OUT = pathlib.Path(__file__).resolve().parent.parent / "biped_sim" / "engine" / "_gen" / "rk_steps.py"
# the engine's state sizes (2 N + 1): the three-link's fixed-base stance (7) and floating base with the work (11);
# a described robot's floating base of 4 coordinates (9) and of 7 (15, RABBIT)
UNROLLED = (7, 9, 11, 15)


class Tableau:
    def __init__(self, name, A, B, C, errors, norm):
        self.name, self.A, self.B, self.C = name, A, B, C
        self.s = len(B)                 # stages before the FSAL stage k_s = fun(t + h, y_new)
        self.errors = errors            # combinations over k_0..k_s giving the error estimates
        self.norm = norm                # "hairer853" or "rms" (scipy's norms for the two pairs)


TABLEAUX = [
    Tableau("dop853", DOP853.A, DOP853.B, DOP853.C, [DOP853.E5, DOP853.E3], "hairer853"),
    Tableau("dopri5", RK45.A, RK45.B, RK45.C, [RK45.E], "rms"),
]


def combination(coefs, names):
    return " + ".join(f"{float(c)!r} * {n}" for c, n in zip(coefs, names) if c != 0.0)


def comprehension(base, coefs):
    """[base_i + h * (sum_j coefs_j k_j,i) for each i] (or the bare sum when base is None)."""
    used = [j for j, c in enumerate(coefs) if c != 0.0]
    names = [f"v{j}" for j in used]
    lin = combination([coefs[j] for j in used], names)
    head = f"{base} + h * ({lin})" if base else lin
    loop = ", ".join(([base] if base else []) + names)
    return f"[{head} for {loop} in zip({', '.join(([base + 's'] if base else []) + [f'k{j}' for j in used])})]"


def error_lines(tb, n, per_entry):
    """Lines computing ``err`` (accept the step when err < 1) from the error combinations."""
    out = []
    if tb.norm == "hairer853":
        out.append("    n5 = n3 = 0.0")
        out += per_entry(["n5", "n3"])
        out.append("    # scipy's |h| |err5|^2 / sqrt((|err5|^2 + 0.01 |err3|^2) n) on the unscaled stages")
        out.append(f"    err = 0.0 if n5 == 0.0 and n3 == 0.0 else h * n5 / sqrt((n5 + 0.01 * n3) * {n})")
    else:
        out.append("    n5 = 0.0")
        out += per_entry(["n5"])
        out.append("    # scipy's RK45: the RMS norm of h K^T E scaled by atol + rtol max(|y|, |y_new|)")
        out.append(f"    err = h * sqrt(n5 / {n})")
    return out


def generic(tb):
    s = tb.s
    ks = ", ".join(f"k{j}" for j in range(s + 1))
    lines = ["", "", f"def {tb.name}_step(fun, t, ys, k0, h, rtol, atol):",
             f'    """One {tb.name} step of size h from (t, ys), k0 = fun(t, ys): (y_new, k{s} = fun(t + h, y_new),',
             '    err, stages). Accept the step when err < 1; ``stages`` (unscaled) feed the dense output."""']
    for i in range(1, s):
        lines.append(f"    k{i} = fun(t + {float(tb.C[i])!r} * h, {comprehension('y', tb.A[i, :i])})")
    lines.append(f"    y_new = {comprehension('y', tb.B)}")
    lines.append(f"    k{s} = fun(t + h, y_new)")
    names = [f"e{i}" for i in range(len(tb.errors))]
    for nm, E in zip(names, tb.errors):
        lines.append(f"    {nm} = {comprehension(None, E)}")

    def per_entry(acc):
        loop = [f"p{i}" for i in range(len(names))]
        body = [f"    for a, b, {', '.join(loop)} in zip(ys, y_new, {', '.join(names)}):",
                "        a = abs(a)", "        b = abs(b)", "        sc = atol + rtol * (a if a > b else b)"]
        for a, p in zip(acc, loop):
            body += [f"        {p} /= sc", f"        {a} += {p} * {p}"]
        return body
    lines += error_lines(tb, "len(ys)", per_entry)
    lines.append(f"    return y_new, k{s}, err, ({ks},)")
    return lines


def unrolled(tb, n):
    s = tb.s
    out = ["", "", f"def {tb.name}_step_{n}(fun, t, ys, k0, h, rtol, atol):",
           f'    """``{tb.name}_step`` for states of exactly {n} entries, unrolled."""',
           "    " + ", ".join(f"y_{i}" for i in range(n)) + " = ys",
           "    " + ", ".join(f"k0_{i}" for i in range(n)) + " = k0"]

    def row(coefs, i, base):
        terms = " + ".join(f"{float(c)!r} * k{j}_{i}" for j, c in enumerate(coefs) if c != 0.0)
        return f"y_{i} + h * ({terms})" if base else terms

    for st in range(1, s):
        entries = ", ".join(row(tb.A[st, :st], i, True) for i in range(n))
        out.append(f"    k{st} = fun(t + {float(tb.C[st])!r} * h, [{entries}])")
        out.append("    " + ", ".join(f"k{st}_{i}" for i in range(n)) + f" = k{st}")
    out.append("    y_new = [" + ", ".join(row(tb.B, i, True) for i in range(n)) + "]")
    out.append(f"    k{s} = fun(t + h, y_new)")
    out.append("    " + ", ".join(f"k{s}_{i}" for i in range(n)) + f" = k{s}")

    def per_entry(acc):
        body = []
        for i in range(n):
            body += [f"    a = abs(y_{i})", f"    b = abs(y_new[{i}])", "    sc = atol + rtol * (a if a > b else b)"]
            for a, E in zip(acc, tb.errors):
                body += [f"    e = ({row(E, i, False)}) / sc", f"    {a} += e * e"]
        return body
    out += error_lines(tb, n, per_entry)
    out.append(f"    return y_new, k{s}, err, ({', '.join(f'k{j}' for j in range(s + 1))},)")
    return out


# the step's stages that the dense output reads (the others have zero weight there)
DOP853_DENSE_STAGES = sorted({0, DOP853.n_stages} | {m for row in list(DOP853.A_EXTRA) + list(DOP853.D)
                                                      for m, v in enumerate(row) if v != 0.0 and m <= DOP853.n_stages})


def dop853_dense(n):
    """The 7th-order dense output of one DOP853 step (scipy's Dop853DenseOutput): its three extra
    stages and the rows f0..f6 of the nested product (see integrators._DOP853Interpolant), per entry."""
    s = DOP853.n_stages     # 12: k0..k12 are the step's stages (k12 the FSAL one)
    ks = ", ".join(f"k{j}" for j in DOP853_DENSE_STAGES)
    out = ["", "", f"def dop853_dense_{n}(fun, t, h, ys, y_new, {ks}):",
           f'    """DOP853\'s dense output over the step (t, t + h) of {n} entries: per entry (y, f0, ..., f6)',
           '    of ((((((f0 x + f1) u + f2) x + f3) u + f4) x + f5) u + f6) x + y, x = (t\' - t) / h, u = 1 - x."""',
           "    " + ", ".join(f"y_{i}" for i in range(n)) + " = ys",
           "    " + ", ".join(f"y1_{i}" for i in range(n)) + " = y_new"]
    for j in DOP853_DENSE_STAGES:
        out.append("    " + ", ".join(f"k{j}_{i}" for i in range(n)) + f" = k{j}")
        out += [f"    K{j}_{i} = h * k{j}_{i}" for i in range(n)]
    for r, (a, c) in enumerate(zip(DOP853.A_EXTRA, DOP853.C_EXTRA)):
        j = s + 1 + r
        entries = ", ".join("y_%d + (%s)" % (i, " + ".join(f"{float(v)!r} * K{m}_{i}" for m, v in enumerate(a[:j])
                                                              if v != 0.0)) for i in range(n))
        out.append(f"    k{j} = fun(t + {float(c)!r} * h, [{entries}])")
        out.append("    " + ", ".join(f"k{j}_{i}" for i in range(n)) + f" = k{j}")
        out += [f"    K{j}_{i} = h * k{j}_{i}" for i in range(n)]
    rows = []
    for i in range(n):
        out.append(f"    dy_{i} = y1_{i} - y_{i}")
        dense = [" + ".join(f"{float(v)!r} * K{m}_{i}" for m, v in enumerate(D_row) if v != 0.0) for D_row in DOP853.D]
        # scipy's F rows: dy, K0 - dy, 2 dy - (K12 + K0), D K; the nested product takes them reversed
        F = [f"dy_{i}", f"K0_{i} - dy_{i}", f"2.0 * dy_{i} - (K{s}_{i} + K0_{i})"] + [f"({d})" for d in dense]
        rows.append("(y_%d, %s)" % (i, ", ".join(reversed(F))))
    out.append("    return [" + ", ".join(rows) + "]")
    return out


def dopri5_dense(n):
    """DOPRI5's free 4th-order dense output (scipy's RK45 with its P): per entry (y, q1, q2, q3, q4) of
    y + h (((q4 x + q3) x + q2) x + q1) x, x = (t' - t) / h."""
    s = RK45.n_stages      # 6: k0..k6
    ks = ", ".join(f"k{j}" for j in range(s + 1))
    out = ["", "", f"def dopri5_dense_{n}(ys, {ks}):",
           f'    """DOPRI5\'s dense output over a step of {n} entries: per entry (y, q1, q2, q3, q4) of',
           '    y + h (((q4 x + q3) x + q2) x + q1) x, x = (t\' - t) / h (scipy\'s Q = K^T P)."""',
           "    " + ", ".join(f"y_{i}" for i in range(n)) + " = ys"]
    for j in range(s + 1):
        out.append("    " + ", ".join(f"k{j}_{i}" for i in range(n)) + f" = k{j}")
    rows = []
    for i in range(n):
        qs = [" + ".join(f"{float(RK45.P[j, p])!r} * k{j}_{i}" for j in range(s + 1) if RK45.P[j, p] != 0.0)
              for p in range(RK45.P.shape[1])]
        rows.append("(y_%d, %s)" % (i, ", ".join(f"({q})" for q in qs)))
    out.append("    return [" + ", ".join(rows) + "]")
    return out


lines = ['"""GENERATED by tools/generate_rk.py from scipy\'s tableaux -- do not edit.',
         "",
         "One step of Dormand-Prince 8(5,3) and of Dormand-Prince 5(4) on Python lists, and their dense",
         "output (see integrators.DOP853Stepper and integrators.DOPRI5Stepper).",

         '"""',
         "from math import sqrt",
         "",
         f"N_STAGES = {{'dop853': {DOP853.n_stages}, 'dopri5': {RK45.n_stages}}}   # stages a step evaluates",
         f"DOP853_DENSE_STAGES = {tuple(int(j) for j in DOP853_DENSE_STAGES)}   # the stages dop853_dense_<n> takes"]
for tb in TABLEAUX:
    lines += generic(tb)
    for n in UNROLLED:
        lines += unrolled(tb, n)
    dense = dop853_dense if tb.name == "dop853" else dopri5_dense
    for n in UNROLLED:
        lines += dense(n)
    lines += ["", "", f"{tb.name.upper()}_DENSE = {{" + ", ".join(f"{n}: {tb.name}_dense_{n}" for n in UNROLLED) + "}"]
    lines += ["", "", f"{tb.name.upper()}_STEPS = {{" + ", ".join(f"{n}: {tb.name}_step_{n}" for n in UNROLLED)
              + "}   # by state size; " + f"{tb.name}_step for any other"]
OUT.write_text("\n".join(lines) + "\n")
print(f"wrote {OUT}")
