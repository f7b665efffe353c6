# Quick start: `make run` (creates .venv, installs, starts the environment) and `make test`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
UP_ARGS ?=   # more `skeye up` options for `make run`, e.g. UP_ARGS="--ground-port 8081"
# pytest-xdist workers for `make test`: one per core and one more, since many tests wait on
# wall-clock time (real-time flights, timeouts, restarts) and leave a core idle meanwhile
# (docs/performance.md, "The test suite"); a test file stays on one worker.
TEST_WORKERS ?= $(shell $(PYTHON) -c "import os; print(len(os.sched_getaffinity(0)) + 1 \
	if hasattr(os, 'sched_getaffinity') else (os.cpu_count() or 1) + 1)")

.PHONY: run test lint bench clean chromium

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip

# The simulator's hot path is compiled at install time (setup.py, skeye/native.py): reinstall
# whenever one of those sources changes, so the compiled modules never lag behind the code.
NATIVE_SOURCES := $(shell $(PYTHON) skeye/native.py --sources)

# skeye/buildprogress.py runs `pip install -v` and shows only its progress lines (which step,
# which file is compiling), so a slow build never looks hung.
# The simulator and ground control are extras of the package (the base install is the
# onboard pilot's, docs/onboard.md): the development environment takes both.
$(VENV)/.installed: $(BIN)/python pyproject.toml setup.py skeye/native.py $(NATIVE_SOURCES)
	$(BIN)/python skeye/buildprogress.py -e '.[sim,ground,mavlink]'
	touch $@

# The test extras only (the package itself is already built and installed above).
$(VENV)/.test-installed: $(VENV)/.installed
	$(BIN)/pip install -q $$($(BIN)/python -c "import tomllib; \
		print(' '.join(d for d in tomllib.load(open('pyproject.toml', 'rb')) \
		['project']['optional-dependencies']['test']))")
	touch $@

# exec: skeye up is make's own child, so make's SIGTERM reaches it; on SIGINT make passes
# nothing on and waits, which skeye up notices (skeye/processes.py, ParentWatch) and stops.
run: $(VENV)/.installed
	MUJOCO_GL=$${MUJOCO_GL:-egl} exec $(BIN)/skeye up --world pad $(UP_ARGS)

# compileall: the tests start skeye as a process hundreds of times, and where
# PYTHONDONTWRITEBYTECODE is set (as on our development image) each start compiled every module it
# imports again (`skeye pilot --help`: 0.7 s, 0.36 s from bytecode). It writes only what changed.
test: $(VENV)/.test-installed chromium
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/python -m compileall -q skeye
	SKEYE_REQUIRE_COMPILED=1 MUJOCO_GL=$${MUJOCO_GL:-egl} $(BIN)/python -m pytest -q \
		-n $(TEST_WORKERS) --dist loadfile

# Browser tests drive the distribution's Chromium (never a browser downloaded by Playwright).
chromium:
	@test -x /usr/bin/chromium || { \
		SUDO=$$([ "$$(id -u)" = 0 ] || echo sudo); \
		$$SUDO apt-get update -qq && $$SUDO apt-get install -y -qq chromium >/dev/null; }

lint: $(VENV)/.test-installed
	$(BIN)/ruff check .
	$(BIN)/mypy

bench: $(VENV)/.installed
	$(BIN)/python benchmarks/bench_sim.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .mypy_cache .ruff_cache
	find . -name '*.so' -not -path './.venv/*' -delete
