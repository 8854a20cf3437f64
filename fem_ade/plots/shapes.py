"""A run's ``shape.png``, made without a display: the vesicle's shape.

* :func:`render_shape` — a 3D view of the membrane {φ = 0} (left) and the
  cross-section of φ on the mid-plane y = L/2 with its zero contour (right).
* :func:`render_meridians` — the same of an axisymmetric run: its surface of revolution and
  φ on the (r, z) half-plane.
* :func:`render_field_2d` — a 2D run's φ over the periodic square.

Rendering without a display
---------------------------
The 3D view is drawn by VTK (through pyvista) off screen. The PyPI ``vtk`` wheels (≥ 9.4)
pick an OpenGL context at run time: X11 if there is a display, else EGL, else OSMesa. With
no display they need the system's Mesa EGL (Debian/Ubuntu: ``apt-get install libegl1
libgl1-mesa-dri``; or OSMesa: ``libosmesa6``); there is no pip-installable Mesa for them any
more (the ``vtk-osmesa`` wheels stopped at 9.3). When no context can be made VTK crashes the
process instead of raising, so ``engine="auto"`` first tries a tiny render in a subprocess
(once per process, about a second) and, if that fails, draws the 3D view with matplotlib
instead (pure pip, slower and plainer, with a one-line warning). ``FEM_ADE_RENDER_ENGINE``
(``vtk`` or ``matplotlib``) skips the probe.

Why a module of its own: the 3D views, their two engines and the camera are most of the
pictures' code and none of the run folder's (:mod:`.render`) or the history's
(:mod:`.history`).
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np

from fem_ade.analysis.shape import Surface, describe, extract_surface, summary_line
from fem_ade.plots.figures import save_figure

ENGINES = ("auto", "vtk", "matplotlib")
#: default camera: azimuth from +x towards +y, elevation above the xy-plane (degrees)
DEFAULT_VIEW = (-60.0, 25.0)
#: surface colours by component (largest first)
COLOURS = ("#e0a84a", "#5b8fc7", "#8cc084", "#c7698b", "#9a86c9", "#7fb7be")

_PROBE = """
import pyvista as pv
p = pv.Plotter(off_screen=True, window_size=(32, 32))
p.add_mesh(pv.Sphere())
img = p.screenshot(return_img=True)
print(type(p.ren_win).__name__, img.shape[0])
p.close()
"""
_vtk_probe: tuple[bool, str] | None = None


def vtk_offscreen_status(timeout: float = 120.0) -> tuple[bool, str]:
    """(works, detail): can VTK render off screen here? Probed once, in a subprocess."""
    global _vtk_probe
    if _vtk_probe is None:
        try:
            r = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                               timeout=timeout)
            words = r.stdout.split()
            ok = r.returncode == 0 and len(words) == 2
            last = re.sub(r"\x1b\[[0-9;]*m", "", r.stderr).strip().splitlines()[-1:]
            detail = words[0] if ok else (f"probe exit code {r.returncode}"
                                          + (f": {last[0][-200:]}" if last else ""))
        except (OSError, subprocess.TimeoutExpired) as err:
            ok, detail = False, str(err)
        _vtk_probe = (ok, detail)
    return _vtk_probe


def choose_engine(engine: str = "auto") -> str:
    """Resolve ``engine`` ("auto", "vtk", "matplotlib"); see the module docstring."""
    engine = os.environ.get("FEM_ADE_RENDER_ENGINE", engine) if engine == "auto" else engine
    if engine not in ENGINES:
        raise ValueError(f"unknown render engine {engine!r}; use one of {ENGINES}")
    if engine != "auto":
        return engine
    ok, detail = vtk_offscreen_status()
    if ok:
        if not os.environ.get("DISPLAY"):  # skip VTK's X11 attempt (and its warning)
            os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", detail)
        return "vtk"
    warnings.warn("VTK cannot render off screen here (no EGL/OSMesa; on Debian/Ubuntu: "
                  "apt-get install libegl1 libgl1-mesa-dri); drawing the 3D view with "
                  f"matplotlib ({detail})", RuntimeWarning, stacklevel=3)
    return "matplotlib"


# --- camera ----------------------------------------------------------------------------
def _view_vectors(view: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(towards the camera, screen right, screen up) for azimuth/elevation in degrees, z up."""
    az, el = (math.radians(v) for v in view)
    back = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    right = np.array([-math.sin(az), math.cos(az), 0.0])
    up = np.cross(back, right)
    return back, right, up


