"""Fields from files: an earlier run's φ read and checked, and resampled to new points.

What a ``file`` initial condition (:class:`fem_ade.scenes.initial.FieldIC`) and ``--phi0`` read:
φ on a uniform periodic grid (a run folder, its final.npz, or any .npz with ``phi_grid`` or
``phi``), or an axisymmetric run's φ at its (r, z) nodes with its axis (and, for a branch
switch, an azimuthal mode), and how either is evaluated at another backend's points: the
trigonometric interpolant onto a tensor grid, cubic splines elsewhere, the meridian's bicubic
spline revolved about its axis. Kept apart from the shapes (:mod:`fem_ade.scenes.initial`),
which are level functions and read no file; it needs nothing of them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fem_ade.model.params import ModelError


def check_grid_field(phi, what: str) -> np.ndarray:
    """``phi`` as a float array of shape (m,)*dim, dim 2 or 3, finite; else ModelError."""
    phi = np.asarray(phi, dtype=float)
    if phi.ndim not in (2, 3) or len(set(phi.shape)) != 1 or phi.shape[0] < 4:
        raise ModelError(f"{what} must be a field on a uniform periodic grid (m, m[, m]), "
                         f"got shape {phi.shape}")
    if not np.all(np.isfinite(phi)):
        raise ModelError(f"{what} has non-finite values")
    return phi


def load_grid_field(path: str | Path) -> np.ndarray:
    """φ on a uniform grid from a run folder, its final.npz, or any .npz (``phi_grid`` first,
    else ``phi``); ModelError if it is missing or is not a grid field."""
    path = Path(path)
    if path.is_dir():
        path = path / "final.npz"
    try:
        with np.load(path) as z:
            key = "phi_grid" if "phi_grid" in z.files else "phi"
            if key not in z.files:
                raise ModelError(f"{path} has no 'phi_grid' or 'phi'")
            phi = np.array(z[key])
    except (OSError, ValueError, EOFError) as err:
        raise ModelError(f"cannot read the initial field {path}: {err}") from None
    return check_grid_field(phi, f"the field in {path}")


#: what a field file of an axisymmetric run holds besides its grid (final.npz's keys)
MERIDIAN_KEYS = ("axis", "points", "phi")
#: an azimuthal mode added to it in 3D, ψ(r, z) cos m(θ − θ₀) (ψ at the same nodes; θ about
#: the axis, from +x; θ₀ the optional ``azimuthal_phase``, default 0): the start of a branch
#: switch (:mod:`fem_ade.campaigns.switch`)
AZIMUTHAL_KEYS = ("azimuthal_m", "azimuthal_psi")


def load_meridian_field(path: str | Path) -> dict | None:
    """{axis, points, phi} of an axisymmetric run's field file (a run folder, its final.npz,
    or an initial.npz that kept them): φ at its (r, z) nodes, a tensor grid, and the (x, y)
    of its axis; None for any other file (a 3D run's, a bare grid)."""
    path = Path(path)
    if path.is_dir():
        path = path / "final.npz"
    try:
        with np.load(path) as z:
            if not set(MERIDIAN_KEYS) <= set(z.files):
                return None
            out = {k: np.array(z[k], dtype=float) for k in MERIDIAN_KEYS}
            if set(AZIMUTHAL_KEYS) <= set(z.files):
                out.update({k: np.array(z[k], dtype=float) for k in AZIMUTHAL_KEYS})
                if "azimuthal_phase" in z.files:
                    out["azimuthal_phase"] = np.array(z["azimuthal_phase"], dtype=float)
    except (OSError, ValueError, EOFError):
        return None
    points, phi = out["points"], out["phi"]
    if out["axis"].shape != (2,) or points.ndim != 2 or points.shape[0] != 2 or \
            phi.shape != (points.shape[1],) or tensor_axes(points) is None:
        return None
    if "azimuthal_m" in out:
        m = out["azimuthal_m"]
        if m.shape != () or m != round(float(m)) or m < 1 or \
                out["azimuthal_psi"].shape != phi.shape or \
                not np.isfinite(out.get("azimuthal_phase", 0.0)).all() or \
                np.shape(out.get("azimuthal_phase", 0.0)) != ():
            raise ModelError(f"{path}: an azimuthal mode needs an integer m >= 1 and psi at "
                             "the field's nodes")
    return out


def meridian_values(m: dict, points: np.ndarray) -> np.ndarray:
    """The surface of revolution of an (r, z) field (:func:`load_meridian_field`) at 3D
    ``points`` (3, ...): the bicubic spline through its nodes (exact there: a run started
    on the same nodes starts from the same field) at r = distance from its axis; beyond its
    nodes the nearest edge's values (the far field). With an azimuthal mode, plus
    ψ(r, z) cos m(θ − θ₀) (ψ's spline; 0 beyond its nodes), clipped to [−1, 1]."""
    from scipy.interpolate import RectBivariateSpline

    r_nodes, z_nodes = tensor_axes(m["points"])
    points = np.asarray(points, dtype=float)
    if points.shape[0] != 3 and "azimuthal_m" in m:
        raise ModelError("an azimuthal mode (m >= 1) is a 3D field: start a 3D run from it")
    dx, dy = points[0] - m["axis"][0], points[1] - m["axis"][1]
    r = np.hypot(dx, dy)
    k = min(3, len(r_nodes) - 1, len(z_nodes) - 1)
    rc, zc = np.clip(r, r_nodes[0], r_nodes[-1]), np.clip(points[2], z_nodes[0], z_nodes[-1])

    def spline(values):
        table = values.reshape(len(r_nodes), len(z_nodes))
        return RectBivariateSpline(r_nodes, z_nodes, table, kx=k, ky=k, s=0).ev(rc, zc)

    values = spline(m["phi"])
    if "azimuthal_m" in m:
        inside = (r <= r_nodes[-1]) & (points[2] >= z_nodes[0]) & (points[2] <= z_nodes[-1])
        mode = np.where(inside, spline(m["azimuthal_psi"]), 0.0)
        theta = np.arctan2(dy, dx) - float(m.get("azimuthal_phase", 0.0))
        values = values + mode * np.cos(float(m["azimuthal_m"]) * theta)
    return np.clip(values, -1.0, 1.0)


def tensor_axes(points: np.ndarray):
    """The 1D coordinates whose tensor grid (C order) ``points`` (dim, N) is, or None."""
    points = np.asarray(points, dtype=float).reshape(np.shape(points)[0], -1)
    axes = [np.unique(x) for x in points]
    if int(np.prod([len(a) for a in axes])) != points.shape[1]:
        return None
    grids = np.meshgrid(*axes, indexing="ij")
    if all(np.array_equal(g.ravel(), x) for g, x in zip(grids, points, strict=True)):
        return axes
    return None


def resample_periodic(grid: np.ndarray, L: float, points: np.ndarray) -> np.ndarray:
    """Values of the periodic grid field ``grid`` (node j at jL/m) at ``points`` (dim, ...):
    its trigonometric interpolant where the points form a tensor grid (every backend's nodes
    on a tensor mesh: a smooth field moves between resolutions and between the spectral
    grid and GLL nodes to round-off, :func:`resample_fourier`), else cubic-spline
    interpolation (exact at the grid nodes)."""
    from scipy import ndimage

    axes = tensor_axes(points)
    if axes is not None:
        return resample_fourier(grid, L, axes).reshape(np.shape(points)[1:])
    m = grid.shape[0]
    coords = np.asarray(points, dtype=float).reshape(grid.ndim, -1) * (m / L)
    values = ndimage.map_coordinates(grid, coords, order=3, mode="grid-wrap")
    return values.reshape(np.shape(points)[1:])


def resample_fourier(grid: np.ndarray, L: float, axes) -> np.ndarray:
    """The trigonometric interpolant of the periodic grid field ``grid`` (node j at jL/m) on
    the tensor grid of the 1D points ``axes`` (one array per dimension; C order): exact for
    the grid's own Fourier modes, so a resolved smooth field moves between grids to round-off
    (a spectral state onto a FEM's GLL nodes, ``studies/convergence.py``). One dense 1D
    matrix per axis, applied along it."""
    grid = np.asarray(grid, dtype=float)
    out = grid.astype(complex)
    for a, x in enumerate(axes):
        m = grid.shape[a]
        k = np.fft.fftfreq(m, d=1.0 / m)
        if m % 2 == 0:
            k[m // 2] = 0.0  # the Nyquist mode as cos: drop its sine part (real interpolant)
        F = np.fft.fft(np.eye(m), axis=0) / m  # coefficients from values
        E = np.exp(2j * np.pi * np.outer(np.asarray(x, dtype=float) / L, k))
        if m % 2 == 0:
            E[:, m // 2] = np.cos(np.pi * m * np.asarray(x, dtype=float) / L)
        T = E @ F  # (len(x), m)
        out = np.moveaxis(np.tensordot(T, np.moveaxis(out, a, 0), axes=(1, 0)), 0, a)
    return out.real
