#!/usr/bin/env bash
# Run by Snakemake inside the new conda environment, from its working directory (the
# repository root): install triaxtrack (editable, so the environment follows src/) with
# the dependencies listed in pyproject.toml.
set -euo pipefail
python -m pip install --no-input -e .
