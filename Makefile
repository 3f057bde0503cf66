# plantcheck developer tasks. `make test` is the one test command (README, .ci/run).
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: test venv lint typecheck pytest demo clean system-deps

$(BIN)/plantcheck: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[dev]"
	touch $@

venv: $(BIN)/plantcheck

lint: venv
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# mypy resolves `plantcheck` through a throw-away link to this folder made outside the tree
# (the package lives at the repository root through setuptools' package-dir mapping).
typecheck: venv
	@tmp=$$(mktemp -d) && ln -s "$(CURDIR)" "$$tmp/plantcheck" && \
	  MYPYPATH="$$tmp" $(BIN)/mypy -p plantcheck; rc=$$?; rm -rf "$$tmp"; exit $$rc

# Debian packages the tests use: PostgreSQL (a throw-away cluster per test session).
system-deps:
	@if ! ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1; then \
	  if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	    echo "installing PostgreSQL (Debian package postgresql) for the storage tests"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq postgresql >/dev/null; \
	  else \
	    echo "PostgreSQL is not installed and cannot be installed here: its tests will be skipped"; \
	  fi; \
	fi

pytest: venv system-deps
	$(BIN)/pytest -q

test: lint typecheck pytest

demo: venv
	$(BIN)/plantcheck diagnose simulator/examples/sticky_flow.csv --loop-type flow

clean:
	rm -rf $(VENV) build .mypy_cache .pytest_cache .ruff_cache
