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


def _run_two_workers(tmp_path, modules: tuple[str, ...]) -> list[tuple[str, str, str]]:
    """Six 0.2-s tests in each of ``modules`` (copies of the suite's conftest.py beside
    them), run on two workers under ``--dist loadgroup``: (worker, module, test) in the
    order they passed."""
    tests = tmp_path / "tests"
    tests.mkdir()
    shutil.copy(HERE / "conftest.py", tests / "conftest.py")
    (tmp_path / "pytest.ini").write_text("[pytest]\ntestpaths = tests\n")
    # each test takes a moment, so that two workers share the ungrouped ones
    body = "import time\n\n\n" + "".join(
        f"def test_{i}():\n    time.sleep(0.2)\n\n\n" for i in range(6)
    )
    for module in modules:
        (tests / f"{module}.py").write_text(body)
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
    where = re.findall(r"\[(gw\d)\].*PASSED tests/(test_\w+)\.py::(test_\d)", run.stdout)
    assert len(where) == 6 * len(modules), run.stdout
    return where


def test_a_whole_module_runs_on_one_worker_and_the_rest_spread(tmp_path):
    where = _run_two_workers(tmp_path, ("test_split", "test_other"))  # split: a whole module
    assert len({w for w, m, _ in where if m == "test_split"}) == 1, where


def test_a_module_reading_a_whole_modules_memo_runs_after_it_on_its_worker(tmp_path):
    where = _run_two_workers(tmp_path, ("test_replan", "test_replan_choice", "test_other"))
    unit = [(w, m) for w, m, _ in where if m != "test_other"]
    assert len({w for w, _ in unit}) == 1, where  # one worker
    assert [m for _, m in unit] == ["test_replan"] * 6 + ["test_replan_choice"] * 6, where
