# Two commands do everything on a fresh machine (Python 3.11 + pip):
#   make demo   -- venv, install, run the main job on the embedded default data
#   make test   -- venv with .[dev], run the test suite
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-dev
export JAX_PLATFORMS ?= cpu

.PHONY: demo test test-slow bench lint clean venv

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

$(STAMP): pyproject.toml | $(VENV)/bin/python
	$(PY) -m pip install -q -e '.[dev]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(PY) -m experiments.demo --out out

test: $(STAMP)
	$(PY) -m pytest -q

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow

bench: $(STAMP)
	$(PY) -m benchmarks.image_filters

lint: $(STAMP)
	$(VENV)/bin/ruff check jaxgfx tests experiments benchmarks

clean:
	rm -rf $(VENV) out .pytest_cache
