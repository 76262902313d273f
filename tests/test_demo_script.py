"""scripts/demo.sh: exit 1 of the campaign is "reported" (0), 2 and 3 are failures."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _demo(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", str(REPO / "scripts" / "demo.sh"), *args],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PATH": f"{REPO / '.venv' / 'bin'}:{os.environ.get('PATH', '')}"},
    )


@pytest.mark.skipif(not (REPO / ".venv" / "bin" / "schedsyn").exists(), reason="needs .venv")
def test_bad_input_fails_the_demo_with_2(tmp_path):
    res = _demo(str(tmp_path / "missing.toml"))
    assert res.returncode == 2, res.stderr
    assert "demo FAILED: bad input" in res.stderr


@pytest.mark.skipif(not (REPO / ".venv" / "bin" / "schedsyn").exists(), reason="needs .venv")
def test_an_unwritable_output_fails_the_demo_with_3(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = _demo("--out", str(blocker / "out"))  # the last --out wins
    assert res.returncode == 3, res.stderr
    assert "fault: cannot write" in res.stderr and "demo FAILED: environment fault" in res.stderr
