# Two commands do everything on a fresh machine: `make demo` and `make test`.
# Each creates or refreshes .venv from requirements.txt, builds the package and its interface packages
# (msg_schemas: infinihand_msgs, and tf2_msgs where no ROS 2 install provides it) with colcon and sets
# the environment (scripts/env.sh). Re-running is fast: nothing is reinstalled or rebuilt unless its inputs changed.

SHELL := /bin/bash
.SHELLFLAGS := -eo pipefail -c
PYTHON ?= python3
VENV := .venv
VENV_STAMP := $(VENV)/.requirements.txt
BUILD_STAMP := install/.build-stamp
INTERFACE_SOURCES := msg_schemas/CMakeLists.txt msg_schemas/package.xml \
  $(wildcard msg_schemas/msg/* msg_schemas/cmake/* msg_schemas/tf2_msgs/* msg_schemas/tf2_msgs/msg/*)
ENV := source scripts/env.sh &&
DEMO_OUT ?= out/demo
PYTEST_ARGS ?=

.PHONY: demo test build venv clean

demo: $(BUILD_STAMP)
	$(ENV) python -m infinihand_ros.demo --out $(DEMO_OUT)

# Tests in two passes: those that need no ROS graph on both cores (pytest-xdist), then the ROS ones
# (live nodes, timed streams) alone, one at a time.
COLCON_TEST := colcon test --base-paths . --event-handlers console_direct+ --return-code-on-test-failure

test: $(BUILD_STAMP)
	$(ENV) $(COLCON_TEST) --pytest-args -n 2 --ros-tests skip $(PYTEST_ARGS)
	$(ENV) $(COLCON_TEST) --pytest-args --ros-tests only $(PYTEST_ARGS)

venv: $(VENV_STAMP)

build: $(BUILD_STAMP)

$(VENV_STAMP): requirements.txt requirements-nodeps.txt
	@test -x $(VENV)/bin/python || $(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --quiet --disable-pip-version-check -r requirements.txt
	$(VENV)/bin/python -m pip install --quiet --disable-pip-version-check --no-deps \
	  -r requirements-nodeps.txt
	cat requirements.txt requirements-nodeps.txt > $(VENV_STAMP)

$(BUILD_STAMP): $(VENV_STAMP) setup.py setup.cfg package.xml $(INTERFACE_SOURCES) \
  $(wildcard config/* data/*)
	@# files removed from the source tree leave dangling links that stop colcon: drop them
	@test ! -d build || find build -xtype l -delete
	$(ENV) colcon build --base-paths . $$(scripts/interface_packages.sh) --symlink-install \
	  --event-handlers console_cohesion-
	touch $(BUILD_STAMP)

clean:
	rm -rf build install log
