"""Where the discocyte's rim modes lead at v = 0.7, ε = 0.01: a four-armed starfish on the
octant, and how its energy stands against the axisymmetric shapes (issue 44: the paper's
starfish).

``starfish.py`` found the discocyte's blocks m = 2 … 6 unstable at its rim at v = 0.7,
ε = 0.01 (κ̄/κ = 1.4, R₀ = 0.2), and left them unfollowed: a 3D run there on the periodic box
at 2.56 nodes per ε was beyond that session. A four-armed shape has the mirrors x, y and z
(cos 4θ with θ₀ = 0, and the disc's equator), so it lies in the octant's sector
(:mod:`fem_ade.backends.fem.octant`): an eighth of the unknowns.

- **The lines** (the (r, z) FEM, order 8, 2.5 nodes per ε, blocks m ≤ 4): the discocyte
  from Δa₀ = 1.0 to 1.6 (``--branch oblate``), and the prolate (``--branch prolate``) from
  1.3 to 1.7: at v = 0.7 the prolate is the lowest axisymmetric branch beyond Δa₀ ≈ 1.2
  (``ade_limit.md``).
- **The switches** (``fem_ade.switch --point I --mode m``): from the discocyte at Δa₀ = 1.6,
  where its blocks m = 4, 3, 2 are unstable (−1.5e-4, −1.1e-4, −4.9e-5), the flow from
  φ + 0.1 ψ_m cos mθ for m = 4 and m = 2 on the octant (order 8, 1.92 nodes per ε); for
  m = 3 on the box (no mirror pair x, y; 128³ nodes of order 4) from Δa₀ = 1.36, and for
  m = 6 on the octant from a second discocyte line (Δa₀ 1.55 … 1.84, blocks m ≤ 6) at
  1.72, each capped where the flow was stopped (:data:`M3_STEPS`, :data:`M6_STEPS`).
- **The ε ladder**: the m = 4 flow's end reseeded at ε = 0.02 and 0.014 (the same v, Δa₀,
  R₀; the octant at 1.92 nodes per ε), each run to its steady state, beside the (r, z)
  prolate at that ε/R₀ (:data:`LADDER_R0`: at R₀ = 0.2 it does not fit the unit box).

Each end: its label, genus, arms, symmetry, its arms' width and thickness in units of ε
(:func:`arm_geometry`), e beside the (r, z) discocyte's and prolate's at its Δa₀, and on the
octant the m = 4 ends' stability in the sector (perturbations even in x, y and z: a lower
bound on the 3D count; Newton's polish first, ``fem_ade.stability``). **The directions**
(:func:`directions`): at ε = 0.02 the end's three lowest sector eigenvectors, their parity
under x ↔ y and their shape at the membrane, and where the flow from the end kicked along
each goes (which way the saddle leads, and a kick that should return). **The whole box**
(:func:`box_end`): the ε = 0.02 end unfolded onto the periodic box (96³ nodes of order 8),
run to steady there and its stability computed with no mirror imposed: the full 3D count.

**Hypothesis**: the m = 4 rim mode leads to a four-armed starfish that is a steady state of
the model at ε = 0.01, with arms many ε wide (so not the phase field's pinching); it is
higher in energy than the prolate (the (r, z) lowest) at its (v, Δa₀). **Control**: the
m = 2 flow on the same octant ends on the prolate (its e equal to the (r, z) prolate's within
the octant mesh's error), which measures that error.

Writes ``OUT/starfish_octant.md`` (with the hand-written ``OUT/starfish_octant_notes.md``),
``.json`` and ``starfish_octant-shapes.png`` (the ends, rendered); the branch and run
folders in ``OUT/starfish_octant/`` (not committed; each run resumes from its checkpoint).

    python studies/starfish_octant.py --out studies/results   # ~4.5 h on one core
    python studies/starfish_octant.py --quick                 # a short line, 10 steps, ~40 s
"""

from __future__ import annotations

from _lib.cli import one_thread, results, study_parser, write_report

one_thread(fft=False)

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from _lib.branches import branch_rows, e_at, make_branch  # noqa: E402
from fem_ade.campaigns.stability import count_text  # noqa: E402