def _draw_triad(ax, view, *, at=(0.1, 0.1), size=0.07) -> None:
    """x, y, z arrows in the corner of an image axis, as the camera sees them."""
    _, right, up = _view_vectors(view)
    for k, (name, colour) in enumerate(zip("xyz", ("#c0392b", "#27ae60", "#2c5aa0"), strict=True)):
        e = np.eye(3)[k]
        d = np.array([e @ right, e @ up]) * size
        ax.annotate("", xy=(at[0] + d[0], at[1] + d[1]), xytext=at, xycoords="axes fraction",
                    arrowprops={"arrowstyle": "-|>", "color": colour, "lw": 1.6})
        if np.hypot(*d) > 0.2 * size:
            ax.text(at[0] + 1.35 * d[0], at[1] + 1.35 * d[1], name, color=colour,
                    transform=ax.transAxes, ha="center", va="center", fontsize=11)


# --- the 3D view -----------------------------------------------------------------------
def _enclosing(desc: dict | None, nc: int) -> set[int]:
    if not desc:
        return set()
    return {j for j in desc.get("inside_of", [])[:nc] if j is not None}


def _render_vtk(S: Surface, size: tuple[int, int], view, slice_y: float,
                translucent: set[int]) -> np.ndarray:
    """The surface rendered by VTK off screen: an RGB image array."""
    import pyvista as pv

    pv.OFF_SCREEN = True
    p = pv.Plotter(off_screen=True, window_size=size)
    p.set_background("white")
    for c in range(S.n_components):
        pts, faces = S.component_mesh(c)
        mesh = pv.PolyData.from_regular_faces(pts, faces)
        mesh.point_data["Normals"] = S.outward_normals_at(pts)  # smooth: from ∇φ
        mesh.point_data.active_normals_name = "Normals"
        p.add_mesh(mesh, color=COLOURS[c % len(COLOURS)], smooth_shading=True,
                   opacity=0.35 if c in translucent else 1.0, specular=0.35,
                   specular_power=25, ambient=0.12, diffuse=0.85)
        trace = mesh.slice(normal="y", origin=(0.0, slice_y, 0.0))
        if trace.n_points:  # the right panel's section, drawn on the surface: lifted off it
            # a little (flush, the surface hid it in pieces: thin broken "seams") and thick
            lift = 0.2 * float(np.min(S.h))
            trace.points = trace.points + lift * S.outward_normals_at(trace.points)
            p.add_mesh(trace, color="#202020", line_width=7)
    if S.n_components:
        pts = S.points
        centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        radius = 0.5 * float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    else:
        centre, radius = S.origin + 0.5 * S.L, 0.5 * S.L
    back, right, up = _view_vectors(view)
    p.camera.focal_point = tuple(centre)
    p.camera.position = tuple(centre + 4.0 * radius * back)
    p.camera.up = tuple(up)
    p.camera.view_angle = 30.0
    p.reset_camera()
    # reset_camera fits the bounding sphere (height ≈ 2·radius); zoom in by up to 1.3, but
    # only so far that the shape's extent across the view still fits (a chain along z
    # would lose its ends at a fixed 1.3)
    zoom = 1.3
    if S.n_components:
        tall = float(np.ptp(pts @ up))
        wide = float(np.ptp(pts @ right)) * size[1] / size[0]
        zoom = min(zoom, 0.92 * 2.0 * radius / max(tall, wide, 1e-12))
    p.camera.zoom(max(zoom, 1.0))
    try:
        p.enable_anti_aliasing("ssaa")
    except Exception:  # noqa: BLE001 (anti-aliasing is cosmetic)
        pass
    img = p.screenshot(return_img=True)
    p.close()
    return img


def _render_mpl(ax, S: Surface, view, translucent: set[int]) -> None:
    """The surface drawn with matplotlib's mplot3d (the fallback engine)."""
    import matplotlib.colors as mcolors
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    back, right, up = _view_vectors(view)
    light = back + 0.6 * up - 0.4 * right
    light /= np.linalg.norm(light)
    for c in range(S.n_components):
        pts, faces = S.component_mesh(c)
        tris = pts[faces]
        n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        shade = 0.35 + 0.65 * np.clip(n @ light, 0.0, 1.0)
        base = np.array(mcolors.to_rgb(COLOURS[c % len(COLOURS)]))
        rgba = np.column_stack([np.clip(shade[:, None] * base, 0, 1),
                                np.full(len(n), 0.35 if c in translucent else 1.0)])
        ax.add_collection3d(Poly3DCollection(tris, facecolors=rgba, edgecolors="none"))
    if S.n_components:
        lo, hi = S.points.min(axis=0), S.points.max(axis=0)
    else:
        lo, hi = S.origin, S.origin + S.L
    mid, half = 0.5 * (lo + hi), 0.55 * float(np.max(hi - lo))
    for setter, m in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid, strict=True):
        setter(m - half, m + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=view[1], azim=view[0])
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z")


