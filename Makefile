# Two commands on a fresh machine: `make demo` and `make test`. Each sets up its own venv.
PYTHON ?= python3
VENV ?= .venv
BIN = $(VENV)/bin

.PHONY: demo test sitl-test bench paper-table clean

$(BIN)/.installed: pyproject.toml
	@echo "setting up $(VENV) (first run, or pyproject.toml changed)" >&2
	@$(PYTHON) -m venv $(VENV)
	@$(BIN)/python -m pip install -q --upgrade pip >&2
	@$(BIN)/python -m pip install -q -e '.[test]' >&2
	@touch $@

demo: $(BIN)/.installed
	@$(BIN)/companion demo $(ARGS)

test: $(BIN)/.installed
	$(BIN)/python -m pytest $(ARGS)

# Only the tests against ArduPilot Rover SITL and PX4 SITL (each skipped unless ARDUPILOT_SITL or
# ARDUPILOT_DIR, PX4_SITL or PX4_DIR is set)
sitl-test: $(BIN)/.installed
	$(BIN)/python -m pytest -m "sitl or px4" $(ARGS)

paper-table: $(BIN)/.installed
	@$(BIN)/companion paper-table $(ARGS)

bench: $(BIN)/.installed
	$(BIN)/python benchmarks/bench_core.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
