# The README's two commands: `make demo` runs the full pipeline, `make test` runs lint, types and tests.
# Both create .venv on first use and reinstall only when pyproject.toml changes; the install
# holds every extra (the camera's pose model, the docs site's tools too), so `make test` runs
# every test and builds the docs.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# Every process we start compiles our modules once and reuses the bytecode after: with
# PYTHONDONTWRITEBYTECODE set (as container images often set it) each service, CLI call and
# test subprocess compiled every module it imported again, 0.3 CPU-s a process.
RUN := env -u PYTHONDONTWRITEBYTECODE
# this file, for the steps `make test` runs through make again (`make -f FILE test` included)
SELF := $(firstword $(MAKEFILE_LIST))

.PHONY: demo test lint typecheck docs numeric-other-kernel pytest bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,camera,docs]'
	touch $(STAMP)

demo: $(STAMP)
	$(RUN) $(BIN)/beyond demo

# Lint, mypy and the docs build side by side first (seconds, and a failure shows before the long
# run); then the numeric tests under another kernel; then the main pytest run, which leaves those
# numeric tests to the run before it (each figure is checked once, on a kernel other than this
# machine's). One after the other: on two cores the numeric run beside pytest took 184 s instead
# of about 50 and slowed pytest by as much. Any step failing fails `make test`.
test: $(STAMP)
	$(MAKE) -f $(SELF) --no-print-directory -j3 --output-sync=target lint typecheck docs
	$(MAKE) -f $(SELF) --no-print-directory numeric-other-kernel
	$(MAKE) -f $(SELF) --no-print-directory pytest

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: $(STAMP)
	$(BIN)/mypy

# The site under docs/ (mkdocs.yml), strict: a broken link, a page missing from the files or a
# warning of any plug-in fails the build. The reference pages are generated from the code. The
# two variables silence a banner some plug-ins print about a future MkDocs 2.
docs: $(STAMP)
	$(RUN) NO_MKDOCS_2_WARNING=1 DISABLE_MKDOCS_2_WARNING=true $(BIN)/mkdocs build --strict --quiet --site-dir site

# The numeric tests (the reproduction, Table II, the network's learning and inference, the HMMs'
# training) once more under another OpenBLAS kernel than the main run's and numpy's baseline
# SIMD, as on a machine with another CPU: a figure compared bit for bit fails here. Under 90 s.
numeric-other-kernel: $(STAMP)
	$(RUN) $(BIN)/python tests/other_kernel.py -q -n 2 --dist loadfile

# Four workers on two cores (most of the suite waits on services starting, podman and paced
# replays), a test file at a time in the order tests/conftest.py gives: the longest files first;
# the numeric tests ran on another kernel just before.
pytest: $(STAMP)
	$(RUN) $(BIN)/python -m pytest -q -n 4 --dist loadfile --no-loadscope-reorder -m 'not numeric'

bench: $(STAMP)
	for b in bench/*.py; do $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) .mypy_cache .pytest_cache .ruff_cache site
