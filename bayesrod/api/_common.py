"""Small helpers the public API shares: dataset coercion, intervals, when to show progress."""

from __future__ import annotations

import copy
import json
import os
import sys
import warnings

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..dataset.model import Specimen


def as_dataset(dataset) -> Specimen:
    """A :class:`~bayesrod.Dataset` from itself or from a dataset directory (read and validated)."""
    from ..dataset import DatasetError, read_dataset, validate_in_memory

    if isinstance(dataset, Specimen):
        if dataset.root is None:  # built in memory: the reader's checks, array by array
            problems = validate_in_memory(dataset)
            if any(p.severity == "error" for p in problems):
                raise DatasetError(problems)
        return dataset
    if isinstance(dataset, (str, os.PathLike)):
        return read_dataset(dataset)
    raise TypeError(f"dataset: expected a bayesrod.Dataset or a dataset directory path, got {type(dataset).__name__}")


def readonly(a) -> NDArray:
    """A float copy of ``a`` that cannot be written (the draws result objects hand out)."""
    arr = np.array(a, dtype=float)
    arr.setflags(write=False)
    return arr


def plain_json(doc):
    """``doc`` with numpy scalars and arrays turned into JSON numbers and lists (a fresh copy)."""
    from ..dataset.io import json_default

    return json.loads(json.dumps(doc, default=json_default))


class DocResult:
    """Mixin of the result objects whose content is one JSON document held in ``self.doc``."""

    def to_dict(self) -> dict:
        """The JSON document the command line writes and prints (docs/format.md), a fresh copy."""
        return copy.deepcopy(dict(self.doc))


def interval(draws: ArrayLike, level: float, axis: int = 0) -> tuple[NDArray, NDArray, NDArray]:
    """Equal-tailed ``level`` interval and median over ``axis``: (lower, median, upper); NaNs ignored.

    Where every draw is NaN (e.g. a force beyond every draw's slip) the result is NaN, silently.
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "All-NaN slice encountered", RuntimeWarning)
        q = np.nanquantile(np.asarray(draws, float), [(1 - level) / 2, 0.5, (1 + level) / 2], axis=axis)
    return q[0], q[1], q[2]


def progress_enabled(progress: bool) -> bool:
    """Show progress bars only when asked and someone watches: a terminal on stderr, or a notebook."""
    if not progress:
        return False
    if "ipykernel" in sys.modules:
        return True
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False
