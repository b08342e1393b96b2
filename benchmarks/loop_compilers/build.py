"""Build the probe's compiled candidates into ``build/loop_compilers`` (ignored by git): rules.py and hooks.py
compiled by Cython (as the modules ``rules_cy``, ``hooks_cy``: a compiled module beside its .py would hide the
Python one), rules.py translated to C by translate.py (``rules_tr``), and glue.h as a shared library for
numba. Each build reports its wall time (seconds)."""
from __future__ import annotations

import hashlib
import importlib.util
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BUILD = ROOT / "build" / "loop_compilers"
ENGINE = ROOT / "biped_sim" / "engine"
CFLAGS = ["-O2", "-ffp-contract=off", "-fPIC"]      # as setup.py builds _core.c and _cmodel.c


def _cc(args):
    subprocess.run(["gcc", *args], check=True, capture_output=True, text=True)


def build_cython(build=BUILD, source="rules", reuse=True):
    """(the compiled module ``<source>_cy``, {"cython": s, "cc": s} or {} where the last build of the same
    inputs was reused, size of the generated C in lines)."""
    build.mkdir(parents=True, exist_ok=True)
    name = source + "_cy"
    src = build / (name + ".py")
    so = build / (name + sysconfig.get_config_var("EXT_SUFFIX"))
    stamp = build / (name + ".sha256")
    digest = _digest(source)
    if reuse and so.exists() and stamp.exists() and stamp.read_text() == digest:
        return _load(name, so), {}, (build / (name + ".c")).read_text().count("\n")
    shutil.copyfile(HERE / (source + ".py"), src)
    times = {}
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "cython", "-3", "-I", str(ROOT), str(src), "-o", str(build / (name + ".c"))],
                   check=True, capture_output=True, text=True)
    times["cython"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    _cc([*CFLAGS, "-shared", "-I", sysconfig.get_paths()["include"], "-I", str(HERE), "-I", str(ENGINE),
         str(build / (name + ".c")), "-o", str(so)])
    times["cc"] = time.perf_counter() - t0
    stamp.write_text(digest)
    return _load(name, so), times, (build / (name + ".c")).read_text().count("\n")


def _digest(source):
    """What a build of ``source`` depends on: the sources, the kernels, Cython's version, the C flags."""
    import Cython
    h = hashlib.sha256()
    for path in (HERE / (source + ".py"), HERE / "kernels.pxd", HERE / "hooks_c.pxd", HERE / "glue.h",
                 ENGINE / "_gen" / "_kernels.h"):
        h.update(path.read_bytes())
    h.update(f"{Cython.__version__} {CFLAGS} {sys.version}".encode())
    return h.hexdigest()


def _load(name, so):
    spec = importlib.util.spec_from_file_location(name, so)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def build_glue_so(build=BUILD):
    """(path of the glue's shared library for numba, seconds)."""
    build.mkdir(parents=True, exist_ok=True)
    so = build / "libglue.so"
    t0 = time.perf_counter()
    _cc([*CFLAGS, "-shared", "-I", str(HERE), "-I", str(ENGINE), str(HERE / "glue_so.c"), "-o", str(so)])
    return so, time.perf_counter() - t0


def build_translated(build=BUILD):
    """(rules.py translated to C by translate.py and compiled: the module ``rules_tr``, {"translate": s, "cc": s},
    lines of C)."""
    from benchmarks.loop_compilers import translate
    build.mkdir(parents=True, exist_ok=True)
    times = {}
    t0 = time.perf_counter()
    c = build / "rules_tr.c"
    c.write_text(translate.translate())
    times["translate"] = time.perf_counter() - t0
    so = build / ("rules_tr" + sysconfig.get_config_var("EXT_SUFFIX"))
    t0 = time.perf_counter()
    _cc([*CFLAGS, "-shared", "-I", sysconfig.get_paths()["include"], "-I", str(HERE), "-I", str(ENGINE), str(c),
         "-o", str(so)])
    times["cc"] = time.perf_counter() - t0
    spec = importlib.util.spec_from_file_location("rules_tr", so)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module, times, c.read_text().count("\n")
