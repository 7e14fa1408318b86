"""Parsing of command-line value forms shared by several commands."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray


def parse_values(text: str, option: str) -> NDArray[np.float64]:
    """Parse ``X``, ``X,Y,Z`` or ``start:stop:num`` (inclusive, like numpy.linspace).

    Raises ValueError naming ``option``, what was expected and what was given.
    """
    expected = "a number, a comma list, or start:stop:num"
    text = text.strip()
    try:
        if ":" in text:
            parts = text.split(":")
            if len(parts) != 3:
                raise ValueError
            start, stop = float(parts[0]), float(parts[1])
            num = int(parts[2])
            if num < 1 or num > 100_000:
                raise ValueError(f"{option}: expected 1 <= num <= 100000 in start:stop:num, got {num}")
            values = np.linspace(start, stop, num)
        else:
            values = np.array([float(v) for v in text.split(",")], dtype=float)
    except ValueError as exc:
        if str(exc).startswith(option):
            raise
        raise ValueError(f"{option}: expected {expected}, got {text!r}") from None
    if values.size == 0 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{option}: expected finite numbers, got {text!r}")
    return values
