# The README's two set-up commands: `make run` and `make test`.
# Each creates .venv in the repository when it is missing and installs the project into it.

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
SCENE  ?= scenes/demo.yaml
FUZZ   ?= 1

# `sudo make install` / `sudo make uninstall`: hilgate as a systemd service (systemd/install.sh;
# docs/operations.md). DESTDIR=DIR writes every file under DIR instead and skips the root-only steps (the
# hilgate user, systemctl); PURGE=1 also removes changed configuration, the user, state and traces.
DESTDIR      ?=
PREFIX       ?= /opt/hilgate
SYSCONFDIR   ?= /etc
UNITDIR      ?= /etc/systemd/system
LOGROTATEDIR ?= /etc/logrotate.d
BINDIR       ?= /usr/local/bin
PIP_ARGS     ?=
PURGE        ?=

.PHONY: run test sim bench fuzz paper install uninstall clean

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

# The fuzz tests (test_fuzz_*) for minutes instead of seconds: HILGATE_FUZZ multiplies their examples.
fuzz: $(VENV)/.installed-test
	HILGATE_FUZZ=$(FUZZ) $(BIN)/python -m pytest -q -k fuzz

# The paper comparison (docs/paper-comparison.md, docs/paper-exp2.md) and the formation figure
# (docs/figures/exp3-formation.png, from the virtual-time run): virtual time only, about a minute.
paper: $(VENV)/.installed-test
	$(BIN)/python docs/paper_exp2.py > /dev/null
	$(BIN)/python docs/paper_comparison.py > /dev/null
	$(BIN)/python docs/formation_figure.py

install uninstall:
	DESTDIR='$(DESTDIR)' PREFIX='$(PREFIX)' SYSCONFDIR='$(SYSCONFDIR)' UNITDIR='$(UNITDIR)' \
	LOGROTATEDIR='$(LOGROTATEDIR)' BINDIR='$(BINDIR)' PYTHON='$(PYTHON)' PIP_ARGS='$(PIP_ARGS)' PURGE='$(PURGE)' \
	sh systemd/install.sh $@

# Every benchmark once (a few minutes each on a loaded 2-core machine); their output goes to bench.out
# and from there into docs/performance.md. NS3_PYTHON=PATH (a Python with the ns3 wheel)
# runs ns-3 UAN alongside the ALOHA ring; without it ns-3 is "not run".
NS3_PYTHON ?=

bench: $(VENV)/.installed
	NS3_PYTHON='$(NS3_PYTHON)' $(BIN)/python benchmarks/run_all.py --out bench.out
	$(BIN)/python benchmarks/readme_bench.py bench.out docs/performance.md

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
