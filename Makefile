# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
OUT    ?= out

.PHONY: install demo test test-slow bench browser urdf clean

# pip's own byte-compiling of what it installs runs on one core (about 33 s of CPU on the 2-core AMD EPYC);
# compileall -j 0 does the same on every core, and the project's own modules (an editable install is not compiled)
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet --no-compile -e '.[test]'
	$(PY) -m compileall -q -j 0 $(VENV)/lib > /dev/null || true   # as pip does: a file that does not compile is left
	$(PY) -m compileall -q -j 0 arm_model calibration correction viz > /dev/null
	touch $(STAMP)

install: $(STAMP)

browser:
	bash scripts/ensure-chromium.sh

demo: $(STAMP)
	$(PY) -m arm_model.demo --out $(OUT)/demo

# the suite without the long studies (-m "not slow"; timings: README, Tests); test-slow: the rest (.ci/run runs both).
# make test runs the lint gate too: ruff first (it stops on a finding), then mypy (about 34 s of CPU from a fresh
# clone) beside pytest, its findings printed after the tests' and failing make test all the same. The tests' order
# under -n 2: tests/conftest.py balanced_order (the longest modules first, from tests/durations.tsv).
# PYTHONDONTWRITEBYTECODE emptied for pytest: its assertion rewriting of every test module (and of hypothesis, a
# plugin) is kept in __pycache__ for the next run instead of done again in each worker (about 5 s of CPU a worker)
PYTEST := PYTHONDONTWRITEBYTECODE= $(PY) -m pytest
test: $(STAMP) browser
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy > $(VENV)/mypy.log 2>&1 & types=$$!; \
	$(PYTEST) -n 2 --dist worksteal -q -m "not slow" tests; tests=$$?; \
	wait $$types; typed=$$?; echo "mypy:"; cat $(VENV)/mypy.log; \
	test $$tests = 0 && test $$typed = 0

test-slow: $(STAMP) browser
	$(PYTEST) -n 2 --dist worksteal -q -m slow tests

# The lint and type gate (configuration in pyproject.toml): ruff, then mypy.
.PHONY: lint
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy

bench: $(STAMP)
	$(PY) -m benchmarks.run $(BENCH)

urdf: $(STAMP)
	$(VENV)/bin/aacmm urdf urdf/aacmm7.dh.toml -o urdf/aacmm7.urdf

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache
