"""Atomic file output: write to a temporary file beside the target, then rename.

A crash never leaves a half-written file, and an output path that is one of the inputs is
refused so that a user's data is never overwritten.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from .errors import SchedsynError


def _check_not_input(path: Path, inputs: Iterable[Path | str]) -> None:
    target = path.resolve()
    for p in inputs:
        if Path(p).resolve() == target:
            raise SchedsynError(
                f"refusing to overwrite the input file {p}; choose another output path"
            )


def write_atomic(
    path: Path | str,
    writer: Callable[[Path], object],
    inputs: Iterable[Path | str] = (),
) -> Path:
    """Call ``writer(tmp_path)`` and move the result to ``path`` atomically."""
    path = Path(path)
    _check_not_input(path, inputs)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        writer(tmp_path)
        # mkstemp creates 0600 files; give outputs the usual permissions (umask applies)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)
        os.replace(tmp_path, path)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise
    return path


def write_text_atomic(path: Path | str, text: str, inputs: Iterable[Path | str] = ()) -> Path:
    return write_atomic(path, lambda p: p.write_text(text, encoding="utf-8"), inputs)


def write_json_atomic(path: Path | str, obj: Any, inputs: Iterable[Path | str] = ()) -> Path:
    return write_text_atomic(path, json.dumps(obj, indent=2, sort_keys=False) + "\n", inputs)


def write_frame_atomic(path: Path | str, frame, inputs: Iterable[Path | str] = ()) -> Path:
    """Write a pandas DataFrame as CSV (no index) atomically."""
    return write_atomic(path, lambda p: frame.to_csv(p, index=False), inputs)
