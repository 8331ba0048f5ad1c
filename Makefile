# rbe_ros: set-up, demo and tests. See README and docs/BUILD.md.
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
# Each test run gets its own DDS domain (1..100) unless ROS_DOMAIN_ID is already set,
# and discovery stays on this host, so parallel runs and CI never cross-talk.
ifeq ($(strip $(ROS_DOMAIN_ID)),)
ROS_DOMAIN_ID := $(shell echo $$(( RANDOM % 100 + 1 )))
endif

.PHONY: setup demo test paper lock clean

setup:
	bash scripts/setup.sh

demo: setup
	$(VENV)/bin/rbe-ros check examples/build_sequence.json --sequence --bag out/demo --force

test: setup
	@echo "[test] ROS_DOMAIN_ID=$(ROS_DOMAIN_ID) ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST"
	ROS_DOMAIN_ID=$(ROS_DOMAIN_ID) ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST \
		$(PY) -m pytest tests -q

# Reproduce the paper's numbers and figures: docs/PAPER.md, docs/figures/ (about a minute).
paper: setup
	$(PY) benchmarks/paper.py

# Regenerate requirements/ros.txt and requirements/py.txt from the .in files
# (resolves with pip, installs nothing; needs CPython 3.11 as python3).
lock:
	python3 scripts/lock.py

clean:
	rm -rf build $(VENV)
