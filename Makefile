# Two commands for a fresh machine (see README):
#   make run   - set up (virtualenv on first use) and run the main job
#   make test  - set up and run the test suite
# and the checks CI runs beside the tests (.ci/run): make lint, make typecheck, make docs.
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

.PHONY: run test lint typecheck docs network clean-venv

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

# The suite on every core (pytest-xdist): TEST_WORKERS=0 runs it in this one process. --dist loadgroup:
# tests/conftest.py keeps each test file on one worker, and the tests that share an expensive fixture
# together. PYTEST_ARGS adds options or picks tests, e.g. PYTEST_ARGS="--durations=40" or "tests/batch".
TEST_WORKERS ?= auto
test: $(STAMP) $(QC_STAMP)
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadgroup $(PYTEST_ARGS)

# Type check (configuration in pyproject.toml: strict on the public interfaces, lenient elsewhere).
typecheck: $(STAMP)
	$(VENV)/bin/mypy

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

# The documentation site (mkdocs.yml) with the docs extra, built strictly: a warning (a broken link, a
# page missing from the navigation, a docstring reference that does not resolve) fails the build.
DOCS_STAMP := $(VENV)/.installed-docs
DOCS_SITE_DIR ?= build/site
$(DOCS_STAMP): $(STAMP)
	$(PY) -m pip install --quiet -c requirements.lock -e ".[docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(VENV)/bin/mkdocs build --strict --site-dir $(DOCS_SITE_DIR)

network: $(STAMP)
	$(PY) -m pedsafe_sumo.site --site xueqing

clean-venv:
	rm -rf $(VENV)
