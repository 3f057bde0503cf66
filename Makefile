# plantcheck developer tasks. `make test` is the one test command (README, .ci/run).
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: test venv lint typecheck pytest demo clean system-deps

# Python writes its bytecode caches (__pycache__, ignored by git) during make's commands, whatever
# the machine's environment says: an image that sets PYTHONDONTWRITEBYTECODE made every process
# the tests start compile plantcheck and the test modules from source again (a worker's
# collection 14 s of CPU instead of 9, each `plantcheck` command the tests run 0.4 s more).
unexport PYTHONDONTWRITEBYTECODE

# The stamp, not the plantcheck script, says the development install is done: README command
# 1 makes .venv with a plain `pip install .` (no ruff, mypy, pytest), and `make test` run after
# it must still install them into that venv.
STAMP  := $(VENV)/.plantcheck-dev

# pip compiles every module it installs to bytecode, one at a time: 85 of the 119 s this
# install took on a 2-core machine. compileall does it on every core, leaving out the packages
# the service never imports (torch and what comes with it, mypy, pip), which the few processes
# that import them compile then: 24 s instead of 85. Left uncompiled, the first services of a
# test run compiled their imports beside each other, at the run's busiest moment. A file that
# does not compile (test data in a package) is left to Python, hence `|| true`. pip's own
# switch against compiling (PIP_NO_COMPILE, set by the set-up test, whose scratch install runs a
# few tests in one process and no service) is kept here too: 48 CPU-s spared in that test.
NOT_PRECOMPILED := /site-packages/(torch|torchgen|functorch|sympy|networkx|mypy|mypyc|pip|setuptools)/
PRECOMPILE := $(if $(filter-out 0 false no off,$(PIP_NO_COMPILE)),no,yes)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet --no-compile -e ".[dev,fit]"
	test $(PRECOMPILE) = no || $(BIN)/python -m compileall -q -j 0 -x '$(NOT_PRECOMPILED)' \
	  "$$($(BIN)/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')" \
	  > /dev/null || true
	touch $@

venv: $(STAMP)

lint: venv
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/lint-imports

# mypy resolves `plantcheck` through a throw-away link to this folder made outside the tree
# (the package lives at the repository root through setuptools' package-dir mapping).
typecheck: venv
	@tmp=$$(mktemp -d) && ln -s "$(CURDIR)" "$$tmp/plantcheck" && \
	  MYPYPATH="$$tmp" $(BIN)/mypy -p plantcheck; rc=$$?; rm -rf "$$tmp"; exit $$rc

# Debian packages the tests use: PostgreSQL (a throw-away cluster per test session), Chromium
# (the web page test, headless) and libfuse3 (the read-only disk of the disk-fault tests).
# Installed with apt-get when missing and root.
system-deps:
	@need=""; \
	ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 || need="$$need postgresql"; \
	command -v chromium >/dev/null 2>&1 || need="$$need chromium"; \
	ls /usr/lib/*/libfuse3.so.3 >/dev/null 2>&1 || need="$$need libfuse3-3"; \
	if [ -n "$$need" ]; then \
	  if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
	    echo "installing Debian packages for the tests:$$need"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$need >/dev/null; \
	  else \
	    echo "missing$$need and cannot install here: the tests that need them will be skipped"; \
	  fi; \
	fi

# PYTEST_ARGS narrows the run (the set-up test runs `make test` in a scratch clone on a few tests)
# Four workers on two cores: the longest tests wait on real time (a simulated plant filling its
# window, a fault drill's outages, a job queue's periods) and the workers beyond two use those
# waits (on a 2-core machine beside a CPU-bound process: three workers 10.2 min of pytest
# instead of 12.6 with two). A fourth gained 3 % while spinning BLAS and OpenMP threads kept both
# cores busy throughout (918 s against 951 s); once they waited passively (below) the suite used
# 81 % of two cores on three workers, and a fourth took pytest from 588 to 546 s.
#
# The tests' processes (workers, the services and commands they start) get one OpenBLAS thread
# and passive OpenMP waits, unless the environment says otherwise: OpenBLAS's second thread
# spun on the other core through the chain's small matrix products (the generated-cases test
# 32.9 CPU-s for 22 s of wall, 20.7 with one thread), and the OpenMP threads of PyTorch and
# LightGBM spun at every barrier while a test's other thread waited for a core (the network-fit
# tests beside two CPU-bound processes: 28.5 CPU-s, 15.5 passive). The fits fix their own
# thread counts, so their results are the same.
pytest: venv system-deps
	OPENBLAS_NUM_THREADS=$${OPENBLAS_NUM_THREADS:-1} OMP_WAIT_POLICY=$${OMP_WAIT_POLICY:-PASSIVE} \
	  $(BIN)/pytest -q -n 4 --dist worksteal --durations=15 $(PYTEST_ARGS)

# mypy (a minute of one core on a fresh clone) runs beside pytest rather than before it: before,
# it held one core while the other waited. Its output follows the tests' and fails the run the
# same way; lint, quick, still goes first.
TYPECHECK_LOG := $(VENV)/typecheck.log

test: lint
	@$(MAKE) --no-print-directory typecheck > $(TYPECHECK_LOG) 2>&1 & types=$$!; \
	$(MAKE) --no-print-directory pytest; tests=$$?; \
	wait $$types; typed=$$?; cat $(TYPECHECK_LOG); \
	test $$tests -eq 0 && test $$typed -eq 0

demo: venv
	$(BIN)/plantcheck demo

clean:
	rm -rf $(VENV) build .mypy_cache .pytest_cache .ruff_cache
