# The two quick-start commands: `make demo` (the main job) and `make test` (the test suite).
# Both create the virtual environment .venv on first use and install stillframe into it, with
# every dependency at the version of constraints.txt (the versions the suite passed on).
# `make test-latest` tries the newest versions instead (in .venv-latest), and `make lock` then
# writes them into constraints.txt (README, "Pinned versions").
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
LATEST := .venv-latest
CONSTRAINTS := constraints.txt
# the suite runs in this many pytest-xdist workers, a test file per worker at a time (loadfile
# keeps a file's module fixtures in one process); its tests wait on processes and DDS more than
# they compute, so three keep two cores busy
TEST_WORKERS ?= 3
PYTEST := python -m pytest -q --durations=25 -n $(TEST_WORKERS) --dist loadfile
NO_ROS := echo "make: real ROS 2 (rclpy) has no wheels for this platform; nodes run on the dds backend"

.PHONY: setup demo test test-latest lock lint clean

$(BIN)/stillframe: pyproject.toml $(CONSTRAINTS)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet -c $(CONSTRAINTS) --upgrade pip
	$(BIN)/pip install --quiet -c $(CONSTRAINTS) -e '.[test,colcon]'
	$(BIN)/pip install --quiet -c $(CONSTRAINTS) -e '.[test,colcon,ros]' 2>/dev/null || $(NO_ROS)
	touch $@

setup: $(BIN)/stillframe

demo: setup
	$(BIN)/stillframe demo --out out/demo

test: setup
	$(BIN)/ruff check .
	$(BIN)/$(PYTEST)

# the newest releases pyproject.toml allows, in a venv of their own, and the suite on them
test-latest:
	rm -rf $(LATEST)
	$(PYTHON) -m venv $(LATEST)
	$(LATEST)/bin/pip install --quiet --upgrade pip
	$(LATEST)/bin/pip install --quiet -e '.[test,colcon]'
	$(LATEST)/bin/pip install --quiet -e '.[test,colcon,ros]' 2>/dev/null || $(NO_ROS)
	$(LATEST)/bin/ruff check .
	$(LATEST)/bin/$(PYTEST)

# the versions of the last `make test-latest` become the pins (run it first, and only on green)
lock:
	@test -x $(LATEST)/bin/pip || { echo "make lock: run make test-latest first"; exit 2; }
	{ echo "# The versions the test suite passed on: make setup installs these (pip -c)."; \
	  echo "# Updated by: make test-latest && make lock (README, Pinned versions)."; \
	  $(LATEST)/bin/pip freeze --exclude-editable | grep -v '^stillframe'; } > $(CONSTRAINTS)

lint: setup
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) $(LATEST) out .pytest_cache .ruff_cache