OUT = Path("runs") / "studies"
V, KBAR, R0, EPS = 0.7, 1.4, 0.2, 0.01
#: the (r, z) lines: (branch, Δa₀ from, to, step)
LINES = (("oblate", 1.0, 1.6, 0.05), ("prolate", 1.3, 1.7, 0.05))
QUICK_LINES = (("oblate", 1.45, 1.46, 0.01),)
#: the switches: (m, geometry, the discocyte's Δa₀ to start from (its nearest point), the
#: end's stability or not: the sector's at 97³ unknowns took 13 min beside two other runs,
#: and m = 2's end is the control, its e the point; a cap on the steps or None). The caps:
#: where this session stopped the m = 3 flow (the box, ~1 s a step) and the m = 6 one,
#: which had left along m = 2 by then (the notes)
M3_STEPS, M6_STEPS = 3942, 2521
#: the quick mode's meshes (nodes per L) and steps: the plumbing only
QUICK_N, QUICK_STEPS = 128, 10
SWITCHES = ((4, "octant", 1.6, True, None), (2, "octant", 1.6, False, None),
            (3, "cartesian", 1.36, False, M3_STEPS), (6, "octant", 1.72, False, M6_STEPS))
QUICK_SWITCHES = ((4, "octant", 1.45, False, QUICK_STEPS),)
#: the discocyte past Δa₀ = 1.6 with its blocks up to m = 6 (m = 6 opens at 1.64): the line
#: the m = 6 switch starts from (m = 6, even, has the octant's mirrors with θ₀ = 0); m = 3
#: needs the box (128³ nodes of order 4: its end's stability, 2M unknowns, not computed)
M6_LINE, M6_MODES = ("oblate", 1.55, 1.75, 0.05), 6
#: the ε ladder: the m = 4 end reseeded at these ε (octant, 1.92 nodes per ε)
LADDER = (0.02, 0.014)
#: the ladder's (r, z) prolate: at R₀ = 0.2 it does not fit the unit box at ε = 0.014 and
#: 0.02 (the seed's fit rule: 0.1 L + 2ε to spare), so it is followed at this R₀ with ε
#: scaled by it (the same ε/R₀; L/R₀ 6.7 instead of 5)
LADDER_R0 = 0.15
QUICK_LADDER = (0.02,)
#: the starfish's directions: its sector's lowest eigenvectors at this ε of the ladder (the
#: cheapest end), and the flows from the end kicked along each by KICK (max |v| = 1)
DIRECTIONS_EPS, DIRECTIONS, KICK = 0.02, 3, 0.1
#: the box end's lowest eigenvectors characterised (:func:`box_directions`): its four
#: unstable ones and the fifth, at −1.5e-6, just above the threshold
BOX_DIRECTIONS = 5


def _line(root: Path, eps: float, branch: str, start: float, stop: float,
          step: float, r0: float = R0, modes: int = 4) -> dict:
    """One (r, z) line at (V, ``eps``) of radius ``r0`` (its ``eps`` in the study's units,
    ε·R₀/r0 in the run's), its blocks m ≤ ``modes``: its folder and rows (ModelError's line
    if none)."""
    name = ("discocyte" if branch == "oblate" else branch) + ("" if modes == 4 else
                                                               f"-m{modes}")
    run_eps = round(eps * r0 / R0, 10)
    made = make_branch(root / (f"{name}-v={V:g}-eps={eps:g}"
                               + ("" if r0 == R0 else f"-R0={r0:g}")),
                       ["vesicle", "--branch", branch, "--v", str(V), "--kbar", str(KBAR),
                        "--eps", str(run_eps), "--R0", str(r0), "--param", "da0", "--from",
                        str(start), "--to", str(stop), "--step", str(step), "--modes",
                        str(modes)])
    if isinstance(made, str):
        return {"branch": branch, "eps": eps, "failed": made}
    rows = [{"da0": float(r["da0"]), "e": float(r["e"]), "label": r["label"],
             "lowest": [float(f"{float(r[f'lowest_m{m}']):.3g}") for m in range(modes + 1)],
             "unstable_3d": int(r["unstable_3d"])} for r in branch_rows(made)]
    return {"branch": branch, "eps": eps, "failed": None, "folder": str(made), "rows": rows}


