# Two targets do all the set-up on a fresh machine that has only python3 (3.11 or newer).
# Everything is installed from a lock of exact, tested versions with their hashes
# (requirements/*.lock, README "Development"); pyproject.toml keeps the ranges library users get.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
# The extras installed: a lock requirements/<extras>.lock per set, extras joined by '+'.
EXTRAS ?= dev+crime
LOCK   := requirements/$(EXTRAS).lock
STAMP  := $(VENV)/.installed-$(EXTRAS)
COMPILE = $(BIN)/uv pip compile --quiet --universal --python-version 3.11 --generate-hashes \
          pyproject.toml requirements/tools.in

.PHONY: run test test-fast bench crosscheck lock upgrade clean

define venv_from_lock
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
	  { echo "make needs Python 3.11 or newer (the lock's numpy needs it): make PYTHON=python3.11 ..." >&2; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --require-hashes -r $(1)
endef

$(STAMP): $(LOCK) pyproject.toml
	$(call venv_from_lock,$(LOCK))
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	$(BIN)/python -m pip check  # the lock satisfies pyproject.toml (else: make lock)
	rm -f $(VENV)/.installed-*
	touch $(STAMP)

# The main job: lint everything, simulate the paper's traffic-rules scenario, report it.
run: $(STAMP)
	$(BIN)/twolevel check rules/ maps/ scenarios/ --dt 0.1 --horizon 10
	status=0; $(BIN)/twolevel simulate scenarios/traffic_rules.yaml --out runs/traffic_rules || status=$$?; \
	$(BIN)/twolevel report runs/traffic_rules && exit $$status

test: $(STAMP)
	$(BIN)/python -m pytest -q

test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow"

bench: $(STAMP)
	for b in benchmarks/*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

# twolevel's CommonRoad rule pack against CommonRoad's own monitor (crmonitor), which needs its
# own environment (.crosscheck/venv from requirements/crosscheck.txt, Python 3.10 or 3.11, built
# once): the benchmark (signs, values, rank correlation and speed side by side), then the opt-in test.
CROSSCHECK_PYTHON ?= python3.11
crosscheck: $(STAMP)
	$(BIN)/python benchmarks/crosscheck/run.py --build --python $(CROSSCHECK_PYTHON)
	TWOLEVEL_CROSSCHECK=1 TWOLEVEL_CROSSCHECK_PYTHON=$(CROSSCHECK_PYTHON) \
	  $(BIN)/python -m pytest -q tests/monitor/test_crosscheck_crmonitor.py

# Every lock re-resolved from pyproject.toml and requirements/tools.in: dev.lock first, then
# each other set constrained by it (the packages they share keep dev.lock's versions).
# $(1): extra uv options (--upgrade).
define compile_locks
	$(COMPILE) $(1) --extra dev -o requirements/dev.lock
	for lock in $(filter-out requirements/dev.lock,$(wildcard requirements/*.lock)); do \
	  extras=$$(basename $$lock .lock | tr '+' '\n' | sed 's/^/--extra /'); \
	  $(COMPILE) $(1) $$extras -c requirements/dev.lock -o $$lock || exit 1; \
	done
endef

# uv, pinned in the locks too, for lock and upgrade (which must work while the locks do not fit
# pyproject.toml yet).
$(BIN)/uv:
	$(call venv_from_lock,requirements/dev.lock)

# After editing pyproject.toml's dependencies: re-lock, keeping every pin that still fits.
lock: $(BIN)/uv
	$(call compile_locks)

# Adopt new releases deliberately: the newest versions the ranges allow, then the whole suite.
upgrade: $(BIN)/uv
	$(call compile_locks,--upgrade)
	$(MAKE) test

clean:
	rm -rf $(VENV) .crosscheck build *.egg-info
