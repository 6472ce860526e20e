# Every target installs what it needs into .venv first, so a fresh clone needs only Python 3.11.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp

.PHONY: install demo test sample-data clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[exr,test]'
	touch $(STAMP)

install: $(STAMP)

# The main job on the bundled sample data (later stages extend this).
demo: install
	$(BIN)/sr3d synth build/demo/synth --scenes 2 --seed 1 --overwrite
	$(BIN)/sr3d evaluate sample_data --pred depth --out build/demo/sample_data --plot
	$(BIN)/sr3d evaluate build/demo/synth --pred depth

test: install
	$(BIN)/python -m pytest -q tests

# Regenerates the bundled sample_data/ byte for byte (deterministic for the seed).
sample-data: install
	rm -rf build/sample_data
	$(BIN)/sr3d synth build/sample_data --scenes 4 --seed 0
	rm -rf sample_data && mv build/sample_data sample_data

clean:
	rm -rf build $(VENV) .pytest_cache
