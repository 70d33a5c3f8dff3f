# Two commands do all the set-up on a fresh machine: `make run` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
# Two install stamps: `make run` needs only the package and its compiled kernels (the reproduction runs its planners
# in NumPy); `make test` adds PyTorch, stable-baselines3, Gymnasium, highway-env, Ray, SUMO and the dev tools.
RUN_STAMP := $(VENV)/.installed-run
STAMP     := $(VENV)/.installed
# PyTorch's CPU build, pinned with its local version: from an index that has no CPU build (PyPI) the pin fails
# instead of pulling the CUDA-bundled wheels (gigabytes). Give the index that has it with
# `make test TORCH_INDEX_URL=...` (docs/usage.md, "Installing").
TORCH          := torch==2.13.0+cpu
TORCH_INDEX_URL ?=

.PHONY: run test lint bench fuzz clean install install-run mutate mutate-ci

$(PY):
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(RUN_STAMP): pyproject.toml | $(PY)
	# The package and the compiled kernels (extra fast, numba): all the reproduction needs.
	$(PY) -m pip install --quiet -e ".[fast]"
	touch $(RUN_STAMP)

$(STAMP): pyproject.toml $(RUN_STAMP)
	$(PY) -m pip install --quiet "$(TORCH)" $(if $(TORCH_INDEX_URL),--extra-index-url $(TORCH_INDEX_URL)) || \
		{ echo "no $(TORCH) on this package index: make test TORCH_INDEX_URL=<PyTorch's CPU index> (docs/usage.md)"; exit 1; }
	$(PY) -m pip install --quiet -e ".[dev,train,gym,rl,highway,fast]"
	# Ray (extra ray; a 79 MB wheel, about 10 s): the Ray backend's tests run in CI (docs/scale.md).
	$(PY) -m pip install --quiet -e ".[ray]"
	# ad-rss (extra rss; wheels for Linux x86_64): the RSS parity tests need it and skip, saying so, where it is absent.
	$(PY) -m pip install --quiet -e ".[rss]" || echo "ad-rss could not be installed here: the RSS parity tests will skip"
	# libsumo (extra sumo; manylinux wheels): CI runs the SUMO integration's tests with it (they skip only without it).
	$(PY) -m pip install --quiet -e ".[sumo]"
	# commonroad-io and the drivability checker (extra commonroad). commonroad-io pins protobuf 3.20.2 for a format
	# safelane never reads; onnx needs protobuf >= 6.31, restored here (pip reports the pin, the XML reader works).
	$(PY) -m pip install --quiet -e ".[commonroad]"
	$(PY) -m pip install --quiet "protobuf>=6.31.1"
	touch $(STAMP)

install: $(STAMP)

install-run: $(RUN_STAMP)

run: $(RUN_STAMP)
	$(VENV)/bin/safelane reproduce --workers 2
	$(VENV)/bin/safelane replay

test: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks
	$(PY) -m pytest -q

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests benchmarks

# Property tests with fresh random examples (the test run itself is derandomized: see tests/conftest.py).
fuzz: $(STAMP)
	for i in 1 2 3 4 5; do HYPOTHESIS_PROFILE=explore $(PY) -m pytest -q -p no:cacheprovider \
		tests/test_sim_responsible.py tests/test_sim_kinematics.py tests/test_v2x.py \
		tests/test_safety_reference.py || exit 1; done

bench: $(STAMP)
	$(PY) benchmarks/bench_safety.py
	$(PY) benchmarks/bench_sim.py
	$(PY) benchmarks/bench_nn.py
	$(PY) benchmarks/bench_env.py

# Mutation testing of the guarantee's code (docs/testing.md): every mutant of each group of modules, run against
# the group's tests that reach it; verdicts cached in mutants/ (a re-run retries only what changed).
mutate: $(STAMP)
	SAFELANE_NO_NUMBA=1 $(PY) tools/mutate.py run
	$(PY) tools/mutate.py table

# CI's fixed, seeded sample of mutants of the shield's decision and the evasion check; fails on a survivor.
# The NumPy path is the one mutated: the compiled kernel (extra `fast`) would stand in for it in large batches.
mutate-ci: $(STAMP)
	SAFELANE_NO_NUMBA=1 $(PY) tools/mutate.py run decide evasion --sample 20 --seed 18 --fresh

clean:
	rm -rf $(VENV) build *.egg-info src/*.egg-info .pytest_cache .ruff_cache .hypothesis mutants
