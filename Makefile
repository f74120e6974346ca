# The README's two set-up commands: `make run` and `make test`.
# Each creates .venv in the repository when it is missing and installs the project into it.

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
SCENE  ?= scenes/demo.yaml

.PHONY: run test sim bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(VENV)/.installed-test: pyproject.toml $(VENV)/.installed
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@

run: $(VENV)/.installed
	$(BIN)/hilgate run $(SCENE)

sim: $(VENV)/.installed
	$(BIN)/hilgate sim $(SCENE)

test: $(VENV)/.installed-test
	$(BIN)/python -m pytest -q

bench: $(VENV)/.installed
	$(BIN)/python benchmarks/ring_aloha.py
	$(BIN)/python benchmarks/realtime_lateness.py
	$(BIN)/python benchmarks/gli_roundtrip.py
	$(BIN)/python benchmarks/aruco.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
