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

.PHONY: demo test lint typecheck docs numeric-other-kernel numeric-other-kernel-held pytest bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,camera,docs]'
	touch $(STAMP)

demo: $(STAMP)
	$(RUN) $(BIN)/beyond demo

# The checks side by side, not one after the other: lint, mypy and the docs build together first
# (seconds, and a failure shows before the long run), then the numeric tests under another
# kernel beside the main pytest run, whose services, podman and paced replays leave the cores
# idle part of the time. The numeric run's output is printed whole when it ends (a minute in),
# so pytest's summary still ends the output. Any step failing fails `make test`.
test: $(STAMP)
	$(MAKE) -f $(SELF) --no-print-directory -j3 --output-sync=target lint typecheck docs
	$(MAKE) -f $(SELF) --no-print-directory -j2 numeric-other-kernel-held pytest

numeric-other-kernel-held: $(STAMP)
	$(MAKE) -f $(SELF) --no-print-directory --output-sync=target numeric-other-kernel

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
# replays), a test file at a time in the order tests/conftest.py gives: the longest files first.
pytest: $(STAMP)
	$(RUN) $(BIN)/python -m pytest -q -n 4 --dist loadfile --no-loadscope-reorder

bench: $(STAMP)
	for b in bench/*.py; do $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) .mypy_cache .pytest_cache .ruff_cache site
