# One entry point per job. `make test` creates .venv, installs everything and runs the suite.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# numba kernels compiled into their cache (curvature/**/__pycache__); numba recompiles a file's
# kernels when the file changes, so the warm-up reruns whenever a library source does.
KERNELS := $(VENV)/.kernels
CORE_SOURCES := $(shell find curvature -name '*.py' 2>/dev/null)

.PHONY: venv run demo test lint bench openapi clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

$(KERNELS): $(STAMP) $(CORE_SOURCES)
	$(PY) -m curvature.warmup
	touch $(KERNELS)

venv: $(STAMP) $(KERNELS)

# Main job: the service on 127.0.0.1:8000 (CURVATURE_HOST/PORT/DATA_DIR honoured).
run: $(STAMP) $(KERNELS)
	$(PY) -m service

# The CLI on a synthetic cloud it generates.
demo: $(STAMP) $(KERNELS)
	mkdir -p data
	$(PY) -m curvature synthetic torus --n 20000 --noise 0.1 --seed 1 -o data/demo_torus.ply
	$(PY) -m curvature estimate data/demo_torus.ply -o data/demo_torus_curvature.ply --fit monge

test: $(STAMP) $(KERNELS)
	$(PY) -m ruff check .
	$(PY) -m pytest -q

lint: $(STAMP)
	$(PY) -m ruff check .

bench: $(STAMP) $(KERNELS)
	$(PY) benchmarks/speed.py

openapi: $(STAMP)
	$(PY) scripts/export_openapi.py

clean:
	rm -rf $(VENV) data .pytest_cache