def e_at_da0(line: dict | None, da0: float) -> float | None:
    """e of an (r, z) line at Δa₀ (:func:`_lib.branches.e_at` on its (Δa₀, e) points: linear
    between the two about it; None outside, or for a line that failed)."""
    if not line or line["failed"]:
        return None
    return e_at([(r["da0"], r["e"]) for r in line["rows"]], da0)


def arm_geometry(grid, L: float, eps: float) -> dict:
    """A flat body's arms, from φ on a uniform periodic grid (the body away from the box's
    faces): in its mid-plane z = z_c (z_c, and the centre, the mean of the nodes inside),
    R(θ), the distance from the centre to the membrane (φ = 0) along 720 rays; the tips
    (max R) and necks (min R); on the circle of radius r½ = (R_tip + R_neck)/2 the number
    of arcs inside (the arms) and their mean length (the arm's width there); along z through
    the arm at r½ in the tip's direction, and through the centre, the body's thickness. The
    lengths in units of ε."""
    import numpy as np
    from scipy.ndimage import map_coordinates

    n = grid.shape[0]
    h = L / n
    c = np.argwhere(grid > 0).mean(axis=0)
    theta = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    r = np.arange(0.0, n / 2, 0.25)

    def at(x, y, z):
        return map_coordinates(grid, [x, y, z], order=1, mode="grid-wrap")

    rays = at(c[0] + np.outer(np.cos(theta), r), c[1] + np.outer(np.sin(theta), r),
              np.full((theta.size, r.size), c[2]))
    R = r[np.argmax(rays <= 0, axis=1)]
    tip, neck = float(R.max()), float(R.min())
    half = (tip + neck) / 2
    ring = at(c[0] + half * np.cos(theta), c[1] + half * np.sin(theta),
              np.full(theta.size, c[2])) > 0
    arms = int(np.count_nonzero(ring & ~np.roll(ring, 1)))
    width = np.count_nonzero(ring) / theta.size * 2 * np.pi * half / max(arms, 1)
    zs = np.arange(0.0, n, 0.25)

    def thickness(x, y):
        return float(np.count_nonzero(at(np.full(zs.size, x), np.full(zs.size, y), zs) > 0)
                     * 0.25)

    t = float(theta[np.argmax(R)])
    arm_t = thickness(c[0] + half * np.cos(t), c[1] + half * np.sin(t))
    return {"arms": arms, "tip_r": tip * h, "neck_r": neck * h,
            "width_eps": float(width * h / eps), "thickness_eps": arm_t * h / eps,
            "centre_thickness_eps": thickness(c[0], c[1]) * h / eps,
            "tip_over_neck": tip / neck if neck > 0 else None}


def run_switch(root: Path, line: dict, m: int, geometry: str, da0: float,
               quick: bool, cap: int | None = None) -> tuple[Path, int]:
    """The flow from the discocyte's point nearest ``da0`` along block m, to ``cap`` steps
    at most: (its run folder, the point)."""
    from fem_ade.campaigns.switch import switch

    rows = line["rows"]
    k = min(range(len(rows)), key=lambda i: abs(rows[i]["da0"] - da0))
    folder = root / f"switched-m{m}-eps={line['eps']:g}"
    kw = {"n": QUICK_N} if quick else {}
    if cap is not None:
        kw["max_steps"] = cap
    # a finished flow is kept, an interrupted one resumed (switch continues its own folder)
    switch(line["folder"], None, folder, point=k, mode=m, quiet=True, geometry=geometry, **kw)
    return folder, k


