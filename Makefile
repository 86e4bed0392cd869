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

.PHONY: help env system-deps test lint typecheck unit demo bench docs clean

help:
	@echo "make demo   - set up and run the demo (emulator + driver + a scenario, with a report)"
	@echo "make test   - set up and run ruff, mypy and the whole test suite"
	@echo "make bench  - run the benchmarks (results: docs/benchmarks.md)"
	@echo "make docs   - regenerate docs/protocol.md and docs/status-codes.md"

system-deps:
	@bash scripts/install-ros.sh

$(STAMP): pyproject.toml
	$(SYSTEM_PYTHON) -m venv --system-site-packages $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	@if $(PY) -c 'import genpy' 2>/dev/null; then \
	  $(PY) -m lowerbase.driver.msggen $(ROS_OUT) --pth "$$($(PY) -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"; \
	else echo "genpy not available: woosh_msgs not generated (ROS tests will skip)"; fi
	touch $@

env: system-deps $(STAMP)

lint: env
	$(VENV)/bin/ruff check lowerbase tests benchmarks

typecheck: env
	$(VENV)/bin/mypy

unit: env
	$(PY) -m pytest -q

test: env lint typecheck unit

demo: env
	$(PY) -m lowerbase demo

bench: env
	$(PY) -m benchmarks --write docs/benchmarks.md

docs: env
	$(PY) -m lowerbase dbc --export-docs docs/protocol.md
	$(PY) -m lowerbase.protocol.status_codes docs/status-codes.md

clean:
	rm -rf $(VENV) build .pytest_cache .mypy_cache .ruff_cache
