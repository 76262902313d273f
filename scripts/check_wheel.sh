#!/usr/bin/env bash
# Prove that schedsyn works when installed from a wheel, not only from a checkout:
#   1. build a wheel from the working tree (pip wheel --no-deps; setuptools comes from the
#      package index, as in any pip build),
#   2. check it carries the package data (the paper campaign and its baseline step table),
#   3. install it into a fresh venv in a temporary directory outside the repository,
#   4. from an unrelated temporary directory run `schedsyn campaign --out OUT` (the default
#      campaign: the paper's four experiments), and
#   5. check OUT: every experiment's step table, and a summary whose experiments are all
#      complete (with the paper-like baseline read from the installed package); and that
#      `schedsyn examples` writes the shipped example files and `estimate` reads the log.
# Exit code 0 when all holds. Takes about a minute plus the campaign (40-60 s on 2 cores).
# Set KEEP=1 to keep the temporary directory; PYTHON to choose the interpreter.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PY="${PYTHON:-}"
if [ -z "$PY" ]; then
  for cand in python3.11 python3 python; do
    if command -v "$cand" >/dev/null 2>&1; then PY="$cand"; break; fi
  done
fi
[ -n "$PY" ] || { echo "check_wheel: no python3 found" >&2; exit 2; }

WORK="$(mktemp -d "${TMPDIR:-/tmp}/schedsyn-wheel.XXXXXX")"
if [ "${KEEP:-0}" = 1 ]; then
  echo "check_wheel: keeping $WORK" >&2
else
  trap 'rm -rf "$WORK"' EXIT
fi
say() { echo "check_wheel: $*" >&2; }
# pip's notes about unusable extra index locations of this machine are noise here
quiet_pip() { "$@" 2> >(grep -v "^WARNING: Location .* is ignored" >&2); }

# 1. the source as it would be committed (tracked and new files, no venv, no outputs),
#    copied so the build leaves nothing in the working tree
mkdir -p "$WORK/src" "$WORK/dist" "$WORK/run"
if git -C "$ROOT" rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  (cd "$ROOT" && git ls-files -z --cached --others --exclude-standard \
    | xargs -0 -I{} sh -c 'test -e "{}" && printf "%s\0" "{}"' \
    | tar --null -T - -cf -) | tar -xf - -C "$WORK/src"
else
  tar -C "$ROOT" --exclude=.venv --exclude=out --exclude=.git -cf - . | tar -xf - -C "$WORK/src"
fi
say "building the wheel"
quiet_pip "$PY" -m pip wheel --quiet --no-deps --wheel-dir "$WORK/dist" "$WORK/src"
WHEEL="$(ls "$WORK"/dist/schedsyn-*.whl)"
say "built $(basename "$WHEEL")"

# 2. the wheel carries the data the default campaign needs
"$PY" - "$WHEEL" <<'EOF'
import sys, zipfile
names = set(zipfile.ZipFile(sys.argv[1]).namelist())
need = [
    f"schedsyn/data/{n}"
    for n in (
        "paper_campaign.toml",
        "baseline_exp1_steps.csv",
        "example_gyro.toml",
        "sample_run_exp1.csv",
    )
]
missing = [n for n in need if n not in names]
if missing:
    sys.exit(f"check_wheel: the wheel lacks {missing}; fix package-data in pyproject.toml")
stray = sorted(n for n in names if n.startswith(("tests/", "scripts/", "data/")))
if stray:
    sys.exit(f"check_wheel: the wheel carries files outside the package: {stray[:5]}")
EOF

# 3. a fresh venv outside the repository, the wheel and its dependencies
say "installing it into a fresh venv"
"$PY" -m venv "$WORK/venv"
quiet_pip "$WORK/venv/bin/python" -m pip install --quiet "$WHEEL"

# 4. the default campaign, from an unrelated directory (no checkout on any path)
cd "$WORK/run"
say "running 'schedsyn campaign --out OUT' in $WORK/run"
rc=0
"$WORK/venv/bin/schedsyn" campaign --out OUT --quiet > campaign.txt || rc=$?
tail -n 3 campaign.txt >&2
if [ "$rc" -ne 0 ]; then
  cat campaign.txt >&2
  say "FAILED: schedsyn campaign exited with $rc (0 = every experiment complete)"
  exit 1
fi

# 4b. the example files a wheel user follows the docs with, and a command that reads one
"$WORK/venv/bin/schedsyn" examples --out EX > /dev/null
"$WORK/venv/bin/schedsyn" estimate EX/sample_run_exp1.csv --out EST > /dev/null
[ -s EST/gradient.csv ] || { say "FAILED: schedsyn examples / estimate wrote no gradient.csv"; exit 1; }

# 5. the outputs, checked with the installed package
"$WORK/venv/bin/python" - "$WORK" <<'EOF'
import sys
from pathlib import Path

import pandas as pd

import schedsyn
from schedsyn import read_steps
from schedsyn.campaign import default_campaign

work = Path(sys.argv[1]).resolve()
here = Path(schedsyn.__file__).resolve()
if work / "venv" not in here.parents:
    sys.exit(f"check_wheel: schedsyn was imported from {here}, not from the fresh venv")
out = Path("OUT")
summary = pd.read_csv(out / "summary.csv")
names = [e.name for e in default_campaign().experiments]
problems = []
if summary["experiment"].tolist() != names:
    problems.append(f"summary lists {summary['experiment'].tolist()}, expected {names}")
for name in names:
    steps = out / name / "steps.csv"
    if not steps.is_file():
        problems.append(f"{steps} was not written")
        continue
    prog = read_steps(steps)  # validates the table (limits, continuity, 540 min)
    row = summary.set_index("experiment").loc[name]
    if abs(prog.total_min - row["duration_min"]) > 1e-6 or prog.n_segments != row["steps"]:
        problems.append(f"{steps} does not match its summary row")
incomplete = summary.loc[~summary["complete"].astype(bool), "experiment"].tolist()
if incomplete or (summary["coverage"] < 1.0).any():
    problems.append(f"incomplete experiments: {incomplete or 'coverage < 100 %'}")
if summary.loc[0, "baseline"] != "baseline_exp1_steps.csv":
    problems.append(f"W1's baseline is {summary.loc[0, 'baseline']!r}, not the shipped table")
if problems:
    sys.exit("check_wheel: FAILED: " + "; ".join(problems))
print(
    f"check_wheel: OK: {len(names)} experiments complete, step tables written, "
    f"schedsyn {schedsyn.__version__} from {here.parent}"
)
EOF
