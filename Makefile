# Two entry points on a fresh machine: `make demo` (the main job) and `make test` (the test suite).
# Both create the virtual environment and install exact versions from the project's lock first.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
LOCK := requirements/wbc.lock
NO_DEPS_LOCK := requirements/no-deps.lock
# The extras the lock covers and the set-up installs: the suite runs its torch tests and the ONNX round trip (pi3
# exported with torch, run with onnxruntime) instead of skipping them. The hardware extra's vendor SDK is locked apart,
# in no-deps.lock, and installed without its dependencies (see requirements/no-deps.in); its other package,
# dynamixel-sdk, is in dev. The docs extra builds the documentation site (`make docs`).
LOCKED_EXTRAS := dev,train,onnx,docs
comma := ,
# uv resolves the lock (for this Python and platform), keeping every pin that still fits unless told --upgrade. Where
# pip is configured with find-links (PIP_FIND_LINKS), uv looks there too, as pip would: that is where a machine may
# keep torch's CPU build; elsewhere give uv PyTorch's CPU index (UV_INDEX=https://download.pytorch.org/whl/cpu
# UV_INDEX_STRATEGY=unsafe-best-match make lock).
UV_COMPILE = $(BIN)/uv pip compile --quiet --generate-hashes --python $(BIN)/python --no-emit-find-links \
	--custom-compile-command "make lock" $(if $(PIP_FIND_LINKS),--find-links $(PIP_FIND_LINKS))

.PHONY: demo help test test-realtime test-all golden bench lint docs lock lock-upgrade clean

# Every package at the version the lock names, each file checked against the lock's hashes (pip refuses any other);
# the venv is cleared first, so nothing outside the lock stays. The project itself is installed last, editable,
# without resolving anything and with the locked setuptools as its build backend.
$(STAMP): $(LOCK) $(NO_DEPS_LOCK) pyproject.toml
	$(PYTHON) -m venv --clear $(VENV)
	$(BIN)/python -m pip install --quiet --require-hashes --no-deps -r $(LOCK) || { echo "make: the locked \
	packages did not install; the lock pins PyTorch's CPU build (torch==2.13.0+cpu), which PyPI does not serve: \
	give pip PyTorch's CPU index, PIP_EXTRA_INDEX_URL=https://download.pytorch.org/whl/cpu make $(MAKECMDGOALS)" >&2; \
	exit 1; }
	$(BIN)/python -m pip install --quiet --require-hashes --no-deps -r $(NO_DEPS_LOCK)
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)
	@echo "installed the locked environment in $(VENV); to have \`wbc\` on your PATH: . $(VENV)/bin/activate"

# Every target with its line (the `## ` comment after its prerequisites).
help:
	@grep -E '^[a-z-]+:.*## ' $(firstword $(MAKEFILE_LIST)) | sed -E 's/^([a-z-]+):.*## /\1\t/' | \
		awk -F '\t' '{ printf "  make %-14s %s\n", $$1, $$2 }'

demo: $(STAMP) ## the main job: mpc against learned on push trials, paired, with the verdict
	$(BIN)/wbc demo

# The suite in parallel, one process a core up to four (pytest-xdist): every test stands alone, on its own temporary
# files and its own loopback ports. The wall-clock suites below stay in one process.
test: $(STAMP) ## the default suite, in parallel (no slow, no wall-clock tests)
	$(BIN)/python -m pytest -q -n auto --maxprocesses 4

# What a real loop achieves against the wall clock (a busy machine can fail these; the default suite does not time).
test-realtime: $(STAMP) ## the wire backends against the wall clock (a busy machine can fail it)
	$(BIN)/python -m pytest -q -m realtime

test-all: $(STAMP) ## every test: the default suite, the slow and the wall-clock tests, in one process
	$(BIN)/python -m pytest -q -m ''

# Re-record the goldens (tests/golden/) in one process: under the parallel workers of `make test` they would race for
# the files, and the suite refuses to record there.
golden: $(STAMP) ## re-record the goldens (tests/golden/) in one process
	WBC_RECORD_GOLDEN=1 $(BIN)/python -m pytest -q -p no:xdist tests/test_golden.py tests/test_mpc_ticks.py

bench: $(STAMP) ## physics steps per second on both robots (wbc bench sim)
	$(BIN)/wbc bench sim --robot a1-wx200
	$(BIN)/wbc bench sim --robot go1-arm

lint: $(STAMP) ## ruff over wbc and tests
	$(BIN)/ruff check wbc tests

# The documentation site (mkdocs.yml, docs/) with its API reference generated from the docstrings, into build/site/.
# --strict turns every warning into an error: a broken link or anchor, a page left out of the nav, a docstring that
# cannot be read.
docs: $(STAMP) ## the documentation site, mkdocs --strict, into build/site/
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir build/site

# Re-resolve the lock after a change of pyproject.toml or requirements/*.in, keeping every pin that still fits;
# `make lock-upgrade` takes the newest versions the ranges allow. Re-record the goldens after either
# (make golden): results reproduce to the bit only under the versions they were recorded with.
# It needs only the locked uv, so it does not reinstall the venv when pyproject.toml is newer than it (the change it
# is run for): the venv is installed only where there is none; the new lock reinstalls it at the next target.
lock: | $(BIN)/uv ## re-resolve the lock after a change of pyproject.toml or requirements/*.in
	$(UV_COMPILE) $(foreach e,$(subst $(comma), ,$(LOCKED_EXTRAS)),--extra $(e)) \
		--output-file $(LOCK) pyproject.toml requirements/lock.in $(UPGRADE)
	$(UV_COMPILE) --no-deps --output-file $(NO_DEPS_LOCK) requirements/no-deps.in $(UPGRADE)

$(BIN)/uv:
	$(MAKE) $(STAMP)

lock-upgrade: ## make lock, taking the newest versions the ranges allow
	$(MAKE) lock UPGRADE=--upgrade

clean: ## remove the virtual environment and pytest's cache
	rm -rf $(VENV) .pytest_cache
