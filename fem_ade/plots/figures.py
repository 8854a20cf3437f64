"""Writing a figure: atomically (an interrupted picture never replaces a whole one) and,
for what the repository keeps, in a palette of few colours. Every picture of fem_ade goes
through :func:`save_figure` — a run's (:mod:`.render`), a sweep's (:mod:`.sweep_plot`), a
branch's (:mod:`fem_ade.campaigns.branch_analysis`) and the studies'.

Why a module of its own: the studies and the campaigns save their figures with it and need
nothing else of the run's pictures.
"""

from __future__ import annotations

import os
from pathlib import Path


def save_figure(fig, path: str | Path, *, dpi=None, colours: int | None = None,
                **savefig_kw) -> Path:
    """Write a matplotlib figure to ``path`` atomically (write, then rename: an interrupted
    picture never replaces a whole one); with ``colours``, as a PNG in a palette of that many
    colours (:func:`compact_png`) — what the studies keep in the repository."""
    path = Path(path)
    tmp = path.with_name(path.stem + ".tmp.png")
    fig.savefig(tmp, dpi=dpi, **savefig_kw)
    if colours:
        compact_png(tmp, colours)
    os.replace(tmp, path)
    return path


def compact_png(path: str | Path, colours: int = 64, *, scale: float = 1.0) -> Path:
    """Rewrite a PNG in place in a palette of ``colours`` colours (and ``scale`` times its
    size): a line plot or a shaded render keeps what a reader sees at a third to a fifth of
    the bytes."""
    from PIL import Image

    path = Path(path)
    with Image.open(path) as im:
        im = im.convert("RGB")
        if scale != 1.0:
            im = im.resize((round(im.size[0] * scale), round(im.size[1] * scale)),
                           Image.Resampling.LANCZOS)
        small = im.quantize(colours)
    small.save(path, optimize=True)
    return path
