# Two commands do everything on a fresh Debian 12 machine:
#   make demo   the main job on the shipped sample sequence
#   make test   the test suite
# Both create the virtualenv (.venv) and install the toolkit into it on first use.

SHELL  := /bin/bash
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
EXTRAS ?= test

.PHONY: demo test bench setup clean help

help:
	@echo "make demo   run the main job on the shipped sample sequence (sets everything up first)"
	@echo "make test   run the test suite (sets everything up first)"
	@echo "make bench  run every benchmark in benchmarks/ (results in benchmarks/results/)"
	@echo "make clean  remove the virtualenv and caches"

setup: $(STAMP)

$(STAMP): pyproject.toml
	@if ! $(PYTHON) -c 'import venv, ensurepip' 2>/dev/null; then \
	    echo "installing python3-venv (needs root)"; \
	    $$( [ "$$(id -u)" = 0 ] || echo sudo ) apt-get update -qq && \
	    $$( [ "$$(id -u)" = 0 ] || echo sudo ) apt-get install -y -qq python3-venv; \
	fi
	@[ -x $(PY) ] || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[$(EXTRAS)]'
	@touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/studio demo

test: $(STAMP)
	$(PY) -m pytest

bench: $(STAMP)
	@for b in benchmarks/*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info
