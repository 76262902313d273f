# Sourced by demo.sh (`core`: run-time dependencies only) and test.sh (`test`: the test
# extras): create .venv if missing and install the project into it
# (re-installing only when pyproject.toml changed). Needs only Python 3.11+ and pip.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
PY="${PYTHON:-}"
if [ -z "$PY" ]; then
  for cand in python3.11 python3 python; do
    if command -v "$cand" >/dev/null 2>&1; then PY="$cand"; break; fi
  done
fi
[ -n "$PY" ] || { echo "error: no python3 found; install Python 3.11" >&2; exit 2; }
if [ ! -x .venv/bin/python ]; then
  echo "creating .venv with $($PY --version 2>&1)" >&2
  "$PY" -m venv .venv
fi
SUM="$(cksum < pyproject.toml | cut -d' ' -f1)"
STAMP=".venv/.schedsyn-installed-$SUM-$1"
# the test extras include the run-time dependencies: a test install serves the demo too
if [ "$1" = core ] && [ -f ".venv/.schedsyn-installed-$SUM-test" ]; then
  STAMP=".venv/.schedsyn-installed-$SUM-test"
fi
if [ ! -f "$STAMP" ]; then
  echo "installing schedsyn and its dependencies into .venv ..." >&2
  .venv/bin/python -m pip install --quiet --upgrade pip >/dev/null 2>&1 || true
  # "core": schedsyn and its run-time dependencies only (the demo); else those extras
  if [ "$1" = core ]; then SPEC="."; else SPEC=".[$1]"; fi
  .venv/bin/python -m pip install --quiet -e "$SPEC"
  rm -f .venv/.schedsyn-installed-*-"$1"
  touch "$STAMP"
fi
