# Two targets do all the set-up on a fresh machine that has only python3.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: run test test-fast bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
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

clean:
	rm -rf $(VENV) build *.egg-info
