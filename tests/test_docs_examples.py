"""Every ```python block of README.md and docs/api.md runs (issue 13: "a short Python API
example in the README, checked by a test").

The blocks of one file run in order in one fresh interpreter, in a temporary folder that
holds a link to the repository's data/ folder, so that examples may read the sample data
and write where they like.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"^```python[^\n]*\n(.*?)^```", re.S | re.M)


def python_blocks(text: str) -> list[str]:
    return [m.group(1) for m in FENCE.finditer(text)]


def test_blocks_are_found():
    text = "x\n```python\na = 1\n```\n```bash\nls\n```\n```python\nb = a\n```\n"
    assert python_blocks(text) == ["a = 1\n", "b = a\n"]


@pytest.mark.parametrize("doc", ["README.md", "docs/api.md"])
def test_python_examples_run(doc, tmp_path):
    blocks = python_blocks((REPO / doc).read_text(encoding="utf-8"))
    if doc == "docs/api.md":
        assert blocks, "docs/api.md must show a Python example"
    if not blocks:
        pytest.skip(f"{doc} has no Python example")
    (tmp_path / "data").symlink_to(REPO / "data", target_is_directory=True)
    script = tmp_path / "example.py"
    script.write_text("\n".join(blocks), encoding="utf-8")
    res = subprocess.run(
        [sys.executable, str(script)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
        env={"MPLBACKEND": "Agg", "PATH": "/usr/bin:/bin"},
    )
    assert res.returncode == 0, f"{doc} example failed:\n{res.stdout}\n{res.stderr}"
