# Two self-sufficient entry points: each creates .venv when missing and installs the package.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.nscontrol-installed
DEMO_STAMP := $(VENV)/.nscontrol-demo-installed
DOCS_STAMP := $(VENV)/.nscontrol-docs-installed
OUT    ?= out

.PHONY: demo warmup test test-sensitive test-all bench lint docs clean

# pip says what it does (no --quiet): a line per package it collects, a bar per download.
# Two stamps: the demo installs what the examples import (the extras optimal and scs); the
# test, lint and bench targets add the test tools, Dask and python-control on top. The full
# install stamps both, so `make demo` after `make test` installs nothing.
define make_venv
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@echo "updating pip in $(VENV)"
	$(PY) -m pip install --upgrade --progress-bar on pip
endef

$(DEMO_STAMP): pyproject.toml
	$(make_venv)
	@echo "installing nscontrol (editable, from this folder) into $(VENV) with what the examples need (the extras optimal and scs): numpy, scipy, numba, cvxpy, casadi, matplotlib and about 20 more packages (about 1 min; more with an empty pip cache)"
	$(PY) -m pip install --progress-bar on -e ".[optimal,scs]"
	touch $(DEMO_STAMP)

$(STAMP): pyproject.toml
	$(make_venv)
	@echo "installing nscontrol (editable, from this folder) into $(VENV) with the extras dev, cluster, control and scs: numpy, scipy, numba, cvxpy, casadi, matplotlib, dask, python-control and about 50 more packages (1-2 min; more with an empty pip cache)"
	$(PY) -m pip install --progress-bar on -e ".[dev,cluster,control,scs]"
	touch $(STAMP) $(DEMO_STAMP)

# JOBS: processes side by side for the warm-up and the report (default: one per core).
JOBS ?=
JOBS_OPT := $(if $(JOBS),--jobs $(JOBS),)

demo: $(DEMO_STAMP)
	$(VENV)/bin/nscontrol warmup $(JOBS_OPT)   # compiles the numba kernels once, saying so
	$(VENV)/bin/nscontrol report --out $(OUT) $(JOBS_OPT)

test: $(STAMP)
	$(PY) -m pytest -m "not slow" -n 2 --dist loadfile

# The modules marked `sensitive` (tests/README.md) once more under an older BLAS kernel and once
# with numba's optimiser off, so rounding that differs between machines shows up here. The
# unoptimised kernels are cached apart (NUMBA_CACHE_DIR), never beside the optimised ones;
# most of them cannot be cached at all (numba finds "dynamic globals" in their unoptimised code),
# and its warning saying so for each is silenced.
# The marked modules are found by name (collecting the whole suite to filter on the marker
# costs minutes of imports; the longest, conformance, goes first); the marker is the one list.
SENSITIVE_CACHE ?= $(VENV)/numba-cache-opt0
SENSITIVE_TESTS = $(shell grep -rlE '^pytestmark = .*pytest\.mark\.sensitive' tests --include='test_*.py' | sort -r)

test-sensitive: $(STAMP)
	OPENBLAS_CORETYPE=Sandybridge $(PY) -m pytest -m "sensitive and not slow" -n 2 \
	    --dist loadfile $(SENSITIVE_TESTS)
	NUMBA_OPT=0 NUMBA_CACHE_DIR=$(SENSITIVE_CACHE) $(PY) -m pytest -m "sensitive and not slow" \
	    -n 2 --dist loadfile -W "ignore:Cannot cache compiled function" $(SENSITIVE_TESTS)

test-all: $(STAMP)
	$(PY) -m pytest -n 2 --dist loadfile

warmup: $(DEMO_STAMP)
	$(VENV)/bin/nscontrol warmup $(JOBS_OPT)

bench: $(STAMP)
	$(VENV)/bin/nscontrol bench

# The site is built with warnings as errors; figures of a previous `make demo` (out/) go
# into the gallery when present. `-j auto` reads and writes pages on every core (about 35 s
# of CPU for a clean build; on a loaded machine two processes also get twice the CPU share).
$(DOCS_STAMP): pyproject.toml $(STAMP)
	$(PY) -m pip install --quiet -e ".[docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	MPLBACKEND=Agg $(PY) -m sphinx -j auto -W --keep-going -q -b html docs docs/_build/html

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests bench
	$(PY) -m mypy

clean:
	rm -rf $(OUT) .pytest_cache build src/*.egg-info docs/_build docs/api/generated docs/_gallery docs/gallery.md
	find src -name '*.nbi' -delete -o -name '*.nbc' -delete
