"""Colours, fonts and deterministic saving shared by keyfill's pictures.

Figures are plain :class:`matplotlib.figure.Figure` objects on an Agg canvas
(no ``pyplot``, no global backend). Saved files carry no date, software
version or random ids, so the same input gives the same bytes.
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import matplotlib
import matplotlib.style
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

#: one colour per input file, in order (matplotlib's "tab10" without its pink,
#: which is reserved for keys)
FILE_COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b", "#17becf", "#bcbd22", "#7f7f7f", "#d62728")
#: keys: ghosted key poses and key markers in previews (pink, as in Zhou et al. 2020)
KEY_COLOR = "#e7298a"
GROUND_COLOR = "#b0b0b0"
GRID_COLOR = "#d2d2d2"
#: the frame around each picture of a filmstrip
FRAME_COLOR = "#d7d7d7"
TEXT_COLOR = "#333333"
#: the grid lines of plot panels
AXIS_GRID_COLOR = "#e5e5e5"

#: rc settings for every picture: a font that ships with matplotlib (same
#: glyphs on every machine) and a fixed SVG id salt (no random ids)
RC = {
    "font.family": "DejaVu Sans",
    "figure.facecolor": "white",
    "font.size": 9,
    "svg.hashsalt": "keyfill",
    "svg.fonttype": "path",
    "path.simplify": True,
    "axes.titlesize": 9,
    "axes.labelsize": 8,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "legend.fontsize": 8,
}

#: metadata that each format would otherwise fill with dates and versions
_NO_METADATA = {
    "svg": {"Date": None, "Creator": None},
    "pdf": {"CreationDate": None, "ModDate": None, "Producer": None, "Creator": None},
}


@contextmanager
def style():
    """matplotlib's default style plus :data:`RC` for the duration of a drawing (never
    globally): a user's matplotlibrc does not change keyfill's pictures."""
    with matplotlib.style.context("default"), matplotlib.rc_context(RC):
        yield


def new_figure(width_in: float, height_in: float, dpi: float = 100) -> Figure:
    """A figure of the given size in inches on its own Agg canvas."""
    fig = Figure(figsize=(width_in, height_in), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig: Figure, path: Path, fmt: str) -> None:
    """Save ``fig`` as ``fmt`` (png, svg or pdf) to ``path`` without dates or versions.

    PNGs are written by Pillow from the Agg buffer with a 256-colour palette:
    the flat colours of the figure exact, then its most frequent colours
    (:class:`keyfill.viz.palette.Palette`); a line plot holds a few thousand
    antialiasing shades, and the rare ones move to their nearest neighbour.
    The file is about a third of a true-colour PNG.
    """
    if fmt == "png":
        import numpy as np
        from matplotlib.colors import to_rgb

        from keyfill.viz.palette import Palette

        fig.canvas.draw()
        rgba = np.asarray(fig.canvas.buffer_rgba())
        flat = ["#ffffff", "#000000", TEXT_COLOR, AXIS_GRID_COLOR, *FILE_COLORS]
        required = [tuple(round(255 * v) for v in to_rgb(c)) for c in flat]
        Palette([rgba], 256, required).apply(rgba).save(path, format="PNG")
        return
    fig.savefig(path, format=fmt, metadata=_NO_METADATA[fmt], facecolor="white")


def lighten(color: str, amount: float) -> tuple[float, float, float]:
    """``color`` mixed with white (``amount`` 0: unchanged, 1: white)."""
    from matplotlib.colors import to_rgb

    r, g, b = to_rgb(color)
    return (r + (1 - r) * amount, g + (1 - g) * amount, b + (1 - b) * amount)