def render_shape(phi: np.ndarray, L: float, path: str | Path, *, title: str | None = None,
                 view: tuple[float, float] = DEFAULT_VIEW, size: tuple[int, int] = (1200, 600),
                 engine: str = "auto", descriptors: dict | None = None,
                 slice_y: float | None = None, subtitle: str | None = None,
                 surface: Surface | None = None) -> Path:
    """Write a PNG: the 3D membrane {φ = 0} (left) and φ on a plane y = const (right).

    ``phi``: (n, n, n) periodic grid field, φ at (i, j, k)·L/n. ``view``: camera (azimuth,
    elevation) in degrees, azimuth from +x towards +y, z up. ``size``: (width, height) in
    pixels. ``descriptors``: a :func:`fem_ade.analysis.shape.describe` result to print under the
    title
    (computed here if None). ``slice_y``: the section plane (the nearest grid plane is shown;
    the 3D view marks the section as a dark line). Default: y = L/2, or, if the membrane
    does not cross it, the plane through the middle of the largest surface. ``subtitle``:
    text under the title (lines separated by newlines); default: the descriptors' summary.
    ``engine``: "auto", "vtk" or "matplotlib" (module docstring). ``surface``: the
    :func:`fem_ade.analysis.shape.extract_surface` of ``phi`` if the caller has it (it is moved to
    display coordinates here). Returns the path written.
    """

    phi = np.asarray(phi, dtype=float)
    if phi.ndim != 3 or len(set(phi.shape)) != 1:
        raise ValueError(f"phi must be an (n, n, n) grid field, got shape {phi.shape}")
    n = phi.shape[1]
    h = L / n
    S = _to_display(surface if surface is not None else extract_surface(phi, L))
    j = int(round((L / 2 if slice_y is None else slice_y) / h)) % n
    if slice_y is None and S.n_components and not _crosses(phi[:, j, :]):
        # y = L/2 misses the membrane: cut through the middle of the largest component
        pts, _ = S.component_mesh(0)
        j = int(round(0.5 * (pts[:, 1].min() + pts[:, 1].max()) / h)) % n
    y_shown = j * h
    if descriptors is None:
        descriptors = describe(phi, L, surface=S)
    translucent = _enclosing(descriptors, S.n_components)
    engine = choose_engine(engine)

    lines = ([title] if title else []) + (
        subtitle.splitlines() if subtitle is not None
        else [summary_line(descriptors)] if descriptors else [])
    dpi = 100
    fig, gs, line_h, top = _two_panels(size, len(lines), dpi)
    # left: 3D view
    ax3 = _surface_panel(fig, gs[0], S, view, engine, size, top,
                         _unwrap_y(S, y_shown) if S.n_components else 0.0, translucent)
    traced = engine == "vtk" and S.n_components
    ax3.set_title(f"membrane φ = 0 (view az {view[0]:g}°, el {view[1]:g}°"
                  + (f"; black: the section y = {y_shown:.3g})" if traced else ")"), fontsize=11)

    # right: section y = const, periodic images closed
    ax = fig.add_subplot(gs[1])
    sec = np.pad(phi[:, j, :], ((0, 1), (0, 1)), mode="wrap")
    xs = np.linspace(0.0, L, n + 1)
    vmax = max(1.0, float(np.max(np.abs(sec))))
    pcm = ax.pcolormesh(xs, xs, sec.T, shading="gouraud", cmap="RdBu_r", vmin=-vmax, vmax=vmax,
                        rasterized=True)
    if _crosses(sec):
        ax.contour(xs, xs, sec.T, levels=[0.0], colors="k", linewidths=1.6)
    ax.set_aspect("equal")
    ax.set_xlim(0, L)
    ax.set_ylim(0, L)
    ax.set_xlabel("x")
    ax.set_ylabel("z")
    ax.set_title(f"φ on the plane y = {y_shown:.4g} (black: φ = 0)", fontsize=12)
    cb = fig.colorbar(pcm, ax=ax, fraction=0.046, pad=0.03)
    cb.set_label("φ  (+1 inside, −1 outside)")

    return _titled(fig, lines, line_h, bool(title), path, dpi)


