"""Shape descriptors of the membrane {φ = 0} of a phase field on a periodic uniform grid.

:func:`describe` answers "what shape is this vesicle?" with a few numbers: how many closed
surfaces there are, the genus of each, whether one lies inside another, the reduced volume
and reduced area difference, and how many arms (lobes) the largest surface has.
:func:`extract_surface` returns the triangulated surface itself (used by
:mod:`fem_ade.plots.shapes`).

Grid convention (model §6): ``phi[i, j, k]`` is φ at (i, j, k)·h, h = L/n, periodic with
period L in each direction.

How the surface is extracted
----------------------------
1. **Centring.** A grid layer (a plane i = const, etc.) is *free* if φ has one sign on all of
   it, so that no part of the surface crosses it. Along each axis the field is rolled so that
   the middle of the longest (circular) run of free layers becomes the box face. For the
   centred paper scenes the roll is zero; a vesicle placed across the periodic boundary is
   moved back in one piece. The surface coordinates are then "unwrapped" physical
   coordinates in the box [s·h, s·h + L] (s the roll, reported as ``shift``).
2. **Periodic closing.** The rolled field is padded periodically by one layer (n + 1 points
   per direction, the last layer a copy of the first) and contoured at 0 with VTK's flying
   edges (``pyvista.ImageData.contour``). Vertices on opposite box faces are then identified
   (coordinates taken modulo L), so that the triangulation has no seam. When an axis has no
   free layer (a surface that winds around the periodic box, e.g. a cylinder spanning it),
   the identified surface is the closed surface on the 3-torus; such a component is marked
   ``wraps`` and has genus but no volume, nesting or arms.
3. **Orientation.** Every triangle is oriented with its normal along −∇φ, i.e. pointing out of
   the region φ > 0.

Descriptors
-----------
* ``components``: connected components of the identified triangulation.
* ``genus``: per component, from the Euler characteristic χ = V − E + F of the closed
  triangulated surface: genus = (2 − χ)/2.
* ``nested``: one component lies inside another (winding number of a vertex of one with
  respect to the other ≥ ½).
* ``reduced_volume`` v = V / (4π/3 · (A/4π)^{3/2}) and ``reduced_area_difference``
  m = ΔA / (8πD·√(A/4π)). V, A, ΔA, D are taken from the arguments when given (the caller
  has the diffuse values from the diagnostics); a value not given is replaced by the sharp
  value of the extracted surface: V enclosed by the surfaces, A = Σ triangle areas, and
  ΔA = 2D·∫H dA with the discrete total mean curvature ∫H dA = ½ Σ_edges |e| θ_e
  (θ_e the signed dihedral angle), so that the sharp m = ∫H dA / (4π√(A/4π)) needs no D.
  A sphere has v = m = 1. The sharp values are always reported too, under ``sharp``.
  Mixing diffuse and sharp values is not like with like: the diffuse V of a sphere exceeds
  the sharp one by 12.6 % at ε/R = 0.16 (model §8).
* ``arms``: the number of lobes of the largest component, see :func:`count_arms`.
  Convention: a body without arms (sphere, ellipsoid, discocyte, torus) has **1** lobe; a
  three-armed starfish 3, a six-armed one 6.
* ``body``: the geometry of the largest region φ > 0 (:func:`body_geometry`): its principal
  semi-axes a₁ ≥ a₂ ≥ a₃ (those of the solid ellipsoid with the same second moments),
  ``elongation`` a₁/a₂ and ``flatness`` a₃/a₂, the ``necks`` along the long axis (minima of
  the cross-section area below 85 % of the smaller maximum beside them) and the ``dimple``
  1 − (thickness at the centre)/(largest thickness) across the short axis (> 0: biconcave).
* ``label``: a name for all of it (:func:`classify`, the one decision tree of both
  geometries): sphere, prolate, oblate, discocyte, cylinder, gourd, chain, torus, genus-g,
  starfish-k, nested, k vesicles, wrapping, no membrane; and from an axisymmetric run's
  meridians also stomatocyte and pear.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from fem_ade.model.params import reduced_area_difference, reduced_volume

#: summary.json → shape: the descriptors of the sharp surface kept at its top level
SHAPE_KEYS = ("components", "genus", "nested", "reduced_volume", "reduced_area_difference",
              "arms", "label", "body")
#: vertex coordinates are identified on a lattice of h / 2**20 (periodic images coincide to
#: round-off; distinct marching-cubes vertices are much further apart unless φ ≈ 0 at a node)
_QUANT = 2**20


@dataclass
class Surface:
    """The closed triangulated surface {φ = 0} (see the module docstring).

    ``points`` are unwrapped physical coordinates in the box ``[origin, origin + L]``;
    ``faces`` index ``points`` and are oriented out of {φ > 0}; ``vertex`` maps each point to
    its identified (periodic) vertex, ``tri`` = ``vertex[faces]`` is the topological
    triangulation; ``component`` is the component of each triangle (0 = largest area).
    """

    points: np.ndarray
    faces: np.ndarray
    vertex: np.ndarray
    tri: np.ndarray
    component: np.ndarray
    n_components: int
    wraps: list[bool]
    shift: tuple[int, ...]
    origin: np.ndarray
    h: np.ndarray
    L: float
    phi: np.ndarray  # the rolled field (not padded), φ at origin + index·h
    background_positive: bool = False
    _edges: dict = field(default_factory=dict, repr=False)  # cache

    # -- geometry helpers ---------------------------------------------------------------
    def _min_image(self, d: np.ndarray) -> np.ndarray:
        return d - self.L * np.round(d / self.L)

    def triangle_vectors(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(p0, e1 = p1 − p0, e2 = p2 − p0) per triangle, edges by minimum image."""
        p = self.points[self.faces]
        return p[:, 0], self._min_image(p[:, 1] - p[:, 0]), self._min_image(p[:, 2] - p[:, 0])

    def triangle_normals(self) -> np.ndarray:
        """Area vectors (|n| = triangle area, outward of φ > 0)."""
        _, e1, e2 = self.triangle_vectors()
        return 0.5 * np.cross(e1, e2)

    def phi_at(self, x: np.ndarray) -> np.ndarray:
        """φ at physical points x (..., 3) by periodic trilinear interpolation."""
        idx = (np.asarray(x, float) - self.origin) / self.h
        coords = np.moveaxis(idx, -1, 0).reshape(3, -1)
        vals = ndimage.map_coordinates(self.phi, coords, order=1, mode="grid-wrap")
        return vals.reshape(idx.shape[:-1])

    def outward_normals_at(self, x: np.ndarray) -> np.ndarray:
        """Unit vectors −∇φ/|∇φ| at physical points x (N, 3): smooth surface normals
        (central differences, periodic trilinear interpolation)."""
        if "grad" not in self._edges:
            self._edges["grad"] = [
                (np.roll(self.phi, -1, axis=a) - np.roll(self.phi, 1, axis=a)) / (2 * self.h[a])
                for a in range(3)]
        idx = ((np.asarray(x, float) - self.origin) / self.h).T
        g = np.stack([ndimage.map_coordinates(ga, idx, order=1, mode="grid-wrap")
                      for ga in self._edges["grad"]], axis=1)
        return -g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)

    def component_mesh(self, c: int) -> tuple[np.ndarray, np.ndarray]:
        """(points, faces) of component c alone, faces re-indexed (for plotting)."""
        faces = self.faces[self.component == c]
        used, inv = np.unique(faces, return_inverse=True)
        return self.points[used], inv.reshape(faces.shape)


