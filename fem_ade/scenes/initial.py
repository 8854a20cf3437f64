"""Initial conditions: diffuse level sets of simple shapes, and fields of earlier runs.

A shape is a level function s(x), positive inside, and the initial field is
φ₀ = tanh(s / (√2 ε)). For the distance-like kinds (everything but the paper's ellipsoid)
s is the signed distance to the surface, or close to it, so φ₀ has the 1D equilibrium
profile across the membrane. Displacements use the periodic minimum image, so a centre
anywhere in the box works. One small class per kind, each with the fields a scene file
gives under ``[ic]`` (``kind = "..."``), validated by
:func:`fem_ade.scenes.catalogue.ic_from_mapping`:

===========  ==================================================================================
kind         fields
===========  ==================================================================================
ellipsoid    centre, axes, c (or c_consistent, c_printed): s = c − Σ(xᵢ − centreᵢ)²/axesᵢ
             (the paper's, model §7; not a distance)
sphere       centre, radius
torus        centre, axis (default z), R (major), r (minor): a ring of tube radius r
spheres      centres, radii, signs (default all +1), neck (default 0): spheres joined in order;
             sign −1 carves a sphere out (a nested vesicle: +1 outer, −1 inner); neck > 0
             joins consecutive +1 spheres by tubes of radius neck × the smaller radius
capsule      centre, axis, length, radius: a tube of this length with round ends
starfish     centre, arms, length, radius, core, plane (default true), axis (default z):
             ``arms`` capsules of ``radius`` from the centre out to ``length``, in the plane
             normal to ``axis`` (or spread over the sphere), around a ball of radius ``core``
discocyte    centre, axis (default z), diameter, c0, c2, c4: the Evans–Fung red-cell profile
             z(ρ) = ±½ d √(1 − ξ²)(c0 + c2 ξ² + c4 ξ⁴), ξ = 2ρ/d (defaults: the human
             red cell, c0 = 0.0518, c2 = 2.0026, c4 = −4.491, in units of d)
meridian     centre, axis (default z), r, z, scale: the surface of revolution of a meridian
             (r, z) × scale, pole to pole or a closed loop (a torus); ``python -m sharp_ref
             BRANCH --v V --json`` prints one (R₀ = 1: scale is R₀ in the box)
file         path: φ of an earlier run (its folder, final.npz, or an .npz with ``phi_grid`` or
             ``phi`` on a uniform grid), resampled by periodic cubic splines; an axisymmetric
             run's field is its (r, z) nodes' values revolved about its axis (plus
             ψ(r, z) cos mθ where the file holds an azimuthal mode: a branch switch's start)
===========  ==================================================================================

Joining shapes takes the maximum of their level functions (their union) and carving one out
the minimum with its negative; the corners this leaves are smoothed by the tanh profile and,
after a few steps, by the flow.

This module holds the shapes only: reading and resampling a ``file``'s field is
:mod:`fem_ade.scenes.fields`, parsing an ``[ic]`` table the catalogue's, beside the rest of a
scene file.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, fields
from typing import ClassVar

import numpy as np

from fem_ade.model.params import ModelError
from fem_ade.scenes.fields import (
    load_grid_field,
    load_meridian_field,
    meridian_values,
    resample_periodic,
)


# ---------------------------------------------------------------------------------------------
# geometry helpers (periodic minimum image)
# ---------------------------------------------------------------------------------------------
def _offsets(points: np.ndarray, centre, L: float) -> np.ndarray:
    """Offsets of ``points`` from ``centre``: the periodic minimum image in a box of side L,
    the plain difference for L = ∞ (a domain that is not periodic: the axisymmetric one)."""
    c = np.asarray(centre, dtype=float).reshape((-1,) + (1,) * (points.ndim - 1))
    d = points - c
    if math.isfinite(L):
        d -= L * np.round(d / L)
    return d


def _unit(v, dim: int) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _along(d: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The component of the offsets d (dim, ...) along the unit vector ``axis``."""
    return np.tensordot(axis, d, axes=1)


def _about_axis(points: np.ndarray, centre, axis, L: float) -> tuple[np.ndarray, np.ndarray]:
    """(ρ, h): the distance of each point from the line through ``centre`` along ``axis``
    and its height along it (3D, periodic minimum image)."""
    d = _offsets(points, centre, L)
    h = _along(d, _unit(axis, 3))
    return np.sqrt(np.maximum(np.sum(d * d, axis=0) - h * h, 0.0)), h


