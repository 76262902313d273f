"""Atomic file output: one file at a time, and one run's outputs all or nothing.

* :func:`write_atomic` writes a file to a temporary name beside the target and renames it:
  a crash never leaves a half-written file, and an output path that is one of the inputs
  is refused, so a user's data is never overwritten.
* :class:`OutputDir` makes a whole run's outputs all-or-nothing: they are written into a
  staging folder and moved into place at the end (see its docstring). A killed run never
  leaves new files beside stale ones without saying so.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import re
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from .errors import EnvironmentFaultError, ParameterError, SchedsynError


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
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    except OSError as exc:  # named by the output, not by a temporary file (red team)
        raise EnvironmentFaultError(
            f"cannot write {path} ({exc.strerror or type(exc).__name__}); choose another "
            "output path or fix the folder's permissions/free space"
        ) from None
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        writer(tmp_path)
        # mkstemp creates 0600 files; give outputs the usual permissions (umask applies)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)
        os.replace(tmp_path, path)
    except OSError as exc:
        tmp_path.unlink(missing_ok=True)
        raise EnvironmentFaultError(
            f"cannot write {path} ({exc.strerror or type(exc).__name__}); choose another "
            "output path or fix the folder's permissions/free space"
        ) from None
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise
    return path


def write_text_atomic(path: Path | str, text: str, inputs: Iterable[Path | str] = ()) -> Path:
    return write_atomic(path, lambda p: p.write_text(text, encoding="utf-8"), inputs)


def strict_json(obj: Any) -> Any:
    """``obj`` with every NaN and infinity replaced by None (JSON ``null``).

    JSON has no NaN or infinity; Python writes ``NaN`` and ``Infinity``, which strict
    parsers (JavaScript's, jq, most other languages') refuse. A file that must tell an
    infinite value from a missing one says so in a field of its own.
    """
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: strict_json(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [strict_json(v) for v in obj]
    return obj


def write_json_atomic(path: Path | str, obj: Any, inputs: Iterable[Path | str] = ()) -> Path:
    """Write ``obj`` as strict JSON (NaN and infinity as ``null``, :func:`strict_json`)."""
    text = json.dumps(strict_json(obj), indent=2, sort_keys=False, allow_nan=False)
    return write_text_atomic(path, text + "\n", inputs)


def write_frame_atomic(path: Path | str, frame, inputs: Iterable[Path | str] = ()) -> Path:
    """Write a pandas DataFrame as CSV (no index) atomically."""
    return write_atomic(path, lambda p: frame.to_csv(p, index=False), inputs)


# ---------------------------------------------------------------------------------------
# one run's outputs, all or nothing
# ---------------------------------------------------------------------------------------
#: The file that lists what the last completed run wrote into a folder.
MANIFEST = "schedsyn-run.json"
#: Present only while (or if killed while) a run moves its outputs into a folder.
INCOMPLETE_MARKER = "SCHEDSYN-RUN-INCOMPLETE.txt"
#: The files of the run being moved in (so that the next run can clean up after it).
PENDING = ".schedsyn-run-pending.json"
_STAGING = re.compile(r"^\.(?P<name>.*)\.schedsyn-staging-(?P<pid>\d+)-[^/]*$")


def os_error_text(exc: OSError) -> str:
    """One line for an OSError: what failed, on which file, and the system's reason."""
    reason = exc.strerror or type(exc).__name__
    name = exc.filename
    return f"{reason}: {name}" if name else f"{reason} ({exc})"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


