"""Pictures of a run folder, made without a display: the vesicle's shape and its history.

* ``shape.png`` — the shape (:mod:`.shapes`: a 3D view of the membrane {φ = 0} and the
  cross-section of φ; an axisymmetric run's surface of revolution; a 2D run's field).
* ``history.png`` — the energy E_M and its parts, and V/α, A/β, ΔA/ΔA₀ against time
  (:mod:`.history`).
* ``python -m fem_ade.render OUT [--view AZ EL] [--size W H] [--engine ...]`` re-renders a
  finished run folder (see :func:`main`).

:func:`draw_run` draws both from what a run has in memory (:mod:`fem_ade.engine.runs` calls
it as the run ends), :func:`render_run` from a run folder's files. Rendering without a
display: :mod:`.shapes`.

This module is what a run folder's pictures are — which are drawn, with which title
(:func:`run_label`) — and the command; how each is drawn is :mod:`.shapes`' and
:mod:`.history`'s, how it is written :mod:`.figures`'.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from fem_ade.analysis.shape import Surface, describe, summary_line
from fem_ade.model.params import Params
from fem_ade.plots.history import render_history
from fem_ade.plots.shapes import (
    DEFAULT_VIEW,
    ENGINES,
    render_field_2d,
    render_meridians,
    render_shape,
)
from fem_ade.store.status import Status


# --- the command line ------------------------------------------------------------------
class _BadInput(ValueError):
    """A run folder that cannot be rendered (one-line message)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit code 2
        self.exit(2, f"fem_ade.render: error: {message}\n")


def _load_run(out: Path) -> tuple[np.ndarray, float, dict]:
    if not out.is_dir():
        raise _BadInput(f"{out} is not a folder")
    for name in ("final.npz", "summary.json", "history.csv"):
        if not (out / name).is_file():
            raise _BadInput(f"{out / name} is missing")
    try:
        summary = json.loads((out / "summary.json").read_text())
        params = summary["parameters"]
        L = float(params["L"])
    except (ValueError, KeyError, TypeError) as err:
        raise _BadInput(f"{out / 'summary.json'} is not a run summary ({err})") from None
    try:
        with np.load(out / "final.npz") as data:
            key = "phi_grid" if "phi_grid" in data else "phi"
            if key not in data or "x" not in data:
                raise _BadInput(f"{out / 'final.npz'} has no 'phi' and 'x'")
            phi, x = np.asarray(data[key], float), np.asarray(data["x"], float)
    except (OSError, ValueError) as err:
        raise _BadInput(f"{out / 'final.npz'} cannot be read ({err})") from None
    n = x.shape[0] if x.ndim == 1 else -1
    if phi.ndim not in (2, 3) or phi.shape != (n,) * phi.ndim:
        raise _BadInput(f"{out / 'final.npz'}: phi of shape {phi.shape} with x of shape "
                        f"{x.shape} is not a field on a uniform grid (n, n[, n])")
    if not np.all(np.isfinite(phi)):
        raise _BadInput(f"{out / 'final.npz'}: phi has non-finite values")
    return phi, L, summary


def main(argv: list[str] | None = None) -> int:
    """``python -m fem_ade.render OUT [--view AZ EL] [--size W H] [--engine E]``.

    Reads ``OUT/final.npz`` (grid form: ``phi`` (n, n, n) and ``x`` (n,), as the spectral
    backend writes it; FEM node fields are not supported yet), ``OUT/summary.json`` and
    ``OUT/history.csv``; writes ``OUT/shape.png`` and ``OUT/history.png`` and prints the
    shape descriptors. Bad input: one line on stderr, exit code 2.
    """
    ap = _Parser(prog="python -m fem_ade.render",
                 description="Re-render a finished run folder: OUT/shape.png, OUT/history.png.")
    ap.add_argument("out", help="the run folder (with final.npz, summary.json, history.csv)")
    ap.add_argument("--view", nargs=2, type=float, metavar=("AZIMUTH", "ELEVATION"),
                    default=DEFAULT_VIEW, help="camera angles in degrees (default -60 25)")
    ap.add_argument("--size", nargs=2, type=int, metavar=("W", "H"), default=(1200, 600),
                    help="shape.png size in pixels (default 1200 600)")
    ap.add_argument("--engine", choices=ENGINES, default="auto",
                    help="3D renderer (default auto: VTK if it can render off screen here)")
    args = ap.parse_args(argv)
    if min(args.size) < 100:
        ap.error("--size must be at least 100 100")
    try:
        render_run(args.out, view=tuple(args.view), size=tuple(args.size), engine=args.engine)
    except _BadInput as err:
        print(f"fem_ade.render: error: {err}", file=sys.stderr)
        return 2
    return 0


