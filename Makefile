# The README's two set-up commands: `make run` and `make test`.
# Each creates .venv in the repository when it is missing and installs the project into it.
# `make run ARGS="--runtime-dir /tmp/mine --tcp 4280"` and `make sim ARGS="--until 600 --seed 3"` pass
# options to `hilgate run` / `hilgate sim`; SCENE=FILE runs another scene.

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
SCENE  ?= scenes/demo.yaml
FUZZ   ?= 1
ARGS   ?=
BELLHOP_VENV := .venv-bellhop
PELAGIC      := 0.5.0

# `sudo make install` / `sudo make uninstall`: hilgate as a systemd service (systemd/install.sh;
# docs/operations.md). DESTDIR=DIR writes every file under DIR instead and skips the root-only steps (the
# hilgate user, systemctl); PURGE=1 also removes changed configuration, the user, state and traces.
# EXTRAS=web,report,ros2 installs those optional extras into the service's venv (default: web, the live view).
DESTDIR      ?=
PREFIX       ?= /opt/hilgate
SYSCONFDIR   ?= /etc
UNITDIR      ?= /etc/systemd/system
LOGROTATEDIR ?= /etc/logrotate.d
BINDIR       ?= /usr/local/bin
PIP_ARGS     ?=
PURGE        ?=
EXTRAS       ?= web

.PHONY: run test sim bench soak fuzz paper install uninstall clean

$(BIN)/python:
	@echo "make: creating $(VENV), a Python environment of this checkout's own"
	$(PYTHON) -m venv $(VENV)

# pip says what it fetches and installs (the first run takes about a minute); later runs skip it.  With the
# extras the README's commands use: the live view (--web, hilgate view: tornado) and the report's figures
# (hilgate report: matplotlib).
$(VENV)/.installed: pyproject.toml | $(BIN)/python
	@echo "make: installing hilgate and its dependencies into $(VENV) (the first time only; about a minute)"
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --upgrade pip
	$(BIN)/python -m pip install --disable-pip-version-check -e '.[web,report]'
	@echo "make: installed; the commands are $(BIN)/hilgate, or run 'source $(BIN)/activate' once"
	touch $@

$(VENV)/.installed-test: pyproject.toml $(VENV)/.installed
	@echo "make: installing the test tools into $(VENV)"
	$(BIN)/python -m pip install --disable-pip-version-check -e '.[test]'
	touch $@

run: $(VENV)/.installed
	$(BIN)/hilgate run $(SCENE) $(ARGS)

sim: $(VENV)/.installed
	$(BIN)/hilgate sim $(SCENE) $(ARGS)

# The suite on TEST_JOBS workers (pytest-xdist): most tests wait on daemons and applications they start,
# so more workers than cores keep both cores busy.  A test file stays on one worker (--dist loadscope):
# its module fixtures (an installed venv, a paper's runs) are made once, not once per worker.  Tests that
# time real-time behaviour or hold much of the user's POSIX-queue budget outside the test kit (marked
# serial: tests/conftest.py says which and why) run after it, alone.  Each part prints its slowest tests (a
# clean clone's run on CI then says where the minutes went).
TEST_JOBS ?= 4

# Where this user may (root, or wherever `unshare --ipc` is allowed), each pytest runs in an IPC namespace of
# its own: the POSIX queues its tests make, even those of a run killed midway, are gone when it ends (their
# bytes back in the user's queue budget, RLIMIT_MSGQUEUE, which every run on the machine shares), and no
# other run sees their names. Elsewhere the tests unlink what they make, as before.
ISOLATE = $(shell unshare --ipc true 2>/dev/null && echo unshare --ipc)

test: $(VENV)/.installed-test $(BELLHOP_VENV)/.installed
	$(ISOLATE) $(BIN)/python -m pytest -q -n $(TEST_JOBS) --dist loadscope -m "not serial" --durations=15
	$(ISOLATE) $(BIN)/python -m pytest -q -m serial --durations=10

