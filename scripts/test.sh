#!/usr/bin/env bash
# Run the test suite (creates .venv and installs what it needs on first use).
# Extra arguments go to pytest, e.g. scripts/test.sh -k coverage
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_venv.sh" test
exec .venv/bin/python -m pytest "$@"
