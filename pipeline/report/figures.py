"""Matplotlib figures of a render (the report's plots, ``segments/segments.png``): drawn without
pyplot and laid out with fixed margins.

They are drawn at the end of ``loom render``, after the last frame, where every second is serial
(docs/13-cluster.md §4). pyplot's figure manager and ``tight_layout`` (which draws every tick label to
measure it, then draws again) cost about a third of a figure's time (a 1 x 3 plot of 135 frames:
0.75 s against 0.48-0.52 s, both cores otherwise busy); a ``matplotlib.figure.Figure`` on the Agg
canvas with margins fixed in inches draws once. The margins hold the axis labels and
titles these plots use (one line each, tick labels up to about six characters).
"""
from __future__ import annotations

import io
import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np
    from matplotlib.figure import Figure

# Inches: room for the y tick labels and label (left, and between columns), the x tick labels and
# label (bottom, and between rows), a title (top)
LEFT_IN, RIGHT_IN, BOTTOM_IN, TOP_IN = 0.85, 0.2, 0.6, 0.35
COLUMN_GAP_IN, ROW_GAP_IN = 0.95, 0.85


def figure(rows: int, cols: int, size: tuple[float, float], dpi: float = 100) -> tuple[Figure, np.ndarray]:
    """A Figure of ``rows`` x ``cols`` axes (always a 2-D array) on the Agg canvas, margins fixed."""
    from matplotlib import rc_context  # heavy: only when drawing
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    width, height = size
    fig = Figure(figsize=size, dpi=dpi)
    FigureCanvasAgg(fig)
    # Titles at the axes' top: placing them "automatically" measures every tick label of the
    # figure at each draw (a third of these plots' time), only to clear ticks no plot puts on top
    with rc_context({"axes.titley": 1.0}):
        axes = fig.subplots(rows, cols, squeeze=False)
    plot_w = (width - LEFT_IN - RIGHT_IN - (cols - 1) * COLUMN_GAP_IN) / cols
    plot_h = (height - BOTTOM_IN - TOP_IN - (rows - 1) * ROW_GAP_IN) / rows
    fig.subplots_adjust(left=LEFT_IN / width, right=1 - RIGHT_IN / width, bottom=BOTTOM_IN / height,
                        top=1 - TOP_IN / height, wspace=COLUMN_GAP_IN / plot_w, hspace=ROW_GAP_IN / plot_h)
    return fig, axes


def png_bytes(fig: Figure, dpi: float) -> bytes:
    """The figure as PNG data."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def save_png(fig: Figure, path: str | Path, dpi: float | None = None) -> Path:
    """Write the figure to ``path`` atomically (a partial file renamed into place)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.partial.png")
    fig.savefig(tmp, format="png", dpi=dpi if dpi is not None else fig.dpi)
    os.replace(tmp, path)
    return path
