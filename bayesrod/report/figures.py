"""Figures for saved runs, drawn on :class:`matplotlib.figure.Figure` objects.

No pyplot and no backend: a figure made here never appears in, nor changes,
the user's interactive session. :func:`png_bytes` renders one to PNG in memory;
writing the bytes to disk is the caller's (``save()``) business.
"""

from __future__ import annotations

import io
from collections.abc import Callable


def new_figure(width: float, height: float, ncols: int = 1, layout: str | None = None):
    """A detached Figure and its axes (one axes, or an array of ``ncols``)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout=layout)
    axes = fig.subplots(1, ncols)
    return fig, axes


def png_bytes(fig, dpi: int = 100) -> bytes:
    """The figure as PNG bytes (Agg canvas attached here, nothing global touched)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def render(draw: Callable, width: float, height: float, ncols: int = 1, dpi: int = 100, tight: bool = True) -> bytes:
    """Draw with ``draw(axes)`` on a detached figure and return the PNG bytes."""
    fig, axes = new_figure(width, height, ncols)
    draw(axes)
    if tight:
        fig.tight_layout()
    return png_bytes(fig, dpi)
