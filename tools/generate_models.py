#!/usr/bin/env python3
"""Generate the shipped robots' dynamics modules and URDFs from their YAML descriptions (docs/models.md).

For each name of biped_sim.config.models.SHIPPED: biped_sim/engine/_gen/models/<name>.py (the generic
generator, biped_sim/config/codegen.py; needs sympy), <name>_parameters.py (its derivatives by the model
parameters, codegen.generate_parameter_source: what a run Jacobian by "<link>.mass", ... reads), its compiled
kernels' C source
biped_sim/engine/_gen/models/_kernels_<name>.c (biped_sim.engine.model_kernels, built by setup.py) and
biped_sim/config/robots/<name>.urdf (the same description as a planar URDF,
biped_sim.engine.description.to_urdf, read back and checked equal).
Run by ``make generate``; the package never generates a shipped model at run time.

    python tools/generate_models.py [NAME ...]             # all of them, or the names given
    python tools/generate_models.py --kernels-only [NAME ...]  # the C sources from the committed modules
"""
import importlib
import pathlib
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent))

from biped_sim.config import codegen, models  # noqa: E402
from biped_sim.engine import model_kernels  # noqa: E402
from biped_sim.engine.description import description_from_urdf, to_urdf  # noqa: E402

OUT = pathlib.Path(__file__).resolve().parent.parent / "biped_sim" / "engine" / "_gen" / "models"


def write_kernels(name):
    """_kernels_<name>.c from the module <name>.py as it is on disk."""
    module = importlib.reload(importlib.import_module(f"{model_kernels.SHIPPED_PACKAGE}.{name}"))
    (OUT / f"_kernels_{name}.c").write_text(model_kernels.kernel_source(module, f"_kernels_{name}"))


def main(names, kernels_only=False):
    if kernels_only:
        for name in names:
            write_kernels(name)
        return
    OUT.mkdir(exist_ok=True)
    init = OUT / "__init__.py"
    if not init.exists():
        init.write_text('"""Generated dynamics of the shipped robots (tools/generate_models.py); do not edit."""\n')
    for name in names:
        t = time.perf_counter()
        desc = models.load_description(name)
        urdf = to_urdf(desc)
        back = description_from_urdf(urdf, name=desc.name)
        assert back.structure() == desc.structure(), f"{name}: the URDF does not read back to the YAML's description"
        (models.ROBOTS_DIR / f"{name}.urdf").write_text(urdf)
        (OUT / f"{name}.py").write_text(codegen.generate_source(desc))
        write_kernels(name)
        seconds = time.perf_counter() - t
        t = time.perf_counter()
        (OUT / f"{name}_parameters.py").write_text(codegen.generate_parameter_source(desc))
        print(f"{name}: {desc.n} coordinates, {len(desc.contacts)} contacts, {seconds:.1f} s; "
              f"{len(codegen.parameter_names(desc))} parameters' derivatives, {time.perf_counter() - t:.1f} s")


if __name__ == "__main__":
    args = sys.argv[1:]
    only = "--kernels-only" in args
    names = [a for a in args if a != "--kernels-only"]
    main(names or models.SHIPPED, kernels_only=only)
