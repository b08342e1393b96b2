"""`make docs-figures`: regenerate the figures and the measured tables of docs/ from the commands the
pages name. Takes a few minutes; not part of `make test`.

A measured table sits in its page between ``<!-- docs-figures: NAME -->`` and ``<!-- /docs-figures -->``
and is replaced whole; the PNGs and the GIF are written over. Wall times vary from run to run (the
pages say on which machine theirs were taken); errors, steps and event times are deterministic.
"""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
BIN = Path(sys.executable).parent
OUT = ROOT / "bench_out" / "docs_figures"


def run(*argv: str) -> str:
    print("$", " ".join(argv), flush=True)
    proc = subprocess.run([str(BIN / argv[0]), *argv[1:]], cwd=ROOT, capture_output=True, text=True)
    if proc.returncode not in (0, 1):   # 1: a sweep or a suite that reports failures, still a result
        sys.exit(f"{' '.join(argv)} failed (exit code {proc.returncode}):\n{proc.stderr[-3000:]}")
    return proc.stdout


def splice(page: Path, name: str, body: str):
    text = page.read_text()
    pattern = re.compile(rf"(<!-- docs-figures: {re.escape(name)} -->\n).*?(<!-- /docs-figures -->)", re.S)
    if not pattern.search(text):
        sys.exit(f"{page}: no <!-- docs-figures: {name} --> block")
    page.write_text(pattern.sub(lambda m: m[1] + body.rstrip("\n") + "\n" + m[2], text))
    print(f"  {page.relative_to(ROOT)}: {name} replaced")


def accuracy():
    out = OUT / "accuracy"
    run("biped-sim", "accuracy", "--repeats", "5", "--out", str(out), "--no-progress")
    shutil.copy(out / "work_precision.png", DOCS / "work_precision.png")
    splice(DOCS / "accuracy.md", "accuracy", (out / "accuracy.md").read_text())


def stability():
    from biped_sim.analysis import stability as suite
    t0 = time.perf_counter()
    verdicts = suite.run_suite()
    wall = time.perf_counter() - t0
    n = {w: sum(v.word == w for v in verdicts) for w in ("PASS", "FAIL", "SKIP")}
    rows = ["| verdict | group | case | figures | s |", "| --- | --- | --- | --- | --- |"]
    rows += [f"| {v.word} | {v.group} | {v.name} | {v.figures.replace('|', '/')} | {v.seconds:.2f} |"
             for v in verdicts]
    rows.append("")
    rows.append(f"`biped-sim stability`: {n['PASS']} passed, {n['FAIL']} failed, {n['SKIP']} not applicable "
                f"in {wall:.1f} s.")
    splice(DOCS / "stability.md", "stability", "\n".join(rows))


def pictures():
    run("biped-sim", "animate", "--scene", "walk", "-o", "docs/walk.gif")
    csv = OUT / "gains.csv"
    run("biped-sim", "sweep", "walk", "--set", "kp=0:150:16", "--set", "kd=0:45:16", "--duration", "5",
        "-o", str(csv), "--plot", "docs/sweep_gain_map.png", "--no-progress")
    run("biped-sim", "basin", "walk", "--span", "0.4,1.0", "--num", "21", "--duration", "5",
        "-o", str(OUT / "basin.csv"), "--plot", "docs/sweep_basin.png", "--no-progress")