def run_reseed(root: Path, source: Path, eps: float, da0: float, quick: bool,
               geometry: str = "octant") -> Path:
    """The run from ``source``'s end at ε = ``eps`` (the same v, Δa₀, R₀; the switch's order
    and nodes per ε, on the octant or, ``geometry="cartesian"``, the whole box: the octant's
    field unfolded by its mirrors), to a steady state as the switch's flows
    (:func:`fem_ade.engine.jobs.ensure`: a finished run kept, an interrupted one resumed)."""
    from fem_ade.campaigns.switch import OCTANT_ORDER, UNTIL_STEADY, octant_nodes
    from fem_ade.engine.jobs import ensure
    from fem_ade.engine.runs import recipe
    from fem_ade.scenes.catalogue import vesicle_scene

    folder = root / (f"reseeded-m4-eps={eps:g}" if geometry == "octant"
                     else f"boxed-m4-eps={eps:g}")
    # seeded on the oblate (the prolate's seed does not fit the box at ε = 0.02); the scene
    # and options given as they are, so that a finished folder is checked against them
    scene = vesicle_scene(v=V, da0=da0, kbar=KBAR, eps=eps, R0=R0, branch="oblate")
    options = {**recipe("steady", scene), "until_steady": UNTIL_STEADY, "backend": "fem",
               "n": octant_nodes(scene.params, OCTANT_ORDER),
               "checkpoint_every": 200,
               "backend_options": {"order": OCTANT_ORDER, "geometry": geometry},
               **({"max_steps": QUICK_STEPS} if quick else {})}
    ensure(folder, scene, options=options, after=source).check()
    return folder


def box_end(root: Path, x: dict) -> dict:
    """The reseeded end ``x`` unfolded onto the whole box (the same nodes per L and order)
    and run to steady there, with the box's stability: the count without the sector's
    mirrors (885k unknowns at ε = 0.02; not in the quick mode, where it would be most of
    the study's time)."""
    boxed = run_reseed(root, root / x["folder"], x["eps"], x["da0"], False, "cartesian")
    return {**describe_end(boxed, x["eps"], stability=True), "da0": x["da0"]}


def describe_end(folder: Path, eps: float, stability: bool) -> dict:
    """A 3D run's end: its status, shape, arms (:func:`arm_geometry`), e and (with
    ``stability``) the sector's or the box's lowest eigenvalues after Newton's polish; kept
    in ``folder/end.json`` (the stability of 1M unknowns takes minutes)."""
    import numpy as np

    from fem_ade.analysis.shape import symmetry_group
    from fem_ade.analysis.sharp import reduced_energy
    from fem_ade.campaigns.stability import cartesian, load_state, polish
    from fem_ade.model.params import ModelError

    kept = folder / "end.json"
    if kept.is_file():
        return json.loads(kept.read_text())
    s = json.loads((folder / "summary.json").read_text())
    shape = s["shape"]
    be, _ = load_state(folder)
    out = {"folder": folder.name, "eps": eps, "status": s["status"], "steps": s["steps"],
           "cpu_s": round(s["cpu_s"], 1), "n": s["n"],
           "order": s["backend_info"].get("order"),
           "geometry": s["backend_info"].get("geometry", "cartesian"),
           "label": shape["label"], "genus": shape["genus"], "arms": shape["arms"],
           "symmetry": symmetry_group(shape),
           "semi_axes": (shape.get("body") or {}).get("semi_axes"),
           "e": reduced_energy(s["final"]),
           "geometry_of_arms": arm_geometry(np.asarray(be.grid_phi()), be.params.L, eps),
           "stability": None}
    if stability:
        try:
            steady = polish(be)
            st = cartesian(be)
            out["stability"] = {"newton": steady["newton_iterations"],
                                "unstable": st.unstable_3d,
                                "eigenvalues": [float(x) for x in st.eigenvalues],
                                "seconds": st.seconds["all"]}
        except ModelError as err:
            out["stability"] = {"failed": str(err)}
    kept.write_text(json.dumps(out, indent=1) + "\n")
    return out


