#!/usr/bin/env bash
# The main job: plan the default campaign (the paper's four experiments W1..W4), write
# step tables, plan.json and plots to out/<experiment>/ and the summary to out/summary.csv.
# Extra arguments go to `schedsyn campaign` (e.g. a CONFIG.toml copied from
# data/paper_campaign.toml). (creates .venv and installs what it needs on first use)
#
# Exit code: 0 when every output was written, including when an experiment is incomplete
# (`schedsyn campaign` exits 1: reported loudly on the console and in out/summary.csv);
# 2 bad input and 3 an environment fault (an output cannot be written, a worker process
# died) are failures and stop the demo with that code; 4 if the independent re-check of
# the exported step tables (scripts/check_tables.py) disagrees with the summary.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_venv.sh" core
rc=0
.venv/bin/schedsyn campaign --out out "$@" || rc=$?
case "$rc" in
  0 | 1) ;;
  2) echo "demo FAILED: bad input (schedsyn campaign exit 2, see the message above)" >&2; exit 2 ;;
  3) echo "demo FAILED: environment fault (schedsyn campaign exit 3, see above)" >&2; exit 3 ;;
  *) echo "demo FAILED: schedsyn campaign exited with $rc" >&2; exit "$rc" ;;
esac
# the paper-like baseline of experiment 1, simulated, for comparison with out/W1/
.venv/bin/schedsyn simulate data/baseline_exp1_steps.csv --region -50 -30 --out out/baseline \
  > /dev/null
if [ "$#" -eq 0 ]; then
  echo "independent re-check of the exported step tables (scipy ODE solver, separate code):"
  .venv/bin/python scripts/check_tables.py out || { echo "re-check FAILED" >&2; exit 4; }
fi
echo "summary (plans next to the paper-like baseline): out/summary.csv"
echo "per experiment: out/<experiment>/steps.csv, plan.json, program.png, phase.png, coverage.png"
echo "paper-like baseline of experiment 1: out/baseline/"
if [ "$rc" -eq 1 ]; then
  echo "note: at least one experiment is NOT complete; see out/summary.csv and its plan.json notes"
fi
exit 0