def scaling():
    out = subprocess.run([sys.executable, "-m", "benchmarks.bench_sweep", "--scaling"], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout
    figures = "\n".join(line for line in out.splitlines() if not re.match(r"\d{4}-\d\d-\d\d ", line))
    splice(DOCS / "scaling.md", "scaling", "```text\n" + figures + "\n```")


def gait():
    """docs/gait.md: the multipliers of every shipped scene's gait (exact, and the largest difference from central
    differences of the same map), each with the command that prints it: the scene's controller, or for a
    scene without one, no torque (``--controller none``: the compass gait's passive gait); a scene with no
    gait (no impacts, or no periodic step from its start) is left out with its reason printed. And
    docs/gait_multipliers.png, the walk scene's multipliers along its slope, and docs/gait_multipliers_rabbit.png,
    RABBIT's along its law's step angle."""
    import numpy as np

    from biped_sim.analysis.gait import gaits_along, scene_gait
    from biped_sim.config.controllers import no_torque
    from biped_sim.config.scenes import available_scenes, load_scene

    rows = ["| scene | command | multipliers (exact) | max \\|exact - central differences\\| | period (s) |",
            "| --- | --- | --- | --- | --- |"]
    for name in available_scenes():
        scene = load_scene(name)
        passive = scene.controller_params is None
        command = f"`biped-sim gait --scene {name}" + (" --controller none`" if passive else "`")
        try:
            g = scene_gait(scene, controller=no_torque if passive else None)
        except ValueError as exc:       # no impacts, or no periodic step (NoGait): no gait
            print(f"  {name}: no gait: {str(exc).splitlines()[0]}")
            continue
        fd = np.linalg.eigvals(g.jacobian_fd())
        diff = np.max(np.abs(np.sort_complex(g.multipliers) - np.sort_complex(fd)))
        mults = ", ".join(f"{m.real:.7f}" if abs(m.imag) < 1e-12 else f"{m.real:.7f} {m.imag:+.7f}j"
                          for m in g.multipliers)
        rows.append(f"| {name} | {command} | {mults} | {diff:.1e} | {g.period:.6f} |")
    splice(DOCS / "gait.md", "multipliers", "\n".join(rows))
    slopes = np.round(np.arange(0.0, 0.0501, 0.0025), 4)
    found = [(v, g) for v, g, _why in gaits_along("walk", "slope", slopes) if g is not None]
    plot_multipliers(found, "slope of the walk scene (rad, downhill)",
                     "walk scene: multipliers of the gait along the slope (exact Jacobian)", "gait_multipliers.png",
                     dict(fontsize=8))
    print(f"  docs/gait_multipliers.png: {len(found)} of {len(slopes)} slopes with a gait")
    rabbit_multipliers()


def gait_fd():
    """docs/gait.md: how far ``Gait.jacobian_fd()`` is from the exact Jacobian on every shipped gait: with its
    defaults, its Richardson extrapolation at the gait's rtol and at 1e-13, and a single central difference
    D(eps) at the gait's rtol and at 1e-12, for eps = 1e-3 to 1e-6. The reference is the exact Jacobian at
    rtol = atol = 1e-13; each cell: the largest difference of the Jacobian over its largest entry / of the
    multipliers (each matched to its nearest, by the assignment of least cost; the compass gait's legs' three:
    the torso rotor's Jordan pair at 1 is split by rounding) over the largest multiplier, and the wall time of
    the differences."""
    import numpy as np
    from scipy.optimize import linear_sum_assignment

    from biped_sim.analysis.gait import FD_RTOL, FD_STEP, StepMap, scene_gait
    from biped_sim.config.controllers import no_torque
    from biped_sim.config.scenes import available_scenes, load_scene

    def multipliers_apart(fd, ref, skip_rotor):
        cost = np.abs(fd[:, None] - ref[None, :])
        rows, cols = linear_sum_assignment(cost)
        keep = np.abs(ref[cols] - 1.0) > 1e-3 if skip_rotor else slice(None)
        return np.max(cost[rows, cols][keep]) / np.max(np.abs(ref))

    gaits = {}
    for name in available_scenes():
        scene = load_scene(name)
        try:
            gaits[name] = scene_gait(scene, controller=no_torque if scene.controller_params is None else None)
        except ValueError as exc:       # no impacts, or no periodic step: no gait
            print(f"  {name}: no gait: {str(exc).splitlines()[0]}")
    rtol = {name: g.step_map.kw["rtol"] for name, g in gaits.items()}
    if len(set(rtol.values())) != 1:
        sys.exit(f"the shipped gaits' rtol differ ({rtol}): one column per gait's rtol is assumed")
    gait_rtol = next(iter(rtol.values()))
    richardson = f"Richardson, steps {FD_STEP:g} and {FD_STEP / 2:g}"
    settings = [(f"**defaults**: {richardson}, rtol {FD_RTOL:g}", dict()),
                (f"{richardson}, rtol {gait_rtol:g}", dict(rtol=gait_rtol)),
                (f"{richardson}, rtol 1e-13", dict(rtol=1e-13))]
    settings += [(f"D({eps:g}), rtol {tol:g}", dict(eps=eps, rtol=tol, extrapolate=False))
                 for tol in (gait_rtol, 1e-12) for eps in (1e-3, 1e-4, 1e-5, 1e-6)]
    cells = {label: [] for label, _ in settings}
    for name, g in gaits.items():
        smap = g.step_map
        options = {k: v for k, v in smap.kw.items() if k not in ("rtol", "atol", "method", "max_events", "phases")}
        U, _ = smap.basis(g.z)
        A_ref = StepMap(smap.model, smap.controller, rtol=1e-13, atol=1e-13, method=smap.kw["method"],
                        **options).jacobian(g.z, U)
        l_ref = np.linalg.eigvals(A_ref)
        for label, kw in settings:
            t0 = time.perf_counter()
            A = g.jacobian_fd(**kw)
            wall = time.perf_counter() - t0
            dA = np.max(np.abs(A - A_ref)) / np.max(np.abs(A_ref))
            dl = multipliers_apart(np.linalg.eigvals(A), l_ref, name == "compass_gait")
            cells[label].append(f"{dA:.1e} / {dl:.1e} ({wall * 1e3:.0f} ms)" if wall < 1
                                else f"{dA:.1e} / {dl:.1e} ({wall:.1f} s)")
            print(f"  {name}, {label}: {cells[label][-1]}", flush=True)
    rows = ["| `jacobian_fd(...)` | " + " | ".join(gaits) + " |", "| --- |" + " --- |" * len(gaits)]
    rows += [f"| {label} | " + " | ".join(cells[label]) + " |" for label, _ in settings]
    splice(DOCS / "gait.md", "jacobian-fd", "\n".join(rows))


def plot_multipliers(found, xlabel, title, png, legend):
    """docs/PNG: the |multipliers| of the gaits ``found`` ((parameter value, Gait) pairs) along the parameter."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    v = np.array([s for s, _ in found])
    m = np.array([np.abs(g.multipliers) for _, g in found])
    fig, ax = plt.subplots(figsize=(7, 4))
    for i in range(m.shape[1]):
        ax.semilogy(v, m[:, i], "o-", ms=3, label=f"|multiplier {i + 1}|")
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("|Floquet multiplier|")
    ax.set_title(title)
    ax.legend(**legend)
    fig.tight_layout()
    fig.savefig(DOCS / png, dpi=100)


def rabbit_multipliers():
    """docs/gait_multipliers_rabbit.png: RABBIT's multipliers along its law's step angle, continued from the
    scene's gait (0.25 rad) down and up in steps of 0.01 rad."""
    import numpy as np

    from biped_sim.analysis.gait import gaits_along

    down = gaits_along("rabbit", "step_angle", np.round(np.arange(0.25, 0.1749, -0.01), 3))
    up = gaits_along("rabbit", "step_angle", np.round(np.arange(0.25, 0.3251, 0.01), 3))
    along = down[::-1] + up[1:]
    for value, _g, why in along:
        if why:
            print(f"  rabbit step_angle {value}: no gait: {why}")
    found = [(v, g) for v, g, _why in along if g is not None]
    plot_multipliers(found, "step_angle of the rabbit scene's law (rad)",
                     "RABBIT: multipliers of the gait along the step angle (exact Jacobian)",
                     "gait_multipliers_rabbit.png", dict(fontsize=7, ncol=3))
    print(f"  docs/gait_multipliers_rabbit.png: {len(found)} of {len(along)} step angles with a gait")
    for value, g in found:
        print(f"  rabbit step_angle {value}: period {g.period:.4f} s, step {g.step_length:.4f} m, "
              f"|multipliers| {', '.join(f'{abs(x):.4g}' for x in g.multipliers[:3])}, ...")


STEPS = {"accuracy": accuracy, "stability": stability, "pictures": pictures, "scaling": scaling, "gait": gait,
         "gait-fd": gait_fd}

if __name__ == "__main__":
    OUT.mkdir(parents=True, exist_ok=True)
    for name in sys.argv[1:] or STEPS:
        STEPS[name]()
