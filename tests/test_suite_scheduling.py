"""The suite's own scheduling (tests/conftest.py): under ``--dist loadgroup`` the modules
named in WHOLE_MODULES run whole on one worker, so their module fixture is computed once."""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("xdist")

HERE = Path(__file__).resolve().parent


def test_a_whole_module_runs_on_one_worker_and_the_rest_spread(tmp_path):
    tests = tmp_path / "tests"
    tests.mkdir()
    shutil.copy(HERE / "conftest.py", tests / "conftest.py")
    (tmp_path / "pytest.ini").write_text("[pytest]\ntestpaths = tests\n")
    # each test takes a moment, so that two workers share the ungrouped ones
    body = "import time\n\n\n" + "".join(
        f"def test_{i}():\n    time.sleep(0.2)\n\n\n" for i in range(6)
    )
    (tests / "test_split.py").write_text(body)  # one of WHOLE_MODULES
    (tests / "test_other.py").write_text(body)
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-n",
            "2",
            "--dist",
            "loadgroup",
            "-v",
            "-p",
            "no:cacheprovider",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    where = re.findall(r"\[(gw\d)\].*PASSED tests/(test_\w+)\.py::", run.stdout)
    assert len(where) == 12, run.stdout
    assert len({w for w, m in where if m == "test_split"}) == 1, run.stdout
