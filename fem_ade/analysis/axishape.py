"""Shape descriptors of an axisymmetric run: the meridians {φ = 0} of its (r, z) field.

The counterpart of :mod:`fem_ade.analysis.shape` for the axisymmetric geometry (docs/model.md §11),
with the same keys (``components``, ``genus``, ``nested``, ``reduced_volume``,
``reduced_area_difference``, ``arms``, ``label``, ``body``, ``sharp``), computed from curves
in the half-plane instead of a triangulated 3D surface — exact to the element's interpolant:

1. **Contours.** φ is interpolated (the element's own interpolant) onto the node grid
   refined :data:`REFINE` times per gap, contoured at 0 (``contourpy``), and every vertex is
   moved onto the zero set of the interpolant itself by Newton steps along ∇φ.
2. **Kinds.** A curve from the axis to the axis is a body of genus 0 (its meridian, pole to
   pole); a closed curve off the axis is a torus's tube (genus 1); a curve that reaches the
   domain's outer edge is ``open`` (the membrane leaves the domain: label ``wrapping``). Each
   is oriented with φ > 0 on its left.
3. **Sharp values.** For a meridian (r(s), z(s)) with tangent angle ψ: V = π∮r² dz,
   A = 2π∫r ds, ∮2H dA = 2π∫(r dψ + sin ψ ds) — exact on the polygon for V and A, and
   O(segment²) for the curvature integral; a curve with φ > 0 on its right (a carved-out
   inner vesicle) counts negatively in V and in ∮2H dA, as in :mod:`fem_ade.analysis.shape`.
4. **Body.** The largest region φ > 0 weighted by 2πr: its principal semi-axes (z and any
   direction in the plane), elongation and flatness, necks along z, the dimple (thickness
   along z at the axis over the largest), the skewness of z (a pear), and the depth of each
   pole below the highest point of its side (a stomatocyte's invaginated pole).
5. **Label**: :func:`fem_ade.analysis.shape.classify`, the one decision tree of both
   geometries, which on these descriptors also says ``stomatocyte`` (one pole invaginated)
   and ``pear`` (a prolate whose z-skewness exceeds :data:`fem_ade.analysis.shape.PEAR`):
   what the 3D descriptors do not tell.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fem_ade.analysis.shape import classify, count_necks
from fem_ade.model.params import reduced_area_difference, reduced_volume

#: the contour grid: each gap between nodes split into this many
REFINE = 4


@dataclass
class Meridians:
    """The φ = 0 curves of an (r, z) field and what the picture needs: ``curves`` ((k, 2)
    arrays, φ > 0 on the left), ``kinds`` ("spheroidal", "loop", "open"), the display grid
    ``r``, ``z``, ``phi`` (len(r), len(z)), the domain (R, z₀, z₁) and the fine zone."""

    curves: list
    kinds: list
    r: np.ndarray
    z: np.ndarray
    phi: np.ndarray
    domain: tuple
    fine: tuple | None = None


def _evaluator(space, values):
    """φ of the tensor space's interpolant at points (P, 2), and its gradient by central
    differences of the interpolant."""
    ar, az = space.axes
    Phi = np.reshape(values, space.shape)
    h = 1e-7 * max(ar.length, az.length)

    def at(pts):
        Br = ar.interpolation(pts[:, 0])
        Bz = az.interpolation(pts[:, 1])
        T = Br @ Phi  # (P, N_z)
        return np.asarray(Bz.multiply(T).sum(axis=1)).ravel()

    def grad(pts):
        dr, dz = np.array([h, 0.0]), np.array([0.0, h])
        gr = (at(pts + dr) - at(pts - dr)) / (2 * h)
        gz = (at(pts + dz) - at(pts - dz)) / (2 * h)
        return np.stack([gr, gz], axis=1)

    return at, grad


def _polish(points, at, grad, R, steps: int = 4):
    """Newton steps along ∇φ onto φ = 0 (points on the axis stay on it)."""
    p = points.copy()
    on_axis = p[:, 0] <= 1e-12 * max(R, 1.0)
    for _ in range(steps):
        f, g = at(p), grad(p)
        g2 = np.sum(g * g, axis=1)
        ok = g2 > 0
        step = np.zeros_like(p)
        step[ok] = (f[ok] / g2[ok])[:, None] * g[ok]
        step[on_axis, 0] = 0.0
        if on_axis.any():  # along z only: φ_z
            gz = g[on_axis, 1]
            step[on_axis, 1] = np.where(gz != 0, f[on_axis] / np.where(gz != 0, gz, 1), 0.0)
        p -= step
        p[:, 0] = np.clip(p[:, 0], 0.0, R)
    return p


def meridians(be) -> Meridians:
    """The φ = 0 curves of an axisymmetric backend's current field (module docstring; or of a
    :class:`fem_ade.backends.fem.axisym.SavedField`)."""
    import contourpy

    space = be.space
    ar, az = space.axes
    R, z0, z1 = be.domain

    def refined(nodes):
        t = np.linspace(0.0, 1.0, REFINE + 1)[:-1]
        return np.append((nodes[:-1, None] + np.diff(nodes)[:, None] * t).ravel(), nodes[-1])

    rs, zs = refined(ar.nodes), refined(az.nodes)
    phi = space.interpolate_to([rs, zs])(be.phi)
    gen = contourpy.contour_generator(rs, zs, phi.T, line_type="Separate")
    at, grad = _evaluator(space, be.phi)
    tol = 1e-9 * max(R, z1 - z0)
    curves, kinds = [], []
    for line in gen.lines(0.0):
        if len(line) < 3:
            continue
        closed = np.allclose(line[0], line[-1], atol=tol, rtol=0)
        pts = line[:-1] if closed else line
        if not closed:
            pts = pts.copy()
            for end in (0, -1):  # an end on the axis: exactly on it
                if pts[end, 0] <= 0.5 * (rs[1] - rs[0]):
                    pts[end, 0] = 0.0
        pts = _polish(pts, at, grad, R)
        if closed:
            kind = "loop"
        elif pts[0, 0] == 0.0 and pts[-1, 0] == 0.0:
            kind = "spheroidal"
        else:
            kind = "open"
        # orientation: φ > 0 on the left of the middle segment
        k = len(pts) // 2
        t = pts[min(k + 1, len(pts) - 1)] - pts[k - 1]
        left = np.array([-t[1], t[0]]) / max(np.hypot(*t), 1e-300)
        mid = pts[k]
        probe = at(np.array([mid + 1e-3 * be.params.eps * left]))[0]
        if probe < 0:
            pts = pts[::-1].copy()
        curves.append(pts)
        kinds.append(kind)
    fine = getattr(be.mesh, "fine", None)
    return Meridians(curves, kinds, rs, zs, phi, (R, z0, z1), fine)


def curve_integrals(pts: np.ndarray, closed: bool) -> dict:
    """V, A and ∮2H dA of the surface of revolution of one oriented meridian (module
    docstring; a spheroidal curve is closed along the axis, which adds nothing)."""
    P = np.vstack([pts, pts[:1]]) if closed else pts
    r1, z1, r2, z2 = P[:-1, 0], P[:-1, 1], P[1:, 0], P[1:, 1]
    dr, dz = r2 - r1, z2 - z1
    ds = np.hypot(dr, dz)
    V = math.pi * float(np.sum((r1 * r1 + r1 * r2 + r2 * r2) / 3.0 * dz))
    A = math.pi * float(np.sum((r1 + r2) * ds))
    psi = np.arctan2(dz, dr)
    turn = np.diff(np.append(psi, psi[0]) if closed else psi)
    turn = (turn + math.pi) % (2.0 * math.pi) - math.pi
    r_vertex = P[1:, 0] if closed else P[1:-1, 0]
    M = 2.0 * math.pi * float(np.sum(r_vertex * turn) + np.sum(np.sin(psi) * ds))
    # a curve with φ > 0 on its right encloses a carved-out region: V < 0, and its normal
    # (out of φ > 0) points into it, so its ∮2H dA has the opposite sign (as in 3D)
    return {"V": V, "A": A, "M": M}


def _inside(point, pts: np.ndarray, closed: bool) -> bool:
    """Whether ``point`` (r, z) lies in the region the curve bounds (with the axis segment)."""
    P = pts if closed else np.vstack([pts, [[0.0, pts[-1, 1]], [0.0, pts[0, 1]]]])
    r, z = point
    (r1, z1), (r2, z2) = P.T, np.roll(P, -1, axis=0).T
    crosses = (z1 > z) != (z2 > z)
    with np.errstate(divide="ignore", invalid="ignore"):
        at = r1 + (z - z1) * (r2 - r1) / (z2 - z1)
    return bool(np.count_nonzero(crosses & (r < at)) % 2)


def _inside_length(phi: np.ndarray, x: np.ndarray, weight=None) -> np.ndarray:
    """Per row of ``phi`` (rows along the last axis, sampled at ``x``): the measure of
    {φ > 0} along x, with φ linear between samples — ∫ dx, or with ``weight="r"`` π∫2x dx
    (a cross-section's area)."""
    out = np.zeros(phi.shape[0])
    for i, row in enumerate(phi):
        pos = row > 0
        if not pos.any():
            continue
        edges = np.flatnonzero(pos[1:] != pos[:-1])
        cuts = x[edges] - row[edges] * (x[edges + 1] - x[edges]) / (row[edges + 1] - row[edges])
        bounds = np.sort(np.concatenate([cuts, x[[0]] if pos[0] else [], x[[-1]] if pos[-1]
                                         else []]))
        a, b = bounds[0::2], bounds[1::2]
        out[i] = np.sum(b - a) if weight is None else math.pi * np.sum(b * b - a * a)
    return out


def _moments(pts: np.ndarray, closed: bool) -> tuple[float, float, float, float]:
    """∫ dV, ∫ z dV, ∫ z² dV, ∫ z³ dV and ∫ r² dV over the solid of revolution the oriented
    curve bounds (Green: ∫∫ f 2πr dr dz = ∮ Q dz with ∂Q/∂r = 2πr f), by 3-point Gauss
    rules on its segments."""
    P = np.vstack([pts, pts[:1]]) if closed else pts
    g, gw = np.polynomial.legendre.leggauss(4)
    t, gw = 0.5 * (g + 1.0), 0.5 * gw
    a, b = P[:-1], P[1:]
    r = a[:, None, 0] + t[None, :] * (b - a)[:, None, 0]
    z = a[:, None, 1] + t[None, :] * (b - a)[:, None, 1]
    dz = (b - a)[:, 1][:, None]
    base = math.pi * r * r * dz * gw[None, :]
    m = [float(np.sum(base * z**k)) for k in range(4)]
    rr = float(np.sum(0.5 * math.pi * r**4 * dz * gw[None, :]))
    return m[0], m[1], m[2], m[3], rr


def body_geometry(M: Meridians) -> dict | None:
    """Semi-axes, elongation, flatness, necks, dimple and z-skewness of the body bounded by
    the largest closed meridian (module docstring), or None."""
    closed = [i for i, k in enumerate(M.kinds) if k != "open"]
    if not closed:
        return None
    areas = [curve_integrals(M.curves[i], M.kinds[i] == "loop")["A"] for i in closed]
    c = closed[int(np.argmax(areas))]
    pts, loop = M.curves[c], M.kinds[c] == "loop"
    V, Mz, Mzz, Mzzz, Mrr = _moments(pts, loop)
    if not V > 0:
        return None
    zbar = Mz / V
    var_z = max(Mzz / V - zbar * zbar, 0.0)
    third = Mzzz / V - 3 * zbar * Mzz / V + 2 * zbar**3
    skew = third / var_z**1.5 if var_z > 0 else 0.0
    var_x = Mrr / V / 2.0
    a_z, a_x = math.sqrt(5.0 * var_z), math.sqrt(5.0 * var_x)
    axes = sorted([a_z, a_x, a_x], reverse=True)
    lo, hi = pts[:, 1].min(), pts[:, 1].max()
    rows = (M.z >= lo) & (M.z <= hi)
    necks, worst = 0, 1.0
    if a_z >= a_x and rows.sum() >= 3:  # cross-section areas along z
        necks, worst = count_necks(_inside_length(M.phi[:, rows].T, M.r, weight="r"))
    cols = M.r <= pts[:, 0].max()
    thickness = _inside_length(M.phi[cols][:, rows], M.z[rows])  # along z, at each r
    dimple = float(1.0 - thickness[0] / thickness.max()) if thickness.max() > 0 else 0.0
    return {"semi_axes": axes, "elongation": axes[0] / axes[1], "flatness": axes[2] / axes[1],
            "necks": necks, "neck_ratio": worst, "dimple": dimple, "skewness": skew}


def pole_depths(pts: np.ndarray) -> tuple[float, float, float]:
    """(top, bottom, height): how far each pole of a spheroidal meridian lies inside the body
    (below the curve's highest point for the top pole, above its lowest for the bottom one)
    and the body's height."""
    z = pts[:, 1]
    top, bottom = max(z[0], z[-1]), min(z[0], z[-1])
    return float(z.max() - top), float(bottom - z.min()), float(z.max() - z.min())


def describe_meridians(M: Meridians, *, V=None, A=None, dA=None, D=None) -> dict:
    """The descriptors of :func:`fem_ade.analysis.shape.describe` from the meridians (module
    docstring); ``V``, ``A``, ``dA``, ``D`` as there (the diffuse values, else the sharp)."""
    ints = [curve_integrals(c, k == "loop") for c, k in zip(M.curves, M.kinds, strict=True)]
    nc = len(M.curves)
    wraps = [k == "open" for k in M.kinds]
    genus = [1 if k == "loop" else 0 for k in M.kinds]
    areas = [i["A"] for i in ints]
    order = np.argsort(areas)[::-1]  # largest area first, as in 3D
    inside_of: list[int | None] = [None] * nc
    for i in range(nc):
        if wraps[i]:
            continue
        probe = M.curves[i][len(M.curves[i]) // 2]
        best = None
        for j in range(nc):
            if j == i or wraps[j]:
                continue
            if _inside(probe, M.curves[j], M.kinds[j] == "loop"):
                if best is None or areas[j] < areas[best]:
                    best = j
        inside_of[i] = best
    A_sharp = float(sum(areas))
    V_sharp = float(sum(i["V"] for i in ints))
    H_total = 0.5 * float(sum(i["M"] for i in ints))  # ∫H dA
    R0 = math.sqrt(A_sharp / (4.0 * math.pi)) if A_sharp > 0 else math.nan
    sharp_m = H_total / (4.0 * math.pi * R0) if A_sharp > 0 else math.nan
    Vu = float(V) if V is not None else V_sharp
    Au = float(A) if A is not None else A_sharp
    m = (reduced_area_difference(float(dA), Au, float(D))
         if dA is not None and D is not None and Au > 0 else sharp_m)
    rank = {int(j): k for k, j in enumerate(order)}
    body = body_geometry(M) if nc else None
    first = int(order[0]) if nc else None
    depths = pole_depths(M.curves[first]) if nc and M.kinds[first] == "spheroidal" else \
        (0.0, 0.0, 1.0)
    d = {
        "geometry": "axisymmetric",
        "components": nc,
        "genus": [genus[j] for j in order],
        "nested": any(k is not None for k in inside_of),
        "inside_of": [None if inside_of[j] is None else rank[inside_of[j]] for j in order],
        "wraps": [wraps[j] for j in order],
        "reduced_volume": reduced_volume(Vu, Au) if Au > 0 else math.nan,
        "reduced_area_difference": m,
        "arms": 1 if nc else 0,
        "arms_per_component": [1] * nc,
        "area_per_component": [areas[j] for j in order],
        "sources": {"V": "given" if V is not None else "sharp",
                    "A": "given" if A is not None else "sharp",
                    "dA": "given" if (dA is not None and D is not None) else "sharp"},
        "sharp": {"V": V_sharp, "A": A_sharp, "mean_curvature_integral": H_total,
                  "reduced_volume": reduced_volume(V_sharp, A_sharp) if A_sharp > 0
                  else math.nan,
                  "reduced_area_difference": sharp_m},
        "body": body,
        "pole_depths": list(depths),
        "kinds": [M.kinds[j] for j in order],
    }
    d["label"] = classify(d)
    return d


def describe_axisymmetric(be, final: dict, grid=None):
    """(shape, (φ revolved on the box's grid, the meridians, the descriptors)) of an
    axisymmetric backend's final state: what :func:`fem_ade.engine.execute.describe_final` gives for
    a 3D run, from the (r, z) field (module docstring)."""
    from fem_ade.analysis.shape import SHAPE_KEYS

    p = be.scene.params
    if not np.all(np.isfinite(be.phi)):
        return None, (None, None, None)
    M = meridians(be)
    d = describe_meridians(M, V=final.get("V"), A=final.get("A"),
                           dA=final.get("dA") if p.on("ade") else None, D=p.D)
    shape = {k: d["sharp"][k] if k in d["sharp"] else d[k] for k in SHAPE_KEYS}
    shape["diffuse"] = {k: d[k] for k in ("reduced_volume", "reduced_area_difference")}
    shape["sharp"] = d["sharp"]
    shape["geometry"] = "axisymmetric"
    shape["fine_zone"] = be.fine_zone_report()["inside"]
    return shape, (be.grid_phi() if grid is None else grid, M, d)


# ---------------------------------------------------------------------------------------------
# the picture: the surface of revolution (what fem_ade.plots.render draws for a 3D run's Surface)
# ---------------------------------------------------------------------------------------------
class RevolvedSurface:
    """The meridians revolved about z into triangulated surfaces, with the few members of
    :class:`fem_ade.analysis.surface.Surface` that :mod:`fem_ade.plots.shapes`' 3D views use
    (``n_components``, ``component_mesh``, ``outward_normals_at``, ``points``, ``origin``,
    ``L``, ``h``); ``axis`` (x, y) places them in the scene's box."""

    def __init__(self, M: Meridians, axis=(0.0, 0.0), L: float = 1.0, angles: int = 96,
                 order=None):
        self.L = L
        self._meshes, self._normals = [], []
        curves = [(c, k) for c, k in zip(M.curves, M.kinds, strict=True) if k != "open"]
        if order is not None:
            curves = [curves[j] for j in order if j < len(curves)]
        th = np.linspace(0.0, 2.0 * math.pi, angles, endpoint=False)
        for pts, kind in curves:
            pts = _resample(pts, kind == "loop", 240)
            closed = kind == "loop"
            t = np.diff(np.vstack([pts, pts[:1]]) if closed else pts, axis=0)
            t = np.vstack([t, t[-1:]]) if not closed else t
            tv = 0.5 * (t + np.roll(t, 1, axis=0)) if closed else np.vstack(
                [t[:1], 0.5 * (t[1:-1] + t[:-2]), t[-2:-1]])
            nr, nz = tv[:, 1], -tv[:, 0]  # right of the tangent: out of φ > 0
            norm = np.maximum(np.hypot(nr, nz), 1e-300)
            nr, nz = nr / norm, nz / norm
            r, z = pts[:, 0], pts[:, 1]
            X = axis[0] + r[:, None] * np.cos(th)[None, :]
            Y = axis[1] + r[:, None] * np.sin(th)[None, :]
            Z = np.broadcast_to(z[:, None], X.shape)
            P = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
            N = np.stack([(nr[:, None] * np.cos(th)[None, :]).ravel(),
                          (nr[:, None] * np.sin(th)[None, :]).ravel(),
                          np.broadcast_to(nz[:, None], X.shape).ravel()], axis=1)
            k, m = len(pts), angles
            i, j = np.meshgrid(np.arange(k if closed else k - 1), np.arange(m), indexing="ij")
            a = i * m + j
            b = ((i + 1) % k) * m + j
            c = ((i + 1) % k) * m + (j + 1) % m
            d = i * m + (j + 1) % m
            # wound so that their normals point out of φ > 0 (along s × θ reversed)
            faces = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3),
                                    np.stack([a, d, c], -1).reshape(-1, 3)])
            self._meshes.append((P, faces))
            self._normals.append(N)
        self.n_components = len(self._meshes)
        self.points = (np.vstack([m[0] for m in self._meshes]) if self._meshes
                       else np.zeros((0, 3)))
        self.origin = np.zeros(3)
        self.h = np.full(3, 1e-3 * L)

    def component_mesh(self, c: int) -> tuple[np.ndarray, np.ndarray]:
        return self._meshes[c]

    def outward_normals_at(self, x: np.ndarray) -> np.ndarray:
        """The normal of the nearest vertex (out of φ > 0)."""
        from scipy.spatial import cKDTree

        P = self.points
        N = np.vstack(self._normals)
        _, idx = cKDTree(P).query(np.asarray(x, float))
        return N[idx]


def _resample(pts: np.ndarray, closed: bool, count: int) -> np.ndarray:
    """The curve at ``count`` points evenly spaced in arc length (a picture needs no more)."""
    P = np.vstack([pts, pts[:1]]) if closed else pts
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(P, axis=0).T))])
    if s[-1] <= 0:
        return pts
    t = np.linspace(0.0, s[-1], count + (1 if closed else 0))
    out = np.stack([np.interp(t, s, P[:, 0]), np.interp(t, s, P[:, 1])], axis=1)
    return out[:-1] if closed else out