def render_meridians(M, path: str | Path, *, title: str = "", subtitle: str = "",
                     descriptors: dict | None = None, view=DEFAULT_VIEW,
                     size: tuple[int, int] = (1200, 600), engine: str = "auto",
                     L: float = 1.0, axis=(0.0, 0.0)) -> Path:
    """An axisymmetric run's picture (``M``: :class:`fem_ade.analysis.axishape.Meridians`): the
    surface of revolution of its φ = 0 meridians (left; black: the meridional section) and
    φ on the meridional plane, mirrored to −r (right; black: φ = 0, dashed: the graded
    mesh's fine zone)."""

    from fem_ade.analysis.axishape import RevolvedSurface

    S = RevolvedSurface(M, axis=(0.0, 0.0), L=L)
    translucent = _enclosing(descriptors, S.n_components)
    engine = choose_engine(engine)
    lines = ([title] if title else []) + (subtitle.splitlines() if subtitle else [])
    dpi = 100
    fig, gs, line_h, top = _two_panels(size, len(lines), dpi)
    ax3 = _surface_panel(fig, gs[0], S, view, engine, size, top, 0.0, translucent)
    ax3.set_title(f"membrane φ = 0, revolved (view az {view[0]:g}°, el {view[1]:g}°"
                  + ("; black: the meridian)" if engine == "vtk" and S.n_components else ")"),
                  fontsize=11)

    ax = fig.add_subplot(gs[1])
    R, z0, z1 = M.domain
    xlim, ylim = (-R, R), (z0, z1)
    if M.curves:  # the membrane with a margin, in the domain
        P = np.vstack(M.curves)
        half = 1.25 * max(P[:, 0].max(), 0.5 * np.ptp(P[:, 1]), 1e-9)
        mid = 0.5 * (P[:, 1].min() + P[:, 1].max())
        xlim = (-min(half, R), min(half, R))
        ylim = (max(z0, mid - half), min(z1, mid + half))
    # φ on a uniform display grid of the window (linear in the fine contour grid's cells):
    # a picture needs no more pixels than it shows
    from scipy.interpolate import RegularGridInterpolator

    nx = 480
    ny = max(2, int(round(nx * (ylim[1] - ylim[0]) / (xlim[1] - xlim[0]))))
    gx, gy = np.linspace(*xlim, nx), np.linspace(*ylim, ny)
    X, Y = np.meshgrid(np.minimum(np.abs(gx), M.r[-1]), gy, indexing="xy")
    sec = RegularGridInterpolator((M.r, M.z), M.phi)(np.stack([X, Y], axis=-1))
    vmax = max(1.0, float(np.max(np.abs(M.phi))))
    pcm = ax.imshow(sec, origin="lower", extent=(*xlim, *ylim), cmap="RdBu_r", vmin=-vmax,
                    vmax=vmax, interpolation="bilinear", aspect="equal")
    for pts in M.curves:
        for sign in (1.0, -1.0):
            ax.plot(sign * pts[:, 0], pts[:, 1], color="k", lw=1.6)
    if M.fine is not None:
        (ra, rb), (za, zb) = M.fine
        for sign in (1.0, -1.0):
            ax.plot(sign * np.array([ra, rb, rb, ra]), [za, za, zb, zb], color="#555555",
                    lw=0.9, ls="--")
    ax.axvline(0.0, color="#444444", lw=0.8, ls="-.")
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    ax.set_xlabel("r (mirrored: −r on the left)")
    ax.set_ylabel("z")
    ax.set_title("φ on the meridional plane (black: φ = 0; dashed: fine zone)", fontsize=12)
    cb = fig.colorbar(pcm, ax=ax, fraction=0.046, pad=0.03)
    cb.set_label("φ  (+1 inside, −1 outside)")
    return _titled(fig, lines, line_h, bool(title), path, dpi)