class OutputDir:
    """One run's output folder, written all or nothing.

    Usage::

        out = OutputDir("out/W1", inputs=[steps_csv], command="schedsyn simulate ...")
        out.check(["trajectory.csv", "coverage.csv"])     # before any long work
        write_frame_atomic(out.path("trajectory.csv"), frame)
        ...
        out.commit()                                     # everything moves into place

    Every output goes first into a staging folder (``.<name>.schedsyn-staging-<pid>-*``)
    beside the target (inside it when the target exists already). :meth:`commit` then

    * renames the staging folder to the target when there was none: one atomic step;
    * otherwise writes :data:`INCOMPLETE_MARKER` into the target, moves each file into
      place (``os.replace``), removes the files the previous run listed in its manifest
      that this run did not write (only if unchanged since, and never an input), writes
      the new manifest :data:`MANIFEST` and removes the marker.

    So a run killed before :meth:`commit` leaves the target untouched (its staging
    folder is removed by the next run), and one killed during it leaves the marker,
    which says that the folder mixes two runs. Files that no run of schedsyn listed are
    never touched. :meth:`discard` (or leaving a ``with`` block by an exception) removes
    the staging folder.

    Errors: an output path that is an input raises :class:`SchedsynError` (bad input),
    a target that exists and is not a folder :class:`ParameterError`; a folder that
    cannot be written raises :class:`EnvironmentFaultError`.
    """

    def __init__(
        self, target: Path | str, inputs: Iterable[Path | str | None] = (), command: str = ""
    ) -> None:
        self.target = Path(target)
        #: The folder's own name (of the resolved path: ``--out .`` has one too).
        self._name = self.target.resolve().name or "out"
        self.inputs = [Path(p) for p in inputs if p is not None and str(p)]
        self.command = command or " ".join(["schedsyn", *sys.argv[1:]])
        #: Which command wrote the files (``plan``, ``compare``...): a run removes only the
        #: stale files of an earlier run of the same command, never another command's
        self.kind = _command_kind(self.command)
        self._staging: Path | None = None
        self._created_parents: list[Path] = []
        self._committed = False
        #: Files of an earlier run that this one did not rewrite and left in place because
        #: they changed since (or are inputs); filled by :meth:`commit`.
        self.kept_stale: list[Path] = []
        if self.target.exists() and not self.target.is_dir():
            raise ParameterError(
                f"--out {self.target} exists and is not a folder; give a folder to write to"
            )

    # -- context manager: leaving by an exception discards the staged outputs -----------
    def __enter__(self) -> OutputDir:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if not self._committed:
            self.discard()

    # -- preflight ----------------------------------------------------------------------
    def check(self, names: Iterable[str] = ()) -> None:
        """Refuse outputs that are inputs, and make sure the folder can be written.

        Call it before any long computation: ``names`` are the outputs the run will
        write (paths relative to the target). Creates the staging folder.
        """
        for name in names:
            _check_not_input(self.target / name, self.inputs)
        self._stage()

    def _stage(self) -> Path:
        if self._staging is not None:
            return self._staging
        target = self.target
        where = target if target.is_dir() else target.parent
        try:
            missing = []
            p = where
            while not p.exists():
                missing.append(p)
                p = p.parent
            where.mkdir(parents=True, exist_ok=True)
            self._created_parents = missing
            for folder in {where, target.parent}:
                self._remove_dead_staging(folder)
            prefix = f".{self._name}.schedsyn-staging-{os.getpid()}-"
            staging = Path(tempfile.mkdtemp(prefix=prefix, dir=where))
            os.chmod(staging, 0o777 & ~_umask())
            probe = staging / ".write-test"
            with open(probe, "wb") as fh:  # a folder can be created but full (ENOSPC)
                fh.write(b"schedsyn")
                fh.flush()
                os.fsync(fh.fileno())
            probe.unlink()
        except OSError as exc:
            raise EnvironmentFaultError(
                f"cannot write the outputs to {target} ({os_error_text(exc)}); choose "
                "another --out or fix the folder's permissions/free space"
            ) from None
        self._staging = staging
        return staging

    def _remove_dead_staging(self, where: Path) -> None:
        """Staging folders for this target left by killed runs (their process is gone)."""
        try:
            entries = list(where.iterdir())
        except OSError:
            return
        for p in entries:
            m = _STAGING.match(p.name)
            if (
                m
                and m.group("name") == self._name
                and p.is_dir()
                and not _pid_alive(int(m.group("pid")))
            ):
                shutil.rmtree(p, ignore_errors=True)

    # -- writing ------------------------------------------------------------------------
    def path(self, name: str | Path) -> Path:
        """Where to write the output ``name`` (relative to the target) during the run."""
        rel = Path(name)
        if rel.is_absolute() or ".." in rel.parts:
            raise ParameterError(f"output name {name} must be relative and inside the folder")
        _check_not_input(self.target / rel, self.inputs)
        p = self._stage() / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    def folder(self, name: str | Path) -> Path:
        """A sub-folder ``name`` of the staged outputs (created), e.g. one experiment's."""
        rel = Path(name)
        if rel.is_absolute() or ".." in rel.parts:
            raise ParameterError(f"output folder {name} must be relative and inside the folder")
        p = self._stage() / rel
        p.mkdir(parents=True, exist_ok=True)
        return p

    def final(self, name: str | Path) -> Path:
        """Where the output ``name`` ends up after :meth:`commit`."""
        return self.target / name

    # -- the end ------------------------------------------------------------------------
    def _staged_files(self) -> list[Path]:
        assert self._staging is not None
        return sorted(
            p.relative_to(self._staging)
            for p in self._staging.rglob("*")
            if p.is_file() and not p.name.startswith(".write-test")
        )

    def commit(self) -> list[Path]:
        """Move every staged output into the target; returns their final paths."""
        if self._committed:
            raise SchedsynError("this output folder was committed already")
        staging = self._stage()
        files = self._staged_files()
        for rel in files:
            _check_not_input(self.target / rel, self.inputs)
        try:
            if not self.target.exists():
                self._write_manifest(staging / MANIFEST, files, staging)
                try:
                    os.rename(staging, self.target)
                except OSError:
                    if not self.target.is_dir():  # not a race with another run
                        raise
                    self._merge(files)
            else:
                self._merge(files)
        except OSError as exc:
            raise EnvironmentFaultError(
                f"cannot move the outputs into {self.target} ({os_error_text(exc)}); "
                f"nothing of this run is missing from {staging} if it still exists"
            ) from None
        self._committed = True
        self._staging = None
        return [self.target / rel for rel in files]

    def _merge(self, files: Sequence[Path]) -> None:
        assert self._staging is not None
        target, staging = self.target, self._staging
        # the earlier run's files, and those of a run killed while moving its files in
        old = _read_manifest(target / MANIFEST) + _read_manifest(target / PENDING)
        self._write_manifest(target / PENDING, files, staging)
        now = _dt.datetime.now().isoformat(" ", "seconds")
        write_text_atomic(
            target / INCOMPLETE_MARKER,
            "A schedsyn run was stopped while it moved its outputs into this folder, so\n"
            "the files here may mix that run and an earlier one. Run the command again:\n"
            f"    {self.command}\n"
            f"(started moving {len(files)} files at {now})\n",
        )
        for rel in files:
            dest = target / rel
            dest.parent.mkdir(parents=True, exist_ok=True)
            os.replace(staging / rel, dest)
        new = {str(rel) for rel in files}
        inputs = {p.resolve() for p in self.inputs}
        self.kept_stale = []
        carried: dict[str, dict] = {}  # another command's files: kept, still listed
        for entry in old:
            name = entry.get("path")
            if not isinstance(name, str) or name in new or ".." in Path(name).parts:
                continue
            p = target / name
            if entry.get("by", "") != self.kind:
                if p.is_file():
                    carried[name] = entry
                continue
            try:
                st = p.stat()
            except OSError:  # gone (or never moved in by a killed run): its empty folders
                _prune_empty(p.parent, target)
                continue
            unchanged = st.st_size == entry.get("size") and st.st_mtime_ns == entry.get("mtime_ns")
            if p.resolve() in inputs or not unchanged:
                self.kept_stale.append(p)  # someone's data now: leave it
                continue
            p.unlink()
            _prune_empty(p.parent, target)
        self._write_manifest(target / MANIFEST, files, target, list(carried.values()))
        (target / INCOMPLETE_MARKER).unlink(missing_ok=True)
        (target / PENDING).unlink(missing_ok=True)
        shutil.rmtree(staging, ignore_errors=True)

    def _write_manifest(
        self, path: Path, files: Sequence[Path], root: Path, carried: Sequence[dict] = ()
    ) -> None:
        """The files this run wrote (``by`` its command), then ``carried``: an earlier
        run's of another command, kept as they were."""
        from . import __version__

        rows = []
        for rel in files:
            st = (root / rel).stat()
            rows.append(
                {
                    "path": str(rel),
                    "size": st.st_size,
                    "mtime_ns": st.st_mtime_ns,
                    "by": self.kind,
                }
            )
        rows += [dict(e) for e in carried]
        write_json_atomic(
            path,
            {
                "schedsyn_version": str(__version__),
                "command": self.command,
                "finished": _dt.datetime.now().isoformat(" ", "seconds"),
                "files": rows,
            },
        )

    def discard(self) -> None:
        """Remove the staged outputs (the target is left as it was); no-op after commit."""
        if self._committed:
            return
        if self._staging is not None:
            shutil.rmtree(self._staging, ignore_errors=True)
            self._staging = None
        for p in self._created_parents:  # folders created for nothing
            try:
                p.rmdir()
            except OSError:
                break


def _prune_empty(folder: Path, root: Path) -> None:
    """Remove ``folder`` and its parents up to (not including) ``root`` while empty."""
    while folder != root and root in folder.parents and folder.is_dir():
        if any(folder.iterdir()):
            return
        folder.rmdir()
        folder = folder.parent


def _command_kind(command: str) -> str:
    """The command of a command line (``schedsyn plan --out x`` -> ``plan``): its first
    word after the program that is not an option."""
    words = command.split()
    return next((w for w in words[1:] if not w.startswith("-")), "")


def _read_manifest(path: Path) -> list[dict]:
    """The files an earlier run listed, each with ``by``, the command that wrote it
    (manifests before it was recorded per file: the manifest's own command)."""
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    files = obj.get("files") if isinstance(obj, dict) else None
    if not isinstance(files, list):
        return []
    kind = _command_kind(str(obj.get("command", "")))
    return [{"by": kind, **f} for f in files if isinstance(f, dict)]
