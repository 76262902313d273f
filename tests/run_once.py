"""A result made once per test run and shared by the test modules that need the very same
one, across pytest-xdist's workers: its documented way to run something once, a lock in
the run's shared temporary folder (tests/test_split.py does the same for its split)."""

from __future__ import annotations

import fcntl
import pickle
from collections.abc import Callable
from typing import Any


def once_per_run(tmp_path_factory, worker_id: str, tag: str, make: Callable[[], Any]) -> Any:
    """``make()``, called by the first test of the run that asks for ``tag``; the others
    (on any worker) wait for it and read its pickled result."""
    root = tmp_path_factory.getbasetemp()
    if worker_id != "master":
        root = root.parent  # shared by this run's workers
    with open(root / f"{tag}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        done = root / f"{tag}.pickle"
        if not done.exists():
            done.write_bytes(pickle.dumps(make()))
        return pickle.loads(done.read_bytes())
