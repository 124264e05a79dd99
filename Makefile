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
# camera drivers the tests exercise: Aravis (library, introspection data, what PyGObject
# builds against) from Debian, then the [genicam] and [aravis] extras
DRIVERS       := $(VENV)/.drivers
DRIVER_DEBS   := gir1.2-aravis-0.8 libgirepository1.0-dev libcairo2-dev pkg-config gcc python3-dev
DRIVER_EXTRAS ?= genicam,aravis

.PHONY: demo test bench mutation setup clean help

help:
	@echo "make demo   run the main job on the shipped sample sequence (sets everything up first)"
	@echo "make test   run the test suite (sets everything up first, camera drivers included)"
	@echo "make bench  run every benchmark in benchmarks/ (results in benchmarks/results/)"
	@echo "make mutation [MODULE=name]  mutation testing of the core modules, or of one (hours / minutes;"
	@echo "             not part of make test; modules in benchmarks/mutation/modules.toml)"
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

$(DRIVERS): $(STAMP)
	@if ! dpkg -s $(DRIVER_DEBS) >/dev/null 2>&1; then \
	    echo "installing the Aravis camera library and PyGObject's build dependencies (needs root)"; \
	    $$( [ "$$(id -u)" = 0 ] || echo sudo ) apt-get update -qq && \
	    $$( [ "$$(id -u)" = 0 ] || echo sudo ) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(DRIVER_DEBS) \
	    || echo "warning: could not install $(DRIVER_DEBS); the aravis tests will be skipped"; \
	fi
	@if $(PY) -m pip install -q -e '.[$(EXTRAS),$(DRIVER_EXTRAS)]'; then touch $(DRIVERS); \
	else echo "warning: the [$(DRIVER_EXTRAS)] extras did not install; their tests will be skipped"; fi

test: $(STAMP) $(DRIVERS)
	$(PY) -m pytest

bench: $(STAMP)
	@for b in benchmarks/*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

# mutation testing (issue 21): mutmut from the [mutation] extra, one module at a time, niced;
# results in benchmarks/results/mutation.json and .md
MUTATION := $(VENV)/.mutation
MODULE   ?=
$(MUTATION): $(STAMP)
	$(PY) -m pip install -q -e '.[$(EXTRAS),mutation]'
	@touch $(MUTATION)

mutation: $(MUTATION)
	nice -n 10 $(PY) benchmarks/mutation/run.py $(if $(MODULE),--module $(MODULE))

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info
