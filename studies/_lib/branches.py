"""Axisymmetric branch folders a study makes once (``python -m fem_ade.branch``) and reads."""

from __future__ import annotations

from pathlib import Path


def make_branch(out: Path, args: list[str]) -> Path | str:
    """A branch folder made once by ``python -m fem_ade.branch`` (kept: a second run reads
    it); ModelError's line where its seed is not the branch."""
    from fem_ade.campaigns.branch import main as branch_main

    if not (out / "branch.csv").is_file():
        import contextlib
        import io

        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            code = branch_main([*args, "--quiet", "--out", str(out)])
        if code != 0:
            return err.getvalue().strip().removeprefix("fem_ade.branch: error: ")
    return out


def branch_rows(folder: Path) -> list[dict]:
    """A branch folder's branch.csv as rows of strings."""
    import csv

    with open(folder / "branch.csv") as f:
        return list(csv.DictReader(f))


def e_at(pts: list[tuple[float, float]], v: float) -> float | None:
    """e of an axisymmetric branch at v, from its (v, e) points: linear between the two
    that hold v (after sorting by v), None outside them."""
    pts = sorted(pts)
    for (v0, e0), (v1, e1) in zip(pts, pts[1:], strict=False):
        if v0 <= v <= v1:
            return e0 + (e1 - e0) * (v - v0) / (v1 - v0)
    return None


def three_points(be, folder: Path, rows: list[dict], title, path: Path, colours: int,
                 scale: float) -> Path:
    """The first, middle and last point of a 3D branch folder (points/NNNN/final.npz, each
    set on ``be``) rendered one above another in one PNG at ``path``, ``title(k, row)`` over
    each, compacted to ``colours`` colours at ``scale`` (the repository's size cap)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from fem_ade.plots.figures import compact_png, save_figure
    from fem_ade.plots.shapes import render_shape

    picks = sorted({0, len(rows) // 2, len(rows) - 1})
    fig, axes = plt.subplots(len(picks), 1, figsize=(10, 5 * len(picks)))
    for ax, k in zip(np.atleast_1d(axes), picks, strict=True):
        with np.load(folder / "points" / f"{k:04d}" / "final.npz") as z:
            be._set(np.array(z["phi"]), None)
        png = folder / f"shape-{k:04d}.png"
        render_shape(be.grid_phi(), be.params.L, png, title=title(k, rows[k]))
        ax.imshow(plt.imread(png))
        ax.set_axis_off()
    fig.subplots_adjust(left=0, right=1, top=1, bottom=0, hspace=0.02)
    save_figure(fig, path)
    plt.close(fig)
    compact_png(path, colours, scale=scale)
    return path
