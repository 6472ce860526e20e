# Every target installs what it needs into .venv first, so a fresh clone needs only Python 3.11.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp

.PHONY: install demo test test-quick bench sample-data clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[exr,test]'
	touch $(STAMP)

install: $(STAMP)

# The main job on the bundled sample data: repair the depth, then score raw vs repaired.
demo: install
	rm -rf build/demo
	$(BIN)/sr3d repair-depth sample_data --out build/demo/sample_data --preview
	$(BIN)/sr3d evaluate sample_data --pred depth --pred repaired --out build/demo/sample_data --plot

# Tests run on every core (pytest-xdist); test-quick leaves out the tests marked slow
# (whole-pipeline and multi-frame scenarios).
test: install
	$(BIN)/python -m pytest -n auto -q -rs tests

test-quick: install
	$(BIN)/python -m pytest -n auto -q -rs -m "not slow" tests

# Regenerates the bundled sample_data/ byte for byte (deterministic for the seed).
sample-data: install
	rm -rf build/sample_data
	$(BIN)/sr3d synth build/sample_data --scenes 4 --seed 0
	rm -rf sample_data && mv build/sample_data sample_data

bench: install
	$(BIN)/python bench/run.py

clean:
	rm -rf build $(VENV) .pytest_cache
