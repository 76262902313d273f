"""Which CSV dialect a table was saved in: the field separator and the decimal mark.

Spreadsheets set to a European locale save "CSV" with semicolons between fields and
decimal commas (``1;0;30;20,0;-10,0;-1``); a tab-separated export is also common. The
detection is a small pure function of the first lines of the file, so that every reader
(step tables, logs) recognises the same formats and can name the one it saw in an error.
"""

from __future__ import annotations

import csv
import re
from typing import NamedTuple

#: Candidate field separators, in order of preference on a tie.
SEPARATORS = (",", ";", "\t")

_DECIMAL_COMMA = re.compile(r"^\s*[+-]?\d+,\d+(?:[eE][+-]?\d+)?\s*$")
_DECIMAL_POINT = re.compile(r"^\s*[+-]?(?:\d+\.\d*|\.\d+)(?:[eE][+-]?\d+)?\s*$")

_NAMES = {",": "comma", ";": "semicolon", "\t": "tab"}
#: The first line some spreadsheets write to name the separator, e.g. ``sep=;``.
SEP_HINT = re.compile(r"^\s*\"?sep=(.)\"?\s*$")


class CsvDialect(NamedTuple):
    """A CSV dialect: ``separator`` between fields and ``decimal`` mark of numbers."""

    separator: str
    decimal: str

    def describe(self) -> str:
        """E.g. ``"semicolon-separated with decimal commas"``."""
        mark = "decimal commas" if self.decimal == "," else "decimal points"
        return f"{_NAMES.get(self.separator, repr(self.separator))}-separated with {mark}"


def _fields(line: str, sep: str) -> list[str]:
    return next(csv.reader([line], delimiter=sep, quotechar='"'), [])


def detect_csv_dialect(head: str) -> CsvDialect:
    """Separator and decimal mark of a CSV table from its first lines.

    Parameters
    ----------
    head : str
        The start of the file (a few kB is plenty). Blank lines and comment lines
        starting with ``#`` are skipped; a last line cut off mid-way is ignored.

    Returns
    -------
    CsvDialect
        ``(separator, decimal)``: the separator named by a ``sep=X`` first line (a
        spreadsheet's hint; readers skip that line), else the one (``","``, ``";"`` or
        tab) that splits the header into the most fields, every data line into as many
        fields as the header (ties go to the comma); the decimal mark is ``","`` when
        the separator is not a comma and the data fields hold more numbers like ``-1,5``
        than like ``-1.5``.
        A table of one column gives ``(",", ".")``.
    """
    text = head.lstrip("\ufeff")
    lines = text.splitlines()
    if lines and not text.endswith(("\n", "\r")) and len(lines) > 1:
        lines = lines[:-1]  # cut off mid-way
    rows = [ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")][:50]
    if not rows:
        return CsvDialect(",", ".")
    hint = SEP_HINT.match(rows[0])
    if hint:  # a spreadsheet's "sep=;" line names the separator
        sep = hint.group(1)
        cells = [c for r in rows[2:] for c in _fields(r, sep)]
        commas = sum(bool(_DECIMAL_COMMA.match(c)) for c in cells)
        points = sum(bool(_DECIMAL_POINT.match(c)) for c in cells)
        return CsvDialect(sep, "," if sep != "," and commas > points else ".")
    best, best_n = ",", 1
    for sep in SEPARATORS:
        n = len(_fields(rows[0], sep))
        consistent = all(len(_fields(r, sep)) == n for r in rows[1:])
        if n > best_n and consistent:
            best, best_n = sep, n
    if best_n == 1:  # no separator splits the header consistently: the most frequent one
        counts = {sep: len(_fields(rows[0], sep)) for sep in SEPARATORS}
        sep = max(SEPARATORS, key=lambda s: counts[s])
        best = sep if counts[sep] > 1 else ","
    decimal = "."
    if best != ",":
        cells = [c for r in rows[1:] for c in _fields(r, best)]
        commas = sum(bool(_DECIMAL_COMMA.match(c)) for c in cells)
        points = sum(bool(_DECIMAL_POINT.match(c)) for c in cells)
        if commas > points:
            decimal = ","
    return CsvDialect(best, decimal)