def _segment_distance(d: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from the points at offsets d (dim, ...) to the segment from a to b."""
    ab = b - a
    shape = (-1,) + (1,) * (d.ndim - 1)
    rel = d - a.reshape(shape)
    t = np.clip(np.tensordot(ab, rel, axes=1) / float(ab @ ab), 0.0, 1.0)
    return np.sqrt(np.sum((rel - t * ab.reshape(shape)) ** 2, axis=0))


def _directions(k: int, dim: int, plane: bool, axis: np.ndarray) -> list[np.ndarray]:
    """k unit vectors: evenly spaced in the plane normal to ``axis`` (2D: the plane), or
    spread over the sphere (6: ±x, ±y, ±z; 4: a tetrahedron; else a Fibonacci lattice)."""
    if dim == 2 or plane:
        if dim == 2:
            e1, e2 = np.array([1.0, 0.0]), np.array([0.0, 1.0])
        else:
            helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
            e1 = np.cross(axis, helper)
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(axis, e1)
        return [math.cos(2 * math.pi * i / k) * e1 + math.sin(2 * math.pi * i / k) * e2
                for i in range(k)]
    if k == 6:
        return [s * e for e in np.eye(3) for s in (1.0, -1.0)]
    if k == 4:
        t = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float) / math.sqrt(3)
        return list(t)
    golden = math.pi * (3.0 - math.sqrt(5.0))
    out = []
    for i in range(k):
        z = 1.0 - 2.0 * (i + 0.5) / k
        rho = math.sqrt(1.0 - z * z)
        out.append(np.array([rho * math.cos(golden * i), rho * math.sin(golden * i), z]))
    return out


def _vertical(centre, axis=(0.0, 0.0, 1.0)) -> tuple[float, float] | None:
    """(x, y) of ``centre`` when it is 3D and ``axis`` is parallel to z, else None."""
    if len(centre) != 3 or len(axis) != 3:
        return None
    a = np.asarray(axis, dtype=float)
    if not (abs(a[0]) <= 1e-12 * abs(a[2]) and abs(a[1]) <= 1e-12 * abs(a[2])):
        return None
    return float(centre[0]), float(centre[1])



# ---------------------------------------------------------------------------------------------
# the kinds
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Shape:
    """Base of the level-set kinds: ``level(points, L, variant) -> (s, scale)``, s > 0 inside
    and ``scale`` the typical size of s (the unit of ``--perturb``)."""

    kind: ClassVar[str] = ""
    #: field name -> "vec" | "vecs" | "float+" (positive) | "floats+" | "floats" | "int+" | "bool" |
    #: "signs" | "float" | "str"
    spec: ClassVar[dict] = {}
    #: fields that may be left out (with their defaults)
    optional: ClassVar[tuple[str, ...]] = ()

    is_field: ClassVar[bool] = False

    def level(self, points: np.ndarray, L: float, variant: str = "consistent"):
        raise NotImplementedError

    def volume_estimate(self, variant: str = "consistent") -> float:
        """Sharp volume enclosed by s = 0 where it has a closed form, else NaN."""
        return math.nan

    def axis_of_revolution(self) -> tuple[float, float] | None:
        """(x, y) of the vertical line (parallel to z) this 3D shape is a surface of revolution
        about, or None (the axisymmetric geometry runs only such shapes)."""
        return None

    def check(self, dim: int, skip: tuple[str, ...] = ()) -> None:
        """ModelError if a field does not fit a ``dim``-dimensional scene."""
        for name, kind in self.spec.items():
            if name in skip:
                continue
            value = getattr(self, name)
            if kind in ("vec", "vecs"):
                vecs = [value] if kind == "vec" else list(value)
                for v in vecs:
                    if len(v) != dim:
                        raise ModelError(f"ic.{name} needs {dim} values for a {dim}D scene, "
                                         f"got {list(v)}")
                    if not all(math.isfinite(x) for x in v):
                        raise ModelError(f"ic.{name} must be finite, got {list(v)}")
                if name == "axis" and not any(v != 0 for v in value):
                    raise ModelError("ic.axis must be a non-zero vector")
            elif kind == "float+" and not (math.isfinite(value) and value > 0):
                raise ModelError(f"ic.{name} must be a positive number, got {value}")
            elif kind == "floats+" and not all(math.isfinite(v) and v > 0 for v in value):
                raise ModelError(f"ic.{name} must be positive numbers, got {list(value)}")
            elif kind == "floats" and not all(math.isfinite(v) for v in value):
                raise ModelError(f"ic.{name} must be finite numbers, got {list(value)}")
            elif kind == "int+" and not value >= 1:
                raise ModelError(f"ic.{name} must be a positive integer, got {value}")
            elif kind == "float" and not math.isfinite(value):
                raise ModelError(f"ic.{name} must be a finite number, got {value}")

    def to_mapping(self) -> dict:
        out = {"kind": self.kind}
        for f in fields(self):
            v = getattr(self, f.name)
            out[f.name] = ([list(x) for x in v] if f.name in ("centres",) else
                           list(v) if isinstance(v, tuple) else v)
        return out


@dataclass(frozen=True)
class Ellipsoid(Shape):
    """The paper's initial conditions: s = c − q(x), q = Σ(xᵢ − centreᵢ)²/axesᵢ (model §7)."""

    kind: ClassVar[str] = "ellipsoid"
    spec: ClassVar[dict] = {"centre": "vec", "axes": "vec", "c_consistent": "float+",
                            "c_printed": "float+"}
    centre: tuple[float, ...]
    axes: tuple[float, ...]
    c_consistent: float
    c_printed: float

    def check(self, dim: int) -> None:
        super().check(dim)
        if not all(a > 0 for a in self.axes):
            raise ModelError(f"ic.axes must be positive, got {list(self.axes)}")

    def level(self, points, L, variant="consistent"):
        d = _offsets(points, self.centre, L)
        axes = np.asarray(self.axes, dtype=float).reshape((-1,) + (1,) * (points.ndim - 1))
        q = np.sum(d * d / axes, axis=0)
        c = self.c_printed if variant == "printed" else self.c_consistent
        return c - q, c

    def volume_estimate(self, variant="consistent"):
        c = self.c_printed if variant == "printed" else self.c_consistent
        return 4.0 / 3.0 * math.pi * math.prod(math.sqrt(c * a) for a in self.axes)


    def axis_of_revolution(self):
        if len(self.axes) != 3 or not math.isclose(self.axes[0], self.axes[1], rel_tol=1e-12):
            return None
        return _vertical(self.centre)

@dataclass(frozen=True)
class Sphere(Shape):
    """s = R − |x − centre|."""

    kind: ClassVar[str] = "sphere"
    spec: ClassVar[dict] = {"centre": "vec", "radius": "float+"}
    centre: tuple[float, ...]
    radius: float

    def level(self, points, L, variant="consistent"):
        d = _offsets(points, self.centre, L)
        return self.radius - np.sqrt(np.sum(d * d, axis=0)), self.radius

    def volume_estimate(self, variant="consistent"):
        return 4.0 / 3.0 * math.pi * self.radius**3


    def axis_of_revolution(self):
        return _vertical(self.centre)

@dataclass(frozen=True)
class Torus(Shape):
    """s = r − dist(x, the circle of radius R about ``axis`` through ``centre``) (3D)."""

    kind: ClassVar[str] = "torus"
    spec: ClassVar[dict] = {"centre": "vec", "axis": "vec", "R": "float+", "r": "float+"}
    optional: ClassVar[tuple[str, ...]] = ("axis",)
    centre: tuple[float, ...]
    R: float
    r: float
    axis: tuple[float, ...] = (0.0, 0.0, 1.0)

    def check(self, dim):
        if dim != 3:
            raise ModelError("ic kind 'torus' needs a 3D scene")
        super().check(dim)
        if self.r >= self.R:
            raise ModelError(f"ic torus needs r < R (a hole), got R = {self.R}, r = {self.r}")

    def level(self, points, L, variant="consistent"):
        rho, h = _about_axis(points, self.centre, self.axis, L)
        return self.r - np.sqrt((rho - self.R) ** 2 + h * h), self.r

    def volume_estimate(self, variant="consistent"):
        return 2.0 * math.pi**2 * self.R * self.r**2


    def axis_of_revolution(self):
        return _vertical(self.centre, self.axis)

@dataclass(frozen=True)
class Spheres(Shape):
    """Spheres joined in order: s ← max(s, dᵢ) for sign +1, min(s, −dᵢ) for sign −1,
    dᵢ = Rᵢ − |x − cᵢ|. Overlapping spheres make connected beads (a neck where they meet);
    +1, −1 nested spheres a shell, +1, −1, +1 a vesicle inside a vesicle."""

    kind: ClassVar[str] = "spheres"
    spec: ClassVar[dict] = {"centres": "vecs", "radii": "floats+", "signs": "signs",
                            "neck": "float"}
    optional: ClassVar[tuple[str, ...]] = ("signs", "neck")
    centres: tuple[tuple[float, ...], ...]
    radii: tuple[float, ...]
    signs: tuple[int, ...] = ()
    neck: float = 0.0

    def check(self, dim):
        super().check(dim)
        if not self.centres or len(self.centres) != len(self.radii):
            raise ModelError("ic.centres and ic.radii need the same, non-zero number of entries")
        if self.signs and (len(self.signs) != len(self.radii)
                           or any(s not in (1, -1) for s in self.signs)):
            raise ModelError("ic.signs needs one +1 or -1 per sphere")

    def level(self, points, L, variant="consistent"):
        s = None
        signs = self.signs or (1,) * len(self.radii)
        for c, R, sign in zip(self.centres, self.radii, signs, strict=True):
            d = _offsets(points, c, L)
            di = R - np.sqrt(np.sum(d * d, axis=0))
            if s is None:
                s = di if sign > 0 else -di
            else:
                s = np.maximum(s, di) if sign > 0 else np.minimum(s, -di)
        if self.neck > 0:  # tubes between consecutive spheres of sign +1
            beads = [(np.asarray(c, float), R) for c, R, sign in
                     zip(self.centres, self.radii, signs, strict=True) if sign > 0]
            for (c0, r0), (c1, r1) in zip(beads, beads[1:], strict=False):
                d = _offsets(points, c0, L)
                tube = self.neck * min(r0, r1) - _segment_distance(d, 0 * c0, c1 - c0)
                s = np.maximum(s, tube)
        return s, max(self.radii)


    def axis_of_revolution(self):
        first = _vertical(self.centres[0])
        if first is None or any(not (math.isclose(c[0], first[0], abs_tol=1e-12) and
                                     math.isclose(c[1], first[1], abs_tol=1e-12))
                                for c in self.centres):
            return None
        return first

@dataclass(frozen=True)
class Capsule(Shape):
    """s = radius − dist(x, the segment of ``length`` along ``axis`` centred at ``centre``)."""

    kind: ClassVar[str] = "capsule"
    spec: ClassVar[dict] = {"centre": "vec", "axis": "vec", "length": "float+",
                            "radius": "float+"}
    centre: tuple[float, ...]
    axis: tuple[float, ...]
    length: float
    radius: float

    def level(self, points, L, variant="consistent"):
        d = _offsets(points, self.centre, L)
        a = 0.5 * self.length * _unit(self.axis, len(self.centre))
        return self.radius - _segment_distance(d, -a, a), self.radius

    def volume_estimate(self, variant="consistent"):
        r = self.radius
        return math.pi * r * r * self.length + 4.0 / 3.0 * math.pi * r**3


    def axis_of_revolution(self):
        return _vertical(self.centre, self.axis)

@dataclass(frozen=True)
class Starfish(Shape):
    """A ball of radius ``core`` with ``arms`` capsules of ``radius`` from the centre out to
    distance ``length`` (in the plane normal to ``axis``, or spread over the sphere)."""

    kind: ClassVar[str] = "starfish"
    spec: ClassVar[dict] = {"centre": "vec", "arms": "int+", "length": "float+",
                            "radius": "float+", "core": "float+", "plane": "bool",
                            "axis": "vec"}
    optional: ClassVar[tuple[str, ...]] = ("plane", "axis")
    centre: tuple[float, ...]
    arms: int
    length: float
    radius: float
    core: float
    plane: bool = True
    axis: tuple[float, ...] = (0.0, 0.0, 1.0)

    def check(self, dim):
        super().check(dim, skip=("axis",) if dim == 2 else ())  # 2D: the plane is the box

    def level(self, points, L, variant="consistent"):
        dim = len(self.centre)
        d = _offsets(points, self.centre, L)
        s = self.core - np.sqrt(np.sum(d * d, axis=0))
        axis = _unit(self.axis, dim) if dim == 3 else None
        zero = np.zeros(dim)
        for e in _directions(self.arms, dim, self.plane, axis):
            s = np.maximum(s, self.radius - _segment_distance(d, zero, self.length * e))
        return s, self.core


@dataclass(frozen=True)
class Discocyte(Shape):
    """The Evans–Fung red blood cell: z along ``axis``, ρ the distance from it, the surface
    |z| = h(ρ) = ½ d √(1 − ξ²)(c0 + c2 ξ² + c4 ξ⁴), ξ = 2ρ/d ≤ 1; s is the signed distance
    to it (so the tanh profile has its equilibrium width everywhere, the rim included)."""

    kind: ClassVar[str] = "discocyte"
    spec: ClassVar[dict] = {"centre": "vec", "axis": "vec", "diameter": "float+",
                            "c0": "float", "c2": "float", "c4": "float"}
    optional: ClassVar[tuple[str, ...]] = ("axis", "c0", "c2", "c4")
    centre: tuple[float, ...]
    diameter: float
    axis: tuple[float, ...] = (0.0, 0.0, 1.0)
    c0: float = 0.0518
    c2: float = 2.0026
    c4: float = -4.491

    def check(self, dim):
        if dim != 3:
            raise ModelError("ic kind 'discocyte' needs a 3D scene")
        super().check(dim)
        xi = np.linspace(0.0, 1.0, 201)[:-1]
        if np.any(self.c0 + self.c2 * xi**2 + self.c4 * xi**4 <= 0):
            raise ModelError("ic discocyte: c0 + c2 ξ² + c4 ξ⁴ must stay positive on [0, 1)")

    def profile(self, xi):
        """h(ξ) = ½ d √(1 − ξ²)(c0 + c2 ξ² + c4 ξ⁴): the half-thickness at ρ = ξ d/2."""
        x2 = xi * xi
        return 0.5 * self.diameter * np.sqrt(np.maximum(1.0 - x2, 0.0)) * (
            self.c0 + self.c2 * x2 + self.c4 * x2 * x2)

    def level(self, points, L, variant="consistent"):
        from scipy.spatial import cKDTree

        rho, z = _about_axis(points, self.centre, self.axis, L)
        z = np.abs(z)
        half = 0.5 * self.diameter
        # the signed distance to the profile curve in the (ρ, |z|) half-plane, the curve
        # sampled densely (ξ = sin θ crowds the samples at the rim)
        xi = np.sin(np.linspace(0.0, 0.5 * np.pi, 4001))
        curve = np.column_stack([half * xi, self.profile(xi)])
        dist, _ = cKDTree(curve).query(np.column_stack([rho.ravel(), z.ravel()]))
        inside = (rho < half) & (z < self.profile(np.minimum(rho / half, 1.0)))
        return np.where(inside, 1.0, -1.0) * dist.reshape(rho.shape), half


    def axis_of_revolution(self):
        return _vertical(self.centre, self.axis)

@dataclass(frozen=True)
class Meridian(Shape):
    """A surface of revolution about ``axis`` through ``centre``, given by its meridian: the
    points (r, z) in a half plane (r ≥ 0 the distance from the axis, z along it), in units
    of ``scale``: ``python -m sharp_ref ... --json`` prints them for R₀ = 1, so ``scale`` is
    the vesicle's R₀ = √(A/4π) in the box. A spheroidal meridian runs from one pole (r = 0)
    to the other; one that starts off the axis is a closed loop (a torus's tube). s is the
    signed distance to the surface (positive inside)."""

    kind: ClassVar[str] = "meridian"
    spec: ClassVar[dict] = {"centre": "vec", "axis": "vec", "r": "floats", "z": "floats",
                            "scale": "float+"}
    optional: ClassVar[tuple[str, ...]] = ("axis",)
    centre: tuple[float, ...]
    r: tuple[float, ...]
    z: tuple[float, ...]
    scale: float
    axis: tuple[float, ...] = (0.0, 0.0, 1.0)

    def check(self, dim):
        if dim != 3:
            raise ModelError("ic kind 'meridian' needs a 3D scene")
        super().check(dim)
        if len(self.r) != len(self.z) or len(self.r) < 4:
            raise ModelError(f"ic.r and ic.z need the same number (≥ 4) of points, got "
                             f"{len(self.r)} and {len(self.z)}")
        if min(self.r) < 0:
            raise ModelError(f"ic.r must be ≥ 0 (distances from the axis), got {min(self.r)}")
        if self.spheroidal and not (self.r[0] < 1e-9 and self.r[-1] < 1e-9):
            raise ModelError("a meridian that starts on the axis must end on it")

    @property
    def spheroidal(self) -> bool:
        return self.r[0] < 1e-9

    def _polygon(self) -> np.ndarray:
        """The closed polygon (r, z) the meridian bounds with the axis, in box units."""
        p = self.scale * np.stack([self.r, self.z], axis=1)
        if self.spheroidal:  # the poles on the axis exactly (the axis is an edge)
            p[0, 0] = p[-1, 0] = 0.0
        return np.vstack([p, p[:1]])

    def level(self, points, L, variant="consistent"):
        rho, h = _about_axis(points, self.centre, self.axis, L)
        poly = self._polygon()
        last = len(poly) - 2 if self.spheroidal else len(poly) - 1  # the axis is no surface
        dist = np.full(rho.shape, np.inf)
        inside = np.zeros(rho.shape, dtype=bool)
        for (r1, z1), (r2, z2), k in zip(poly[:-1], poly[1:], range(len(poly) - 1),
                                         strict=True):
            if k < last:
                dr, dz = r2 - r1, z2 - z1
                t = np.clip(((rho - r1) * dr + (h - z1) * dz) / max(dr * dr + dz * dz, 1e-300),
                            0.0, 1.0)
                dist = np.minimum(dist, np.hypot(rho - r1 - t * dr, h - z1 - t * dz))
            crosses = (z1 > h) != (z2 > h)  # even-odd rule along a ray of growing r
            with np.errstate(divide="ignore", invalid="ignore"):
                at = r1 + (h - z1) * (r2 - r1) / (z2 - z1)
            inside ^= crosses & (rho < at)
        return np.where(inside, dist, -dist), self.scale

    def volume_estimate(self, variant="consistent"):
        p = self._polygon()
        (r1, z1), (r2, z2) = p[:-1].T, p[1:].T
        return abs(float(np.sum(math.pi / 3.0 * (z2 - z1) * (r1 * r1 + r1 * r2 + r2 * r2))))


    def axis_of_revolution(self):
        return _vertical(self.centre, self.axis)

@dataclass(frozen=True)
class FieldIC(Shape):
    """φ of an earlier run (``path``) or an array (``grid``), resampled to the new points.
    The field of an axisymmetric run (its (r, z) nodes and axis, :func:`load_meridian_field`)
    is a surface of revolution about that axis: it is evaluated from its nodes, in either
    geometry.

    ``base``: the folder a relative ``path`` is read from (not part of the scene: a run
    records its own start as ``initial.npz``, relative to its folder, so the folder can be
    moved; :func:`fem_ade.engine.runs.read_run` gives the folder)."""

    kind: ClassVar[str] = "file"
    spec: ClassVar[dict] = {"path": "str"}
    is_field: ClassVar[bool] = True
    path: str = ""
    grid: np.ndarray | None = field(default=None, compare=False, repr=False)
    base: str = field(default="", compare=False, repr=False)

    @property
    def file(self) -> str:
        """The path to read: ``path``, under ``base`` if it is relative and a base is set."""
        if self.base and not os.path.isabs(self.path):
            return os.path.join(self.base, self.path)
        return self.path

    def check(self, dim):
        grid = self.values()
        if grid.ndim != dim:
            raise ModelError(f"the initial field is {grid.ndim}D, the scene is {dim}D")

    def values(self) -> np.ndarray:
        return self.grid if self.grid is not None else load_grid_field(self.file)

    def meridian(self) -> dict | None:
        """The (r, z) field of an axisymmetric run's file, or None."""
        return load_meridian_field(self.file) if self.path else None

    def axis_of_revolution(self):
        m = self.meridian()
        return None if m is None else tuple(float(a) for a in m["axis"])

    def field_values(self, points, L):
        m = self.meridian()
        if m is not None:
            return meridian_values(m, points)
        return resample_periodic(self.values(), L, points)

    def to_mapping(self):
        if self.grid is not None and not self.path:
            raise ModelError("an initial field given as an array cannot be stored in a scene "
                             "file; save it (final.npz) and give its path")
        return {"kind": "file", "path": str(self.path)}


KINDS: dict[str, type[Shape]] = {c.kind: c for c in (Ellipsoid, Sphere, Torus, Spheres, Capsule,
                                                     Starfish, Discocyte, Meridian, FieldIC)}
