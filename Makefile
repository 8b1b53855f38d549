# The two quick-start commands: `make demo` (the main job) and `make test` (the test suite).
# Both create the virtual environment .venv on first use and install stillframe into it.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: setup demo test lint clean

$(BIN)/stillframe: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test,colcon]'
	$(BIN)/pip install --quiet -e '.[test,colcon,ros]' 2>/dev/null \
	  || echo "make: real ROS 2 (rclpy) has no wheels for this platform; nodes run on the dds backend"
	touch $@

setup: $(BIN)/stillframe

demo: setup
	$(BIN)/stillframe demo --out out/demo

test: setup
	$(BIN)/ruff check .
	$(BIN)/python -m pytest -q --durations=25

lint: setup
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) out .pytest_cache .ruff_cache
