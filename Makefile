# The two commands of the README: `make demo` and `make test`. Both build .venv on first use.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
DEMO_OUT ?= results

.PHONY: demo readme guard-figures test lint unit bench clean

# setup.py builds the one C extension (scrapcut_cli/_native.c) in place; an edit to it reinstalls.
$(STAMP): pyproject.toml setup.py scrapcut_cli/_native.c
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	# `import open3d` works in this venv without a system libusb (docs/python.md).
	$(BIN)/python -c "import pathlib, sysconfig; pathlib.Path(sysconfig.get_paths()['purelib'], \
		'scrapcut_open3d.pth').write_text('import scrapcut_cli._open3d_hook\n')"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/scrapcut reproduce -o $(DEMO_OUT)

# The README's tables, generated: Table I over simulator seeds (mean ± 95 % interval) and the
# scrap-yard table with its self-calibrated rows, each rewriting its marked section of README.md
# with the command, machine and date. Table I runs without --self-calibrate: on its d435i scenes
# (no frames while moving) the self-calibrated rows equal the plain ones and double the run.
# Ten seeds of Table I take about 20 min of two idle cores (1197 s on 2026-12-02); the yard
# table, with every piece and the self-calibration, several times that: pass fewer seeds on a
# small machine.
README_SEEDS ?= 0-9
YARD_SEEDS ?= $(README_SEEDS)
README_SELF_CALIBRATE ?= --self-calibrate
readme: $(STAMP)
	$(BIN)/scrapcut reproduce --seeds $(README_SEEDS) -o $(DEMO_OUT)-seeds \
		--readme README.md --readme-section table1
	$(BIN)/scrapcut reproduce --objects all --noise yard --leaf-sweep-mm none \
		--seeds $(YARD_SEEDS) $(README_SELF_CALIBRATE) -o yard --readme README.md \
		--readme-section yard

# The figures tests/test_commands_reproduce.py guards: Table I's fast configuration (160×120,
# explore, seed 0), NURBS on two objects and the skeleton on two others. Run it when a change
# improves them on purpose (or moves them within the test's margin) and commit the CSV.
GUARD_OPTIONS := --width 160 --height 120 --leaf-sweep-mm none --no-plots --no-motion --seeds 0
guard-figures: $(STAMP)
	rm -rf .guard && mkdir -p .guard
	$(BIN)/scrapcut reproduce --objects cylinder,t_piece --methods nurbs $(GUARD_OPTIONS) -o .guard/nurbs
	$(BIN)/scrapcut reproduce --objects i_beam,air_chamber --methods skeleton $(GUARD_OPTIONS) \
		-o .guard/skeleton
	(head -n 1 .guard/nurbs/report.csv && tail -q -n +2 .guard/nurbs/report.csv \
		.guard/skeleton/report.csv) > fixtures/reproduce_fast.csv
	rm -rf .guard

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy scrapcut_cli

# One pytest worker per core (pytest-xdist; a module's tests stay on one worker, so its
# fixtures are built once); the slowest tests are listed at the end of every run.
unit: $(STAMP)
	$(BIN)/python -m pytest -q -n auto --dist loadscope --durations=15

test: lint unit

bench: $(STAMP)
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) .mypy_cache .ruff_cache .pytest_cache
