"""Progress of long steps on stderr: a tqdm bar on a terminal, plain lines otherwise.

The core reports progress through a callable ``progress(stage, done, total)`` (``total``
0 when unknown) and never prints; this is the CLI's side of it.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

#: Plain (non-terminal) output: one line per stage at most every this many percent...
LINE_STEP_PERCENT = 10
#: ... and not more often than every this many seconds (except a stage's first and last).
LINE_MIN_INTERVAL_S = 2.0

_UNITS = {"reading": "B", "writing": "rows", "filter": "rows", "smoother": "rows"}


class StderrProgress:
    """``progress(stage, done, total)`` for the CLI.

    On a terminal each stage gets a tqdm bar (removed when it ends); otherwise (a log
    file, a pipe, CI) plain lines ``"<prefix>: <stage> 40 % (80 of 200 MB)"`` every
    ``LINE_STEP_PERCENT`` percent. Call :meth:`close` when the work is done.
    """

    def __init__(self, prefix: str, stream: TextIO | None = None, tty: bool | None = None):
        self.prefix = prefix
        self.stream = sys.stderr if stream is None else stream
        self.tty = self.stream.isatty() if tty is None else tty
        self.stage: str | None = None
        self.bar = None
        self.next_percent = 0
        self.last_line_s = 0.0

    def __call__(self, stage: str, done: int, total: int) -> None:
        if stage != self.stage:
            self.close()
            self.stage = stage
            self.next_percent = 0
            if self.tty:
                from tqdm import tqdm

                unit = _UNITS.get(stage, "it")
                self.bar = tqdm(
                    total=total or None,
                    desc=f"{self.prefix}: {stage}",
                    unit=unit,
                    unit_scale=unit == "B",
                    file=self.stream,
                    leave=False,
                )
            elif not total:
                self._line(f"{stage} ...")
        if self.bar is not None:
            self.bar.update(done - self.bar.n)
            return
        if not total:
            return
        percent = 100 * done // total
        now = time.monotonic()
        last = done >= total
        if percent >= self.next_percent and (
            last or self.next_percent == 0 or now - self.last_line_s >= LINE_MIN_INTERVAL_S
        ):
            self._line(f"{stage} {percent} % ({_amount(stage, done)} of {_amount(stage, total)})")
            self.next_percent = (percent // LINE_STEP_PERCENT + 1) * LINE_STEP_PERCENT
            self.last_line_s = now

    def _line(self, text: str) -> None:
        print(f"{self.prefix}: {text}", file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        self.stage = None


def _amount(stage: str, n: int) -> str:
    if _UNITS.get(stage) == "B":
        return f"{n / 1e6:.0f} MB" if n >= 1e6 else f"{n / 1e3:.0f} kB"
    return f"{n:,} rows".replace(",", " ")
