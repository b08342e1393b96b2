# biped_sim: `make demo` and `make test` set everything up on a fresh machine.
VENV    ?= .venv
PY      := $(VENV)/bin/python
STAMP   := $(VENV)/.installed
DEV_STAMP := $(VENV)/.installed-dev
PYTHON  ?= $(shell command -v python3.11 || command -v python3)

.PHONY: venv venv-dev venv-drake demo test bench generate generate-loop docs-figures clean-venv

# venv: what a run needs (requirements.txt); venv-dev adds the tests, ruff, colcon and Ray
# (requirements-dev.txt), which `make test` installs and `make demo` does not
venv: $(STAMP)
venv-dev: $(DEV_STAMP)

# uv installs the stack in ~8 s here (pip: ~45 s); pip stays as the fallback.
# compileall: uv writes no .pyc (pip does), and where Python does not write them
# either (PYTHONDONTWRITEBYTECODE, a read-only install) every biped-sim process compiled its imports
# from source: `biped-sim simulate --duration 0.1` took 0.86 s instead of 0.48 s (docs/performance.md).
# --reinstall-package: uv would keep an installed editable biped_sim and not rebuild the compiled
# twin (biped_sim/engine/_gen/_cmodel.c), the compiled loop (biped_sim/engine/_core.c), the compiled walking
# laws (biped_sim/control/_laws.c), the variational steps (biped_sim/engine/_variational.c), the shipped
# robots' kernels (biped_sim/engine/_gen/models/_kernels_*.c and the
# runtime they include, biped_sim/engine/_kernels_runtime.h) or the
# recorder's frame buffer (biped_sim/recording/_frames.c) after a change.
$(STAMP): requirements.txt setup.py setup.cfg biped_sim/engine/_gen/_cmodel.c biped_sim/engine/_core.c \
          biped_sim/engine/_gen/_kernels.h biped_sim/recording/_frames.c biped_sim/control/_laws.c \
          biped_sim/engine/_loop_rules.c biped_sim/engine/_loop_state.h biped_sim/engine/_kernel_table.h \
          biped_sim/engine/_loop_table.h biped_sim/engine/_kernels_runtime.h \
          biped_sim/engine/_gen/_derivatives.h biped_sim/engine/_stance_derivative.h biped_sim/engine/_variational.c \
          biped_sim/engine/_py_doubles.h \
          $(wildcard biped_sim/engine/_gen/models/_kernels_*.c)
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@if $(PY) -m pip install -q uv==0.13.8 >/dev/null 2>&1; then \
	    $(VENV)/bin/uv pip install -q --python $(PY) -r requirements.txt --reinstall-package biped_sim -e . ; \
	else \
	    $(PY) -m pip install -q -r requirements.txt -e . ; \
	fi
	@$(PY) -m compileall -q -j 0 "$$($(PY) -c 'import sysconfig; print(sysconfig.get_path("purelib"))')" biped_sim >/dev/null
	@touch $(STAMP)

demo: $(STAMP)
	$(PY) -m biped_sim.cli.demo

$(DEV_STAMP): $(STAMP) requirements-dev.txt
	@if test -x $(VENV)/bin/uv; then \
	    $(VENV)/bin/uv pip install -q --python $(PY) -r requirements-dev.txt ; \
	else \
	    $(PY) -m pip install -q -r requirements-dev.txt ; \
	fi
	@$(PY) -m compileall -q -j 0 "$$($(PY) -c 'import sysconfig; print(sysconfig.get_path("purelib"))')" >/dev/null
	@touch $(DEV_STAMP)

test: $(DEV_STAMP)
	$(PY) -m pytest -q test

