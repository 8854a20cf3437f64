"""The body's frame and its point symmetry: rotation axes, mirror planes, a Schoenflies name.

:func:`principal_frame` is the frame of the largest region {φ > 0} of a surface's field (its
voxels, centroid and principal axes from the second moments), which
:func:`fem_ade.analysis.shape.body_geometry` measures the semi-axes in; :func:`symmetry`
asks which rotations about those axes and which reflections map φ onto itself.

How the symmetry is measured
----------------------------
1. **Samples.** The grid nodes x (of the surface's centred field, φ(x) exact there) within
   the ball about the centroid c of radius (the largest distance of a region voxel from c)
   + :data:`MARGIN` grid spacings, at most half the box; at most :data:`MAX_SAMPLES` of
   them (a fixed pseudo-random subset). The ball is mapped onto itself by every rotation about an
   axis through c and every reflection in a plane through c, so an exact symmetry compares
   the field with itself. Everything in the ball counts (a nested inner vesicle, a
   neighbour that reaches into it).
2. **Error of a map T** (a rotation or reflection through c):
   err(T) = ‖φ(T x) − φ(x)‖ / ‖φ(x) − mean φ‖ over the samples, φ(T x) by the periodic
   trilinear interpolation :meth:`fem_ade.analysis.surface.Surface.phi_at`. Some 60 maps
   are tried per body: 0.1–0.15 s at 48³–96³ (measured beside another job on 2 cores).
3. **Axes.** The three principal axes e_k. For each, err of the rotation by 2π/m for
   m = 2 … :data:`MAX_ORDER`; the axis's ``order`` is the largest m with err < ``tol``
   (1: none), and it is ``axisymmetric`` when the largest err of the rotations by 2πj/17,
   j = 1 … 8, is below ``tol`` (17 is prime: none of those angles is a multiple of 2π/m for
   m ≤ 8). A rotation axis of order m ≥ 2 of a body is an eigenvector of its second
   moments, and a mirror plane's normal is one; so the principal axes are the candidates.
   When two semi-axes are equal (a body of revolution, an m ≥ 3-armed flat starfish) the
   two axes in their plane are any pair the eigensolver returns: the third, the
   non-degenerate one, is the axis that is found (the degenerate pair may pass or fail by
   where they happen to lie). When all three are equal the frame is arbitrary: a sphere
   passes about every axis (``Kh``); a cubic body is reported with whatever the arbitrary
   axes pass — its axes are not searched for: the six-armed starfish with its arms on the
   grid axes is ``Oh`` (three 4-fold axes) where the eigensolver puts the frame on its
   arms, ``D4h`` where it puts one axis on an arm and two between (both seen), less where
   none lies on an arm.
4. **Mirrors.** The planes through c normal to each e_k; and, about the main axis of order
   m ≥ 2 (not axisymmetric), the *vertical* plane containing it at the azimuth of least
   err within π/(4m) of θ₀ = arg(Σ (1 + φ) e^{imθ})/m, the phase of the body's m-th
   angular harmonic about that axis (an m-fold pattern with a mirror has its mirror lines
   at θ₀ + kπ/m), with the m planes it and the axis generate. An axisymmetric axis has
   every vertical plane as a mirror.
5. **Name** (Schoenflies, by this rule only; inversion, improper rotations and 2-fold axes
   off the principal ones are not tested): two or three axisymmetric axes → ``Kh`` (the
   sphere); one → ``D∞h`` with the mirror normal to it (σh), else ``C∞v``. Three 4-fold
   axes (they generate the cube's rotations) → ``Oh`` with a mirror, else ``O``. Else the
   main axis is the one of highest order m (ties: the first, the longest): with σh and a
   vertical mirror (σv) → ``Dmh``; σv only → ``Cmv``; σh only → ``Cmh``; neither → ``Dm`` if
   another principal axis is 2-fold, else ``Cm``. No axis of order ≥ 2: ``Cs`` with a
   mirror, else ``C1``.

The tolerance (measured; tests/test_shape.py holds some of these fields)
-----------------------------------------------------------------------
On analytic fields φ = tanh(s/(√2ε)) of exactly symmetric bodies (a sphere, a prolate
spheroid, a triaxial ellipsoid, a pear, a flat three- and four-armed starfish, each once on
the grid axes and once tilted off them) the largest err of a true symmetry element was
0.057 at 32³ with ε = h (the tilted four-armed starfish, three nodes thick), 0.043 at 32³
with ε = 1.6h, 0.039 / 0.034 / 0.025 at 48³ with ε = h / 1.2h / 2h, 0.024 at 64³ with
ε = 1.28h and 0.022 / 0.009 at 96³ with ε = h / 2.5h: the O(h²/ε²) error of the trilinear
interpolation in the interface, and the voxel frame's tilt. The paper's prolate start
(s = c − q, an interface 2–3× narrower than ε) on the grid axes: 0.064 at 32³ with
ε = 1.28h, 0.069 at 48³ with ε = 0.96h, 0.114 at 32³ with ε = 0.64h (an interface of a
fifth of a grid spacing: too sharp for this test). The smallest err of a map that is no
symmetry of those bodies was 0.36–0.54. What err means for a shape: a spheroid
0.3 × 0.12 × 0.12 whose cross-section is made elliptic has the ∞ test's err ≈
1.15 (a₂/a₃ − 1) (0.050 at a₂/a₃ = 1.04, 0.095 at 1.08, at 48³ and 64³ alike); a Gaussian
bump of height 0.03 / 0.04 / 0.05 and width 0.05 on its side gives 0.062 / 0.080 / 0.096.
:data:`SYMMETRY_TOL` = 0.1 lies 1.75× above the largest err of a symmetry of the analytic
fields (2.5× at 48³ and finer, 1.45× for the paper's start at 48³) and 3.6× below the
smallest of a non-symmetry: a body of revolution is reported axisymmetric up to a
cross-section ellipticity a₂/a₃ ≈ 1.09.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.optimize import minimize_scalar

from fem_ade.analysis.surface import Surface, extract_surface

#: rotations tested about each axis: by 2π/m for m = 2 … MAX_ORDER
MAX_ORDER = 8
#: the ∞ test: rotations by 2πj/AXI_DIVISIONS, j = 1 … AXI_DIVISIONS // 2
AXI_DIVISIONS = 17
#: the sample ball reaches this many grid spacings beyond the farthest region voxel
MARGIN = 4
#: at most this many samples (a fixed pseudo-random subset of the grid nodes in the ball)
MAX_SAMPLES = 20000
#: err below which a map is a symmetry (chosen from measured errors: the module docstring)
SYMMETRY_TOL = 0.1


@dataclass
class Frame:
    """The largest region {φ > 0} of a surface's field: ``points`` (its voxels' physical
    positions, (N, 3)), ``centre`` (their mean), ``semi_axes`` a₁ ≥ a₂ ≥ a₃ (those of the
    solid ellipsoid with the same second moments: √(5λ)) and ``axes`` (3, 3), the unit
    principal directions as columns in that order."""

    points: np.ndarray
    centre: np.ndarray
    semi_axes: np.ndarray
    axes: np.ndarray


def principal_frame(S: Surface) -> Frame | None:
    """The :class:`Frame` of the largest connected region {φ > 0} of ``S.phi`` (None if
    there is none, it spans an axis of the box, or it has fewer than 27 voxels)."""
    labels, count = ndimage.label(S.phi > 0)
    if count == 0:
        return None
    sizes = np.bincount(labels.ravel())[1:]
    idx = np.argwhere(labels == 1 + int(np.argmax(sizes)))
    if any(idx[:, a].min() == 0 and idx[:, a].max() == S.phi.shape[a] - 1 for a in range(3)):
        return None  # it spans an axis of the box: no finite body to measure
    if len(idx) < 27:
        return None  # a few grid cells: too small to measure
    X = S.origin + idx * S.h
    c = X.mean(axis=0)
    Y = X - c
    lam, vec = np.linalg.eigh(Y.T @ Y / len(Y))
    lam, vec = lam[::-1], vec[:, ::-1]  # a₁ ≥ a₂ ≥ a₃
    return Frame(X, c, np.sqrt(5.0 * np.maximum(lam, 0.0)), vec)


# --- the maps ---------------------------------------------------------------------------
def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """The 3 × 3 rotation by ``angle`` about the unit vector ``axis`` (Rodrigues)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * K @ K


