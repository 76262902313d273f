#!/usr/bin/env bash
# The main job: plan the default campaign (the paper's four experiments W1..W4), write
# step tables, plan.json and plots to out/<experiment>/ and the summary to out/summary.csv.
# Extra arguments go to `schedsyn campaign` (e.g. a CONFIG.toml copied from
# data/paper_campaign.toml). Exit code 0 when every output was written (an incomplete
# experiment is reported loudly on the console and in out/summary.csv), 2 on bad input;
# `schedsyn campaign` itself exits 1 when an experiment is incomplete. The exported tables
# are then re-checked by scripts/check_tables.py (exit 3 if that check disagrees).
# (creates .venv and installs what it needs on first use)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_venv.sh" test
rc=0
.venv/bin/schedsyn campaign --out out "$@" || rc=$?
# the paper-like baseline of experiment 1, simulated, for comparison with out/W1/
.venv/bin/schedsyn simulate data/baseline_exp1_steps.csv --region -50 -30 --out out/baseline \
  > /dev/null
if [ "$#" -eq 0 ] && [ "$rc" -le 1 ]; then
  echo "independent re-check of the exported step tables (scipy ODE solver, separate code):"
  .venv/bin/python scripts/check_tables.py out || { echo "re-check FAILED"; exit 3; }
fi
echo "summary (plans next to the paper-like baseline): out/summary.csv"
echo "per experiment: out/<experiment>/steps.csv, plan.json, program.png, phase.png, coverage.png"
echo "paper-like baseline of experiment 1: out/baseline/"
if [ "$rc" -eq 1 ]; then
  echo "note: at least one experiment is NOT complete; see out/summary.csv and its plan.json notes"
  exit 0
fi
exit "$rc"