# mujoco: for benchmarks/bench_mujoco.py only (MuJoCo side by side), installed here and nowhere else.
# pin (Pinocchio, 382 MB installed, 0.3 s to import): test/unit/test_robot_models.py's cross-check of the
# shipped robots' dynamics, which make test skips without it; make bench installs it and runs that check.
# Drake side by side (benchmarks/bench_drake.py) runs when .venv-drake exists (make venv-drake).
bench: $(DEV_STAMP)
	@$(PY) -c "import mujoco" 2>/dev/null || $(VENV)/bin/uv pip install -q --python $(PY) mujoco==4.0.0
	@$(PY) -c "import pinocchio" 2>/dev/null || $(VENV)/bin/uv pip install -q --python $(PY) pin==4.1.0
	$(PY) -m pytest -q -p no:cacheprovider test/unit/test_robot_models.py -k pinocchio
	$(PY) -m benchmarks.bench

# drake 1.58 (pydrake.examples.CompassGait, for benchmarks/bench_drake.py) installs from PyPI for Python 3.12
# only: a venv of its own, never part of make test
# (the first Python 3.12 that runs: a pyenv shim may be on the PATH without a 3.12 behind it)
DRAKE_PYTHON ?= $(shell for p in $$(command -v python3.12) $$(ls -d /root/.pyenv/versions/3.12*/bin/python 2>/dev/null); do \
	$$p -c 'import sys; assert sys.version_info[:2] == (3, 12)' 2>/dev/null && echo $$p && break; done)
venv-drake: .venv-drake/.installed
.venv-drake/.installed:
	@test -n "$(DRAKE_PYTHON)" || { echo "make venv-drake: no Python 3.12 found (drake 1.58 installs for 3.12 only): give one, make venv-drake DRAKE_PYTHON=/path/to/python3.12"; exit 2; }
	@test -x .venv-drake/bin/python || $(DRAKE_PYTHON) -m venv .venv-drake
	.venv-drake/bin/python -m pip install -q drake==1.58.0
	@touch $@

# Regenerate every figure of docs/ from the command its page names (tools/docs_figures.py; a few minutes,
# not part of `make test`): work_precision.png and accuracy.md's tables (biped-sim accuracy), the table of
# stability.md (the stability suite), walk.gif (biped-sim animate), sweep_gain_map.png and sweep_basin.png
# (biped-sim sweep, basin), scaling.md's figures (benchmarks.bench_sweep --scaling). The prose that reads
# the figures is the writer's job: read the diff. docs/demo_walk.png is `make demo`'s (it runs the nodes).
docs-figures: $(STAMP)
	$(PY) tools/docs_figures.py

# Regenerate biped_sim/engine/_gen/closed_forms.py from the energies (needs sympy, installed here only),
# the shipped robots' modules biped_sim/engine/_gen/models/*.py and URDFs (tools/generate_models.py),
# biped_sim/engine/_gen/rk_steps.py (the unrolled Runge-Kutta steps) from scipy's tableaux, and from both
# their compiled twin biped_sim/engine/_gen/_cmodel.c; then rebuild the twin.
generate: $(STAMP)
	@$(PY) -c "import sympy" 2>/dev/null || $(VENV)/bin/uv pip install -q --python $(PY) sympy==1.14.0
	$(PY) tools/generate_model.py
	$(PY) tools/generate_models.py
	$(PY) tools/generate_rk.py
	$(PY) tools/generate_c.py
	$(MAKE) --always-make venv

# Regenerate the compiled hybrid loop's single-source parts (tools/generate_loop.py): the state's declarations
# biped_sim/engine/_loop_state.{h,pxd} from loop_state.py, and biped_sim/engine/_loop_rules.c from
# loop_rules.py by Cython (requirements-dev.txt); then rebuild. Run it after an edit of loop_rules.py,
# loop_rules.pxd, loop_kernels.pxd or loop_state.py (test/unit/test_loop_rules.py fails until then).
generate-loop: $(DEV_STAMP)
	$(PY) tools/generate_loop.py
	$(MAKE) --always-make venv

clean-venv:
	rm -rf $(VENV)
