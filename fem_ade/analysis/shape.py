"""Shape descriptors of the membrane {φ = 0} of a phase field on a periodic uniform grid.

:func:`describe` answers "what shape is this vesicle?" with a few numbers: how many closed
surfaces there are, the genus of each, whether one lies inside another, the reduced volume
and reduced area difference, and how many arms (lobes) the largest surface has.
The surface itself (extracted, periodically closed and oriented, and a component's
topology, volume, curvature and arms) is :mod:`fem_ade.analysis.surface`'s:
:func:`~fem_ade.analysis.surface.extract_surface` returns it (also for
:mod:`fem_ade.plots.shapes`). This module turns its measures into descriptors, and those into a
label by the thresholds below, the one decision tree of both geometries.

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
* ``arms``: the number of lobes of the largest component, see
  :func:`fem_ade.analysis.surface.count_arms`.
  Convention: a body without arms (sphere, ellipsoid, discocyte, torus) has **1** lobe; a
  three-armed starfish 3, a six-armed one 6.
* ``body``: the geometry of the largest region φ > 0 (:func:`body_geometry`): its principal
  semi-axes a₁ ≥ a₂ ≥ a₃ (those of the solid ellipsoid with the same second moments),
  ``elongation`` a₁/a₂ and ``flatness`` a₃/a₂, the ``necks`` along the long axis (minima of
  the cross-section area below 85 % of the smaller maximum beside them) and the ``dimple``
  1 − (thickness at the centre)/(largest thickness) across the short axis (> 0: biconcave).
  In 3D also its ``symmetry`` (:func:`fem_ade.analysis.symmetry.symmetry`): which rotations
  about the principal axes (m-fold, m ≤ 8, or axisymmetric) and which mirror planes map φ
  onto itself within :data:`~fem_ade.analysis.symmetry.SYMMETRY_TOL`, and the Schoenflies
  ``group`` they make (Kh for a sphere, D∞h for a prolate or oblate, C∞v for a pear, D2h
  for a triaxial ellipsoid, D3h/D4h for a flat three-/four-armed starfish, …).
* ``label``: a name for all of it (:func:`classify`, the one decision tree of both
  geometries): sphere, prolate, oblate, discocyte, cylinder, gourd, chain, torus, genus-g,
  starfish-k, nested, k vesicles, wrapping, no membrane, ellipsoid (a triaxial one: see
  :func:`classify`); and from an axisymmetric run's meridians also stomatocyte and pear.
"""

from __future__ import annotations

import math

import numpy as np

from fem_ade.analysis.surface import (
    Surface,
    count_arms,
    euler_characteristic,
    extract_surface,
    mean_curvature_integral,
    signed_volume,
    winding_number,
)
from fem_ade.analysis.symmetry import Frame, principal_frame, symmetry
from fem_ade.model.params import reduced_area_difference, reduced_volume

#: summary.json → shape: the descriptors of the sharp surface kept at its top level
SHAPE_KEYS = ("components", "genus", "nested", "reduced_volume", "reduced_area_difference",
              "arms", "label", "body")


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
    ``arms_per_component``, ``area_per_component``, ``body`` (:func:`body_geometry` and its
    ``symmetry``, None without a finite body), ``label``, ``sources`` and ``sharp`` (V, A,
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
        H_total += mean_curvature_integral(S, mask)
        if S.wraps[c]:
            arms.append(None)
            closed_vols.append(None)
        else:
            arms.append(count_arms(S, c, threshold=arm_threshold))
            closed_vols.append(signed_volume(S, mask)[0])
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
    frame = principal_frame(S) if nc else None
    body = body_geometry(S, frame) if frame is not None else None
    if body is not None:
        body["symmetry"] = symmetry(S, frame=frame)
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


def body_geometry(S: Surface, frame: Frame | None = None) -> dict | None:
    """Principal semi-axes, necks and dimple of the largest region {φ > 0} (None if there is
    none, or it winds around the periodic box), in its :func:`principal_frame` (``frame``:
    a precomputed one). See the module docstring."""
    F = frame if frame is not None else principal_frame(S)
    if F is None:
        return None
    c, vec, axes = F.centre, F.axes, F.semi_axes
    Y = F.points - c
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
    the axis (a pear) — is asked where the descriptors hold it; and what only a 3D body
    can be — triaxial: elongated (a₁/a₂ > :data:`PROLATE`, up to :data:`CYLINDER`) and
    flat (a₃/a₂ < :data:`OBLATE`) with the symmetry D2h of an ellipsoid with three
    different axes (so no axisymmetric axis: ``body["symmetry"]``) — is ``ellipsoid``
    where it would otherwise be prolate."""
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
        if body["flatness"] < OBLATE and symmetry_group(d) == "D2h":
            return "ellipsoid"
        return "pear" if abs(body.get("skewness", 0.0)) > PEAR else "prolate"
    if body["flatness"] < OBLATE:
        return "discocyte" if body["dimple"] > DIMPLE else "oblate"
    return "sphere"


def symmetry_group(d: dict) -> str | None:
    """The Schoenflies name of the body's symmetry in :func:`describe`'s result or in
    summary.json's ``shape`` (None where there is none: no finite body, or an axisymmetric
    run's descriptors)."""
    return ((d.get("body") or {}).get("symmetry") or {}).get("group")


def summary_line(d: dict, given: str = "given V, A, ΔA") -> str:
    """A one-line human summary of :func:`describe`'s result (sharp values always shown;
    the body's symmetry group where there is one)."""
    nc = d["components"]
    g = ", ".join(str(x) for x in d["genus"]) or "-"
    group = symmetry_group(d)
    head = (f"{nc} component{'s' if nc != 1 else ''}, genus {g}"
            f"{', nested' if d['nested'] else ''}, arms = {d['arms']}"
            f"{f', symmetry {group}' if group else ''}")
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

