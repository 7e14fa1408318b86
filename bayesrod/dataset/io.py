"""Output helpers: atomic directories and files, CSV writing. Inputs are never modified."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np


class OutputExistsError(ValueError):
    """An output directory that already holds results; the caller decides whether to overwrite."""

    def __init__(self, path: Path):
        self.path = Path(path)
        super().__init__(f"{self.path}: expected a new or empty directory, got one that is not empty")


def check_out_dir(out: str | os.PathLike, force: bool) -> Path:
    """Refuse an existing non-empty output directory unless ``force`` (:class:`OutputExistsError`)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out}: expected a directory path, got a file")
    if out.is_dir() and any(out.iterdir()) and not force:
        raise OutputExistsError(out)
    return out


@contextlib.contextmanager
def atomic_dir(out: str | os.PathLike, force: bool = False) -> Iterator[Path]:
    """Write a directory's content into a temporary sibling, then swap it in.

    A crash or an error leaves ``out`` as it was (absent, or the old content).
    """
    out = check_out_dir(out, force)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if out.exists():
        old = out.with_name(f".{out.name}.old-{os.getpid()}")
        out.rename(old)
        tmp.rename(out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        tmp.rename(out)


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write a UTF-8 text file via a temporary sibling and an atomic rename."""
    write_bytes_atomic(path, text.encode("utf-8"))


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    """Write bytes via a temporary sibling and an atomic rename (parents created)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_json(path: str | os.PathLike, doc) -> None:
    write_text_atomic(path, json.dumps(doc, indent=2, default=json_default) + "\n")


def json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def write_csv(path: str | os.PathLike, columns: Mapping[str, np.ndarray | list], fmt: str = "%.10g") -> None:
    """Write equal-length columns with a header (numbers with ``fmt``, strings as-is)."""
    names = list(columns)
    cols = [np.asarray(columns[n]) for n in names]
    n = {len(c) for c in cols}
    if len(n) > 1:
        raise ValueError(f"columns: expected equal lengths, got {dict(zip(names, map(len, cols), strict=True))}")
    lines = [",".join(names)]
    for i in range(n.pop() if n else 0):
        cells = []
        for c in cols:
            v = c[i]
            cells.append(str(v) if isinstance(v, (str, np.str_)) else fmt % v)
        lines.append(",".join(cells))
    write_text_atomic(path, "\n".join(lines) + "\n")


def read_rows(path: str | os.PathLike) -> list[dict]:
    """Rows of a results CSV written by :func:`append_rows` (strings), or [] when it does not exist yet."""
    import csv

    path = Path(path)
    if not path.is_file():
        return []
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def append_rows(path: str | os.PathLike, fields: list[str], rows, new_file: bool):
    """Append each row of the iterable ``rows`` to a CSV as it arrives (flushed), header first when new.

    For long studies that resume: finished rows survive an interruption. Yields the rows. A file
    written before a column was added is first rewritten (atomically) with the new header, its old
    rows keeping empty cells in the new columns.
    """
    import csv

    old = read_rows(path) if not new_file else []
    if old and list(old[0]) != list(fields):
        missing = [f for f in old[0] if f not in fields]
        if missing:
            raise ValueError(
                f"{path}: columns {missing} are gone from the study's fields {fields}; expected a superset"
            )
        tmp = Path(path).with_suffix(".tmp")
        with tmp.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fields)
            w.writeheader()
            w.writerows(old)
        os.replace(tmp, path)
    with Path(path).open("a", newline="") as fh:
        w = csv.DictWriter(fh, fields)
        if new_file:
            w.writeheader()
        for r in rows:
            w.writerow(r)
            fh.flush()
            yield r
