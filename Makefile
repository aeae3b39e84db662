# Two self-sufficient entry points: each creates .venv when missing and installs the package.
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.nscontrol-installed
OUT    ?= out

.PHONY: demo warmup test test-all bench lint clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev,cluster,control]"
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/nscontrol warmup   # compiles the numba kernels once, saying so
	$(VENV)/bin/nscontrol report --out $(OUT)

test: $(STAMP)
	$(PY) -m pytest -m "not slow" -n 2 --dist loadfile

test-all: $(STAMP)
	$(PY) -m pytest -n 2 --dist loadfile

warmup: $(STAMP)
	$(VENV)/bin/nscontrol warmup

bench: $(STAMP)
	$(VENV)/bin/nscontrol bench

lint: $(STAMP)
	$(VENV)/bin/ruff check src tests bench

clean:
	rm -rf $(OUT) .pytest_cache build src/*.egg-info
	find src -name '*.nbi' -delete -o -name '*.nbc' -delete