# BELLHOP for the channel that knows the water (docs/channel-models.md, "BELLHOP"): pelagic, GPL-3.0-or-later,
# in an environment of its own that hilgate (MIT) never imports; hilgate runs tools/bellhop_run.py with its
# Python as a separate program. `make test` makes it: the BELLHOP tests run the real program.
$(BELLHOP_VENV)/.installed:
	@echo "make: creating $(BELLHOP_VENV), BELLHOP (pelagic $(PELAGIC)) in an environment of its own"
	$(PYTHON) -m venv $(BELLHOP_VENV)
	$(BELLHOP_VENV)/bin/python -m pip install --quiet --disable-pip-version-check 'pelagic==$(PELAGIC)'
	touch $@

# The fuzz tests (test_fuzz_*) for minutes instead of seconds: HILGATE_FUZZ multiplies their examples; and the
# red team at the doors (tests/test_redteam_doors.py: every stranger at once, the honest clients' tries, -s
# prints the figures) with more tries.
fuzz: $(VENV)/.installed-test
	HILGATE_FUZZ=$(FUZZ) $(BIN)/python -m pytest -q -k "fuzz or redteam"

# The paper comparison (docs/paper-comparison.md, docs/paper-exp2.md) and the formation figure
# (docs/figures/exp3-formation.png, from the virtual-time run): virtual time only. 42 s on this project's
# 2-core machine while other test runs shared it (0.8 + 36 + 5 s); longer when every core is busy.
PAPER_TIME := under a minute of CPU time (longer when the cores are busy)
paper: $(VENV)/.installed-test
	@echo "make paper: three steps, $(PAPER_TIME)"
	@echo "make paper: 1/3 docs/paper-exp2.md (the second experiment as the paper ran it)"
	$(BIN)/python docs/paper_exp2.py > /dev/null
	@echo "make paper: 2/3 docs/paper-comparison.md (every finding of the paper; it counts its runs)"
	$(BIN)/python docs/paper_comparison.py > /dev/null
	@echo "make paper: 3/3 docs/figures/exp3-formation.png (the formation figure)"
	$(BIN)/python docs/formation_figure.py

install uninstall:
	DESTDIR='$(DESTDIR)' PREFIX='$(PREFIX)' SYSCONFDIR='$(SYSCONFDIR)' UNITDIR='$(UNITDIR)' \
	LOGROTATEDIR='$(LOGROTATEDIR)' BINDIR='$(BINDIR)' PYTHON='$(PYTHON)' PIP_ARGS='$(PIP_ARGS)' PURGE='$(PURGE)' \
	EXTRAS='$(EXTRAS)' \
	sh systemd/install.sh $@

# Every benchmark once (a few minutes each on a loaded 2-core machine); their output goes to bench.out
# and from there into docs/performance.md (all of it) and docs/compiled-hot-path.md (the pass and the round
# trips). NS3_PYTHON=PATH (a Python with the ns3 wheel; .venv-ns3/bin/python when it exists, see
# docs/performance.md) runs ns-3 UAN alongside the ALOHA ring and its real-time scheduler alongside the
# lateness benchmark; without it ns-3 is "not run".
NS3_PYTHON ?= $(wildcard .venv-ns3/bin/python)

# (the test tools' environment: it has the optional extras some benchmarks measure, tornado for web_cost.py)
bench: $(VENV)/.installed-test
	NS3_PYTHON='$(NS3_PYTHON)' $(BIN)/python benchmarks/run_all.py --out bench.out
	$(BIN)/python benchmarks/readme_bench.py bench.out docs/performance.md
	$(BIN)/python benchmarks/readme_bench.py bench.out docs/compiled-hot-path.md --only pass_cost.py gli_roundtrip.py multihost.py

# The soak (benchmarks/soak.py, docs/performance.md "Soak"): two daemons of one scene (network namespaces as
# root, else loopback), 50 links at 100 frames/s for an hour, a reload every minute, daemon B restarted every
# ten minutes: the daemons' memory slope and an account of every frame.  Not part of `make test` (which runs
# 18 s of it); `nohup make soak > soak.out &` and wait an hour.  SOAK_ARGS="--keep DIR" keeps
# the traces and the applications' logs (about 200 MB).
SOAK_ARGS ?=
soak: $(VENV)/.installed-test
	$(BIN)/python benchmarks/soak.py --minutes 60 --reload-every 60 --restart-every 600 $(SOAK_ARGS)

clean:
	rm -rf $(VENV) $(BELLHOP_VENV) build *.egg-info .pytest_cache