# --- extraction ------------------------------------------------------------------------
def _free_layers(pos: np.ndarray, axis: int) -> np.ndarray:
    other = tuple(a for a in range(3) if a != axis)
    return pos.all(axis=other) | (~pos).all(axis=other)


def _centring_shift(free: np.ndarray) -> int | None:
    """Index of the middle of the longest circular run of True in ``free`` (None if none)."""
    n = free.size
    if not free.any():
        return None
    if free.all():
        return 0
    start = int(np.argmin(free))  # a False: runs do not wrap past it
    f = np.roll(free, -start)
    best_len, best_mid, run = 0, 0, 0
    for i in range(n + 1):
        if i < n and f[i]:
            run += 1
            continue
        if run > best_len:
            best_len, best_mid = run, i - run + (run - 1) // 2
        run = 0
    return int((best_mid + start) % n)


def extract_surface(phi: np.ndarray, L: float) -> Surface:
    """The closed, oriented, periodically identified surface {φ = 0} of a grid field.

    ``phi``: array (n0, n1, n2), φ at (i, j, k)·L/n per direction (periodic). See the module
    docstring for centring, periodic closing and orientation.
    """
    phi = _checked_field(phi)
    shape = np.array(phi.shape)
    h = L / shape
    phi = np.where(phi == 0.0, 1e-12, phi)  # no exact zeros at nodes: no degenerate triangles
    pos = phi > 0
    shift = []
    for a in range(3):
        s = _centring_shift(_free_layers(pos, a))
        shift.append(0 if s is None else s)
    rolled = np.roll(phi, [-s for s in shift], axis=(0, 1, 2))
    origin = np.array(shift) * h
    mesh = _contour(rolled, h, origin)
    if mesh is None:
        empty = np.zeros((0, 3), dtype=np.int64)
        return Surface(np.zeros((0, 3)), empty, np.zeros(0, np.int64), empty,
                       np.zeros(0, np.int64), 0, [], tuple(shift), origin, h, float(L), rolled,
                       bool(rolled.flat[0] > 0))
    points, faces = mesh
    vertex, faces, tri, nv = _identify_periodic(points, faces, origin, h, shape)
    # components of the identified triangulation
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    adj = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(nv, nv))
    ncomp, vlabel = connected_components(adj, directed=False)
    tlabel = vlabel[tri[:, 0]]

    S = Surface(points, faces, vertex, tri, tlabel, ncomp, [], tuple(shift), origin, h,
                float(L), rolled, bool(rolled[0, 0, 0] > 0))
    _orient(S)
    S.component = _ranked_by_area(S, tlabel, ncomp)
    S.wraps = _wrapping(S, ncomp, L)
    return S


