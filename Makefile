# intersection_estimator: two commands for a user, `make demo` and `make test`.
# Both run `make setup` first: a venv with pinned ROS 2 Jazzy wheels, the message package
# built with cmake straight into the venv, and this package installed into it, so nothing
# needs sourcing. Every step is stamped, so a second `make setup` is a no-op.

PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.stamps
MSGS   := msgs/intersection_estimator_msgs
MSG_SRC := $(wildcard $(MSGS)/msg/*.msg) $(MSGS)/CMakeLists.txt $(MSGS)/package.xml
PKG_SRC := setup.py setup.cfg package.xml $(wildcard resource/*) $(wildcard config/*) \
           $(shell find intersection_estimator msg_adapters -name '*.py' -o -name '*.msg' 2>/dev/null) \
           $(wildcard bags/*/* bags/*)

# DDS on this host only, fast discovery, logs out of $HOME (see README, "Use it with ROS 2").
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export FASTRTPS_DEFAULT_PROFILES_FILE ?= $(CURDIR)/config/fastdds_localhost.xml
export AMENT_PREFIX_PATH := $(CURDIR)/$(VENV)
export PYTHONUNBUFFERED := 1

.PHONY: setup demo test bench colcon-test clean distclean
.DEFAULT_GOAL := test

setup: $(STAMP)/package

$(STAMP)/venv:
	@command -v $(PYTHON) >/dev/null || { echo "setup: $(PYTHON) not found (need CPython 3.11)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	@mkdir -p $(STAMP) && touch $@

$(STAMP)/requirements: requirements.txt $(STAMP)/venv
	$(PY) -m pip install --disable-pip-version-check -q -r requirements.txt
	. $(VENV)/bin/activate && scripts/fix_ros_wheel_cmake.sh
	@touch $@

$(STAMP)/msgs: $(MSG_SRC) $(STAMP)/requirements
	mkdir -p build && . $(VENV)/bin/activate && \
	  cmake -S $(MSGS) -B build/cmake_msgs -DCMAKE_INSTALL_PREFIX="$(CURDIR)/$(VENV)" \
	        -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$(CURDIR)/$(PY)" >build/cmake_msgs.log 2>&1 \
	  || { tail -30 build/cmake_msgs.log; exit 1; }
	. $(VENV)/bin/activate && cmake --build build/cmake_msgs -j2 >>build/cmake_msgs.log 2>&1 \
	  && cmake --install build/cmake_msgs >>build/cmake_msgs.log 2>&1 \
	  || { tail -30 build/cmake_msgs.log; exit 1; }
	@touch $@

$(STAMP)/package: $(PKG_SRC) $(STAMP)/msgs
	$(PY) -m pip install --disable-pip-version-check -q --no-deps --no-build-isolation . >/dev/null
	@rm -rf build/lib build/bdist.* intersection_estimator.egg-info
	$(PY) -c "import rclpy, intersection_estimator, msg_adapters, intersection_estimator_msgs.msg" \
	  || { echo "setup: the venv does not import rclpy / intersection_estimator / its messages"; exit 1; }
	cd / && $(CURDIR)/$(PY) -c "from intersection_estimator.pipeline import warmup; \
	  print(f'setup: numba kernels compiled and cached in {warmup():.0f} s')"
	@touch $@

demo: setup
	$(VENV)/bin/intersection-estimator demo

# The whole suite, then the same package built and tested through colcon (as on a ROS machine).
test: setup
	ROS_HOME=$$(mktemp -d) $(PY) -m pytest test $(PYTEST_ARGS)
	$(MAKE) --no-print-directory colcon-test

bench: setup
	$(VENV)/bin/intersection-estimator bench --n 1000 --mode tracked --seed 0 --json bench_tracked.json

# colcon build + test of both packages, into build/colcon, install/, log/ (see README).
colcon-test: setup
	. $(VENV)/bin/activate && colcon --log-base log build --base-paths . msgs \
	    --build-base build/colcon --install-base install --cmake-args -DBUILD_TESTING=OFF
	. $(VENV)/bin/activate && . install/setup.sh && colcon --log-base log test --base-paths . msgs \
	    --build-base build/colcon --install-base install --return-code-on-test-failure \
	    --event-handlers console_direct+ --pytest-args -m colcon_smoke
	. $(VENV)/bin/activate && colcon test-result --test-result-base build/colcon --verbose

clean:
	rm -rf build install log .pytest_cache .hypothesis

distclean: clean
	rm -rf $(VENV)
