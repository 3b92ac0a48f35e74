# Two commands for a fresh machine (see README):
#   make run   - set up (virtualenv on first use) and run the main job
#   make test  - set up and run the test suite
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
ifndef RUN_DIR
RUN_DIR := results/crossing-$(shell date -u +%Y%m%d-%H%M%S)
endif

.PHONY: run test lint typecheck network clean-venv

# The dev extra includes the cluster extra (Dask): the tests run a batch on a Dask LocalCluster.
$(STAMP): pyproject.toml requirements.lock
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c requirements.lock -e ".[dev]"
	touch $(STAMP)

# The main job: a batch of paired SV/V2I crossing episodes (about 20 s on 2 cores), its Table I and report.
run: $(STAMP)
	$(PY) -m pedsafe_sumo.batch --scenario crossing --out $(RUN_DIR)
	$(PY) -m pedsafe_sumo.report $(RUN_DIR)

test: $(STAMP)
	$(PY) -m pytest -q $(PYTEST_ARGS)

# Type check (configuration in pyproject.toml: strict on the public interfaces, lenient elsewhere).
typecheck: $(STAMP)
	$(VENV)/bin/mypy

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

network: $(STAMP)
	$(PY) -m pedsafe_sumo.network --site xueqing

clean-venv:
	rm -rf $(VENV)
