# Two commands do everything on a fresh machine (Python 3.11 + pip):
#   make demo   -- venv, install, run the main job on the embedded default data
#   make test   -- venv with .[dev], run the test suite
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-dev
export JAX_PLATFORMS ?= cpu

.PHONY: demo test test-slow test-mitsuba bench bench-render lint clean venv

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip

$(STAMP): pyproject.toml | $(VENV)/bin/python
	$(PY) -m pip install -q -e '.[dev]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(PY) -m experiments.demo --out out

# the default and slow suites compile with XLA:CPU's legacy emitters (28 % less CPU, values within
# float32 rounding; docs/testing.md); mutate and test-mitsuba keep XLA's defaults
TEST_XLA_FLAGS := --xla_cpu_use_fusion_emitters=false
TEST_PYTEST = XLA_FLAGS="$(XLA_FLAGS) $(TEST_XLA_FLAGS)" $(PY) -m pytest

test: $(STAMP)
	$(TEST_PYTEST) -q -n 2 --dist loadfile --durations=15

test-slow: $(STAMP)
	$(TEST_PYTEST) -q -n 2 --dist loadfile --durations=25 -m 'slow and not mitsuba'

# Mitsuba 3 comparison renders (scalar_rgb variant: needs only the PyPI wheel)
test-mitsuba: $(STAMP)
	$(PY) -m pip install -q -e '.[dev,mitsuba]'
	$(PY) -m pytest -q -m mitsuba

bench: $(STAMP)
	$(PY) -m benchmarks.image_filters

# renderer: samples/s vs Mitsuba 3 (llvm_ad_rgb needs `apt-get install libllvm19`), equal-time RMSE
bench-render: $(STAMP)
	$(PY) -m pip install -q -e '.[dev,mitsuba]'
	$(PY) -m benchmarks.render --plot out/bench

# mutation check (issue 15): each curated mutant in tools/mutants.py must fail its tests
.PHONY: mutate
mutate: $(STAMP)
	$(PY) tools/mutate.py --json out/mutate.json

lint: $(STAMP)
	$(VENV)/bin/ruff check jaxgfx tests experiments benchmarks tools

clean:
	rm -rf $(VENV) out .pytest_cache
