# Two commands for a fresh machine (see README):
#   make run   - set up (virtualenv on first use) and run the main job
#   make test  - set up and run the test suite
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# ASAM's OpenSCENARIO/OpenDRIVE checkers in a virtualenv of their own (they need numpy<2; see tools/asam_qc).
QC_VENV ?= .venv-qc
QC_STAMP := $(QC_VENV)/.installed
ifndef RUN_DIR
RUN_DIR := results/crossing-$(shell date -u +%Y%m%d-%H%M%S)
endif

.PHONY: run test lint typecheck network clean-venv

# The dev extra includes the cluster extra (Dask): the tests run a batch on a Dask LocalCluster.
$(STAMP): pyproject.toml requirements.lock Makefile
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -c requirements.lock -e ".[dev]"
	# The official Euro NCAP rating calculator, which tests/ncap checks pedsafe_sumo.ncap's scoring against.
	# It declares pandas<3, but the functions the tests call run on the pinned pandas 3: installed without
	# its dependency pins, its own dependencies pinned here.
	$(PY) -m pip install --quiet --no-deps euroncap-rating-2026==5.4.9
	$(PY) -m pip install --quiet -c requirements.lock openpyxl==3.1.5 pydantic==2.14.3 pydantic-settings==2.16.3
	touch $(STAMP)

# The main job: a batch of paired SV/V2I crossing episodes (about 40 s on 2 cores), its Table I and report.
run: $(STAMP)
	$(PY) -m pedsafe_sumo.batch --scenario crossing --out $(RUN_DIR)
	$(PY) -m pedsafe_sumo.report $(RUN_DIR)

$(QC_STAMP): tools/asam_qc/requirements.txt
	$(PYTHON) -m venv $(QC_VENV)
	$(QC_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(QC_VENV)/bin/python -m pip install --quiet -r tools/asam_qc/requirements.txt
	touch $(QC_STAMP)

test: $(STAMP) $(QC_STAMP)
	$(PY) -m pytest -q $(PYTEST_ARGS)

# Type check (configuration in pyproject.toml: strict on the public interfaces, lenient elsewhere).
typecheck: $(STAMP)
	$(VENV)/bin/mypy

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

network: $(STAMP)
	$(PY) -m pedsafe_sumo.site --site xueqing

clean-venv:
	rm -rf $(VENV)
