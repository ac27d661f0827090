# Quickstart: `make demo`, `make test`. Both create .venv on first use.
PYTHON ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

# The demo and the bench stay on loopback unless the caller's environment says otherwise (a
# value set in your shell wins; make changes nothing in your shell); the tests always do
# (test/conftest.py). Each run picks a free ROS_DOMAIN_ID itself (demo and bench through
# manip_kin.pipeline.ensure_ros_isolation, tests in test/conftest.py) unless one is set, and
# keeps it reserved while it runs (manip_kin.pipeline.pick_free_domain).
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export RMW_IMPLEMENTATION ?= rmw_fastrtps_cpp
export AMENT_PREFIX_PATH := $(CURDIR)/$(VENV)$(if $(AMENT_PREFIX_PATH),:$(AMENT_PREFIX_PATH),)
export PYTHONUNBUFFERED := 1

.PHONY: venv demo test lint format bench bench-anchors soak mutate clean system-deps

venv: $(STAMP)

# The Foxglove WebSocket client the live_view tests and bench run (Node 20+, npm).
FOXGLOVE_CLIENT := test/foxglove_client/node_modules/.package-lock.json

$(FOXGLOVE_CLIENT): test/foxglove_client/package.json test/foxglove_client/package-lock.json
	cd test/foxglove_client && npm ci --no-audit --no-fund

$(STAMP): requirements.txt requirements-dev.txt setup.py package.xml
	test -x $(VPY) || $(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install --quiet --upgrade pip "setuptools>=64,<80" wheel
	$(VPY) -m pip install --quiet -r requirements-dev.txt
	$(VPY) -m pip install --quiet --no-deps -e .
	$(VPY) -m manip_kin.collision.narrow_phase
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/manip_kin demo

# Two pytest workers, a test file each at a time (--dist loadgroup, each file its own group: a
# module's fixtures, such as its pipeline, stay in one process), the files that run pipelines
# one after another on one worker (test/conftest.py): most of a serial run waits on nodes, not
# the CPU (on 2 cores, 5:11 against 9:39 for the suite, docs/performance.md). Each worker has its own
# ROS_DOMAIN_ID (test/conftest.py). TEST_WORKERS=0 runs it in one process. -r fER lists
# failures, errors and reruns (a test that runs nodes in real time gets one: test/conftest.py).
TEST_WORKERS ?= 2
test: lint system-deps $(FOXGLOVE_CLIENT)
	$(VPY) -m pytest -q -r fER $(if $(filter 0,$(TEST_WORKERS)),,-n $(TEST_WORKERS) --dist loadgroup) test

# MuJoCo's offscreen renderer (`manip_kin plot --render` and its test) draws through EGL: Mesa's,
# on the CPU where there is no GPU. Installed once where missing (needs root, as CI is).
EGL_PACKAGES := libegl1 libegl-mesa0 libgl1-mesa-dri
system-deps:
	@dpkg -s $(EGL_PACKAGES) >/dev/null 2>&1 || { apt-get update -qq && apt-get install -y -qq $(EGL_PACKAGES); } \
		|| echo "warning: could not install $(EGL_PACKAGES): manip_kin plot --render and its test need them" >&2

# ruff (configured in ruff.toml): lint and format check; `make format` rewrites.
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

format: $(STAMP)
	$(VENV)/bin/ruff format .
	$(VENV)/bin/ruff check --fix .

bench: $(STAMP) $(FOXGLOVE_CLIENT)
	$(VPY) bench/run.py --out bench/results/bench.json

# manip_kin against pinocchio and robotics-toolbox-python, in a venv of its own (never a
# dependency of the package): interleaved rounds, same configurations and targets.
ANCHORS_VENV := .venv-anchors
ANCHORS_STAMP := $(ANCHORS_VENV)/.installed

$(ANCHORS_STAMP): bench/requirements-anchors.txt setup.py
	test -x $(ANCHORS_VENV)/bin/python || $(PYTHON) -m venv $(ANCHORS_VENV)
	$(ANCHORS_VENV)/bin/python -m pip install --quiet --upgrade pip "setuptools>=64,<80" wheel
	$(ANCHORS_VENV)/bin/python -m pip install --quiet -r bench/requirements-anchors.txt
	$(ANCHORS_VENV)/bin/python -m pip install --quiet --no-deps -e .
	touch $(ANCHORS_STAMP)

bench-anchors: $(ANCHORS_STAMP)
	$(ANCHORS_VENV)/bin/python bench/anchors.py --out bench/results/anchors.json

# Full pipeline (Panda: joint limits, collision geometry, obstacles) + recorder + live view with
# a client, at 1 kHz for SOAK_MINUTES, lines alternating; not part of `make test`.
# `make soak SOAK_MINUTES=1` for a short run. The loops run at SCHED_FIFO 20 where permitted;
# SOAK_ARGS="--realtime-priority 0" for normal scheduling.
SOAK_MINUTES ?= 10
SOAK_ARGS ?=
soak: $(STAMP) $(FOXGLOVE_CLIENT)
	$(VPY) bench/soak.py --minutes $(SOAK_MINUTES) --out bench/results/soak.json $(SOAK_ARGS)

# A small mutation round over the core (tools/mutate.py): a seeded sample of one-expression
# changes per module, each run against that module's tests in a copy of the package; lists the
# survivors (a missing test or an equivalent change). About 15 minutes here; not part of `make test`.
# `make mutate MUTATE_ARGS="--per-module 2"` for a short one.
MUTATE_ARGS ?=
mutate: $(STAMP)
	$(VPY) tools/mutate.py --out bench/results/mutate.json $(MUTATE_ARGS)

clean:
	rm -rf $(VENV) $(ANCHORS_VENV) build install log *.egg-info .pytest_cache test/foxglove_client/node_modules
