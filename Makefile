# Everyday commands. Needs only python3 (3.10+) and make; no root.
#   make install   create $(VENV) (if missing) and install triaxtrack with its dev tools
#   make run       the workflow with the default config (simulates and checks `demo`)
#   make test      the test suite (what CI runs, after `make lint`)
#   make lint      ruff, snakefmt, snakemake --lint and mypy
#   make dag       dry run, and the rule graph in results/rulegraph.dot
#   make bench     benchmarks (print figures; never assert a time)
#   make clean     remove results/, logs/, benchmarks/ and Snakemake's run state

VENV ?= .venv
PYTHON ?= python3
BIN := $(VENV)/bin
STAMP := $(VENV)/.triaxtrack-installed

.PHONY: install run test lint bench dag clean

install: $(STAMP)

# The venv itself (needs Python's venv module with ensurepip, as python.org and pyenv builds have).
$(BIN)/python:
	$(PYTHON) -m venv $(VENV) || { echo "error: '$(PYTHON) -m venv' failed: install a Python with venv/ensurepip"; exit 1; }

# Re-installs whenever pyproject.toml changes (editable: code changes need no reinstall).
$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --upgrade pip
	$(BIN)/python -m pip install -e '.[dev]'
	touch $@

run: $(STAMP)
	$(BIN)/snakemake --cores 2

test: $(STAMP)
	$(BIN)/pytest -q

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/snakefmt --check Snakefile workflow/
	$(BIN)/snakemake --lint
	$(BIN)/mypy src/triaxtrack

# Installs trackpy (extra `bench`) once, for the linking comparison; the bench runs without it.
# Options: make bench BENCH_ARGS="--size 1280x720 --frames 12" (see python bench/pipeline.py -h).
bench: $(STAMP)
	@$(BIN)/python -c 'import trackpy' 2>/dev/null || $(BIN)/python -m pip install -e '.[dev,bench]' \
	  || echo "warning: trackpy could not be installed (pip install -e '.[dev,bench]'): its line is skipped"
	$(BIN)/python bench/pipeline.py $(BENCH_ARGS)

dag: $(STAMP)
	mkdir -p results
	$(BIN)/snakemake -n --quiet rules
	$(BIN)/snakemake --rulegraph > results/rulegraph.dot
	@echo "rule graph: results/rulegraph.dot (render with graphviz: dot -Tsvg)"

# Keeps .snakemake/conda (environments built by --sdm conda are slow to rebuild).
clean:
	rm -rf results logs benchmarks
	rm -rf .snakemake/metadata .snakemake/incomplete .snakemake/log .snakemake/locks \
	  .snakemake/auxiliary .snakemake/iocache .snakemake/scripts .snakemake/shadow
