# Quick start: `make demo` runs the end-to-end demo, `make test` runs the tests, `make lint` runs
# ruff and mypy.
# Each creates .venv and installs the project on first use.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-all lint bench mutation clean

$(STAMP): pyproject.toml
	$(PY) -m venv $(VENV)
	# torch first, pinned, so nothing resolves a CUDA build.
	$(BIN)/pip install --quiet "torch==2.13.0"
	$(BIN)/pip install --quiet -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	bash scripts/demo.sh

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy

test: $(STAMP)
	$(BIN)/python -m pytest -q

test-all: $(STAMP)
	$(BIN)/python -m pytest -q -m ""

bench: $(STAMP)
	for b in friction diagnose robot toolpath machining ranking explain service circle; do $(BIN)/greybench bench $$b || exit 1; done

# Mutation testing of the core numeric and safety modules (docs/mutation-testing.md): mutmut over
# [tool.mutmut] in pyproject.toml, niced, one worker by default (MUTATION_JOBS=2 on an idle machine);
# MUTANTS narrows it, e.g. make mutation MUTANTS='simulate.costs.*'. Results are kept in mutants/:
# a rerun only tests what changed.
MUTATION_JOBS ?= 1
MUTANTS ?=
mutation: $(STAMP)
	nice -n 10 $(BIN)/python scripts/mutmut_kernels.py run --max-children $(MUTATION_JOBS) $(MUTANTS)
	$(BIN)/python scripts/mutation_report.py

clean:
	rm -rf $(VENV) demo-output mlruns.db mlflow.db mlartifacts greybench-service