def directions(root: Path, folder: Path, quick: bool) -> list[dict]:
    """The end's :data:`DIRECTIONS` lowest sector eigenvectors (after Newton's polish): each
    one's parity under x ↔ y (a mirror of the D4h starfish, its arms along x and y: odd is
    B1, two opposite arms against the other two; even is A1, all four alike), its mean at
    the membrane (|φ| < 0.9) in the mid-plane at θ = 0°, 45°, 90° (the arms' tips, the
    neck, the other arms), and where the flow from the end kicked by :data:`KICK` along it
    goes (the end's own run, from the kicked field; kept, resumed:
    :func:`fem_ade.engine.jobs.ensure`)."""
    from dataclasses import fields

    import numpy as np
    from scipy.spatial import cKDTree

    from fem_ade.campaigns.stability import cartesian, load_state, polish
    from fem_ade.engine.config import RunConfig
    from fem_ade.engine.jobs import ensure
    from fem_ade.engine.runs import read_run

    kept = folder / "directions.json"
    if kept.is_file():
        return json.loads(kept.read_text())
    be, _ = load_state(folder)
    if not quick:
        polish(be)
    st = cartesian(be, k=DIRECTIONS, vectors=True, most=DIRECTIONS)
    X = np.asarray(be.space.doflocs).T
    swap = cKDTree(X).query(X[:, [1, 0, 2]])[1]
    phi0 = be.phi.copy()
    scene, config = read_run(folder)
    options = {f.name: getattr(config, f.name) for f in fields(RunConfig)}
    rows = []
    for j, lam in enumerate(st.eigenvalues):
        v = st.vectors[:, j] / np.max(np.abs(st.vectors[:, j]))
        minus, plus = np.linalg.norm(v - v[swap]), np.linalg.norm(v + v[swap])
        odd = minus > plus
        be._set(phi0 + KICK * v, None)
        start = root / f"kick-{j}-eps={DIRECTIONS_EPS:g}.npz"
        np.savez(start, phi_grid=np.asarray(be.grid_phi()))
        run = root / f"kicked-{j}-eps={DIRECTIONS_EPS:g}"
        ensure(run, scene, options={**options, "phi0": str(start)}).check()
        end = describe_end(run, DIRECTIONS_EPS, stability=False)
        rows.append({"j": j, "eigenvalue": float(lam), "parity": "B1" if odd else "A1",
                     "mixed": float(min(minus, plus) / max(minus, plus)),
                     "at_membrane": _at_membrane(X, phi0, v, be.params.L),
                     "end": end})
    kept.write_text(json.dumps(rows, indent=1) + "\n")
    return rows


def box_directions(folder: Path) -> list[dict]:
    """The box end's :data:`BOX_DIRECTIONS` lowest eigenvectors (Newton's polish first),
    grouped into eigenspaces (eigenvalues equal to 1e-6, relative): each one's D4h irrep
    (:func:`fem_ade.analysis.symmetry.irrep`, its characters) and its largest cosine with a
    rigid motion (the translations and rotations,
    :func:`fem_ade.backends.fem.modes.rigid_motions`, which the stability projects out: a
    direction near one is that motion left over). Kept in
    ``folder/directions.json`` (minutes: 885k unknowns)."""
    import numpy as np

    from fem_ade.analysis.symmetry import d4h_characters, irrep
    from fem_ade.backends.fem.modes import rigid_motions
    from fem_ade.campaigns.stability import cartesian, load_state, polish

    kept = folder / "directions.json"
    if kept.is_file():
        return json.loads(kept.read_text())
    be, _ = load_state(folder)
    polish(be)
    st = cartesian(be, k=BOX_DIRECTIONS, vectors=True, most=BOX_DIRECTIONS)
    X, w = np.asarray(be.space.doflocs), np.asarray(be.space.weights)
    vals, V = np.asarray(st.eigenvalues), st.vectors
    rigid = [r / np.sqrt(np.sum(w * r * r)) for r in rigid_motions(be, be.phi)]
    rows, j = [], 0
    while j < len(vals):
        k = j + 1
        while k < len(vals) and abs(vals[k] - vals[j]) <= 1e-6 * abs(vals[j]):
            k += 1
        S = V[:, j:k]
        chars = d4h_characters(X, w, S, be.params.L)
        Q = S @ np.linalg.cholesky(np.linalg.inv(S.T @ (w[:, None] * S)))  # w-orthonormal
        cosines = [float(np.linalg.norm(Q.T @ (w * r))) for r in rigid]
        name, off = irrep(chars)
        rows.append({"eigenvalues": [float(x) for x in vals[j:k]], "irrep": name,
                     "off": off, "characters": chars, "rigid_cosine": max(cosines)})
        j = k
    kept.write_text(json.dumps(rows, indent=1) + "\n")
    return rows