def reflection(normal: np.ndarray) -> np.ndarray:
    """The 3 × 3 reflection in the plane through 0 normal to ``normal``."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    return np.eye(3) - 2.0 * np.outer(n, n)


def _norm(v: np.ndarray) -> float:
    """‖v‖₂ by a plain sum of squares (no BLAS call: np.linalg.norm's dot product was
    measured at 8 ms for 20000 values beside another job's threads, the sum at 0.03 ms)."""
    return float(np.sqrt(np.sum(v * v)))


class _Samples:
    """The sample nodes about the frame's centre and err of a linear map about it."""

    def __init__(self, S: Surface, F: Frame):
        h = float(S.h.min())
        radius = min(float(np.linalg.norm(F.points - F.centre, axis=1).max()) + MARGIN * h,
                     0.5 * S.L)
        lo = np.floor((F.centre - radius - S.origin) / S.h).astype(int)
        hi = np.ceil((F.centre + radius - S.origin) / S.h).astype(int)
        idx = np.stack(np.meshgrid(*[np.arange(lo[a], hi[a] + 1) for a in range(3)],
                                   indexing="ij"), axis=-1).reshape(-1, 3)
        x = S.origin + idx * S.h
        keep = np.flatnonzero(np.linalg.norm(x - F.centre, axis=1) <= radius)
        if len(keep) > MAX_SAMPLES:  # a fixed pseudo-random subset: the same on every call
            keep = np.sort(np.random.default_rng(0).choice(keep, MAX_SAMPLES, replace=False))
        idx, x = idx[keep], x[keep]
        self.S, self.c = S, F.centre
        self.y = x - F.centre
        self.phi = S.phi[tuple((idx % np.array(S.phi.shape)).T)]
        self.norm = _norm(self.phi - self.phi.mean()) or 1.0

    def error(self, T: np.ndarray) -> float:
        """‖φ(c + T(x − c)) − φ(x)‖ / ‖φ(x) − mean‖ over the samples."""
        mapped = self.S.phi_at(self.c + self.y @ T.T)
        return _norm(mapped - self.phi) / self.norm

    def harmonic_phase(self, axis: np.ndarray, u: np.ndarray, m: int) -> float:
        """θ₀ = arg(Σ (1 + φ) e^{imθ})/m, θ the azimuth about ``axis`` from ``u``: the
        maximum of the body's m-th harmonic (a pattern cos m(θ − θ₀) has it there; 1 + φ
        vanishes outside, so the lattice of the samples adds no harmonic of its own)."""
        w = np.cross(axis, u)
        theta = np.arctan2(self.y @ w, self.y @ u)
        coef = np.sum((1.0 + self.phi) * np.exp(1j * m * theta))
        return float(np.angle(coef)) / m


# --- the symmetry ------------------------------------------------------------------------
def symmetry(S_or_phi, L: float | None = None, *, frame: Frame | None = None,
             tol: float = SYMMETRY_TOL) -> dict | None:
    """The point symmetry of the largest body (module docstring), or None if there is no
    finite body (:func:`principal_frame`).

    ``S_or_phi``: a :class:`~fem_ade.analysis.surface.Surface`, or a (n, n, n) grid field
    of period ``L``. ``frame``: a precomputed :func:`principal_frame`.

    Returns ``group`` (the Schoenflies name), ``tol``, ``centre``; ``axes`` (per principal
    axis, longest first: ``direction``, ``semi_axis``, ``order`` (largest m ≤
    :data:`MAX_ORDER` with err < tol, 1: none), ``axisymmetric``, ``errors`` (err of the
    rotation by 2π/m, m = 2 … MAX_ORDER), ``axisymmetric_error`` (the largest err of the
    rotations by 2πj/17) and ``mirror_error`` (err of the reflection in the plane normal to
    it)); ``main_axis`` (its index, None if no axis of order ≥ 2); ``vertical_mirror_error``
    (the best vertical plane about the main axis, None if not searched); ``mirrors`` (unit
    normals of the mirror planes found, each plane once).
    """
    S = S_or_phi if isinstance(S_or_phi, Surface) else extract_surface(S_or_phi, L)
    F = frame if frame is not None else principal_frame(S)
    if F is None:
        return None
    P = _Samples(S, F)
    axes = [_axis_elements(P, F.axes[:, k], float(F.semi_axes[k]), tol) for k in range(3)]
    mirrors = [ax["direction"] for ax in axes if ax["mirror_error"] < tol]
    main = _main_axis(axes)
    vertical = None
    if main is not None and not axes[main]["axisymmetric"]:
        vertical, normals = _vertical_mirrors(P, F, main, axes[main]["order"])
        if vertical < tol:
            mirrors += normals
    out = {"group": "", "tol": tol, "centre": [float(v) for v in F.centre], "axes": axes,
           "main_axis": main, "vertical_mirror_error": vertical,
           "mirrors": _distinct(mirrors)}
    out["group"] = point_group(out)
    return out


def _axis_elements(P: _Samples, e: np.ndarray, a: float, tol: float) -> dict:
    """The rotation and mirror errors about one principal axis (see :func:`symmetry`)."""
    errors = [P.error(rotation(e, 2.0 * math.pi / m)) for m in range(2, MAX_ORDER + 1)]
    passing = [m for m, err in zip(range(2, MAX_ORDER + 1), errors, strict=True) if err < tol]
    axi = max(P.error(rotation(e, 2.0 * math.pi * j / AXI_DIVISIONS))
              for j in range(1, AXI_DIVISIONS // 2 + 1))
    return {"direction": [float(v) for v in e], "semi_axis": a,
            "order": max(passing, default=1), "axisymmetric": bool(axi < tol),
            "errors": errors, "axisymmetric_error": axi,
            "mirror_error": P.error(reflection(e))}


def _main_axis(axes: list[dict]) -> int | None:
    """The axis of the highest order (axisymmetric first; ties: the first), None if no axis
    has order ≥ 2."""
    rank = [(1 if ax["axisymmetric"] else 0, ax["order"]) for ax in axes]
    best = max(range(3), key=lambda k: (rank[k], -k))
    return best if rank[best] > (0, 1) else None


def _vertical_mirrors(P: _Samples, F: Frame, main: int, m: int) -> tuple[float, list]:
    """(err of the best vertical mirror about the main axis, the normals of the m vertical
    planes it and the m-fold axis make): the plane at the azimuth of least err within
    π/(4m) of the m-th harmonic's phase θ₀ (bounded scalar search, to 10⁻³ rad)."""
    e, u = F.axes[:, main], F.axes[:, (main + 1) % 3]
    w = np.cross(e, u)

    def normal(theta: float) -> np.ndarray:  # of the plane holding e and the azimuth theta
        return -math.sin(theta) * u + math.cos(theta) * w

    theta0 = P.harmonic_phase(e, u, m)
    half = math.pi / (4 * m)
    best = minimize_scalar(lambda t: P.error(reflection(normal(t))), method="bounded",
                           bounds=(theta0 - half, theta0 + half), options={"xatol": 1e-3})
    normals = [normal(float(best.x) + k * math.pi / m) for k in range(m)]
    return float(best.fun), [[float(v) for v in n] for n in normals]


def _distinct(normals: list) -> list:
    """The normals with each plane once (|n·n'| > cos 5° is the same plane)."""
    out: list = []
    for n in normals:
        if all(abs(float(np.dot(n, o))) < math.cos(math.radians(5.0)) for o in out):
            out.append([float(v) for v in n])
    return out


def point_group(sym: dict) -> str:
    """The Schoenflies name of :func:`symmetry`'s elements by the module docstring's rule."""
    axes, main = sym["axes"], sym["main_axis"]
    if sum(ax["axisymmetric"] for ax in axes) >= 2:
        return "Kh"
    if main is None:
        return "Cs" if sym["mirrors"] else "C1"
    e = np.asarray(axes[main]["direction"])
    sigma_h = axes[main]["mirror_error"] < sym["tol"]
    if axes[main]["axisymmetric"]:
        return "D∞h" if sigma_h else "C∞v"
    if all(ax["order"] in (4, 8) for ax in axes):
        return "Oh" if sym["mirrors"] else "O"
    m = axes[main]["order"]
    sigma_v = any(abs(float(np.dot(n, e))) < 1e-6 for n in sym["mirrors"])
    if sigma_h and sigma_v:
        return f"D{m}h"
    if sigma_v:
        return f"C{m}v"
    if sigma_h:
        return f"C{m}h"
    others = [ax for k, ax in enumerate(axes) if k != main]
    return f"D{m}" if any(ax["order"] % 2 == 0 for ax in others) else f"C{m}"


# ---------------------------------------------------------------------------------------------
# the irreducible representation an eigenspace of a D4h state carries
# ---------------------------------------------------------------------------------------------
#: the characters of D4h's irreducible representations under C4 (about z), C2 (about z),
#: σh (z), σv (x), σd (x ↔ y) and i, about the box's centre (for a four-armed starfish
#: with its arms along x and y: ``studies/starfish_octant.py``)
D4H = {"A1g": (1, 1, 1, 1, 1, 1), "A2g": (1, 1, 1, -1, -1, 1), "B1g": (-1, 1, 1, 1, -1, 1),
       "B2g": (-1, 1, 1, -1, 1, 1), "Eg": (0, -2, -2, 0, 0, 2),
       "A1u": (1, 1, -1, -1, -1, -1), "A2u": (1, 1, -1, 1, 1, -1),
       "B1u": (-1, 1, -1, -1, 1, -1), "B2u": (-1, 1, -1, 1, -1, -1),
       "Eu": (0, -2, 2, 0, 0, -2)}


def d4h_characters(X, w, V, L: float) -> list[float]:
    """The characters of the space spanned by the columns of V (fields on the nodes X, 3 × N,
    of a mesh symmetric about the box's centre; inner product weighted by w) under the
    operations of :data:`D4H`: trace(G⁻¹ Vᵀ W V∘g), G = Vᵀ W V — ±1 for a one-dimensional
    irreducible space, the irrep's character for a degenerate pair."""
    from scipy.spatial import cKDTree

    c = L / 2.0
    x, y, z = X - c
    images = [(-y, x, z), (-x, -y, z), (x, y, -z), (-x, y, z), (y, x, z), (-x, -y, -z)]
    tree = cKDTree(np.mod(X.T, L), boxsize=L)
    G = V.T @ (w[:, None] * V)
    out = []
    for image in images:
        moved = tree.query(np.mod(np.stack(image).T + c, L))[1]
        out.append(float(np.trace(np.linalg.solve(G, V.T @ (w[:, None] * V[moved])))))
    return out


def irrep(chars: list[float]) -> tuple[str, float]:
    """The irreducible representation of D4h whose characters are nearest ``chars`` (of one
    eigenspace: :func:`d4h_characters`), and that distance (0: exactly it)."""
    name = min(D4H, key=lambda k: np.linalg.norm(np.subtract(D4H[k], chars)))
    return name, float(np.linalg.norm(np.subtract(D4H[name], chars)))
