"""The described robots' kernels per call: the compiled twin (biped_sim/engine/model_kernels.py) against
the numpy path (the generated Python and ``np.linalg.solve`` of the KKT system), lists in, lists out, as
the hybrid loop calls them; for RABBIT (N = 7) and the three-link biped's description (N = 5); each of
the twin's six kernels for RABBIT; and the time a user's robot waits for its twin to be built on first
use (the C compiler, once per description).

    python -m benchmarks.bench --only models
    python -m benchmarks.bench_models --numba      # adds numba.njit of the generated Python (option b)

Owns measurement only (no assertions). Each figure is the median over 7 repeats of the mean per call.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
import timeit
from pathlib import Path

import numpy as np

from biped_sim.config.models import generated_model
from biped_sim.engine import model_kernels


def _median_us(fn, number, repeat=7):
    return statistics.median(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e6


def numpy_stance(model):
    """k_stance as the numpy path runs it: the generated functions, the (N+2)x(N+2) KKT system, np.linalg.solve."""
    mod, n, B = model.module, model.n, model.B
    w = 2 * n

    def k_stance(q, dq, u, c):
        K = np.zeros((n + 2, n + 2))
        K[:n, :n] = np.array(mod.mass_matrix(q)).reshape(n, n)
        J = np.array(mod.contact_jacobians(q)[w * c: w * c + w]).reshape(2, n)
        K[:n, n:], K[n:, :n] = -J.T, J
        Jd = np.array(mod.contact_jacobian_dots(q, dq)[w * c: w * c + w]).reshape(2, n)
        rhs = np.concatenate([B @ np.asarray(u, dtype=float) - np.array(mod.bias_forces(q, dq)),
                              -Jd @ np.asarray(dq, dtype=float)])
        x = np.linalg.solve(K, rhs)
        return x[:n].tolist(), x[n:].tolist()
    return k_stance


def numba_stance(model):
    """Option (b): numba.njit of the generated module's functions and of the KKT solve (cache on disk), called
    with lists converted to arrays; None without numba."""
    try:
        import numba
    except ImportError:
        return None
    mod, n = model.module, model.n
    B = np.ascontiguousarray(model.B)
    mass_matrix = numba.njit(cache=True)(mod.mass_matrix)
    bias = numba.njit(cache=True)(mod.bias_forces)
    jac = numba.njit(cache=True)(mod.contact_jacobians)
    jacdot = numba.njit(cache=True)(mod.contact_jacobian_dots)
    # the generated functions return tuples that mix ints and floats: numba indexes them by constants only,
    # so the KKT system is filled by unrolled statements
    lines = ["def solve(q, dq, u, c):", "    K = np.zeros((n + 2, n + 2))", "    rhs = np.zeros(n + 2)",
             "    Dt, Jt, Jdt, h = mass_matrix(q), jac(q), jacdot(q, dq), bias(q, dq)",
             "    bu = B @ u"]
    lines += [f"    K[{i}, {j}] = Dt[{i * n + j}]" for i in range(n) for j in range(n)]
    lines += [f"    rhs[{k}] = bu[{k}] - h[{k}]" for k in range(n)]
    for c in range(len(model.contacts)):
        lines.append(f"    {'if' if c == 0 else 'elif'} c == {c}:")
        for r in range(2):
            for k in range(n):
                e = 2 * n * c + r * n + k
                lines += [f"        K[{n + r}, {k}] = Jt[{e}]", f"        K[{k}, {n + r}] = -Jt[{e}]",
                          f"        rhs[{n + r}] -= Jdt[{e}] * dq[{k}]"]
    lines.append("    return np.linalg.solve(K, rhs)")
    scope = dict(np=np, n=n, B=B, mass_matrix=mass_matrix, jac=jac, jacdot=jacdot, bias=bias)
    exec("\n".join(lines), scope)
    solve = numba.njit(scope["solve"])

    def k_stance(q, dq, u, c):
        x = solve(np.array(q), np.array(dq), np.array(u, dtype=float), c)
        return x[:n].tolist(), x[n:].tolist()
    return k_stance


def bench_stance(names=("rabbit", "three_link"), with_numba=False, number=20000):
    print("\n== k_stance per call, lists in and out (median of 7 repeats) ==")
    rng = np.random.default_rng(3)
    for name in names:
        model = generated_model(name)
        n, m = model.n, model.B.shape[1]
        q = rng.uniform(-1.0, 1.0, n).tolist()
        q[1] = 1.0
        dq, u = rng.uniform(-1.0, 1.0, n).tolist(), rng.uniform(-5.0, 5.0, m).tolist()
        rows = [("numpy (generated Python + np.linalg.solve)", numpy_stance(model))]
        twin = model_kernels.compiled_kernels(model)
        rows.append(("compiled twin (C)", twin.k_stance if twin else None))
        if with_numba:
            rows.append(("numba.njit of the generated Python", numba_stance(model)))
        figures = {}
        for label, fn in rows:
            if fn is None:
                print(f"  {name:11s} {label:44s} (not available)")
                continue
            fn(q, dq, u, 0)            # compiles numba's; checks it runs
            figures[label] = _median_us(lambda fn=fn: fn(q, dq, u, 0), number)
        base = figures[rows[0][0]]
        for label, us in figures.items():
            print(f"  {name:11s} (N = {n}) {label:44s} {us:8.2f} us  ({base / us:5.1f}x)")


def bench_kernels(name="rabbit", number=20000):
    """Each of the twin's six kernels per call (lists in and out)."""
    model = generated_model(name)
    twin = model_kernels.compiled_kernels(model)
    if twin is None:
        return
    n, m = model.n, model.B.shape[1]
    q, dq, u = [0.1, 0.9] + [3.0 + 0.1 * i for i in range(n - 2)], [0.3] * n, [1.0] * m
    calls = {"k_stance": lambda: twin.k_stance(q, dq, u, 0), "k_flight": lambda: twin.k_flight(q, dq, u),
             "k_impact": lambda: twin.k_impact(q, dq, 1), "k_foot_positions": lambda: twin.k_foot_positions(q),
             "k_foot_kinematics": lambda: twin.k_foot_kinematics(q, dq), "k_energy": lambda: twin.k_energy(q, dq)}
    print(f"\n== the compiled twin of {name} (N = {n}), each kernel per call (median of 7 repeats) ==")
    for label, fn in calls.items():
        print(f"  {label:20s} {_median_us(fn, number):6.2f} us")


def bench_build(names=("rabbit", "three_link"), repeat=3):
    """Wall time of emitting and compiling a twin (what a user's description costs once, besides its sympy
    generation): the shipped modules' sources built into a temporary folder."""
    print("\n== building a twin on first use: emit the C source, compile, link (median of 3) ==")
    for name in names:
        module = generated_model(name).module
        times = []
        for i in range(repeat):
            with tempfile.TemporaryDirectory() as tmp:
                t = time.perf_counter()
                source = model_kernels.kernel_source(module, f"_kernels_bench_{name}")
                model_kernels.build(source, Path(tmp) / f"k{i}.so")
                times.append(time.perf_counter() - t)
        print(f"  {name:11s} (N = {len(module.COORDINATES)}) {statistics.median(times):6.2f} s")


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_models", description=__doc__.split("\n")[0])
    parser.add_argument("--numba", action="store_true", help="add numba.njit of the generated Python")
    parser.add_argument("--number", type=int, default=20000, help="calls per repeat")
    args = parser.parse_args(argv)
    bench_stance(with_numba=args.numba, number=args.number)
    bench_kernels(number=args.number)
    bench_build()
    return 0


if __name__ == "__main__":
    sys.exit(main())
