# Two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
OUT    ?= out

.PHONY: install demo test test-slow bench browser urdf clean

# Python writes the bytecode of what it imports (a PYTHONDONTWRITEBYTECODE of the environment would have every
# process compile the libraries again, about 6 s of CPU each); pytest keeps its rewritten test modules the same way
export PYTHONDONTWRITEBYTECODE :=

# uv installs the dependencies (about 1.3 GB of wheels) in about 10 s where pip took 50 s, and its byte-compiling
# of all of them 40 s more, on the 2-core AMD EPYC. Only what the toolkit imports is compiled (importing each of
# its modules writes their bytecode and that of the libraries they use, about 1500 files, and the test runner's),
# so a command starts as fast as before. Where uv cannot be had, pip installs the same.
# $(DEPS): the libraries installed; $(STAMP): their bytecode too (make test starts mypy between the two).
DEPS   := $(VENV)/.dependencies
$(DEPS): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	( $(PY) -m pip install --quiet 'uv>=0.5' && $(VENV)/bin/uv pip install --quiet --python $(PY) -e '.[test]' ) \
	  || $(PY) -m pip install --quiet -e '.[test]'
	touch $(DEPS)

$(STAMP): $(DEPS)
	$(PY) -c "import pkgutil, importlib, pytest, xdist, hypothesis; [importlib.import_module(m.name) for p in \
	  ('arm_model', 'calibration', 'correction', 'viz') for m in pkgutil.walk_packages(importlib.import_module(p).__path__, p + '.')]"
	touch $(STAMP)

install: $(STAMP)

browser:
	bash scripts/ensure-chromium.sh

demo: $(STAMP)
	$(PY) -m arm_model.demo --out $(OUT)/demo

# the suite without the long studies (-m "not slow"; timings: README, Tests; what CI runs: .ci/run); test-slow: the
# rest, run by hand before merging a change to estimation.
# make test runs the lint gate too: mypy (about 25 s of CPU from a fresh clone) starts as soon as the libraries are
# installed, beside the single-process bytecode step, ruff and then pytest, its findings printed after the tests' and
# failing make test all the same; ruff stops make test on a finding before the tests start. The tests' order under
# -n 2: tests/conftest.py balanced_order (the longest modules first, from tests/durations.tsv).
PYTEST := $(PY) -m pytest
test: $(DEPS) browser
	$(VENV)/bin/mypy > $(VENV)/mypy.log 2>&1 & types=$$!; \
	if ! { $(MAKE) --no-print-directory $(STAMP) && $(VENV)/bin/ruff check .; }; then \
	  kill $$types 2>/dev/null; wait $$types; exit 1; fi; \
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
