# hevsim developer entry points. `make demo` and `make test` are the README's two commands.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup demo examples test docs lint refinement bench clean openfoam calculix

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

# The numba kernels are compiled first (`hevsim compile`, one process per core, while the
# linters run), then pytest runs on every core (pytest-xdist; one test file per worker at a
# time, so a module's fixtures are built once). JOBS=1: one compile process, one test worker.
JOBS ?= $(shell nproc 2>/dev/null || echo 2)

test: $(STAMP) openfoam calculix
	@mkdir -p build
	$(BIN)/hevsim compile --jobs $(JOBS) 2>build/compile.log & compile=$$!; \
	  $(BIN)/ruff check src tests benchmarks examples && \
	  $(BIN)/ruff format --check src tests benchmarks examples && \
	  $(BIN)/mypy && \
	  $(BIN)/lint-imports && \
	  $(BIN)/pylint --disable=all --enable=duplicate-code --min-similarity-lines=7 src/hevsim && \
	  $(BIN)/python -m sphinx -W -q -b html docs/api build/api-html; lint=$$?; \
	  wait $$compile; built=$$?; cat build/compile.log; \
	  [ $$lint = 0 ] && [ $$built = 0 ]
	$(BIN)/python -m pytest -q -n $(JOBS) --dist loadfile

docs: $(STAMP)
	$(BIN)/python -m sphinx -W --keep-going -b html docs/api build/api-html
	@echo "API reference: build/api-html/index.html"

refinement: $(STAMP)
	$(BIN)/hevsim refinement --cycle udds

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_simulate.py

clean:
	rm -rf $(VENV) results build .pytest_cache .mypy_cache .ruff_cache
