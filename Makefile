# Quick start: `make demo` runs the end-to-end demo, `make test` runs the tests, `make lint` runs
# ruff and mypy.
# Each creates .venv and installs the project on first use.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# Every dependency at an exact version with its hashes (torch: the 2.13.0 CPU wheel from the
# machine's wheel folder, named by the lock's --find-links; no nvidia-* package). `make lock` remakes it.
LOCK := requirements.lock
# uv installs from the lock (a warm cache installs in seconds); taken from PATH, else bootstrapped
# into .venv/uv with pip from the registry. The venv has no pip of its own (ensurepip alone takes
# longer than the locked install): `uv pip install --python .venv/bin/python ...` adds packages.
UV_VERSION := 0.13.9
UV := $(or $(shell command -v uv 2>/dev/null),$(VENV)/uv/bin/uv)

.PHONY: demo test test-all lint bench mutation mutation-hand lock clean

$(VENV)/uv/bin/uv:
	$(PY) -m pip install --quiet --disable-pip-version-check --root-user-action=ignore --target $(VENV)/uv "uv==$(UV_VERSION)"

# Order-only on uv: a newer uv does not reinstall the project.
$(STAMP): pyproject.toml $(LOCK) | $(UV)
	$(PY) -m venv --without-pip $(VENV)
	$(UV) pip install --quiet --python $(BIN)/python --require-hashes -r $(LOCK)
	$(UV) pip install --quiet --python $(BIN)/python --no-deps -e .
	# A dependency added to pyproject.toml but not locked fails here: run `make lock`.
	$(UV) pip check --quiet --python $(BIN)/python
	touch $(STAMP)

# Resolve pyproject.toml (all extras) for this machine kind (CPython 3.11, x86_64 Linux) into the lock;
# versions already in the lock are kept where they still fit (uv's preference for the output file).
lock: | $(UV)
	$(UV) pip compile pyproject.toml --all-extras --generate-hashes --python-version 3.11 \
	    --python-platform x86_64-manylinux_2_28 --find-links /opt/wheels --emit-find-links \
	    --custom-compile-command "make lock" --quiet -o $(LOCK)
	! grep -E '^(nvidia-|triton)' $(LOCK)

# Quick sizes; make demo FULL=1 runs the full-size demo (scripts/demo.sh).
FULL ?= 0
demo: $(STAMP)
	FULL=$(FULL) bash scripts/demo.sh

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy

# The tests run on every core this process may use (pytest-xdist; -n auto), one pytest worker per core;
# TEST_JOBS=1 runs them in one process. Tests that must not overlap share an xdist_group (tests/conftest.py).
TEST_JOBS ?= auto
TEST_XDIST := -n $(TEST_JOBS) --dist loadgroup
test: $(STAMP)
	$(BIN)/python -m pytest -q $(TEST_XDIST)

test-all: $(STAMP)
	$(BIN)/python -m pytest -q -m "" $(TEST_XDIST)

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

# Hand-written realistic mutants (scripts/hand_mutants.py): every one must be killed (about 1.5 min).
mutation-hand: $(STAMP)
	$(BIN)/python scripts/hand_mutants.py

clean:
	rm -rf $(VENV) demo-output mlruns.db mlflow.db mlartifacts greybench-service
