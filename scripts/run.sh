#!/usr/bin/env bash
# Builds legkit from this checkout and installs it into the project's virtual environment (see venv.sh:
# .venv, created on first use) with the extras the command needs, then runs `legkit` with the given
# arguments from it, e.g.
#   bash scripts/run.sh balance --duration 1.5
# The extras (pyproject.toml), as the command checks them (legkit/cli.py): plot for the experiments' figures,
# viewer for balance's animation, optimize and viewer for gait --optimize; sweep for sweep and tune, or
# cluster when --ray is given; demo none. LEGKIT_EXTRAS adds more,
# e.g. LEGKIT_EXTRAS=viewer,sweep. Afterwards `.venv/bin/legkit ...` (or `source .venv/bin/activate`) runs
# legkit without reinstalling, and `.venv/bin/pip install '.[EXTRA]'` adds an extra.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/venv.sh

extras="${LEGKIT_EXTRAS:-}"
case "${1:-}" in
    balance) extras+=",plot,viewer" ;;
    strain) extras+=",plot" ;;
    gait) [[ " $* " == *" --optimize "* ]] && extras+=",plot,optimize,viewer" || extras+=",plot" ;;
    sweep | tune) [[ " $* " == *" --ray "* ]] && extras+=",cluster" || extras+=",sweep" ;;
esac
extras="${extras#,}"
legkit_install ".${extras:+[$extras]}"
legkit "$@"
