"""Read delimited tables from rigs: CSV, TSV, semicolon with decimal comma, metadata lines above the header.

The header row is the first line that names every asked column (or the line the
caller gives); lines above it are kept as metadata. Data rows are read by
column name, never by position, so a row with the wrong number of fields or a
cell that is not a number is skipped and reported (line and reason), never
shifted into another column. Nothing here writes.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

DELIMITERS = ("\t", ";", ",", "|")
_DECIMAL_COMMA = re.compile(r"^[+-]?(\d+,\d*|,\d+)([eE][+-]?\d+)?$")
_DECIMAL_DOT = re.compile(r"^[+-]?(\d+\.\d*|\.\d+)([eE][+-]?\d+)?$")
_NAMES = {"\t": "tab", ";": "semicolon", ",": "comma", "|": "bar"}


@dataclass(frozen=True)
class Table:
    """Numeric columns of one table, by header name, shape (n,) each, in file order.

    ``header_line`` is the 1-based line of the header; ``metadata`` the lines above it; ``skipped`` the
    (line, reason) of every data line that was not read; ``text`` the columns read as text (ids, names),
    by header name, shape (n,) of str each.
    """

    columns: dict
    header: tuple[str, ...]
    header_line: int
    delimiter: str
    decimal: str
    metadata: tuple[str, ...]
    skipped: tuple[tuple[int, str], ...]
    lines: NDArray  # 1-based file line of each row read, shape (n,)
    text: dict = field(default_factory=dict)

    @property
    def n_rows(self) -> int:
        return int(self.lines.size)


def _cells(line: str, delimiter: str) -> list[str]:
    try:
        row = next(csv.reader([line], delimiter=delimiter, quotechar='"', skipinitialspace=True))
    except (csv.Error, StopIteration):
        row = line.split(delimiter)
    return [c.strip().strip('"').strip() for c in row]


def _decode(data: bytes) -> str:
    for enc in ("utf-8-sig", "cp1252", "latin-1"):
        try:
            return data.decode(enc)
        except UnicodeDecodeError:
            continue
    return data.decode("latin-1", errors="replace")  # pragma: no cover - latin-1 decodes every byte


def _number(cell: str, decimal: str) -> float | None:
    if decimal == ",":
        cell = cell.replace(",", ".")
    try:
        v = float(cell)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def read_table(
    source,
    columns: Sequence[str],
    *,
    header_row: int | None = None,
    name: str | None = None,
    text_columns: Sequence[str] = (),
) -> Table:
    """Read the asked ``columns`` (header names) of a delimited table.

    Parameters
    ----------
    source : path or str
        The file, or its text (then ``name`` names it in messages).
    columns : sequence of str
        Header names to read; each must appear in the header row.
    header_row : int or None
        1-based line of the header; default: the first line naming every column.
    text_columns : sequence of str
        Header names read as text (a specimen's or a test's id, a condition's name); a row whose cell is
        empty there is skipped and reported like a row whose number is not one.
    """
    if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source and Path(source).is_file()):
        path = Path(source)
        name = name or str(path)
        try:
            text = _decode(path.read_bytes())
        except OSError as e:
            raise ValueError(f"{name}: expected a readable table file, got {type(e).__name__}: {e}") from None
    elif isinstance(source, str):
        text, name = source, name or "table"
        if "\n" not in source and not source.strip().count(","):
            raise ValueError(f"{name}: expected a table file, got no such file")
    else:
        raise TypeError(f"source: expected a path or the table's text, got {type(source).__name__}")
    columns = list(dict.fromkeys(columns))
    if not columns:
        raise ValueError(f"{name}: expected at least one column name to read, got none")
    texts = [c for c in dict.fromkeys(text_columns) if c not in columns]
    numeric = columns
    columns = columns + texts
    lines = text.splitlines()
    found = None
    if header_row is not None:
        if not (isinstance(header_row, int) and 1 <= header_row <= len(lines)):
            raise ValueError(f"header_row: expected a line number from 1 to {len(lines)} of {name}, got {header_row!r}")
        best = max(
            DELIMITERS,
            key=lambda d: (
                sum(c in _cells(lines[header_row - 1], d) for c in columns),
                len(_cells(lines[header_row - 1], d)),
            ),
        )
        cells = _cells(lines[header_row - 1], best)
        missing = [c for c in columns if c not in cells]
        if missing:
            raise ValueError(
                f"{name}, line {header_row}: column {missing[0]!r}: expected a header naming it, got "
                f"columns {', '.join(repr(c) for c in cells)}"
            )
        found = (header_row - 1, best)
    else:
        for i, line in enumerate(lines):
            hits = [d for d in DELIMITERS if all(c in _cells(line, d) for c in columns)]
            if hits:
                found = (i, max(hits, key=lambda d: len(_cells(line, d))))
                break
        if found is None:
            raise ValueError(
                f"{name}: expected a header row naming the columns {', '.join(repr(c) for c in columns)}, "
                f"got no such line in {len(lines)} lines (check the names, or give the header row)"
            )
    i0, delim = found
    header = _cells(lines[i0], delim)
    dupes = [c for c in columns if header.count(c) > 1]
    if dupes:
        raise ValueError(f"{name}, line {i0 + 1}: column {dupes[0]!r}: expected each column once, got it twice")
    idx = {c: header.index(c) for c in columns}
    body = [(k + 1, line) for k, line in enumerate(lines) if k > i0 and line.strip()]
    decimal = "."
    if delim != ",":
        sample = [_cells(line, delim) for _, line in body[:200]]
        cells = [r[idx[c]] for r in sample for c in numeric if len(r) == len(header) and r[idx[c]]]
        commas = sum(bool(_DECIMAL_COMMA.match(x)) for x in cells)
        dots = sum(bool(_DECIMAL_DOT.match(x)) for x in cells)
        if commas and commas >= dots:  # integers say nothing; more comma decimals than dot decimals decide
            decimal = ","
    vals = {c: [] for c in columns}
    kept, skipped = [], []
    for lineno, line in body:
        cells = _cells(line, delim)
        if len(cells) != len(header):
            skipped.append((lineno, f"{len(cells)} fields, the header has {len(header)}"))
            continue
        row = {}
        for c in columns:
            v = cells[idx[c]] if c in texts else _number(cells[idx[c]], decimal)
            if v is None or v == "":
                row = None
                why = "is empty" if c in texts else "is not a finite number"
                skipped.append((lineno, f"column {c!r}: {cells[idx[c]]!r} {why}"))
                break
            row[c] = v
        if row is None:
            continue
        for c in columns:
            vals[c].append(row[c])
        kept.append(lineno)
    if not kept:
        why = f" (first: line {skipped[0][0]}, {skipped[0][1]})" if skipped else ""
        raise ValueError(f"{name}: expected numeric data rows below the header (line {i0 + 1}), got none{why}")
    return Table(
        columns={c: np.asarray(vals[c], float) for c in numeric},
        header=tuple(header),
        header_line=i0 + 1,
        delimiter=delim,
        decimal=decimal,
        metadata=tuple(lines[:i0]),
        skipped=tuple(skipped),
        lines=np.asarray(kept, int),
        text={c: np.asarray(vals[c], str) for c in texts},
    )


def delimiter_name(d: str) -> str:
    return _NAMES.get(d, repr(d))
