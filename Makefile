# Two commands on a fresh machine with Python 3.11 and pip:  make demo  and  make test.
# The first one creates .venv and installs brachycal (editable) with its test tools; later runs
# reuse it until pyproject.toml changes.
# make test runs the fast tests; make test-all (what CI runs) runs them, then the slow tail (marked slow).

PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-all lint docs bench mutants clean

demo: $(STAMP)
	$(BIN)/brachycal demo --force  # demo_output is make's own: a second run replaces it
	@echo "brachycal is installed in $(BIN): 'source $(BIN)/activate' puts it on your PATH"

test: $(STAMP)
	$(BIN)/ruff check src tests benchmarks examples urdf docs
	$(BIN)/lint-imports
	$(BIN)/mypy
	$(BIN)/python -m pytest -m 'not slow'

test-all: test
	$(BIN)/python -m pytest -m slow

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks examples urdf docs
	$(BIN)/ruff format --check src tests benchmarks examples urdf docs
	$(BIN)/lint-imports
	$(BIN)/mypy

docs: $(STAMP)
	$(BIN)/mkdocs build --strict --site-dir site

bench: $(STAMP)
	$(BIN)/python benchmarks/fk_throughput.py
	$(BIN)/python benchmarks/fk_scale.py
	$(BIN)/python benchmarks/calibrate_speed.py
	$(BIN)/python benchmarks/startup.py
	$(BIN)/python benchmarks/plan_speed.py
	$(BIN)/python benchmarks/chain_checks.py
	$(BIN)/python benchmarks/table3.py
	$(BIN)/python benchmarks/robot_identification.py
	$(BIN)/python benchmarks/nwire_segmentation.py
	$(BIN)/python benchmarks/nwire_variants.py
	$(BIN)/python benchmarks/needle_tip.py
	$(BIN)/python benchmarks/verify_check.py
	$(BIN)/python benchmarks/parallel_pool.py
	$(BIN)/python benchmarks/mukca.py panda_2_clean
	$(BIN)/python benchmarks/mukca.py panda_3
	$(BIN)/python benchmarks/figaroh_mocap.py
	$(BIN)/python benchmarks/trus_stepper.py
	$(BIN)/python benchmarks/trus_segmentation.py

# Each stated SD, dof count, inflation and threshold has a test that fails when it is wrong: every
# mutant of benchmarks/mutants.py's table must be caught (a few minutes; non-zero exit if one survives).
mutants: $(STAMP)
	$(BIN)/python benchmarks/mutants.py

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

clean:
	rm -rf $(VENV) demo_output site .pytest_cache .hypothesis .ruff_cache .mypy_cache
