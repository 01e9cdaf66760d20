# Two entry points for a fresh machine: `make demo` (main job) and `make test` (the CI suite).
# Both create .venv and install the package with the pins in constraints.txt.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
PIP := $(BIN)/python -m pip
EXTRAS ?= robosuite,ray,notebooks,dev
STAMP := $(VENV)/.installed
# Notebooks run through nbmake here; the `notebooks`-marked test (a subprocess run of the same) is deselected.
# Two test workers (pytest-xdist), one per core of the CI machine.
PYTEST_ARGS ?= -n 2 -m "not slow and not notebooks" --nbmake --nbmake-timeout=600 tests notebooks

.PHONY: install demo test test-all bench clean

$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q -c constraints.txt -e ".[$(EXTRAS)]"
	touch $@

install: $(STAMP)

# Main job: train HUBS-GO on KeyDoor with the default budget and print the learned sub-goal sets (G*).
demo: $(STAMP)
	$(BIN)/hubsgo train keydoor --agent hubsgo --seed 0 --out runs/demo-keydoor \
		$$(test -f runs/demo-keydoor/checkpoint.pt && echo --resume)
	$(BIN)/hubsgo evaluate runs/demo-keydoor --episodes 10

# The CI suite: every part (critic, MiniGrid, robosuite, CLI, notebooks), slow tests excluded.
# HUBSGO_REQUIRE_ROBOSUITE=1: a missing robosuite fails the run instead of skipping the arm tests.
test: $(STAMP)
	HUBSGO_REQUIRE_ROBOSUITE=1 $(BIN)/python -m pytest $(PYTEST_ARGS)

test-all: $(STAMP)
	HUBSGO_REQUIRE_ROBOSUITE=1 $(BIN)/python -m pytest --nbmake tests notebooks

bench: $(STAMP)
	$(BIN)/python benchmarks/critic.py

clean:
	rm -rf $(VENV) build *.egg-info

# Re-make every table of docs/results.md: the commands the page quotes, in its order (days on 2 cores;
# `python scripts/make_tables.py --dry-run` lists them, `--start K` goes on from command K).
.PHONY: tables
tables: $(STAMP)
	$(BIN)/python scripts/make_tables.py
