# One obvious way to run things. Every target creates or reuses the local virtual environment.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
DATA ?= 4V_xmotion.mcap
FIT_ARGS ?=

.PHONY: venv test test-unit test-all lint format fit bench datasets reproduce clean

venv: $(STAMP)

$(STAMP): pyproject.toml constraints.txt
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	@echo "Setting up $(VENV): pip shows what it downloads and installs (first time: a few minutes)"
	$(BIN)/python -m pip install --progress-bar on --upgrade pip
	$(BIN)/python -m pip install --progress-bar on -c constraints.txt -e '.[test]'
	@# pip compiles what it installs, not an editable package: its bytecode once here, so
	@# that each command does not compile its ~160 modules again (0.2 s of every command
	@# where PYTHONDONTWRITEBYTECODE is set; later edits recompile only what changed).
	$(BIN)/python -m compileall -q hframe_id
	@touch $(STAMP)

# The default suite leaves out the long studies marked `slow` (recovery, one-axis, hframe-20
# fits); test-all runs everything, as CI does. One pytest-xdist worker per logical core, each
# test file on one worker (its module fixtures, some of them fits, are built once).
PYTEST := MPLBACKEND=Agg $(BIN)/python -m pytest -q -n logical --dist loadfile

test: $(STAMP)
	$(PYTEST) -m "not slow"

# A quick check while editing: the tests not marked `integration` (whole fits and commands;
# every test in tests/fitting/integration/ is, by its path) or `slow`.
test-unit: $(STAMP)
	$(PYTEST) -m "not integration and not slow"

test-all: $(STAMP)
	$(PYTEST)

lint: $(STAMP)
	$(BIN)/ruff check hframe_id bench studies tests examples
	$(BIN)/ruff format --check hframe_id bench studies tests examples

format: $(STAMP)
	$(BIN)/ruff format hframe_id bench studies tests examples
	$(BIN)/ruff check --fix hframe_id bench studies tests examples

fit: $(STAMP)
	MPLBACKEND=Agg $(BIN)/hframe-id fit $(DATA) $(FIT_ARGS)

# The package's sections, then the checkout's unseen-plants section (bench/, 9-13 minutes).
bench: $(STAMP)
	MPLBACKEND=Agg $(BIN)/python -m bench
	MPLBACKEND=Agg $(BIN)/python -m bench.unseen_plants

datasets: $(STAMP)
	$(BIN)/hframe-id datasets make --out datasets

reproduce: $(STAMP)
	MPLBACKEND=Agg $(BIN)/hframe-id reproduce --out reports/reproduction --force

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
