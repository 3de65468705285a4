# hevsim developer entry points. `make demo` and `make test` are the README's two commands.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup demo examples test docs lint refinement bench clean openfoam calculix chromium

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)
	$(BIN)/hevsim simulate examples/series_hev.toml --cycle udds --out results/series_hev_udds

# the examples' build products (not in git): the native module FMU of examples/cosim_module,
# rebuilt only if missing or stale (its GUID hashes the generated model data and C sources)
examples: $(STAMP)
	$(BIN)/python examples/cosim_module/run_module.py --build-fmu

# test also checks the layers of DESIGN.md (lint-imports, the contract in pyproject.toml; issue 24).
# test also runs a duplicate-code scan (issue 18): no block of 7+ lines twice in src/hevsim; at
# 4-6 lines two remain, neither physics: optimal/__init__ vs optimal/dp (__all__), battery/cell
# vs battery/module (current-profile checks).
# OpenFOAM (simpleFoam) for the turbulent coolant flow (hevsim.thermal.rans, tests/test_rans.py):
# Debian's package when missing, if we are root with apt-get; otherwise say so and go on (the
# RANS tests then skip, and `hevsim flow` says what to install).
openfoam:
	@if command -v simpleFoam >/dev/null 2>&1 || [ -n "$$HEVSIM_OPENFOAM" ]; then \
		echo "openfoam: found ($$(command -v simpleFoam || echo $$HEVSIM_OPENFOAM))"; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		echo "openfoam: installing Debian's package: apt-get install -y openfoam"; \
		DEBIAN_FRONTEND=noninteractive apt-get install -y openfoam || \
		{ apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y openfoam; } || \
		echo "openfoam: apt-get install openfoam failed: the RANS tests will be skipped"; \
	else \
		echo "openfoam: simpleFoam not found and not root with apt-get: skipping (install 'openfoam'" \
			"as root, or openfoam.com/.org packages; the RANS tests will be skipped)"; \
	fi

# CalculiX (ccx), the independent FEM reference of the nonlinear Abaqus-deck tests
# (tests/test_thermal_nonlinear.py): Debian's package when missing, as for OpenFOAM.
calculix:
	@if command -v ccx >/dev/null 2>&1; then \
		echo "calculix: found ($$(command -v ccx))"; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		echo "calculix: installing Debian's package: apt-get install -y calculix-ccx"; \
		DEBIAN_FRONTEND=noninteractive apt-get install -y calculix-ccx || \
		{ apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y calculix-ccx; } || \
		echo "calculix: apt-get install calculix-ccx failed: the CalculiX comparisons will be skipped"; \
	else \
		echo "calculix: ccx not found and not root with apt-get: skipping (the CalculiX comparisons" \
			"will be skipped)"; \
	fi

# Headless Chromium for the documentation site's browser test (tests/test_docs_site.py renders
# the built pages to PNG): Debian's package when missing, as for OpenFOAM; the test skips
# with a message without it.
chromium:
	@if command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1; then \
		echo "chromium: found ($$(command -v chromium || command -v chromium-browser))"; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
		echo "chromium: installing Debian's package: apt-get install -y chromium"; \
		DEBIAN_FRONTEND=noninteractive apt-get install -y chromium || \
		{ apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y chromium; } || \
		echo "chromium: apt-get install chromium failed: the browser test will be skipped"; \
	else \
		echo "chromium: not found and not root with apt-get: skipping (install 'chromium' as root;" \
			"the browser test of the documentation site will be skipped)"; \
	fi

# The numba kernels are compiled first (`hevsim compile`, one process per core, while the
# linters run), then pytest runs on every core (pytest-xdist; one test file per worker at a
# time, so a module's fixtures are built once). JOBS=1: one compile process, one test worker.
# Between the two, the documentation site is built (warnings as errors): its tutorial gallery
# runs on the compiled kernels, and tests/test_docs_site.py checks the built pages.
JOBS ?= $(shell nproc 2>/dev/null || echo 2)

test: $(STAMP) openfoam calculix chromium
	@mkdir -p build
	$(BIN)/hevsim compile --jobs $(JOBS) 2>build/compile.log & compile=$$!; \
	  $(BIN)/ruff check src tests benchmarks examples docs/conf.py docs/tutorials && \
	  $(BIN)/ruff format --check src tests benchmarks examples docs/conf.py docs/tutorials && \
	  $(BIN)/mypy && \
	  $(BIN)/lint-imports && \
	  $(BIN)/pylint --disable=all --enable=duplicate-code --min-similarity-lines=7 src/hevsim; lint=$$?; \
	  wait $$compile; built=$$?; cat build/compile.log; \
	  [ $$lint = 0 ] && [ $$built = 0 ]
	$(BIN)/python -m sphinx -W -q -b html docs docs/_build/html
	$(BIN)/python -m pytest -q -n $(JOBS) --dist loadfile

# The documentation site (issue 28): user guides, the executed tutorial gallery (its scripts run
# at every build, short cases on the cached kernels), how-to guides and the API reference.
# Offline; `make test` builds it too (warnings as errors) before the tests that check it.
docs: $(STAMP)
	$(BIN)/python -m sphinx -W --keep-going -b html docs docs/_build/html
	@echo "documentation site: docs/_build/html/index.html"

refinement: $(STAMP)
	$(BIN)/hevsim refinement --cycle udds

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_simulate.py

clean:
	rm -rf $(VENV) results build docs/_build docs/auto_tutorials .pytest_cache .mypy_cache .ruff_cache
