# Two commands on a fresh machine: `make demo` and `make test`. Each sets up its own venv.
PYTHON ?= python3
VENV ?= .venv
BIN = $(VENV)/bin

# pytest-xdist workers for `make test` (docs/development.md): 4 on two cores, since many tests
# wait on real-time flights, not the CPU; WORKERS=0 is one process. Each test file goes to one
# worker (--dist loadfile), so a module's shared fixture (one demo flight, 28 processes at once)
# runs once (`--dist loadgroup` no longer groups under pytest 9.2: pytest-xdist issue 1386); in
# the order tests/conftest.py gives (the slow first), not the most tests first.
WORKERS ?= 4
# The linter's paths; the type checker's are in pyproject.toml ([tool.mypy] files)
LINT_PATHS = companion sitl_plant tests testbed benchmarks

.PHONY: bytecode demo test check sitl-test bench paper-table lock clean

# The tested versions (constraints.txt) of everything pyproject.toml's ranges admit. Installed
# with uv (itself pinned there) because it takes about 25 s where pip takes about 80 (pip
# compiles bytecode one module at a time, uv on every core); pip if uv cannot be had.
$(BIN)/.installed: pyproject.toml constraints.txt
	@echo "setting up $(VENV) (first run, or pyproject.toml / constraints.txt changed)" >&2
	@$(PYTHON) -m venv $(VENV)
	@if $(BIN)/python -m pip install -q -c constraints.txt uv >&2; then \
	   $(BIN)/uv pip install -q --compile-bytecode --python $(BIN)/python -c constraints.txt -e '.[test,check]' >&2; \
	 else echo "uv could not be installed: pip installs instead" >&2; \
	   $(BIN)/python -m pip install -q -c constraints.txt -e '.[test,check]' >&2; fi
	@touch $@

# The checkout's own bytecode, written once (only what changed since): the tests start hundreds
# of `companion` and `sitl-plant` processes, and where PYTHONDONTWRITEBYTECODE is set each of
# them would compile about 80 modules again (0.2 s of CPU a process).
bytecode: $(BIN)/.installed
	@$(BIN)/python -m compileall -q -j 0 companion sitl_plant testbed >&2

demo: bytecode
	@$(BIN)/companion demo $(ARGS)

# Two runs: everything but the `solo` tests on the workers, then the `solo` ones (judged against
# the wall clock, or loading both cores) alone in one process. Either run may select nothing
# (ARGS naming one file); nothing selected by both is pytest's "no tests", exit 5.
test: bytecode
	@$(BIN)/python -m pytest -n $(WORKERS) --dist loadfile --no-loadscope-reorder -m "not solo" $(ARGS); a=$$?; \
	 $(BIN)/python -m pytest -m solo $(ARGS); b=$$?; \
	 if [ $$a -eq 5 ] && [ $$b -eq 5 ]; then exit 5; fi; \
	 for c in $$a $$b; do if [ $$c -ne 0 ] && [ $$c -ne 5 ]; then exit $$c; fi; done

# The linter and the type checker, both configured in pyproject.toml (docs/development.md)
check: $(BIN)/.installed
	$(BIN)/ruff check $(LINT_PATHS)
	$(BIN)/mypy

# Only the tests against ArduPilot Rover SITL and PX4 SITL (each skipped unless ARDUPILOT_SITL or
# ARDUPILOT_DIR, PX4_SITL or PX4_DIR is set)
sitl-test: bytecode
	$(BIN)/python -m pytest -m "sitl or px4" $(ARGS)

paper-table: $(BIN)/.installed
	@$(BIN)/companion paper-table $(ARGS)

bench: $(BIN)/.installed
	$(BIN)/python benchmarks/bench_core.py

# Re-resolve the newest versions pyproject.toml admits into constraints.txt (in a scratch venv,
# so the project's own stays as tested until the next `make`); then run `make check test`.
lock:
	@rm -rf .lock-venv
	@$(PYTHON) -m venv .lock-venv
	@.lock-venv/bin/python -m pip install -q --upgrade pip >&2
	@.lock-venv/bin/python -m pip install -q -e '.[test,check]' >&2
	@.lock-venv/bin/python -m pip install -q uv >&2
	@{ echo "# The tested versions: \`make\` and .ci/run install with -c constraints.txt."; \
	   echo "# Made by \`make lock\` (pip freeze of a fresh venv, the project itself left out);"; \
	   echo "# pyproject.toml keeps the ranges. tests/project/test_lock_and_lint.py holds the two together."; \
	   .lock-venv/bin/python -m pip freeze --exclude-editable; } > constraints.txt
	@rm -rf .lock-venv
	@echo "constraints.txt: $$(grep -c '==' constraints.txt) pinned" >&2

clean:
	rm -rf $(VENV) .lock-venv build *.egg-info .pytest_cache .mypy_cache .ruff_cache
