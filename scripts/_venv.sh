# Sourced by demo.sh and test.sh: create .venv if missing and install the project into it
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
STAMP=".venv/.schedsyn-installed-$(cksum < pyproject.toml | cut -d' ' -f1)-$1"
if [ ! -f "$STAMP" ]; then
  echo "installing schedsyn and its dependencies into .venv ..." >&2
  .venv/bin/python -m pip install --quiet --upgrade pip >/dev/null 2>&1 || true
  .venv/bin/python -m pip install --quiet -e ".[$1]"
  rm -f .venv/.schedsyn-installed-*-"$1"
  touch "$STAMP"
fi
