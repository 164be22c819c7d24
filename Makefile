# Two entry points on a fresh machine: `make demo` (the main job) and `make test` (the test suite).
# Both create the virtual environment and install the project with its own files first.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-all bench lint clean

# The vendor's Go1 SDK is a client of the emulator in the hardware tests; its metadata lists ~30 build tools it never
# imports, hence --no-deps (the `hardware` extra names it for users who install by hand). The train and onnx extras
# are installed so that the suite runs its torch tests and the ONNX round trip (pi3 exported with torch, run with
# onnxruntime) instead of skipping them; torch is pinned to the release they were tested with, whose CPU build is
# all they need.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,train,onnx]' 'torch==2.13.0'
	$(BIN)/python -m pip install --quiet --no-deps 'unitree-legged-sdk==3.8.20231105'
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/wbc demo

test: $(STAMP)
	$(BIN)/python -m pytest -q

test-all: $(STAMP)
	$(BIN)/python -m pytest -q -m ''

bench: $(STAMP)
	$(BIN)/wbc bench sim --robot a1-wx200
	$(BIN)/wbc bench sim --robot go1-arm

lint: $(STAMP)
	$(BIN)/ruff check wbc tests

clean:
	rm -rf $(VENV) .pytest_cache
