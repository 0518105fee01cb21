# Every target bootstraps .venv from nothing, so `make demo` / `make test` work on a fresh clone.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# the demo needs only the package itself (no test tools, no optional extras): a shorter first install
DEMO_STAMP := $(VENV)/.installed-demo
# numba's cache of compiled kernels is chosen by the package (finkensim/numba_cache.py: one directory per version of
# the sources, shared by make, the CLI, notebooks and plain Python; NUMBA_CACHE_DIR overrides it)
export MPLBACKEND ?= Agg

.PHONY: demo test coverage fuzz docs screenshots notebooks bench bench-peers clean venv

venv: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test,docs]"
	@# the byte code of what `make demo` installed without it (pip --no-compile below): else, with
	@# PYTHONDONTWRITEBYTECODE set, every process of the suite would compile numpy's, scipy's, … sources at import
	$(BIN)/python -m compileall -q -j 0 $$($(BIN)/python -c "import sysconfig; print(sysconfig.get_path('purelib'))") \
		>/dev/null || true
	touch $(STAMP) $(DEMO_STAMP)

# --no-compile: pip does not byte-compile every module of the dependencies (12.6 of its 23.3 s of CPU, measured in
# docs/performance.md); Python writes the byte code of the modules the demo imports at their first import (≈ 1.8 s once)
$(DEMO_STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --no-compile -e .
	touch $(DEMO_STAMP)

# compile the demo's kernels first (two processes side by side), then fly: the first run does not wait for numba.
# OpenMP threads wait passively between parallel kernels (as in `make test`): on a busy machine threads that spin take
# the cores from the rest (600 calls of a small parallel kernel: 7-31 s wall spinning, 0.01 s passive at load 17)
demo: export OMP_WAIT_POLICY ?= passive
demo: $(DEMO_STAMP)
	$(BIN)/finkensim compile
	$(BIN)/finkensim run --out out/demo

# The suite runs on TEST_WORKERS processes (pytest-xdist; work stealing evens out the long tests; 0 = one process);
# it lists its 30 slowest steps, so that a CI log says where the time went.
# OpenMP threads wait passively: with several processes on the cores, threads that spin between parallel kernels
# take the cores from the other process (measured on 2 cores: 621 s spinning, 405 s passive, 757 s in one process).
TEST_WORKERS ?= 2
test: $(STAMP)
	$(BIN)/ruff check .
	OMP_WAIT_POLICY=$${OMP_WAIT_POLICY:-passive} $(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist worksteal \
		--durations=30 tests --nbmake notebooks
	$(MAKE) docs

# Line coverage of the engine's kernels as plain Python (NUMBA_DISABLE_JIT=1, as STUMPY measures its own): the tests of
# the kernel modules, the engine layers' modules measured; not part of `make test` (≈ 10 min on 2 quiet cores).
# The figure is quoted in docs/contributing.md.
COVERAGE_TESTS := tests/test_geometry.py tests/test_rng.py tests/test_trig.py tests/test_sonar.py \
	tests/test_ranging.py tests/test_imu.py tests/test_cellgrid.py tests/test_world.py tests/test_arena.py \
	tests/test_sonar_hold.py
COVERAGE_MODULES := finkensim.kernels finkensim.sensors finkensim.swarm finkensim.behaviours finkensim.world \
	finkensim.arena finkensim.copters
coverage: $(STAMP)
	NUMBA_DISABLE_JIT=1 $(BIN)/python -m pytest -q -n $(TEST_WORKERS) -W ignore::RuntimeWarning \
		$(foreach m,$(COVERAGE_MODULES),--cov=$(m)) --cov-report=term $(COVERAGE_TESTS)

# The documentation site (docs/conf.py): every warning is an error, so a broken cross-reference in a page or a
# docstring fails the build. Notebooks are rendered with their committed outputs, never executed here.
docs: $(STAMP)
	$(BIN)/python -m sphinx -b html -W --keep-going -n -q docs docs/_build/html
	@echo "docs: open docs/_build/html/index.html"

# Screenshots of the built site for docs/contributing.md (headless Chromium from the system's packages; not in
# `make test`): the landing page and one API page, into docs/img/.
screenshots: docs
	command -v chromium >/dev/null || (apt-get update && apt-get install -y chromium)
	$(BIN)/python docs/screenshots.py --browser chromium --site docs/_build/html --out docs/img

# The full fuzz corpus (malformed inputs on every surface through the real command line; `make test` runs a fixed
# bounded subset of it). One process, so that the counts per category it prints at the end are complete; they are
# in docs/reliability.md.
fuzz: $(STAMP)
	FINKENSIM_FUZZ=full $(BIN)/python -m pytest -q -p no:xdist tests/test_fuzz_cli.py \
		tests/test_fuzz_defects.py tests/test_fuzz_inputs.py

# re-execute the notebooks and write their outputs back (commit them: figures show on the repository page)
notebooks: $(STAMP)
	MPLBACKEND=module://matplotlib_inline.backend_inline $(BIN)/python -m pytest -q --nbmake --overwrite notebooks

bench: $(STAMP)
	$(BIN)/python -m benchmarks.run $(if $(QUICK),--quick,)

# Peer simulators in their own venv (torch is large and must not enter .venv): VMAS on torch CPU. Once installed,
# `make bench` runs it on the comparison workload (benchmarks/peers/vmas_scenario.py) in the same run, each
# configuration right after finkensim's.
PEERS_VENV := .venv-peers
bench-peers:
	test -x $(PEERS_VENV)/bin/python || $(PYTHON) -m venv $(PEERS_VENV)
	$(PEERS_VENV)/bin/python -m pip install --quiet "numpy>=1.26" "torch==2.13.0"
	$(PEERS_VENV)/bin/python -m pip install --quiet "vmas==1.5.2" || $(PEERS_VENV)/bin/python -m pip install --quiet vmas
	$(PEERS_VENV)/bin/python -c "import torch, vmas; print('VMAS', vmas.__version__, 'on torch', torch.__version__, 'ready for make bench')"

clean:
	rm -rf $(VENV) .numba_cache out .pytest_cache .hypothesis docs/_build docs/api/generated
