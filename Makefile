# Two commands for a fresh machine (see README):
#   make run   - set up (virtualenv on first use) and run the main job
#   make test  - set up and run the test suite
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: run test lint network clean-venv

$(STAMP): pyproject.toml requirements.lock
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c requirements.lock -e ".[dev]"
	touch $(STAMP)

# Until the batch runner exists, the main job builds the study network and summarises it.
run: $(STAMP)
	$(PY) -m pedsafe_sumo.network --site xueqing

test: $(STAMP)
	$(PY) -m pytest -q $(PYTEST_ARGS)

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

network: $(STAMP)
	$(PY) tools/build_network.py --site xueqing

clean-venv:
	rm -rf $(VENV)
