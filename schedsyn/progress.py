"""How long work reports how far it is: one small helper for every command.

A :class:`Progress` writes to stderr (or a given stream):

* on a terminal, a tqdm bar for counted work and messages printed above it;
* in a file or pipe (a log), plain timestamped lines, ``2025-01-31 14:02:07 W1 [ 12.3 s]
  sweep 4/6 placed``, and counted work as a line every 10 % (and at least every 30 s);
* nothing at all when disabled (``--quiet``).

A ``Progress`` is picklable (it holds no stream unless given one), so it can travel to the
worker processes of :func:`schedsyn.sweep.run_map` and report from there. Computation
never prints on its own: it receives a progress callable and calls it with a message.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["Progress", "ProgressBar"]


def _timestamp() -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S")


class Progress:
    """A progress reporter: ``progress("message")`` and ``with progress.bar(n, "desc")``.

    Parameters
    ----------
    enabled : bool
        False: report nothing (``--quiet``).
    stream : file, optional
        Where to write (default: ``sys.stderr`` at the time of writing).
    tty : bool, optional
        Force the terminal (True) or the log (False) form; default: whether ``stream`` is
        a terminal.
    """

    __slots__ = ("enabled", "_stream", "_tty")

    def __init__(
        self, enabled: bool = True, stream: TextIO | None = None, tty: bool | None = None
    ) -> None:
        self.enabled = bool(enabled)
        self._stream = stream
        self._tty = tty

    def __getstate__(self):
        return (self.enabled, self._stream, self._tty)

    def __setstate__(self, state) -> None:
        self.enabled, self._stream, self._tty = state

    @property
    def stream(self) -> TextIO:
        return self._stream if self._stream is not None else sys.stderr

    @property
    def tty(self) -> bool:
        if self._tty is not None:
            return self._tty
        try:
            return bool(self.stream.isatty())
        except (AttributeError, ValueError, OSError):
            return False

    def __call__(self, message: str) -> None:
        """Report one message (a line)."""
        if not self.enabled:
            return
        text = str(message).rstrip("\n")
        if self.tty:
            # clear a bar drawn on this line (by this or another process) first
            self.stream.write("\r\x1b[2K" + text + "\n")
        else:
            self.stream.write(f"{_timestamp()} {text}\n")
        self.stream.flush()

    def bar(self, total: int, desc: str = "") -> ProgressBar:
        """Counted work: a tqdm bar on a terminal, periodic lines in a log."""
        return ProgressBar(self, int(total), desc)


class ProgressBar:
    """``with progress.bar(n, "experiments") as bar: ... bar.update()`` (see :class:`Progress`)."""

    #: In the log form: a line at every tenth of the work and at least this often, s.
    LINE_EVERY_S = 30.0

    def __init__(self, progress: Progress, total: int, desc: str) -> None:
        self.progress, self.total, self.desc = progress, total, desc
        self.done = 0
        self._tqdm = None
        self._tic = time.perf_counter()
        self._last_line = self._tic
        self._last_tenth = 0

    def __enter__(self) -> ProgressBar:
        p = self.progress
        if p.enabled and p.tty:
            from tqdm import tqdm

            self._tqdm = tqdm(total=self.total, file=p.stream, desc=self.desc or None, leave=False)
        return self

    def __exit__(self, *exc) -> None:
        if self._tqdm is not None:
            self._tqdm.close()
            self._tqdm = None

    def update(self, n: int = 1) -> None:
        """``n`` more items done."""
        self.done += n
        if self._tqdm is not None:
            self._tqdm.update(n)
            return
        p = self.progress
        if not p.enabled:
            return
        now = time.perf_counter()
        tenth = (10 * self.done) // max(self.total, 1)
        if tenth > self._last_tenth or now - self._last_line >= self.LINE_EVERY_S:
            self._last_tenth, self._last_line = tenth, now
            what = f"{self.desc}: " if self.desc else ""
            p(f"{what}{self.done}/{self.total} done ({now - self._tic:.0f} s)")
