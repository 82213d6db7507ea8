# One entry point per job. `make test` creates .venv, installs everything and runs the suite.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: venv run demo test lint bench openapi clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

venv: $(STAMP)

# Main job: the service on 127.0.0.1:8000 (CURVATURE_HOST/PORT/DATA_DIR honoured).
run: $(STAMP)
	$(PY) -m service

# The CLI on a synthetic cloud it generates.
demo: $(STAMP)
	mkdir -p data
	$(PY) -m curvature synthetic torus --n 20000 --noise 0.1 --seed 1 -o data/demo_torus.ply
	$(PY) -m curvature estimate data/demo_torus.ply -o data/demo_torus_curvature.ply --fit monge

test: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m pytest -q

lint: $(STAMP)
	$(PY) -m ruff check .

bench: $(STAMP)
	$(PY) benchmarks/speed.py

openapi: $(STAMP)
	$(PY) scripts/export_openapi.py

clean:
	rm -rf $(VENV) data .pytest_cache
