# Two commands for a new user: `make run` and `make test`. Everything else is a helper.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
RUN_ARGS ?= gui
# The suite runs on TEST_WORKERS processes (pytest-xdist), a test file per process at a
# time; each process one OpenMP thread, so two workers fill two cores without spinning.
# TEST_WORKERS=0 runs it in this process (a debugger, -x, -s). A worker that crashes
# (a segfault) ends the run, naming its test: pytest-xdist 3.8 replaces a crashed worker by
# default, and under --dist loadfile the run can then hang until CI's limit (xdist #784, #1323).
TEST_WORKERS ?= 2
XDIST  := -n $(TEST_WORKERS) --dist loadfile --max-worker-restart 0
LOCK   := requirements.lock
PIP    := $(BIN)/python -m pip install --quiet -c $(LOCK)

.PHONY: run test lint typecheck layers pytest sysdeps bench clean bundle lock
.DEFAULT_GOAL := run

run: $(VENV)/.installed
	$(BIN)/fieldapp $(RUN_ARGS)

test: $(VENV)/.installed-dev
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy fieldapp devices ui
	$(BIN)/lint-imports
	QT_QPA_PLATFORM=offscreen OMP_NUM_THREADS=$${OMP_NUM_THREADS:-1} \
	  $(BIN)/python -m pytest $(XDIST) --durations=15 $(PYTEST_ARGS)

sysdeps:
	@sh packaging/sysdeps.sh

$(VENV)/.python: | sysdeps
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
	  { echo "fieldapp needs Python >= 3.11 (found: $$($(PYTHON) --version 2>&1)); set PYTHON=python3.11"; exit 1; }
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(PIP) --upgrade pip
	touch $@

$(VENV)/.installed: pyproject.toml $(LOCK) $(VENV)/.python
	$(PIP) -e ".[gui]"
	touch $@

$(VENV)/.installed-dev: pyproject.toml $(LOCK) $(VENV)/.python
	$(PIP) -e ".[gui,dev]"
	touch $@ $(VENV)/.installed

# The self-contained app (packaging/README.md): build/bundle/dist/fieldapp/ and a .tar.gz.
# Slow (minutes), so never part of `make test`.
bundle: $(VENV)/.installed-bundle
	sh packaging/build.sh $(BIN)/python

$(VENV)/.installed-bundle: pyproject.toml $(LOCK) $(VENV)/.python
	$(PIP) -e ".[gui,dev,bundle]"
	touch $@ $(VENV)/.installed-dev $(VENV)/.installed

bench: $(VENV)/.installed-dev
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

# Upgrade the pinned versions (docs/INSTALL.md); run `make clean test` before committing.
lock:
	PYTHON=$(PYTHON) sh packaging/lock.sh

clean:
	rm -rf $(VENV) .mypy_cache .pytest_cache .ruff_cache build *.egg-info
