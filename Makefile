# Quick start: `make demo` runs the end-to-end demo, `make test` runs the tests, `make lint` runs
# ruff and mypy.
# Each creates .venv and installs the project on first use.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-all lint bench clean

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

clean:
	rm -rf $(VENV) demo-output mlruns.db mlflow.db mlartifacts greybench-service
