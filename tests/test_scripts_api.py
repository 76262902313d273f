"""The scripts use only what the package exports: a name dropped from ``schedsyn.__all__``
(for example ``run_map``, which lives in ``schedsyn.sweep``) must not be reached as
``schedsyn.<name>`` by a benchmark that only fails when someone runs it."""

from __future__ import annotations

import re
from pathlib import Path

import schedsyn

REPO = Path(__file__).resolve().parents[1]
ATTRIBUTE = re.compile(r"\bschedsyn\.([A-Za-z_][A-Za-z0-9_]*)\b(?!\s*import)")


def test_scripts_reach_only_exported_names():
    exported = set(schedsyn.__all__)
    bad = []
    for path in sorted((REPO / "scripts").glob("*.py")):
        text = path.read_text(encoding="utf-8")
        if not re.search(r"^import schedsyn\b", text, re.M):
            continue
        for line_no, line in enumerate(text.splitlines(), 1):
            if line.lstrip().startswith(("from ", "import ", "#")):
                continue
            for name in ATTRIBUTE.findall(line):
                if name.startswith("__"):  # __file__, __version__
                    continue
                if (
                    name not in exported
                    and not (REPO / "schedsyn" / name).exists()
                    and not (REPO / "schedsyn" / f"{name}.py").exists()
                ):
                    bad.append(f"{path.name}:{line_no}: schedsyn.{name}")
    assert not bad, "names not in schedsyn.__all__ nor a module: " + ", ".join(bad)
