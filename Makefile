# lowerbase: `make demo` runs the main job, `make test` runs every test; both set up first.
SHELL := /bin/bash
.DEFAULT_GOAL := help

VENV ?= .venv
PY := $(VENV)/bin/python
# Debian's python3 is the one its ROS packages are built for; the venv sees them through
# --system-site-packages while pip-installed dependencies take precedence.
SYSTEM_PYTHON ?= $(shell test -x /usr/bin/python3 && echo /usr/bin/python3 || command -v python3)
STAMP := $(VENV)/.lowerbase-installed
ROS_OUT := build/ros
# The oldest supported Python (requires-python >= 3.10), from pyenv; a venv of its own without
# the system's site-packages (so the ROS tests skip there).
OLDEST_VENV ?= .venv-py310
OLDEST_PYTHON ?= $(shell { ls -d "$$(pyenv root 2>/dev/null)"/versions/3.10*/bin/python3.10 \
  "$$HOME"/.pyenv/versions/3.10*/bin/python3.10 2>/dev/null; command -v python3.10; } | sort -uV | tail -n 1)
OLDEST_STAMP := $(OLDEST_VENV)/.lowerbase-installed
ROS2_VENV ?= .venv-ros2

.PHONY: help env system-deps test test-oldest lint typecheck unit demo bench docs clean ros2 \
  ros2-optional

help:
	@echo "make demo   - set up and run the demo (the whole robot: a transport task, a low battery, a charge; a report)"
	@echo "make test   - set up and run ruff, mypy and the whole test suite (ROS 2's too where it can be set up; ROS2=0: not)"
	@echo "make test-oldest - the test suite on the oldest supported Python (3.10, from pyenv)"
	@echo "make ros2   - ROS 2 Kilted (PyPI wheels) in .venv-ros2 and its interface packages (docs/ros2.md)"
	@echo "make bench  - run the benchmarks and print the results (WRITE=1: into docs/benchmarks.md)"
	@echo "make docs   - regenerate docs/protocol.md, docs/status-codes.md, docs/legged-protocol.md"

system-deps:
	@bash scripts/install-ros.sh

$(STAMP): pyproject.toml
	$(SYSTEM_PYTHON) -m venv --system-site-packages $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	@if $(PY) -c 'import genpy' 2>/dev/null; then \
	  $(PY) -m lowerbase.driver.msggen $(ROS_OUT) --pth "$$($(PY) -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"; \
	else echo "genpy not available: woosh_msgs not generated (ROS tests will skip)"; fi
	$(PY) -m lowerbase warm
	touch $@

env: system-deps $(STAMP)

lint: env
	$(VENV)/bin/ruff check lowerbase tests benchmarks

typecheck: env
	$(VENV)/bin/mypy

unit: env
	$(PY) -m pytest -q

# ROS 2 first (its own venv; skipped in one line where this machine cannot have it), so that
# tests/ros2 run too
test: env ros2-optional lint typecheck unit

$(OLDEST_STAMP): pyproject.toml
	@test -n "$(OLDEST_PYTHON)" || { echo "make test-oldest: no Python 3.10 found (pyenv install 3.10, or pass OLDEST_PYTHON=/path/to/python3.10)" >&2; exit 1; }
	$(OLDEST_PYTHON) -m venv --clear $(OLDEST_VENV)
	$(OLDEST_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(OLDEST_VENV)/bin/python -m pip install --quiet -e '.[dev]'
	touch $@

# This venv has no ROS on purpose: LOWERBASE_WITHOUT_ROS=1 lets the ROS tests skip under CI=true.
test-oldest: $(OLDEST_STAMP)
	LOWERBASE_WITHOUT_ROS=1 $(OLDEST_VENV)/bin/python -m pytest -q $(TESTS)

# ROS 2 in a venv of its own (.venv-ros2) and woosh_msgs, tf2_msgs, nav2_msgs,
# lowerbase_legged_msgs built once into build/ros2/<hash> (docs/ros2.md). `make test` runs it
# with --optional: where it cannot be (no registry, not x86_64, ROS2=0), one line and on.
ros2:
	ROS2_VENV=$(ROS2_VENV) bash scripts/ros2-env.sh

ros2-optional:
	ROS2_VENV=$(ROS2_VENV) bash scripts/ros2-env.sh --optional

demo: env
	$(PY) -m lowerbase demo

# prints the results; `make bench WRITE=1` also writes them into docs/benchmarks.md
bench: env
	$(PY) -m benchmarks $(if $(WRITE),--write docs/benchmarks.md)

docs: env
	$(PY) -m lowerbase dbc --export-docs docs/protocol.md
	$(PY) -m lowerbase.protocol.status_codes docs/status-codes.md
	$(PY) -m lowerbase.protocol.docs --legged docs/legged-protocol.md

clean:
	rm -rf $(VENV) $(OLDEST_VENV) $(ROS2_VENV) build .pytest_cache .mypy_cache .ruff_cache