def _checked_field(phi) -> np.ndarray:
    """``phi`` as a float array; ValueError unless it is a finite 3D grid."""
    phi = np.asarray(phi, dtype=float)
    if phi.ndim != 3:
        raise ValueError(f"phi must be a 3D grid array, got shape {phi.shape}")
    if not np.all(np.isfinite(phi)):
        raise ValueError("phi has non-finite values")
    return phi


def _contour(rolled: np.ndarray, h: np.ndarray,
             origin: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Marching cubes (flying edges) of {φ = 0} on the periodically padded grid: its
    points and triangles (None if there is no surface)."""
    import pyvista as pv

    padded = np.pad(rolled, [(0, 1)] * 3, mode="wrap")
    grid = pv.ImageData(dimensions=padded.shape, spacing=tuple(h), origin=tuple(origin))
    grid.point_data["phi"] = padded.ravel(order="F")
    surf = grid.contour([0.0], scalars="phi", method="flying_edges")
    if surf.n_points == 0 or surf.n_cells == 0:
        return None
    surf = surf.triangulate()
    return np.asarray(surf.points, dtype=float), np.asarray(surf.regular_faces, dtype=np.int64)


def _identify_periodic(points: np.ndarray, faces: np.ndarray, origin: np.ndarray,
                       h: np.ndarray, shape: np.ndarray):
    """Periodic images (and any duplicate point) identified on a fine lattice: the vertex
    of each point, the faces left non-degenerate, their vertex triples and the number of
    vertices."""
    periods = shape.astype(np.int64) * _QUANT
    keys = np.round((points - origin) / h * _QUANT).astype(np.int64) % periods
    _, first, vertex = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    vertex = vertex.ravel()
    tri = vertex[faces]
    good = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])
    return vertex, faces[good], tri[good], first.size


def _orient(S: Surface) -> None:
    """Turn each triangle of ``S`` out of {φ > 0} (normal · ∇φ < 0)."""
    faces = S.faces
    p0, e1, e2 = S.triangle_vectors()
    centroid = p0 + (e1 + e2) / 3.0
    normal = np.cross(e1, e2)
    step = 0.25 * float(S.h.min())
    nn = normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    outward = S.phi_at(centroid + step * nn) < S.phi_at(centroid - step * nn)
    S.faces = np.where(outward[:, None], faces, faces[:, [0, 2, 1]])
    S.tri = S.vertex[S.faces]


def _ranked_by_area(S: Surface, tlabel: np.ndarray, ncomp: int) -> np.ndarray:
    """Each triangle's component renumbered by area, largest first."""
    area = np.linalg.norm(S.triangle_normals(), axis=1)
    comp_area = np.bincount(tlabel, weights=area, minlength=ncomp)
    order = np.argsort(-comp_area, kind="stable")
    rank = np.empty(ncomp, dtype=np.int64)
    rank[order] = np.arange(ncomp)
    return rank[tlabel]


def _wrapping(S: Surface, ncomp: int, L: float) -> list[bool]:
    """Per component: it reaches a box face, so it wraps (only possible along axes without a
    free layer)."""
    rel = S.points - S.origin
    on_face = np.any((rel < 1e-9 * S.h) | (rel > L - 1e-9 * S.h), axis=1)
    touches = np.zeros(ncomp, dtype=bool)
    touches[S.component[on_face[S.faces].any(axis=1)]] = True
    return [bool(w) for w in touches]


# --- topology and geometry of one component --------------------------------------------
def _edges(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique undirected edges (E, 2), the edge of each (triangle, side) (F, 3), use counts."""
    e = np.stack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]], axis=1)  # (F, 3, 2)
    es = np.sort(e.reshape(-1, 2), axis=1)
    uniq, inv, counts = np.unique(es, axis=0, return_inverse=True, return_counts=True)
    return uniq, inv.reshape(-1, 3), counts


def euler_characteristic(tri: np.ndarray) -> int:
    """χ = V − E + F of a triangulation given as vertex-index triples."""
    if len(tri) == 0:
        return 0
    uniq, _, _ = _edges(tri)
    return int(np.unique(tri).size - len(uniq) + len(tri))


def _mean_curvature_integral(S: Surface, mask: np.ndarray) -> float:
    """∫H dA = ½ Σ_e |e| θ_e over the triangles in ``mask`` (H the mean of the principal
    curvatures, θ_e > 0 at a convex edge); a sphere of radius R gives 4πR."""
    faces, tri = S.faces[mask], S.tri[mask]
    uniq, side_edge, counts = _edges(tri)
    p0, e1, e2 = S.triangle_vectors()
    p0, e1, e2 = p0[mask], e1[mask], e2[mask]
    n = np.cross(e1, e2)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    # for each edge, its two (triangle, side) uses
    flat = side_edge.ravel()
    order = np.argsort(flat, kind="stable")
    sorted_edges = flat[order]
    starts = np.searchsorted(sorted_edges, np.arange(len(uniq)))
    two = counts == 2
    a_use, b_use = order[starts[two]], order[starts[two] + 1]
    ta, sa = a_use // 3, a_use % 3
    tb, sb = b_use // 3, b_use % 3
    pts = S.points
    # edge of triangle ta, side sa: from corner sa to corner sa+1; the opposite corner of tb
    start = pts[faces[ta, sa]]
    evec = S._min_image(pts[faces[ta, (sa + 1) % 3]] - start)
    opp_b = S._min_image(pts[faces[tb, (sb + 2) % 3]] - start)
    na, nb = n[ta], n[tb]
    theta = np.arctan2(np.linalg.norm(np.cross(na, nb), axis=1), np.sum(na * nb, axis=1))
    convex = np.sum(opp_b * na, axis=1) < 0
    theta = np.where(convex, theta, -theta)
    return float(0.5 * np.sum(np.linalg.norm(evec, axis=1) * theta))


def _signed_volume(S: Surface, mask: np.ndarray) -> tuple[float, np.ndarray]:
    """Σ (1/6) det(p0, p1, p2) about the box centre, and the first moment (for the centroid)."""
    c0 = S.origin + 0.5 * S.L
    p = S.points[S.faces[mask]] - c0
    det = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])) / 6.0
    moment = np.sum(det[:, None] * (p[:, 0] + p[:, 1] + p[:, 2]) / 4.0, axis=0)
    return float(det.sum()), moment + det.sum() * c0


def winding_number(point: np.ndarray, tris: np.ndarray) -> float:
    """Winding number of a closed oriented triangle soup (T, 3, 3) around ``point``."""
    a, b, c = (tris[:, i] - point for i in range(3))
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
    num = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc
           + np.einsum("ij,ij->i", a, c) * lb + np.einsum("ij,ij->i", b, c) * la)
    return float(np.sum(2.0 * np.arctan2(num, den)) / (4.0 * math.pi))


# --- arms ------------------------------------------------------------------------------
def count_arms(S: Surface, c: int, *, threshold: float = 0.1,
               see_level: float = -0.5) -> int:
    """Number of lobes of component ``c`` (1 for a body without arms).

    Method: lobes are the peaks of the distance r = |x − x_c| from the volume centroid x_c
    over the surface vertices, found by 0-dimensional persistence (a merge tree: vertices
    are added in order of decreasing r and the regions around the peaks grow until they
    meet at saddles). When two regions meet at a saddle vertex s, the younger region becomes
    a separate lobe only if

    1. its persistence r(peak) − r(s) is at least ``threshold``·max r (this removes the
       discretisation noise of nearly constant r, e.g. on a sphere), and
    2. its lobe peak nearest to s and the other region's lobe peak nearest to s are less
       than 135° apart seen from the centroid (neighbouring arms), or cannot see each other
       through the body: φ < ``see_level`` somewhere on the straight segment between them
       (φ by trilinear interpolation).

    Otherwise the two meet within one lobe. So a convex body has one lobe however elongated
    (the two tips of a prolate ellipsoid see each other through the centre), while adjacent
    arms of a starfish are separated by the gap between them. A dumbbell or a straight chain
    of beads also counts as 1 (its ends see each other through the necks), and a T (arms
    along +x, −x, +y) counts 2: its collinear pair sees itself through the body like the two
    tips of an ellipsoid. Opposite arms of the four- and six-armed stars are not neighbours
    on the surface, so each counts.
    """
    mask = S.component == c
    found = _component_vertices(S, mask)
    if found is None:
        return 0
    P, t = found
    vol, moment = _signed_volume(S, mask)
    if abs(vol) > 1e-12 * S.L**3:
        xc = moment / vol
    else:
        xc = P.mean(axis=0)
    r = np.linalg.norm(P - xc, axis=1)
    tree = _LobeTree(S, P, xc, r, see_level)
    tol = threshold * float(r.max())
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    nv = len(P)
    adj = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(nv, nv)).tocsr()
    adj = (adj + adj.T).tocsr()
    indptr, indices = adj.indptr, adj.indices
    for v in np.argsort(-r, kind="stable"):
        tree.add(v, indices[indptr[v]:indptr[v + 1]], tol)
    return tree.count()


def _component_vertices(S: Surface, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """A point (unwrapped coordinates) per identified vertex of the triangles in ``mask``
    and those triangles as indices into them; None for fewer than 4 vertices."""
    tri = S.tri[mask]
    faces = S.faces[mask]
    verts = np.unique(tri)
    if verts.size < 4:
        return None
    local = np.full(int(S.tri.max()) + 1, -1, dtype=np.int64)
    local[verts] = np.arange(verts.size)
    P = np.zeros((verts.size, 3))
    P[local[S.tri[mask].ravel()]] = S.points[faces.ravel()]
    return P, local[tri]


class _LobeTree:
    """The merge tree of :func:`count_arms`: vertices (points ``P`` at distances ``r`` from
    the centroid ``xc``) added in order of decreasing r; each region (a union-find root)
    keeps its highest vertex and its lobe peaks."""

    def __init__(self, S: Surface, P: np.ndarray, xc: np.ndarray, r: np.ndarray,
                 see_level: float):
        self.S, self.P, self.xc, self.r, self.see_level = S, P, xc, r, see_level
        self.parent = np.full(len(P), -1, dtype=np.int64)
        self.peak: dict[int, int] = {}  # root -> highest vertex of its region
        self.lobes: dict[int, list[int]] = {}  # root -> lobe peaks of its region
        self._seen: dict[tuple[int, int], bool] = {}

    def find(self, i):
        """The root of ``i``'s region (compressing the path to it)."""
        parent = self.parent
        root = i
        while parent[root] != root:
            root = parent[root]
        while parent[i] != root:
            parent[i], i = root, parent[i]
        return root

    def sees(self, i: int, j: int) -> bool:
        """φ ≥ see_level all along the segment between vertices i and j."""
        key = (min(i, j), max(i, j))
        if key not in self._seen:
            P = self.P
            length = float(np.linalg.norm(P[j] - P[i]))
            m = max(8, int(math.ceil(length / (0.5 * float(self.S.h.min())))))
            s = np.linspace(0.0, 1.0, m + 1)[1:-1, None]
            self._seen[key] = bool(self.S.phi_at(P[i] + s * (P[j] - P[i])).min()
                                   >= self.see_level)
        return self._seen[key]

    def apart(self, i: int, j: int) -> bool:
        """Two peaks less than 135° apart seen from the centroid: neighbouring arms, even
        where the segment between them crosses the body (stubby arms of a fat starfish)."""
        a, b = self.P[i] - self.xc, self.P[j] - self.xc
        return float(a @ b) > -0.7 * float(np.linalg.norm(a) * np.linalg.norm(b))

    def nearest(self, peaks: list[int], v: int) -> int:
        """The peak of ``peaks`` nearest to vertex v."""
        d = np.linalg.norm(self.P[peaks] - self.P[v], axis=1)
        return peaks[int(np.argmin(d))]

    def add(self, v, neighbours: np.ndarray, tol: float) -> None:
        """Add vertex v: a new region, or the regions of its added neighbours joined at v."""
        parent, r, peak = self.parent, self.r, self.peak
        roots = {self.find(u) for u in neighbours if parent[u] >= 0}
        parent[v] = v
        if not roots:
            peak[v], self.lobes[v] = v, [v]
            return
        ordered = sorted(roots, key=lambda q: -r[peak[q]])
        main = ordered[0]
        parent[v] = main
        for other in ordered[1:]:
            parent[other] = main
            self.join(main, other, v, tol)

    def join(self, main, other, v, tol: float) -> None:
        """Region ``other`` meets the higher ``main`` at saddle v: its lobes become main's,
        as lobes of their own if it persists ``tol`` and the two nearest peaks are
        neighbouring arms or do not see each other, else with the two peaks as one."""
        lobes, r = self.lobes, self.r
        a, b = self.nearest(lobes[main], v), self.nearest(lobes[other], v)
        if r[self.peak[other]] - r[v] >= tol and (not self.sees(a, b) or self.apart(a, b)):
            lobes[main] = lobes[main] + lobes[other]
        else:  # one lobe: keep the higher of the two meeting peaks
            keep = [q for q in lobes[other] if q != b]
            if r[b] > r[a]:
                lobes[main] = [q for q in lobes[main] if q != a] + [b]
            lobes[main] = lobes[main] + keep
        del lobes[other], self.peak[other]

    def count(self) -> int:
        """The number of lobes of all regions."""
        roots = {self.find(i) for i in range(len(self.P))}
        return int(sum(len(self.lobes[q]) for q in roots))


# --- the descriptors -------------------------------------------------------------------
def describe(phi: np.ndarray, L: float, *, V: float | None = None, A: float | None = None,
             dA: float | None = None, D: float | None = None, arm_threshold: float = 0.1,
             surface: Surface | None = None) -> dict:
    """Shape descriptors of {φ = 0} (see the module docstring).

    ``phi``: (n, n, n) grid field of period ``L``. ``V``, ``A``, ``dA`` (= ΔA) and ``D``:
    the values to build the reduced volume and area difference from (typically the
    diagnostics' diffuse values and the scene's D); any not given is replaced by the sharp
    value of the surface (``sources`` says which was used). ``surface``: a precomputed
    :func:`extract_surface` result.

    Returns a dict with ``components`` (int), ``genus`` (list of int, by component, largest
    area first), ``nested`` (bool), ``inside_of`` (per component: the index of the smallest
    component enclosing it, or None), ``wraps`` (per component: it winds around the
    periodic box), ``reduced_volume``, ``reduced_area_difference``, ``arms`` (int, lobes of
    the largest component, 1 = no arms; 0 if there is no surface or it wraps),
    ``arms_per_component``, ``area_per_component``, ``sources`` and ``sharp`` (V, A,
    mean_curvature_integral, reduced_volume, reduced_area_difference of the extracted
    surface), and ``shift`` (the grid roll used to centre the surface).
    """
    S = surface if surface is not None else extract_surface(phi, L)
    nc = S.n_components
    genus, arms, areas, closed_vols, H_total = _per_component(S, arm_threshold)
    A_sharp = float(sum(areas))
    if nc and all(v is not None for v in closed_vols):
        V_sharp = float(sum(closed_vols)) + (S.L**3 if S.background_positive else 0.0)
    else:  # a wrapping surface encloses no volume of R³: count grid cells with φ > 0
        V_sharp = float(np.count_nonzero(S.phi > 0) * np.prod(S.h))
    inside_of = _nesting(S, areas)
    sharp_m = (H_total / (4.0 * math.pi * math.sqrt(A_sharp / (4.0 * math.pi)))
               if A_sharp > 0 else math.nan)
    sources = {"V": "given" if V is not None else "sharp",
               "A": "given" if A is not None else "sharp",
               "dA": "given" if (dA is not None and D is not None) else "sharp"}
    Vu = float(V) if V is not None else V_sharp
    Au = float(A) if A is not None else A_sharp
    if dA is not None and D is not None and Au > 0:
        m = reduced_area_difference(float(dA), Au, float(D))
    else:
        m = sharp_m
    return {
        "components": nc,
        "genus": genus,
        "nested": any(k is not None for k in inside_of),
        "inside_of": inside_of,
        "wraps": list(S.wraps),
        "reduced_volume": reduced_volume(Vu, Au),
        "reduced_area_difference": m,
        "arms": (arms[0] if arms[0] is not None else 0) if nc else 0,
        "arms_per_component": arms,
        "area_per_component": areas,
        "sources": sources,
        "sharp": {"V": V_sharp, "A": A_sharp, "mean_curvature_integral": H_total,
                  "reduced_volume": reduced_volume(V_sharp, A_sharp),
                  "reduced_area_difference": sharp_m},
        "shift": list(S.shift),
    } | _with_label(S, nc, genus, inside_of, arms)


def _per_component(S: Surface, arm_threshold: float):
    """Per component, largest first: genus, arms (None if it wraps), area and enclosed
    volume (None if it wraps); and the mean curvature integral of them all."""
    genus, arms, areas, closed_vols = [], [], [], []
    area_t = np.linalg.norm(S.triangle_normals(), axis=1) if S.n_components else np.zeros(0)
    H_total = 0.0
    for c in range(S.n_components):
        mask = S.component == c
        chi = euler_characteristic(S.tri[mask])
        genus.append(int(round((2 - chi) / 2)))
        areas.append(float(area_t[mask].sum()))
        H_total += _mean_curvature_integral(S, mask)
        if S.wraps[c]:
            arms.append(None)
            closed_vols.append(None)
        else:
            arms.append(count_arms(S, c, threshold=arm_threshold))
            closed_vols.append(_signed_volume(S, mask)[0])
    return genus, arms, areas, closed_vols, H_total


def _nesting(S: Surface, areas: list[float]) -> list[int | None]:
    """Per component: the smallest closed component enclosing it (a vertex of it inside),
    or None."""
    nc = S.n_components
    inside_of: list[int | None] = [None] * nc
    tris = S.points[S.faces]
    for i in range(nc):
        if S.wraps[i]:
            continue
        probe = S.points[S.faces[S.component == i][0, 0]]
        best = None
        for j in range(nc):
            if j == i or S.wraps[j]:
                continue
            if abs(winding_number(probe, tris[S.component == j])) >= 0.5:
                if best is None or areas[j] < areas[best]:
                    best = j
        inside_of[i] = best
    return inside_of


def _with_label(S, nc, genus, inside_of, arms) -> dict:
    body = body_geometry(S) if nc else None
    first = (arms[0] if arms[0] is not None else 0) if nc else 0
    d = {"components": nc, "genus": genus, "nested": any(k is not None for k in inside_of),
         "arms": first, "body": body}
    return {"body": body, "label": classify(d)}


#: a neck: a minimum of the cross-section area along the long axis below this fraction of the
#: smaller of the maxima on either side
NECK_RATIO = 0.85
#: biconcave: the centre's thickness is below (1 − this) of the largest thickness
DIMPLE = 0.08
#: elongation a₁/a₂ above which a body is prolate, and cylinder when also without necks
PROLATE, CYLINDER = 1.15, 2.2
#: flatness a₃/a₂ below which a body is oblate
OBLATE = 0.85
#: |skewness along the axis| above which an elongated body without a neck is a pear (a
#: prolate has 0; sharp_ref's pear at v = 0.85 next to where it leaves the prolate, 0.2)
PEAR = 0.1
#: a pole is invaginated when it lies more than this fraction of the body's height below the
#: highest point on its side; a stomatocyte has one such pole, a discocyte two
INVAGINATED = 0.02


def count_necks(area: np.ndarray) -> tuple[int, float]:
    """(necks, the smallest ratio): the minima of a cross-section area profile below
    :data:`NECK_RATIO` of the smaller of the largest areas on either side, one per minimum
    however flat."""
    necks, worst = 0, 1.0
    i = 1
    while i < len(area) - 1:
        if area[i] <= area[i - 1] and area[i] <= area[i + 1] and area[i] > 0:
            ratio = area[i] / min(area[:i].max(), area[i + 1:].max())
            if ratio < NECK_RATIO:
                necks += 1
                worst = min(worst, float(ratio))
                while i < len(area) - 1 and area[i + 1] <= area[i] * (1 + 1e-9) + 1e-300:
                    i += 1  # one neck per minimum, however flat
        i += 1
    return necks, worst


def body_geometry(S: Surface) -> dict | None:
    """Principal semi-axes, necks and dimple of the largest region {φ > 0} (None if there is
    none, or it winds around the periodic box). See the module docstring."""
    region = S.phi > 0
    labels, count = ndimage.label(region)
    if count == 0:
        return None
    sizes = np.bincount(labels.ravel())[1:]
    mask = labels == 1 + int(np.argmax(sizes))
    idx = np.argwhere(mask)
    if any(idx[:, a].min() == 0 and idx[:, a].max() == S.phi.shape[a] - 1 for a in range(3)):
        return None  # it spans an axis of the box: no finite body to measure
    if len(idx) < 27:
        return None  # a few grid cells: too small to measure
    X = S.origin + idx * S.h
    c = X.mean(axis=0)
    Y = X - c
    lam, vec = np.linalg.eigh(Y.T @ Y / len(Y))
    lam, vec = lam[::-1], vec[:, ::-1]  # a₁ ≥ a₂ ≥ a₃
    axes = np.sqrt(5.0 * np.maximum(lam, 0.0))
    h = float(S.h.min())
    cell = float(np.prod(S.h))
    # cross-section area along the long axis
    s1 = Y @ vec[:, 0]
    bins = np.arange(s1.min() - h, s1.max() + 2 * h, h)
    area = np.convolve(np.histogram(s1, bins)[0] * cell / h, np.ones(3) / 3, mode="same")
    necks, worst = count_necks(area)
    # thickness across the short axis along lines parallel to it, as a function of their
    # distance ρ from the centroid (8 directions, φ by trilinear interpolation)
    t = np.arange(-axes[0] - 2 * h, axes[0] + 2 * h, 0.5 * h)
    rhos = np.arange(0.0, max(axes[0], h), h)
    angles = np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)
    offsets = (np.cos(angles)[:, None] * vec[:, 0] + np.sin(angles)[:, None] * vec[:, 1])
    pts = (c + rhos[:, None, None, None] * offsets[None, :, None, :]
           + t[None, None, :, None] * vec[:, 2])
    inside = S.phi_at(pts) > 0
    thickness = inside.sum(axis=2).mean(axis=1) * 0.5 * h
    dimple = float(1.0 - thickness[0] / thickness.max()) if thickness.max() > 0 else 0.0
    return {"semi_axes": [float(a) for a in axes],
            "elongation": float(axes[0] / axes[1]), "flatness": float(axes[2] / axes[1]),
            "necks": necks, "neck_ratio": worst, "dimple": dimple}


def classify(d: dict) -> str:
    """One name for the descriptors of a 3D surface (:func:`describe`) or of an
    axisymmetric run's meridians (:func:`fem_ade.analysis.axishape.describe_meridians`):
    the one decision tree of both geometries (the module docstring). What only the meridians
    can tell — an invaginated pole (``pole_depths``: a stomatocyte) and the skewness along
    the axis (a pear) — is asked where the descriptors hold it."""
    nc = d["components"]
    if nc == 0:
        return "no membrane"
    if any(d.get("wraps", ())):
        return "wrapping"
    if d["nested"]:
        return "nested"
    if nc > 1:
        return f"{nc} vesicles"
    g = d["genus"][0]
    if g:
        return "torus" if g == 1 else f"genus-{g}"
    if d["arms"] >= 3:
        return f"starfish-{d['arms']}"
    body = d.get("body")
    if body is None:
        return "wrapping"
    if body["necks"] >= 2:
        return "chain"
    if body["necks"] == 1:
        return "gourd"
    if "pole_depths" in d:
        top, bottom, height = d["pole_depths"][:3]
        dented = [x > INVAGINATED * height for x in (top, bottom)]
        if any(dented) and not all(dented):
            return "stomatocyte"
    if body["elongation"] > PROLATE:
        if body["elongation"] > CYLINDER:
            return "cylinder"
        return "pear" if abs(body.get("skewness", 0.0)) > PEAR else "prolate"
    if body["flatness"] < OBLATE:
        return "discocyte" if body["dimple"] > DIMPLE else "oblate"
    return "sphere"


def summary_line(d: dict, given: str = "given V, A, ΔA") -> str:
    """A one-line human summary of :func:`describe`'s result (sharp values always shown)."""
    nc = d["components"]
    g = ", ".join(str(x) for x in d["genus"]) or "-"
    head = (f"{nc} component{'s' if nc != 1 else ''}, genus {g}"
            f"{', nested' if d['nested'] else ''}, arms = {d['arms']}")
    sharp = d["sharp"]
    sharp_part = (f"v = {sharp['reduced_volume']:.3f}, Δa = "
                  f"{sharp['reduced_area_difference']:.3f} (sharp surface)")
    src = d["sources"]
    parts = []
    if src["V"] == "given" or src["A"] == "given":
        parts.append(f"v = {d['reduced_volume']:.3f}")
    if src["dA"] == "given":
        parts.append(f"Δa = {d['reduced_area_difference']:.3f}")
    if not parts:
        return f"{head}; {sharp_part}"
    return f"{head}; {sharp_part}; {', '.join(parts)} ({given})"
