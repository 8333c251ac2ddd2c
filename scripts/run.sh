#!/usr/bin/env bash
# Builds legkit from this checkout and installs it into the project's virtual environment (see venv.sh:
# .venv, created on first use), then runs `legkit` with the given arguments from it, e.g.
#   bash scripts/run.sh balance --duration 1.5
# Afterwards `.venv/bin/legkit ...` (or `source .venv/bin/activate`) runs legkit without reinstalling.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/venv.sh
python -m pip install --quiet .
legkit "$@"
