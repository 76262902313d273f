"""What produced a result: package versions, input files with their SHA-256, the command.

Versions are looked up in the installed package metadata (nothing heavy is imported).
"""

from __future__ import annotations

import hashlib
import platform
import sys
from collections.abc import Mapping
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

#: Packages whose versions a report names.
PACKAGES = (
    "schedsyn",
    "numpy",
    "scipy",
    "pandas",
    "cvxpy",
    "clarabel",
    "highspy",
    "matplotlib",
)


def versions(packages: tuple[str, ...] = PACKAGES) -> dict[str, str]:
    """Python, the platform and each package's installed version ("not installed")."""
    out = {"python": platform.python_version(), "platform": platform.platform()}
    for name in packages:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def sha256_file(path: Path | str) -> str:
    """SHA-256 of a file's bytes (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def describe_inputs(inputs: Mapping[str, Path | str | None]) -> list[dict[str, Any]]:
    """``[{"role", "path", "bytes", "sha256"}]`` for every input file given (None skipped);
    a folder lists each file in it (sorted), with the role ``"<role>: <name>"``."""
    rows: list[dict[str, Any]] = []
    for role, p in inputs.items():
        if p is None:
            continue
        path = Path(p)
        files = sorted(q for q in path.rglob("*") if q.is_file()) if path.is_dir() else [path]
        for f in files:
            rows.append(
                {
                    "role": role if f == path else f"{role}: {f.relative_to(path)}",
                    "path": str(f),
                    "bytes": f.stat().st_size,
                    "sha256": sha256_file(f),
                }
            )
    return rows


def command_line(argv: list[str] | None = None) -> str:
    """The ``schedsyn ...`` command being run, or "" when not run from the command line
    (e.g. from Python or a test)."""
    argv = sys.argv if argv is None else argv
    if not argv or Path(argv[0]).name not in ("schedsyn", "__main__.py"):
        return ""
    if Path(argv[0]).name == "__main__.py" and Path(argv[0]).parent.name != "schedsyn":
        return ""
    return " ".join(["schedsyn", *argv[1:]])


def provenance(inputs: Mapping[str, Path | str | None]) -> dict[str, Any]:
    """Versions, inputs (with hashes), command line and time (UTC) of a result."""
    return {
        "generated_utc": datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
        "command": command_line(),
        "versions": versions(),
        "inputs": describe_inputs(inputs),
    }