def _at_membrane(X, phi, v, L: float) -> dict:
    """v's mean at the membrane (|φ| < 0.9) in the mid-plane z = L/2, in wedges of ±4° about
    θ = 0°, 45°, 90° (about the box's centre)."""
    import numpy as np

    c = L / 2
    mid = (np.abs(X[:, 2] - c) < 1e-9) & (np.abs(phi) < 0.9)
    theta = np.degrees(np.arctan2(X[mid, 1] - c, X[mid, 0] - c))
    out = {}
    for a in (0, 45, 90):
        near = np.abs(theta - a) < 4
        out[str(a)] = float(np.mean(v[mid][near])) if near.any() else None
    return out


def figure(result: dict, root: Path, out: Path) -> Path | None:
    """The ends' 3D views (each run's shape.png, its left half), one panel each."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image

    from fem_ade.plots.figures import save_figure

    ends = [x for x in [*result["switches"], *result["ladder"]]
            if (root / x["folder"] / "shape.png").is_file()]
    if not ends:
        return None
    fig, axes = plt.subplots(1, len(ends), figsize=(2.6 * len(ends), 2.6), squeeze=False)
    for ax, x in zip(axes[0], ends, strict=True):
        with Image.open(root / x["folder"] / "shape.png") as im:
            w, h = im.size
            ax.imshow(im.convert("RGB").crop((int(0.08 * w), int(0.3 * h), w // 2,
                                              int(0.85 * h))))
        ax.set_axis_off()
        ax.set_title(f"{_start(x)}, ε = {x['eps']:g}\n{x['label']}, e = {x['e']:.3f}",
                     fontsize=7)
    path = out / "starfish_octant-shapes.png"
    save_figure(fig, path, dpi=90, colours=48, bbox_inches="tight")
    plt.close(fig)
    return path


def _ends(result: dict) -> list[dict]:
    """The 3D ends of the report's table, in its order: the switches, the ladder, the box."""
    return [*result["switches"], *result["ladder"], *result.get("box", [])]


def _start(x: dict) -> str:
    if "m" in x:
        return f"m = {x['m']}"
    return "reseeded" if x["geometry"] == "octant" else "unfolded"


def _stability(x: dict) -> str:
    st = x["stability"]
    if st is None:
        return "not computed"
    if "failed" in st:
        return st["failed"]
    sector = "sector" if x["geometry"] == "octant" else "box"
    return (f"{count_text(st['unstable'], st['eigenvalues'])} unstable ({sector}; lowest "
            f"{', '.join(f'{v:.2g}' for v in st['eigenvalues'][:2])}; {st['seconds']:.0f} s)")


def _row(x: dict, disc: float | None, prolate: float | None) -> str:
    g = x["geometry_of_arms"]
    mesh = (f"{x['geometry']}, {x['n']}/L, p = {x['order']}")

    def vs(e):
        return "—" if e is None else f"{e:.4f} ({x['e'] - e:+.4f})"

    return (f"| {_start(x)} | {x['eps']:g} | {x.get('da0', 0):.4f} | {mesh} | {x['status']}, "
            f"{x['steps']} steps, {x['cpu_s']:.0f} s | {x['label']}, genus "
            f"{', '.join(map(str, x['genus']))}, {x['symmetry']} | {g['arms']} | "
            f"{g['width_eps']:.1f} | {g['thickness_eps']:.1f} | {g['centre_thickness_eps']:.1f}"
            f" | {x['e']:.4f} | {vs(disc)} | {vs(prolate)} | {_stability(x)} |")


def _lines_table(result: dict) -> list[str]:
    out = ["| branch | ε | R₀ | Δa₀ | end | first point unstable in m = 2 | m = 3 | m = 4 | "
           "m = 6 |", "|---|---|---|---|---|---|---|---|---|"]
    for x in result["lines"]:
        if x["failed"]:
            out.append(f"| {x['branch']} | {x['eps']:g} | {x.get('r0', R0):g} | — | "
                       f"{x['failed']} | | | | |")
            continue
        rows = x["rows"]
        first = [next((f"{r['da0']:.3f}" for r in rows if r["lowest"][m] < 0), "stable")
                 if m < len(rows[0]["lowest"]) else "—" for m in (2, 3, 4, 6)]
        out.append(f"| {x['branch']} | {x['eps']:g} | {x.get('r0', R0):g} | "
                   f"{rows[0]['da0']:.3f}–{rows[-1]['da0']:.3f}"
                   f" | {rows[-1]['label']} | " + " | ".join(first) + " |")
    return out


