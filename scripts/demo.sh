#!/usr/bin/env bash
# The main job: plan the default campaign, write step tables and plots to out/.
# (creates .venv and installs what it needs on first use)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_venv.sh" test
.venv/bin/schedsyn simulate data/baseline_exp1_steps.csv --region -50 -30 --out out/baseline "$@"
echo "plots and coverage of the paper-like baseline in out/baseline/"
