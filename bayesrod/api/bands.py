"""Credible bands: immutable arrays with named fields and the level they hold."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True, eq=False)
class Band:
    """A credible band over a grid ``x``: ``lower``, ``median``, ``upper``, shape (m,) each.

    ``level`` is the band's credible level (equal-tailed: lower and upper are the (1 - level)/2 and
    (1 + level)/2 posterior quantiles); ``x_name`` names the grid (``s_m``, ``height_m``,
    ``displacement_m``) and ``unit`` the unit of the banded quantity.
    """

    x: NDArray
    lower: NDArray
    median: NDArray
    upper: NDArray
    level: float
    x_name: str = "x"
    unit: str = ""

    def __post_init__(self) -> None:
        for name in ("x", "lower", "median", "upper"):
            arr = np.array(getattr(self, name), dtype=float)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    def __len__(self) -> int:
        return int(self.x.size)

    def to_records(self) -> np.ndarray:
        """The band as a structured array with fields (``x_name``, lower, median, upper)."""
        rec = np.empty(len(self), dtype=[(self.x_name, float), ("lower", float), ("median", float), ("upper", float)])
        rec[self.x_name], rec["lower"], rec["median"], rec["upper"] = self.x, self.lower, self.median, self.upper
        return rec


@dataclass(frozen=True, eq=False)
class ForceBand(Band):
    """Posterior-predictive force band at one contact height, with the probability the stem has slipped."""

    height_m: float = float("nan")
    slip_probability: NDArray | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.slip_probability is not None:
            arr = np.array(self.slip_probability, dtype=float)
            arr.setflags(write=False)
            object.__setattr__(self, "slip_probability", arr)
