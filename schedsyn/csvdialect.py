"""Which CSV dialect a file is written in: separator and decimal mark, from its first lines.

Spreadsheets set to a European locale save "CSV" with semicolons between fields and
decimal commas (``time_s;t_int_c`` / ``10;-23,45``); tab-separated exports exist too.
:func:`detect_csv_dialect` looks at the head of a file (a pure function of the text, so
every reader can use it and it is tested without files) and says how to read it, or
raises :class:`ValueError` naming the problem when the text cannot be read unambiguously
(decimal commas in a comma-separated file).
"""

from __future__ import annotations

import re
from typing import NamedTuple

#: Separators tried, most specific first: a comma in a semicolon- or tab-separated file
#: is a decimal mark, never the other way round.
SEPARATORS = (";", "\t", ",")
#: Data lines of the head that are examined (the rest of the file is not looked at).
MAX_DATA_LINES = 50

_POINT_NUMBER = re.compile(r"^[+-]?(\d+\.\d*|\.\d+)([eE][+-]?\d+)?$")
_COMMA_NUMBER = re.compile(r"^[+-]?(\d+,\d*|,\d+)([eE][+-]?\d+)?$")
_NAMES = {",": "comma", ";": "semicolon", "\t": "tab"}
#: The first line some spreadsheets write to name the separator, e.g. ``sep=;``; readers
#: skip it.
SEP_HINT = re.compile(r"^\s*\"?sep=(.)\"?\s*$")


class CsvDialect(NamedTuple):
    """How to read a CSV file: field separator and decimal mark (``"."`` or ``","``)."""

    separator: str
    decimal: str

    def describe(self) -> str:
        """E.g. ``"semicolon-separated, decimal comma"``."""
        mark = "decimal comma" if self.decimal == "," else "decimal point"
        return f"{_NAMES[self.separator]}-separated, {mark}"


def _split(line: str, sep: str) -> list[str]:
    """Fields of one line, separators inside double quotes not counted."""
    fields: list[str] = []
    cur: list[str] = []
    quoted = False
    for ch in line:
        if ch == '"':
            quoted = not quoted
        elif ch == sep and not quoted:
            fields.append("".join(cur))
            cur = []
            continue
        cur.append(ch)
    fields.append("".join(cur))
    return [f.strip().strip('"').strip() for f in fields]


def detect_csv_dialect(head: str) -> CsvDialect:
    """Separator and decimal mark of a CSV file from its first lines.

    Parameters
    ----------
    head : str
        The beginning of the file as text (a few kB is plenty; a last line cut short is
        ignored). Blank lines and lines starting with ``#`` are skipped.

    Returns
    -------
    CsvDialect
        ``(separator, decimal)``: the separator is the first of ``;``, tab, ``,`` that
        splits the header and (at least 90 % of) the examined data lines into the same
        number (> 1) of fields (``,`` when none does: a one-column file); the decimal
        mark is ``","`` when numbers with a decimal comma (``-23,45``) appear, else
        ``"."``.

    Raises
    ------
    ValueError
        Decimal commas in a comma-separated file (the header has fewer fields than the
        data lines), or decimal commas and decimal points mixed in one file.
    """
    text = head.lstrip("\ufeff")
    lines = text.splitlines()
    if lines and not text.endswith(("\n", "\r")) and len(lines) > 1:
        lines = lines[:-1]  # cut short by the size of the head
    lines = [ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        return CsvDialect(",", ".")
    hint = SEP_HINT.match(lines[0])
    if hint:  # a spreadsheet's "sep=;" line names the separator: no guessing
        lines = lines[1:] or [""]
    header, data = lines[0], lines[1 : 1 + MAX_DATA_LINES]
    for i, ln in enumerate([header, *data]):
        if ln.count('"') % 2:  # it swallows the lines after it into one field
            raise ValueError(
                f"{'the header' if i == 0 else f'data line {i}'} ({ln.strip()!r}) has an "
                'unterminated quote ("): close it or remove it'
            )
    sep = hint.group(1) if hint else ","
    found = bool(hint)
    for cand in () if hint else SEPARATORS:
        n = len(_split(header, cand))
        same = sum(len(_split(ln, cand)) == n for ln in data)
        # a stray ragged line is left to the parser, which names its line number
        if n > 1 and same >= 0.9 * len(data):
            sep, found = cand, True
            break
    if not found:
        n_head = len(_split(header, ","))
        longer = [i for i, ln in enumerate(data) if len(_split(ln, ",")) > n_head]
        if longer:
            i = longer[0]
            fields = _split(data[i], ",")
            raise ValueError(
                f"data line {i + 1} ({data[i].strip()!r}) has {len(fields)} comma-separated "
                f"fields but the header has {n_head}: decimal commas in a comma-separated "
                "file cannot be read unambiguously; save it with decimal points, or as "
                "semicolon-separated CSV (the European spreadsheet format: ';' between "
                "fields, decimal commas)"
            )
    fields = [f for ln in data for f in _split(ln, sep)]
    comma = next((f for f in fields if _COMMA_NUMBER.match(f)), None)
    point = next((f for f in fields if _POINT_NUMBER.match(f)), None)
    if comma is not None and sep == ",":
        comma = None  # quoted "1,5" in a comma file: left to the number check of the reader
    if comma is not None and point is not None:
        raise ValueError(
            f"the file mixes decimal commas ({comma!r}) and decimal points ({point!r}); "
            "use one decimal mark throughout"
        )
    return CsvDialect(sep, "," if comma is not None else ".")
