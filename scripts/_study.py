"""What the resumable study scripts share: skip the jobs whose rows are already in the results CSV, run
the rest in a process pool and append each row as it finishes (an interrupted study resumes)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from bayesrod.dataset.io import append_rows, read_rows


def run_pending(
    csv_path: Path, fields: list[str], jobs: Iterable[tuple], fn: Callable, *, done_key: Callable, workers: int = 1
) -> Iterator[dict]:
    """Rows of ``fn(job)`` for the ``jobs`` not yet in ``csv_path`` (``done_key(row)`` gives a written row's
    job), appended to it as they arrive. A CSV of other columns is refused, not appended to."""
    old = read_rows(csv_path)
    if old and list(old[0]) != list(fields):
        raise SystemExit(f"{csv_path}: columns {', '.join(old[0])}, expected {', '.join(fields)}: use another --out")
    done = {done_key(r) for r in old}
    todo = [j for j in jobs if j not in done]
    new_file = not Path(csv_path).exists()
    with ProcessPoolExecutor(workers) as pool:
        yield from append_rows(csv_path, fields, pool.map(fn, todo), new_file=new_file)
