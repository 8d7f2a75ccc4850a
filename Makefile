# `make demo` and `make test` each build .venv when it is missing and install
# the package into it non-editably: an editable install leaves out the data
# files (ament index marker, lib/estimation_nodes) that `ros2 run` needs.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
SOURCES := $(shell find estimation_nodes msgs_config foxglove maps scripts resource interfaces -type f \
	-not -name '*.pyc') \
	pyproject.toml package.xml setup.py setup.cfg

# DDS stays on loopback, in a domain of its own, unless the caller chose otherwise: not
# one of the tests' (1..80) or the benchmarks' (81..98), so a demo beside them reaches neither.
ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
ROS_DOMAIN_ID ?= 99
export ROS_AUTOMATIC_DISCOVERY_RANGE ROS_DOMAIN_ID

# The suite runs in PYTEST_WORKERS processes (pytest-xdist), a test file per worker at a
# time: most graph tests wait on DDS and timers, so two workers halve the wall time on two
# cores. Each test reserves a ROS domain of its own, so the workers never hear each other.
# PYTEST_WORKERS=0 runs it in one process.
PYTEST_WORKERS ?= 2
XDIST := -n $(PYTEST_WORKERS) --dist loadfile

.PHONY: demo test test-under-load replay-under-load bench install clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade "pip>=23"

# build/ is setuptools' staging folder: a module moved or removed since the last
# build would otherwise stay in it and be installed again.
$(STAMP): $(BIN)/python $(SOURCES)
	rm -rf build
	$(BIN)/python -m pip install --quiet --upgrade ".[test]"
	# numba's kernels compiled once into its cache: a node's first start and the suite then
	# load them (compiling them all takes 20 s on an idle machine, minutes on a busy one).
	$(BIN)/python -m estimation_nodes.core.compiled_loader
	touch $@

install: $(STAMP)

demo: $(STAMP)
	AMENT_PREFIX_PATH=$(abspath $(VENV)) $(BIN)/estimation_demo $(DEMO_ARGS)

test: $(STAMP)
	AMENT_PREFIX_PATH=$(abspath $(VENV)) $(BIN)/python -m pytest $(XDIST) $(PYTEST_ARGS)

# The same suite with every core kept busy by other processes (.ci/test-under-load starts
# them and ends each by its pid); LOAD_PROCESSES sets how many (default: one per core).
test-under-load: $(STAMP)
	VENV=$(VENV) PYTHON=$(PYTHON) .ci/test-under-load $(XDIST) $(PYTEST_ARGS)

# Issue 35's acceptance: fresh recorded demo runs of each recorded kind, each replayed, with
# one core kept busy by a process the script starts and ends by its pid; prints per scenario
# how many replayed EQUAL (bench/tools/replay_under_load.py; REPLAY_ARGS="--runs 2" for a quick one).
replay-under-load: $(STAMP)
	AMENT_PREFIX_PATH=$(abspath $(VENV)) $(BIN)/python bench/tools/replay_under_load.py $(REPLAY_ARGS)

# Benchmarks print tables of figures with ratios to references measured in the
# same run (see bench/README.md); they assert nothing and take a few minutes.
bench: $(STAMP)
	$(BIN)/python bench/core/core_bench.py
	$(BIN)/python bench/dds/dds_bench.py
	$(BIN)/python bench/dds/large_world_bench.py
	$(BIN)/python bench/startup/startup_bench.py

clean:
	rm -rf $(VENV) build *.egg-info
