"""Generate the compiled hybrid loop's single-source parts (run by `make generate-loop`; needs Cython, which
requirements-dev.txt pins: nothing else needs it, setup.py builds the committed C with gcc alone).

  * biped_sim/engine/_loop_state.h and _loop_state.pxd: the state's offsets and struct members, from the
    declaration in biped_sim/engine/loop_state.py;
  * biped_sim/engine/_loop_rules.c: biped_sim/engine/loop_rules.py (with its augmenting loop_rules.pxd)
    compiled by Cython's pure-Python mode, under the module name ``biped_sim.engine._loop_rules`` (a name
    apart from the .py, which stays the Python loop's code). The compiled loop's _core.c includes it and
    calls its public functions. Its first line carries SOURCES_SHA256, the digest of the sources it was
    made from; test/unit/test_loop_rules.py recomputes it, so the committed C cannot go stale.

    python tools/generate_loop.py           # write the three files
    python tools/generate_loop.py --check   # exit 1 if a committed file is not what the sources give
"""
from __future__ import annotations

import argparse
import hashlib
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ENGINE = ROOT / "biped_sim" / "engine"
# what _loop_rules.c is made from (_loop_state.pxd stands for loop_state.py's offsets)
RULE_SOURCES = ("loop_rules.py", "loop_rules.pxd", "loop_kernels.pxd", "_loop_state.pxd")
DIGEST_LINE = "/* SOURCES_SHA256 {digest}: biped_sim/engine/{{{names}}} (tools/generate_loop.py) */\n"


def sources_digest(folder=ENGINE) -> str:
    """The digest of the rules' sources in ``folder``, as _loop_rules.c's first line carries it."""
    h = hashlib.sha256()
    for name in RULE_SOURCES:
        h.update(name.encode() + b"\0" + (Path(folder) / name).read_bytes() + b"\0")
    return h.hexdigest()


def committed_digest() -> str | None:
    """The digest the committed _loop_rules.c says it was made from (None: no such line)."""
    path = ENGINE / "_loop_rules.c"
    first = path.read_text().split("\n", 1)[0] if path.exists() else ""
    m = re.match(r"/\* SOURCES_SHA256 ([0-9a-f]{64})", first)
    return m.group(1) if m else None


def state_files() -> dict:
    """{path: text} of the generated state declarations."""
    sys.path.insert(0, str(ROOT))
    from biped_sim.engine import loop_state
    return {ENGINE / "_loop_state.h": loop_state.c_header(), ENGINE / "_loop_state.pxd": loop_state.cython_pxd()}


def cythonize() -> dict:
    """{path: text} of _loop_rules.c, made by Cython in a scratch copy of the package
    (so that the module is biped_sim.engine._loop_rules and Cython finds its augmenting .pxd)."""
    with tempfile.TemporaryDirectory() as tmp:
        pkg = Path(tmp) / "biped_sim" / "engine"
        pkg.mkdir(parents=True)
        (pkg.parent / "__init__.py").write_text("")
        (pkg / "__init__.py").write_text("")
        shutil.copyfile(ENGINE / "loop_rules.py", pkg / "_loop_rules.py")
        shutil.copyfile(ENGINE / "loop_rules.pxd", pkg / "_loop_rules.pxd")
        subprocess.run([sys.executable, "-m", "cython", "-3", "-I", str(ROOT), "biped_sim/engine/_loop_rules.py",
                        "-o", "_loop_rules.c"], cwd=tmp, check=True)
        digest = DIGEST_LINE.format(digest=sources_digest(), names=",".join(RULE_SOURCES))
        return {ENGINE / "_loop_rules.c": digest + (Path(tmp) / "_loop_rules.c").read_text()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="compare with the committed files instead of writing")
    args = parser.parse_args(argv)
    files = state_files()
    if args.check:
        stale = [p for p, text in files.items() if not p.exists() or p.read_text() != text]
        if committed_digest() != sources_digest():
            stale.append(ENGINE / "_loop_rules.c")
        for p in stale:
            print(f"{p.relative_to(ROOT)} is not what its sources give: run python tools/generate_loop.py")
        return 1 if stale else 0
    for path, text in files.items():        # first: the rules' compilation reads _loop_state.pxd
        path.write_text(text)
    for path, text in cythonize().items():
        path.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
