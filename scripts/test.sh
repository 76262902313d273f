#!/usr/bin/env bash
# Run the checks and the test suite (creates .venv and installs what it needs on first use):
# ruff (lint and format), mypy (types of the package), then pytest.
# Extra arguments go to pytest, e.g. scripts/test.sh -k coverage
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/_venv.sh" test
echo "ruff: lint and format" >&2
.venv/bin/ruff check --quiet .
.venv/bin/ruff format --check --quiet .
echo "mypy: types of the package" >&2
.venv/bin/mypy --no-error-summary
# -n auto: one worker per core (pytest-xdist); pass -n 0 to run in one process.
# --dist loadgroup: the tests spread over the workers one by one, except that the modules
# with an expensive module fixture (tests/conftest.py's WHOLE_MODULES) each run on one
# worker, so the fixture is computed once instead of once per worker
exec .venv/bin/python -m pytest -n auto --dist loadgroup "$@"