def report(result: dict, out: Path, suffix: str) -> None:
    lines = ["# Where the discocyte's rim modes lead at v = 0.7: starfish on the octant", "",
             "Written by `studies/starfish_octant.py` (its docstring says what it runs). "
             f"v = {V:g}, κ̄/κ = {KBAR:g}, R₀ = {R0:g}. The (r, z) lines (order 8, 2.5 nodes "
             "per ε, blocks m ≤ 4, on the second discocyte line m ≤ 6; a block's first unstable "
             "point on the line):", "",
             *_lines_table(result), "",
             "The 3D ends: the flow from the discocyte's point at Δa₀ along block m (switch), "
             "or from the m = 4 end at another ε (reseeded), or the reseeded end at "
             f"ε = {DIRECTIONS_EPS:g} unfolded onto the whole box by its mirrors (unfolded; "
             "the same nodes per L and order), to a steady state (E changing by "
             "< 1e-13 per step, relative) or the step cap. Arms: on the circle halfway between "
             "the necks and the tips in the mid-plane, the arcs inside, their mean width; the "
             "arm's and the centre's thickness along z; in units of ε. e beside the (r, z) "
             "discocyte's and prolate's at the same Δa₀ and ε (the difference in brackets). "
             "The stability after Newton's polish: the sector's (perturbations even in x, y "
             "and z: a lower bound on the 3D count) or the box's (every perturbation, the "
             "rigid motions projected out); CPU: the flow's, one BLAS thread.", "",
             "| start | ε | Δa₀ | mesh | end | shape | arms | width/ε | arm thickness/ε | "
             "centre thickness/ε | e | e discocyte | e prolate | stability |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    def e_of(branch, x):  # R₀'s lines first, then the ladder's: the first that holds Δa₀
        for line in sorted(result["lines"], key=lambda y: y.get("r0", R0) != R0):
            if not line["failed"] and (line["branch"], line["eps"]) == (branch, x["eps"]):
                e = e_at_da0(line, x["da0"])
                if e is not None:
                    return e
        return None

    for x in _ends(result):
        lines.append(_row(x, e_of("oblate", x), e_of("prolate", x)))
    if not suffix and (out / "starfish_octant-shapes.png").is_file():
        lines += ["", "![the ends](starfish_octant-shapes.png)"]
    lines += _directions_table(result.get("directions") or [])
    lines += _box_directions_table(result.get("box_directions") or [])
    write_report(out, f"starfish_octant{suffix}", lines)


def _directions_table(rows: list[dict]) -> list[str]:
    if not rows:
        return []
    out = ["", f"The starfish's directions at ε = {DIRECTIONS_EPS:g} (the reseeded end, Newton's "
           "polish first): its sector's lowest eigenvectors v (max |v| = 1), each one's parity "
           "under x ↔ y (the arms lie along x and y; B1: odd, two opposite arms against the "
           "other two; A1: even, all four alike), v's mean at the membrane in the mid-plane at "
           "θ = 0° and 90° (arms) and 45° (neck), and the flow from the end kicked by "
           f"{KICK:g} v (the end's own run, to a steady state or its cap):", "",
           "| v | λ | parity | at 0° / 45° / 90° | kicked flow's end | e | e − e(end) |",
           "|---|---|---|---|---|---|---|"]
    for r in rows:
        at, end = r["at_membrane"], r["end"]
        where = " / ".join("—" if at[a] is None else f"{at[a]:+.2f}" for a in ("0", "45", "90"))
        e0 = r.get("e_start")
        diff = "—" if e0 is None else f"{end['e'] - e0:+.1e}"
        out.append(f"| {r['j']} | {r['eigenvalue']:.2e} | {r['parity']} | {where} | "
                   f"{end['label']}, {end['symmetry']} ({end['status']}, {end['steps']} steps,"
                   f" {end['cpu_s']:.0f} s) | {end['e']:.5f} | {diff} |")
    return out


def _box_directions_table(rows: list[dict]) -> list[str]:
    if not rows:
        return []
    out = ["", f"The unfolded end's lowest eigenspaces on the whole box (ε = {DIRECTIONS_EPS:g}, "
           "Newton's polish first; `box_directions`): each one's eigenvalues, the "
           "irreducible representation of D4h it carries (its characters under C4 and C2 "
           "about z, σh (z), σv (x; the arms lie along x and y), σd (x ↔ y) and i, about the "
           "box's centre; in brackets their distance from that irrep's) and its largest "
           "cosine with a rigid motion (translations and rotations, which the stability "
           "projects out):", "",
           "| λ | irrep | characters (C4, C2, σh, σv, σd, i) | cosine with a rigid motion |",
           "|---|---|---|---|"]
    for r in rows:
        lams = ", ".join(f"{v:.3e}" for v in r["eigenvalues"])
        chars = ", ".join(f"{c:+.2f}" for c in r["characters"])
        out.append(f"| {lams} | {r['irrep']} ({r['off']:.0e}) | {chars} | "
                   f"{r['rigid_cosine']:.2e} |")
    return out


def compute(root: Path, quick: bool) -> dict:
    root.mkdir(parents=True, exist_ok=True)
    lines = [_line(root, EPS, *x) for x in (QUICK_LINES if quick else LINES)]
    disc = lines[0]
    if disc["failed"]:
        return {"lines": lines, "switches": [], "ladder": []}
    wide = None if quick else _line(root, EPS, *M6_LINE, modes=M6_MODES)  # blocks to m = 6
    if wide is not None:
        lines.append(wide)
    switches = []
    for m, geometry, da0, stability, cap in QUICK_SWITCHES if quick else SWITCHES:
        line = wide if m > 4 else disc
        folder, k = run_switch(root, line, m, geometry, da0, quick, cap)
        end = describe_end(folder, EPS, stability)
        switches.append({**end, "m": m, "point": k, "da0": line["rows"][k]["da0"]})
    source = root / switches[0]["folder"]
    if not quick:  # the control of the ladder's smaller R₀ (L/R₀ 6.7): at ε = 0.01 beside R₀'s
        lines.append({**_line(root, EPS, "prolate", *LINES[1][1:], r0=LADDER_R0),
                      "r0": LADDER_R0})
    ladder = []
    for eps in QUICK_LADDER if quick else LADDER:
        if not quick:
            lines.append({**_line(root, eps, "prolate", *LINES[1][1:], r0=LADDER_R0),
                          "r0": LADDER_R0})
        folder = run_reseed(root, source, eps, switches[0]["da0"], quick)
        ladder.append({**describe_end(folder, eps, stability=not quick),
                       "da0": switches[0]["da0"]})
    x = next(x for x in ladder if x["eps"] == DIRECTIONS_EPS)
    dirs = [{**r, "e_start": x["e"]} for r in directions(root, root / x["folder"], quick)]
    # the same end unfolded onto the whole box: its stability without the sector's mirrors
    box = [] if quick else [box_end(root, x)]
    box_dirs = [] if quick else box_directions(root / box[0]["folder"])
    return {"lines": lines, "switches": switches, "ladder": ladder, "box": box,
            "directions": dirs, "box_directions": box_dirs}


def main(argv=None) -> dict:
    ap = study_parser(__doc__, OUT, quick="one short line at eps = 0.01, 10 steps of each 3D run",
                      report_only="rewrite the report from starfish_octant.json")
    args = ap.parse_args(argv)
    suffix = "_quick" if args.quick else ""
    root = args.out / f"starfish_octant{suffix}"
    result = results(args, "starfish_octant", lambda: compute(root, args.quick))
    if not args.report_only and not args.quick:
        figure(result, root, args.out)
    report(result, args.out, suffix)
    for x in _ends(result):
        print(f"{_start(x)}, eps = {x['eps']:g}: {x['label']} ({x['status']}), "
              f"e = {x['e']:.4f}", flush=True)
    return result


if __name__ == "__main__":
    main()