def render_run(out: str | Path, *, view: tuple[float, float] = DEFAULT_VIEW,
               size: tuple[int, int] = (1200, 600), engine: str = "auto",
               quiet: bool = False) -> dict:
    """Re-render a run folder from its files: ``OUT/shape.png`` and ``OUT/history.png``;
    return the descriptors.

    Reads ``final.npz`` (``phi_grid`` or ``phi`` on the uniform grid ``x``), ``summary.json``
    and ``history.csv``. Raises ``_BadInput`` (a ValueError) on a folder that is not a run.
    """
    from fem_ade.store.output import read_history

    out = Path(out)
    phi, L, summary = _load_run(out)
    try:
        params = Params(**{**summary["parameters"],
                           "effects": frozenset(summary["parameters"]["effects"])})
        history = read_history(out / "history.csv")
    except (KeyError, TypeError, ValueError, IndexError) as err:
        raise _BadInput(f"{out} is not a complete run folder ({err})") from None
    final = summary.get("final") or {}
    desc = None
    if (summary.get("backend_info") or {}).get("geometry") == "axisymmetric":
        from fem_ade.analysis.axishape import describe_meridians, meridians
        from fem_ade.backends.fem.axisym import SavedField

        try:
            with np.load(out / "final.npz") as data:
                M = meridians(SavedField(data, params.eps))
        except (KeyError, ValueError, OSError) as err:
            raise _BadInput(f"{out / 'final.npz'} is not an axisymmetric run's ({err})") \
                from None
        desc = describe_meridians(M, V=final.get("V"), A=final.get("A"),
                                  dA=final.get("dA") if params.on("ade") else None, D=params.D)
        return draw_run(out, phi, params, history, desc, label=run_label(summary, 0),
                        view=view, size=size, engine=engine, quiet=quiet, surface=M,
                        physical_time=not summary.get("accelerate", False))
    if phi.ndim == 3:
        desc = describe(phi, L, V=final.get("V"), A=final.get("A"),
                        dA=final.get("dA") if params.on("ade") else None, D=params.D)
    return draw_run(out, phi, params, history, desc, label=run_label(summary, phi.shape[0]),
                    view=view, size=size, engine=engine, quiet=quiet,
                    physical_time=not summary.get("accelerate", False))


def run_label(summary: dict, n_grid: int) -> str:
    """The title of a run's pictures: scene, backend, grid, time, and a divergence if any."""
    steps, t = summary.get("steps"), summary.get("t")
    when = f"t = {t:.3g} ({steps} steps)" if isinstance(t, (int, float)) else ""
    if summary.get("accelerate"):  # momentum: t is not a physical time
        when = f"{steps} iterations (momentum)"
    status = summary.get("status")
    flag = "DIVERGED: last finite state" if status == Status.DIVERGED else (
        "interrupted" if status == Status.INTERRUPTED else "")
    info = summary.get("backend_info") or {}
    order = info.get("order")
    grid = (f"p = {order}, {n_grid} nodes per axis" if order and summary.get("backend") == "fem"
            else f"n = {n_grid}")
    if info.get("geometry") == "axisymmetric":
        nodes = info.get("nodes") or ["?", "?"]
        grid = f"axisymmetric, p = {order}, {nodes[0]} x {nodes[1]} nodes (r x z)"
    head = f"{summary.get('scene', '')} [{summary.get('backend', '')}, {grid}]"
    return " — ".join(s for s in (head, when, flag) if s)


def draw_run(out: str | Path, phi: np.ndarray, params: Params, history,
             descriptors: dict | None, *, label: str, surface: Surface | None = None,
             view: tuple[float, float] = DEFAULT_VIEW, size: tuple[int, int] = (1200, 600),
             engine: str = "auto", quiet: bool = True,
             physical_time: bool = True) -> dict | None:
    """Write ``OUT/shape.png`` and ``OUT/history.png`` from what a run has in memory: φ on the
    uniform grid, the parameters, the history columns and the descriptors (and the surface,
    if extracted already; 2D runs: the field and its zero contour). Returns the descriptors."""
    out = Path(out)
    if descriptors is not None and descriptors.get("geometry") == "axisymmetric":
        subtitle = summary_line(descriptors, given="diffuse, from the diagnostics")
        v0, m0 = params.reduced_targets()
        ade = params.on("ade")
        subtitle += (f"\ntargets α, β{', ΔA₀' if ade else ''}: v = {v0:.3f}"
                     + (f", Δa = {m0:.3f}" if ade else ""))
        render_meridians(surface, out / "shape.png", title=label, subtitle=subtitle,
                         descriptors=descriptors, view=view, size=size, engine=engine,
                         L=params.L)
        render_history(history, out / "history.png", params, title=label,
                       physical_time=physical_time)
        return descriptors
    if np.ndim(phi) == 2:
        render_field_2d(phi, params.L, out / "shape.png", title=label)
        render_history(history, out / "history.png", params, title=label,
                       physical_time=physical_time)
        return descriptors
    subtitle = summary_line(descriptors, given="diffuse, from the diagnostics")
    v0, m0 = params.reduced_targets()
    ade = params.on("ade")
    subtitle += (f"\ntargets α, β{', ΔA₀' if ade else ''}: v = {v0:.3f}"
                 + (f", Δa = {m0:.3f}" if ade else ""))
    render_shape(phi, params.L, out / "shape.png", title=label, view=view, size=size,
                 engine=engine, descriptors=descriptors, subtitle=subtitle, surface=surface)
    render_history(history, out / "history.png", params, title=label,
                   physical_time=physical_time)
    if not quiet:
        print(f"{label}: " + subtitle.replace("\n", "; "))
        print(f"wrote {out / 'shape.png'} and {out / 'history.png'}")
    return descriptors


if __name__ == "__main__":
    sys.exit(main())