def _two_panels(size, n_lines: int, dpi: int):
    """(figure, grid of two panels, the height of a text line, the panels' top) of a
    picture of ``size`` pixels with ``n_lines`` lines of text above (no pyplot: no global
    state)."""
    from matplotlib.figure import Figure

    W, H = size
    fig = Figure(figsize=(W / dpi, H / dpi), dpi=dpi)
    line_h = 26.0 / H  # figure fraction per text line
    top = 0.97 - line_h * n_lines - 30.0 / H
    gs = fig.add_gridspec(1, 2, width_ratios=(1.0, 0.95), left=0.01, right=0.93, bottom=0.09,
                          top=top, wspace=0.08)
    return fig, gs, line_h, top


def _surface_panel(fig, cell, S, view, engine: str, size, top: float, slice_y: float,
                   translucent: set[int]):
    """The left panel: the surface S (a :class:`fem_ade.analysis.shape.Surface`, or a revolved one)
    rendered by VTK (the section at y = ``slice_y`` traced on it) or by matplotlib."""
    W, H = size
    if engine == "vtk":
        ax3 = fig.add_subplot(cell)
        px = (max(int(W * 0.5 * 2), 64), max(int(H * (top - 0.09) * 2), 64))
        if S.n_components:
            ax3.imshow(_render_vtk(S, px, view, slice_y, translucent),
                       interpolation="antialiased")
        ax3.set_axis_off()
        _draw_triad(ax3, view)
    else:
        ax3 = fig.add_subplot(cell, projection="3d")
        _render_mpl(ax3, S, view, translucent)
    if not S.n_components:
        ax3.text(0.5, 0.5, "no φ = 0 surface", transform=ax3.transAxes, ha="center")
    return ax3


def _titled(fig, lines, line_h, titled: bool, path, dpi) -> Path:
    """The lines above a picture (the first bold when it is the title), then save it."""
    for k, line in enumerate(lines):
        first = k == 0 and titled
        fig.text(0.5, 0.985 - k * line_h, line, ha="center", va="top",
                 fontsize=14 if first else 11, fontweight="bold" if first else "normal",
                 color="black" if first else "#333333")
    path = Path(path)
    _save(fig, path, dpi)
    return path


def _save(fig, path, dpi) -> Path:
    """Write the figure to ``path`` atomically (write, then rename): an interrupted picture
    never replaces a whole one."""
    return save_figure(fig, path, dpi=dpi)


def render_field_2d(phi: np.ndarray, L: float, path: str | Path, *, title: str = "",
                    subtitle: str = "") -> Path:
    """shape.png of a 2D run: φ over the periodic square with its zero contour."""
    from matplotlib.figure import Figure

    phi = np.asarray(phi, dtype=float)
    n = phi.shape[0]
    fig = Figure(figsize=(7.0, 6.6), dpi=100)
    ax = fig.subplots()
    grid = np.pad(phi, ((0, 1), (0, 1)), mode="wrap")
    xs = np.linspace(0.0, L, n + 1)
    vmax = max(1.0, float(np.max(np.abs(grid))))
    pcm = ax.pcolormesh(xs, xs, grid.T, shading="gouraud", cmap="RdBu_r", vmin=-vmax,
                        vmax=vmax, rasterized=True)
    if _crosses(grid):
        ax.contour(xs, xs, grid.T, levels=[0.0], colors="k", linewidths=1.6)
    ax.set_aspect("equal")
    ax.set(xlabel="x", ylabel="y", title=subtitle or "φ (black: φ = 0)")
    fig.colorbar(pcm, ax=ax, fraction=0.046, pad=0.03).set_label("φ (+1 inside, −1 outside)")
    if title:
        fig.suptitle(title, fontsize=12, fontweight="bold")
    return _save(fig, path, 100)


def _crosses(a: np.ndarray) -> bool:
    return bool(a.min() < 0 < a.max())


def _to_display(S: Surface) -> Surface:
    """Translate the (unwrapped) surface by whole periods so that the middle of its bounding
    box lies in [0, L)³: axis labels then read as box coordinates. In place; returns S."""
    if S.n_components:
        centre = 0.5 * (S.points.min(axis=0) + S.points.max(axis=0))
        offset = -S.L * np.floor(centre / S.L)
        S.points = S.points + offset
        S.origin = S.origin + offset  # φ lookups (periodic) follow the points
    return S


def _unwrap_y(S: Surface, y: float) -> float:
    """The periodic image of the plane y nearest to the middle of the surface."""
    c = 0.5 * float(S.points[:, 1].min() + S.points[:, 1].max())
    return y + S.L * round((c - y) / S.L)
