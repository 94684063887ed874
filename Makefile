# Each target works on a fresh machine with only Python 3.11+: it creates .venv and installs into it.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo docs test test-fast fuzz bench bench-sim bench-capacity bench-batched bench-links bench-sweeps soak sim clean golden golden-spread

DEMO   := $(VENV)/.installed-demo
DOCS   := $(VENV)/.installed-docs

# The installs go through uv (PyPI's `uv`, put into the venv by its pip): it resolves and unpacks in
# parallel.  Measured 2026-12-07 on a fresh clone, 2 cores: `.[test]` in 29.5 s with pip (its cache
# warm) and 17.6 s with uv, uv's own install and a cold cache included.  --compile-bytecode: pip
# writes the packages' bytecode as it installs them, uv does not by default, and where
# PYTHONDONTWRITEBYTECODE is set every process then compiled numpy, Zenoh's bindings and the rest
# at each start (the first layer's CPU went from 826 s to 946 s).  The venv keeps its pip (the
# compose test's `pip wheel` uses it).  uv reads its own settings (UV_INDEX_URL ...), not pip's: where
# it cannot be had or cannot install (behind a mirror that only pip is set up for), pip does.
INSTALL = $(PY) -m uv pip install --quiet --compile-bytecode --python $(PY) $(1) || $(PY) -m pip install --quiet $(1)
$(VENV)/.uv:
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet uv || echo "no uv: pip installs"
	touch $@

# Everything the tests use (the viewer, Dask, Sphinx, the test tools); it serves the demo and the docs too.
$(STAMP): pyproject.toml $(VENV)/.uv
	$(call INSTALL,-e '.[test]')
	touch $(STAMP) $(DEMO) $(DOCS)

# What the demo needs and nothing else (379 MB with uv, measured 2026-12-07: no viewer, Dask or test tools).
$(DEMO): pyproject.toml $(VENV)/.uv
	$(call INSTALL,-e .)
	touch $(DEMO)

$(DOCS): pyproject.toml $(VENV)/.uv
	$(call INSTALL,-e '.[docs]')
	touch $(DOCS) $(DEMO)

## make demo: the §3.2 scenario over real processes (router, world, 8 agents, recorder), then the summary
demo: $(DEMO)
	$(VENV)/bin/zswarm run topologies/thesis-3.2-fixed8.toml --duration 40

## make docs: the documentation site in docs/_build/html (Sphinx; any warning, a broken internal link among
## them, is an error)
docs: $(DOCS)
	$(PY) -m sphinx -W --keep-going -q -b html docs docs/_build/html
	@echo "docs/_build/html/index.html"

## make test: unit and component tests on four workers (by file, the longest first), with the tests of real processes
## that need no real time (marker "processes"); then the integration tests alone, with
## the CPU-bound component tests that keep no real time (marker "background") beside them at idle
## priority; each part lists its slowest tests (tests/layers.sh says how and why)
test: $(STAMP)
	bash tests/layers.sh $(PY)

## make test-fast: everything but the integration tests
test-fast: $(STAMP)
	$(PY) -m pytest -q -m "not integration" -n 2 --dist loadfile --no-loadscope-reorder

## make fuzz: the property tests (Hypothesis) with a random seed and 10x their examples; the seed is
## printed first, and FUZZ_SEED=N make fuzz runs that draw again (make test runs the pinned examples)
fuzz: $(STAMP)
	@seed=$${FUZZ_SEED:-$$(od -An -N4 -tu4 /dev/urandom | tr -d ' ')}; \
	echo "make fuzz: seed $$seed (FUZZ_SEED=$$seed make fuzz draws the same examples)"; \
	HYPOTHESIS_PROFILE=fuzz $(PY) -m pytest -q -m hypothesis -n 2 --dist loadfile --hypothesis-seed=$$seed tests/unit tests/component

## make bench: latency, step time, rate and CPU over real processes, beside raw zenoh pub/sub
bench: $(STAMP)
	$(PY) bench/bench_runtime.py

## make bench-sim: zswarm sim of §3.2 (40 s, default recording) against 631834b (before issue 28), alternately
bench-sim: $(STAMP)
	$(PY) bench/bench_sim.py

## make bench-batched: CPU per draw of a basin and per run of a sweep, zswarm sim against the batched engine (the §5.6 laws,
## §4.5 observers and §3 observers, 3 s per draw, 10/100/1000 draws together; the §5.6 laws again with 2 ms of command delay and 10 % loss)
bench-batched: $(STAMP)
	$(PY) bench/bench_batched.py --duration 3 --draws 10,100,1000

## make bench-links: the README's §3.2 delay x drop sweep (120 runs of 40 s) with zswarm sweep on the batched engine, then
## on sim, timed as a user runs it and the rows compared (bench/bench_links_sweep.py; about 9 minutes, most of it sim)
bench-links: $(STAMP)
	$(PY) bench/bench_links_sweep.py

## make bench-sweeps: running.md's three sweeps (20 runs of 10 s each) on the batched engine and on sim, timed as a user runs
## them, the rows compared; writes docs/data/sweep-examples.json (bench/bench_sweep_examples.py; about 2 minutes)
bench-sweeps: $(STAMP)
	$(PY) bench/bench_sweep_examples.py

## make soak: one hour of zswarm run with every process's RSS sampled each minute (bench/soak.py)
soak: $(STAMP)
	$(PY) bench/soak.py

## make bench-capacity: zswarm run beside a raw zenoh-python swarm at N = 4..24 agents (about 7 minutes)
bench-capacity: $(STAMP)
	$(PY) bench/bench_capacity.py

clean:
	rm -rf $(VENV) runs sweeps .pytest_cache

## make golden: write tests/data/golden_sim.json anew on this machine (a command, not a test: it reports no
## result; commit the file with the reason its numbers changed; tests/golden.py says what it holds)
golden: $(STAMP)
	$(PY) -m tests.write_golden

## make fine-references: the step-size tests' fine runs made anew (the convergence study's 5x-rate runs, the §5.6
## hybrid loop at 1 kHz) and their numbers kept in tests/data/convergence_fine.json and tests/data/sync_fine.json,
## which the tests compare the default-rate runs with (~5 min of CPU); commit the files with the reason they changed
.PHONY: fine-references
fine-references: $(STAMP)
	$(PY) -m tests.component.test_convergence_study --write
	$(PY) -m tests.component.test_sim_sync --write

## make golden-spread: measure how far the golden runs move under every kernel and SIMD setting this machine
## can force (OpenBLAS, numpy dispatch, libm, compiled loops) and how far a 1e-6 gain change moves them; writes
## tests/data/golden_spread.json, which tests/golden.py's bound is derived from, and tests/data/golden_growth.json
## (the same runs at other lengths; how much a run grows a turned initial estimate): ~10 min of one core, at nice 19
golden-spread: $(STAMP)
	nice -n 19 $(PY) -m tests.measure_golden_spread
	nice -n 19 $(PY) -m tests.measure_golden_spread --growth
