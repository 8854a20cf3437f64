"""The membrane {φ = 0} of a phase field on a periodic uniform grid, as a closed triangulated
surface, and the measures of its components.

:func:`extract_surface` returns the surface (a :class:`Surface`), which
:mod:`fem_ade.analysis.shape` describes and :mod:`fem_ade.plots.render` draws. The measures of
one component are here too: its Euler characteristic, its mean curvature integral, the volume
it encloses, winding numbers about it, and its number of arms (:func:`count_arms`, by a merge
tree of lobes).

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

Why a module of its own: this is the geometry of a triangulated surface (extraction, periodic
identification, orientation, a component's topology and measures, the lobe tree), and it knows
no label or threshold of a shape. :mod:`fem_ade.analysis.shape` turns these measures into the
descriptors and the label, and this module imports nothing of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

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


def mean_curvature_integral(S: Surface, mask: np.ndarray) -> float:
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


def signed_volume(S: Surface, mask: np.ndarray) -> tuple[float, np.ndarray]:
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
    vol, moment = signed_volume(S, mask)
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

