"""Writing the report's matplotlib figures as PNG files: drawn once, no alpha, no metadata."""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

__all__ = ["save_figure"]


def save_figure(fig: Figure, path) -> None:
    """Write ``fig`` as an RGB PNG at its own size and dpi.

    ``Figure.savefig`` draws a figure with a layout engine twice — once to lay it out, once to paint
    it — and a strip of fifteen images pays for its resampling twice; drawing on an Agg canvas lays
    out and paints in one pass, to the same pixels. The figures are opaque, so the alpha channel is
    dropped (a tenth smaller file), and the PNG holds no software version: the same figure gives the
    same bytes.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        An opaque figure (white face colour).
    path : str or Path
        The ``.png`` to write.
    """
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3]).save(path, format="PNG")
