# The two commands of the README:
#   make demo   set up (first time), then replay the default jamming experiment through the suite,
#               and the spoofing experiment (report in $(OUT)/spoofed)
#   make test   set up (first time), then run every test (unit, node, bag replay, linters)
# make test-loaded RUNS=10 HOGS=1: make test RUNS times beside HOGS busy loops, with a tally (docs/testing.md)
# Set-up needs only Python 3.10-3.12, cmake and a C compiler: no ROS install.
SHELL := /bin/bash
PYTHON ?= python3
VENV ?= .venv
BAG ?= bags/default
PARAMS ?= $(BAG).params.yaml
OUT ?= report
ATTACK_BAG ?= bags/spoofed
PYTEST_ARGS ?=
RUNS ?= 10
HOGS ?= 1

# A shell with the venv (the ROS 2 prefix) and the workspace sourced; DDS stays on this host.
RUN = set -eo pipefail; source $(VENV)/bin/activate; source install/setup.bash; \
      export ROS_AUTOMATIC_DISCOVERY_RANGE=$${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST};

.PHONY: all setup build test test-loaded demo lint clean distclean constraints

all: test

setup build:
	@PYTHON=$(PYTHON) VENV=$(VENV) tools/setup_workspace.sh

test: setup
	@$(RUN) python -m pytest $(PYTEST_ARGS)

test-loaded: setup
	@$(RUN) python tools/test_loaded.py --runs $(RUNS) --hogs $(HOGS) -- $(PYTEST_ARGS)

demo: setup
	@$(RUN) tools/ros2_run rfi_experiments run $(BAG) --out $(OUT) $$([ -f $(PARAMS) ] && echo --params-file $(PARAMS)) \
	  && { [ -z "$(ATTACK_BAG)" ] || { echo; echo "== the spoofing experiment: $(ATTACK_BAG) =="; \
	       tools/ros2_run rfi_experiments run $(ATTACK_BAG) --out $(OUT)/spoofed; }; }

lint: setup
	@$(RUN) ruff check src test tools benchmarks && mypy

# Re-pin every version from the current venv (after a deliberate upgrade).
constraints: setup
	@v=$$($(VENV)/bin/python -c 'import sys; print(f"{sys.version_info.major}.{sys.version_info.minor}")'); \
	  { echo "# Exact versions of every package in .venv (pip freeze of a working set-up, Python $$v, x86_64)."; \
	    echo "# Regenerate with: make constraints"; \
	    $(VENV)/bin/python -m pip freeze --all --exclude-editable | grep -v -E '^(pip|wheel)==' | sort; } > constraints/py$$v.txt; \
	  echo "wrote constraints/py$$v.txt"

clean:
	rm -rf build install log $(OUT)

distclean: clean
	rm -rf $(VENV)
