"""Figures of the reports: matplotlib without a display (the Agg canvas), written atomically, one palette."""
from __future__ import annotations

import os
from pathlib import Path


def new_figure(width: float, height: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=100)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, path: Path) -> None:
    tmp = path.with_name(path.stem + ".tmp.png")
    fig.savefig(tmp, format="png")
    os.replace(tmp, path)


def colour(index: int):
    import matplotlib

    return matplotlib.colormaps["tab10"](index % 10)
