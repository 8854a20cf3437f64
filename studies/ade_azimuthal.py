"""Is the ADE plane's lowest shape stable in 3D? (issue 43) At each point of the 8 × 8
(v, Δa₀) grid at κ̄/κ = 1.4 and ε = 0.01, the lowest genus-0 branch of the phase field
there (``studies/results/ade_branches.json``: the lowest of the prolate, pear, oblate and
stomatocyte; the torus is left out, a phase-field competitor that a membrane does not reach
by a smooth change) is made at that point — its seed made steady by Newton, the first point
of ``fem_ade.campaigns.branch`` in Δa₀ (axisymmetric, order 8, the default 2.5 nodes per ε, the
line's
R₀) — and its stability taken in every azimuthal mode m = 0 … 8 (``fem_ade.backends.fem.modes``).

A cell is unstable where a block's lowest eigenvalue is below −0.5 (ε/R₀)⁴ (m = 0: within
axisymmetry already; m ≥ 1: in 3D only); it is marginal where its lowest eigenvalue over all
blocks lies within ±0.5 (ε/R₀)⁴ of zero, which the default resolution does not resolve
(``azimuthal_notes.md``: at 2.5 nodes per ε an eigenvalue near zero was off by up to 0.4
(ε/R₀)⁴); the count below the branch's own threshold (−0.025 (ε/R₀)⁴,
``fem_ade.campaigns.stability.threshold``) is kept beside it. A cell whose seed relaxes into another
shape says so.

Writes ``OUT/ade_azimuthal.md`` (the grid: each cell's branch, its 3D count and the modes
of its unstable directions; the hand-written ``OUT/ade_azimuthal_notes.md``),
``OUT/ade_azimuthal.json`` and ``OUT/ade_azimuthal.png``; each cell's folder
``OUT/ade_azimuthal/v=V_da0=D`` (a one-point branch; its ``points/`` are not committed).
A cell whose folder holds its point is not made again; ``--report-only`` makes nothing.

``--refine`` makes each flagged cell (unstable or marginal) again on the meshes of
:data:`REFINED` — 4 nodes per ε at the plane's ε, ε/2 at 2.5 nodes per ε, and ε/2 at 4
nodes per ε where those two disagree — at the same v, Δa₀ and R₀, each in
``OUT/ade_azimuthal/refined/MESH/v=V_da0=D``, and the report says what they decide.

    python studies/ade_azimuthal.py --out studies/results          # ~10 min on 2 cores
    python studies/ade_azimuthal.py --out studies/results --refine # + the flagged cells
    python studies/ade_azimuthal.py --quick                        # the code (a minute)

One thread per worker: ``OPENBLAS_NUM_THREADS=1``, ``FEM_ADE_FFT_WORKERS=1`` unless set.
"""

from __future__ import annotations

from _lib.cli import one_thread, study_parser

one_thread()

import json  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

OUT = Path("runs") / "studies"
PLANE = Path(__file__).resolve().parent / "results" / "ade_branches.json"
#: the genus-0 branches (the torus left out)
GENUS0 = ("prolate", "pear", "oblate", "stomatocyte")
MODES, KBAR = 8, 1.4
#: a cell is marginal where its lowest eigenvalue is within this many (ε/R₀)⁴ of zero
MARGINAL = 0.5
#: the flagged cells (unstable or marginal at the default resolution) made again by
#: ``--refine``: (folder, ε as a fraction of the plane's, nodes per ε, heading, only where
#: the meshes before leave the cell undecided) — the same ε on a finer mesh (does the sign
#: stand where the mesh resolves it?), half the ε at the same R₀ and the default 2.5 nodes
#: per ε (does it stand nearer the sharp limit?), and half the ε at 4 nodes per ε where
#: those two disagree (is the sign at ε/2 the mesh's?). A cell is decided by the first and
#: the last of these made at it (:func:`decided`)
REFINED = (("nodes=4", 1.0, 4.0, "4 nodes per ε", False),
           ("half-eps", 0.5, 2.5, "ε/2, 2.5 per ε", False),
           ("half-eps-4", 0.5, 4.0, "ε/2, 4 per ε", True))
#: the quick cells: (v, Δa₀, branch, R₀) at ε = 0.04, modes m ≤ 3
QUICK = [(0.9, 0.8, "oblate", 0.25), (0.85, 1.16, "prolate", 0.2)]
QUICK_EPS, QUICK_MODES = 0.04, 3


def lowest_genus0(energies: dict) -> str | None:
    """The branch of least e among the genus-0 ones that have a value."""
    found = {b: e for b, e in energies.items() if b in GENUS0 and e is not None}
    return min(found, key=found.get) if found else None


def cells(plane: dict) -> list[dict]:
    """Each grid point with its phase-field and sharp genus-0 lowest branches and R₀."""
    return [{"v": p["v"], "da0": p["da0"], "branch": lowest_genus0(p["e_pf"]),
             "sharp": lowest_genus0(p["e_sharp"]), "lowest_any": p["pf"],
             "R0": plane["R0"][f"{p['v']:g}"], "eps": plane["eps"]} for p in plane["points"]]


def cell_name(cell: dict) -> str:
    return f"v={cell['v']:g}_da0={cell['da0']:g}"


def scene_of(cell: dict):
    """The seed of the cell's branch at its (v, Δa₀): the vesicle family's (the pear's from
    :mod:`fem_ade.scenes.pear`, as the ADE-lines study makes it)."""
    if cell["branch"] == "pear":
        from fem_ade.scenes.pear import pear_scene

        return pear_scene(cell["v"], cell["da0"], cell["eps"], cell["R0"], KBAR)
    from fem_ade.scenes.catalogue import vesicle_scene

    return vesicle_scene(v=cell["v"], da0=cell["da0"], kbar=KBAR, eps=cell["eps"],
                         R0=cell["R0"], branch=cell["branch"])


def make_cell(args) -> str | None:
    """The cell's point and its modes (a one-point branch in Δa₀, with ``per_eps`` nodes per
    ε: None the default); None, or why not."""
    cell, folder, modes, per_eps = args
    from fem_ade.backends.fem.axisym import DEFAULT_ORDER, default_nodes
    from fem_ade.campaigns.branch import follow
    from fem_ade.model.params import ModelError

    try:
        scene = scene_of(cell)
        n = None if per_eps is None else default_nodes(cell["eps"], scene.params.L,
                                                       DEFAULT_ORDER, per_eps)
        follow(scene, param="da0", start=cell["da0"], stop=cell["da0"] - 0.002,
               step=0.002, out=folder, quiet=True, max_points=1, modes=modes, n=n)
    except (ModelError, ArithmeticError) as err:
        return f"{type(err).__name__}: {err}"
    return None


def summarize(root: Path, todo: list[dict], modes: int) -> dict:
    """Per cell: the shape its point is, its 3D unstable count, the modes below the
    threshold, its lowest eigenvalue in units of (ε/R₀)⁴ (``lows``: each mode's) and whether
    that is marginal."""
    from fem_ade.campaigns.branch_analysis import same_branch
    from fem_ade.campaigns.branch_folder import read_branch_table
    from fem_ade.campaigns.stability import UNSTABLE, shape_scale

    out = []
    for cell in todo:
        folder = root / cell_name(cell)
        rows = read_branch_table(folder) if (folder / "branch.csv").is_file() else []
        entry = {**cell, "label": None, "same": None, "unstable_3d": None, "modes_below": [],
                 "lowest": None, "lowest_m": None, "marginal": None}
        failed = folder / "failed.txt"
        entry["failed"] = failed.read_text().strip() if failed.is_file() else None
        if rows:
            r = rows[0]
            scale = shape_scale(cell["eps"], cell["R0"])
            lows = {m: float(r[f"lowest_m{m}"]) for m in range(modes + 1)
                    if r.get(f"lowest_m{m}") not in (None, "")}
            m_low = min(lows, key=lows.get)
            entry.update(label=r["label"], same=same_branch(cell["branch"], r["label"]),
                         unstable_3d=r.get("unstable_3d"),
                         below_threshold=[m for m, x in lows.items() if x < UNSTABLE * scale],
                         modes_below=[m for m, x in lows.items() if x < -MARGINAL * scale],
                         lowest=_digits(lows[m_low] / scale), lowest_m=m_low,
                         lows={str(m): _digits(x / scale) for m, x in lows.items()},
                         marginal=abs(lows[m_low]) < MARGINAL * scale,
                         e=r["e"], seconds=r.get("seconds"))
        out.append(entry)
    return {"modes": modes, "marginal": MARGINAL, "cells": out}


def _digits(x: float) -> float:
    """A scaled eigenvalue to the 4 significant digits the meshes' differences leave
    meaningful (2.5 and 4 nodes per ε differ in the second)."""
    return float(f"{x:.4g}")


def write_report(out: Path, result: dict, suffix: str) -> None:
    cells_ = result["cells"]
    done = [c for c in cells_ if c["label"] is not None]
    unstable = [c for c in done if c["same"] and c["modes_below"]]
    axisym = [c for c in unstable if 0 in c["modes_below"]]
    marginal = [c for c in done if c["same"] and c["marginal"]]
    other = [c for c in done if not c["same"]]
    lines = ["# Is the ADE plane's lowest shape stable in 3D?", "",
             "Written by `studies/ade_azimuthal.py`: at each point of the (v, Δa₀) grid "
             "(κ̄/κ = 1.4, ε = "
             f"{cells_[0]['eps'] if cells_ else '—'}), the phase field's lowest genus-0 "
             "branch (the torus left out; `ade_branches.json`) made at that point by Newton "
             f"from its seed, and its stability in every azimuthal mode m = 0 … "
             f"{result['modes']} (2.5 nodes per ε). ✕: unstable (the modes m whose lowest "
             f"eigenvalue is below −{MARGINAL:g} (ε/R₀)⁴; m = 0 within axisymmetry already); "
             f"~: marginal, its lowest eigenvalue within ±{MARGINAL:g} (ε/R₀)⁴ of zero, which "
             "this resolution does not resolve; ≠: the seed relaxed into another shape; "
             "blank: stable in 3D.", "",
             f"Of {len(cells_)} cells: {len(done)} made; {len(unstable)} unstable "
             f"({len(axisym)} of them in m = 0, {len(unstable) - len(axisym)} in m ≥ 1 "
             f"only); {len(marginal)} marginal; {len(other)} relaxed into another shape.", ""]
    v_list = sorted({c["v"] for c in cells_})
    da_list = sorted({c["da0"] for c in cells_})
    lines += ["| v \\ Δa₀ | " + " | ".join(f"{d:g}" for d in da_list) + " |",
              "|---|" + "---|" * len(da_list)]
    for v in reversed(v_list):
        row = []
        for d in da_list:
            c = next((x for x in cells_ if x["v"] == v and x["da0"] == d), None)
            row.append(_cell_text(c))
        lines.append(f"| {v:g} | " + " | ".join(row) + " |")
    lines += ["", "Each cell: the genus-0 lowest branch (sharp's in brackets where it differs), "
              "its mark, and its lowest eigenvalue over the blocks in units of (ε/R₀)⁴ with "
              "its m.", "",
              f"![the ADE plane's genus-0 lowest shapes in 3D](ade_azimuthal{suffix}.png)", ""]
    lines += refined_report(result)
    notes = out / f"ade_azimuthal{suffix}_notes.md"
    if notes.is_file():
        lines += [notes.read_text().rstrip(), ""]
    (out / f"ade_azimuthal{suffix}.md").write_text("\n".join(lines))


def refined_report(result: dict) -> list[str]:
    """The refined cells' table (``--refine``): each flagged cell's lowest eigenvalue and
    its mark at the plane's mesh and at each of :data:`REFINED`'s, and what they decide
    (:func:`decided`)."""
    refined = result.get("refined")
    if not refined:
        return []
    base = {cell_name(c): c for c in result["cells"]}
    names = [r for r in REFINED if r[0] in refined]
    lines = ["## The flagged cells refined", "",
             "Each cell unstable or marginal above, made again with "
             + " and with ".join(f"{h} (ε = {refined[n][0]['eps']:g})"
                                 for n, _, _, h, _ in names if refined[n])
             + " at the same v, Δa₀ and R₀: its lowest eigenvalue over the blocks in units of "
             "that mesh's (ε/R₀)⁴, its m, and its mark. Decided by 4 nodes per ε at ε and "
             "ε/2 at 2.5 per ε, or where those two disagree by the 4 per ε meshes at both ε: "
             f"unstable where both put a common mode below −{MARGINAL:g} (ε/R₀)⁴, stable "
             "where neither has one nor is marginal.", "",
             "| v | Δa₀ | branch | plane's mesh | " + " | ".join(r[3] for r in names)
             + " | decided |", "|---|---|---|---|" + "---|" * len(names) + "---|"]
    verdicts = decisions(result)
    for key, c in base.items():
        if key not in verdicts:
            continue
        lines.append(f"| {c['v']:g} | {c['da0']:g} | {c['branch']} | {_mark(c)} | "
                     + " | ".join("" if x is None and r[4] else _mark(x)
                                  for x, r in refined_at(refined, key))
                     + f" | {verdicts[key]} |")
    return lines + [""]


def refined_at(refined: dict, key: str) -> list[tuple]:
    """[(the cell ``key``'s entry at a refined mesh, or None; that mesh's :data:`REFINED`
    row)] for each mesh in ``refined``, in REFINED's order."""
    return [(next((x for x in refined[r[0]] if cell_name(x) == key), None), r)
            for r in REFINED if r[0] in refined]


def decisions(result: dict) -> dict:
    """{cell name: what its refined meshes decide (:func:`decided`)} for each refined
    cell."""
    refined = result.get("refined") or {}
    out = {}
    for c in result["cells"]:
        key = cell_name(c)
        at = refined_at(refined, key)
        if any(x is not None for x, _ in at):
            out[key] = decided([x for x, r in at if x is not None or not r[4]])
    return out


def _mark(c: dict | None) -> str:
    if c is None or c["label"] is None:
        return "not made" + (f" ({c['failed'][:40]})" if c and c.get("failed") else "")
    if not c["same"]:
        return f"≠ {c['label']}"
    return f"{c['lowest']:.2g} (m = {c['lowest_m']}){_flag(c)}"


def _flag(c: dict) -> str:
    """A made cell's mark: ✕ with the modes below −MARGINAL (ε/R₀)⁴, ~ marginal, or none."""
    return (f" ✕ m = {', '.join(map(str, c['modes_below']))}" if c["modes_below"]
            else " ~" if c["marginal"] else "")


def decided(at: list) -> str:
    """What the first and the last of a cell's refined entries (in :data:`REFINED`'s order,
    those made; None: failed) say — 4 nodes per ε at the plane's ε and at ε/2 where the
    tie-break was made (2.5 per ε at ε/2 left out there: it disagreed), else ε/2 at 2.5 per
    ε: "unstable, m = …" where both put a common mode below −MARGINAL (ε/R₀)⁴, "stable"
    where neither has one nor is marginal, else "undecided"."""
    at = [at[0], at[-1]]
    if any(x is None or x["label"] is None or not x["same"] for x in at):
        return "undecided (not made or relaxed)"
    common = set.intersection(*(set(x["modes_below"]) for x in at))
    if common:
        return "unstable, m = " + ", ".join(map(str, sorted(common)))
    if not any(x["modes_below"] or x["marginal"] for x in at):
        return "stable"
    return "undecided"


def _cell_text(c: dict | None) -> str:
    if c is None or c["branch"] is None:
        return "—"
    name = c["branch"] + (f" ({c['sharp']})" if c["sharp"] != c["branch"] else "")
    if c["label"] is None:
        return f"{name}: not made" + (f" ({c['failed'][:40]})" if c.get("failed") else "")
    if not c["same"]:
        return f"{name} ≠ {c['label']}"
    return f"{name}{_flag(c)}, {c['lowest']:.2g} (m = {c['lowest_m']})"


#: the ring drawn round a refined cell, by what its meshes decide
RINGS = {"unstable": "tab:red", "stable": "tab:green", "undecided": "0.45"}


def draw(path: Path, result: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem_ade.plots.figures import save_figure

    colours = {"prolate": "tab:blue", "pear": "tab:purple", "oblate": "tab:orange",
               "stomatocyte": "tab:green"}
    fig, ax = plt.subplots(figsize=(8.4, 5.6))
    verdicts = decisions(result)
    for c in result["cells"]:
        if c["branch"] is None:
            continue
        ax.scatter([c["da0"]], [c["v"]], s=260, color=colours.get(c["branch"], "grey"),
                   alpha=0.35 if c["label"] is None or not c["same"] else 0.9)
        if c["label"] is None:
            continue
        mark = ("≠" if not c["same"] else "✕" if c["modes_below"]
                else "~" if c["marginal"] else "")
        if mark:
            ax.annotate(mark, (c["da0"], c["v"]), ha="center", va="center", fontsize=13)
        if c["same"] and c["modes_below"]:
            ax.annotate("m=" + ",".join(map(str, c["modes_below"])), (c["da0"], c["v"]),
                        textcoords="offset points", xytext=(0, -16), ha="center",
                        fontsize=7)
        verdict = verdicts.get(cell_name(c))
        if verdict is not None:  # the refined meshes' verdict: a ring
            ax.scatter([c["da0"]], [c["v"]], s=520, facecolors="none", linewidths=1.6,
                       edgecolors=RINGS[verdict.split(",")[0].split(" (")[0]])
    for name, colour in colours.items():
        ax.scatter([], [], s=80, color=colour, label=name)
    for verdict, colour in RINGS.items() if verdicts else ():
        ax.scatter([], [], s=80, facecolors="none", edgecolors=colour,
                   label=f"refined: {verdict}")
    ax.set(xlabel="Δa₀", ylabel="v", title="genus-0 lowest (phase field, ε = 0.01): "
           "✕ unstable, ~ marginal, ≠ relaxed")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path, dpi=100, colours=128)
    plt.close(fig)


def main(argv=None) -> dict:
    from fem_ade.store.output import write_json_atomic

    ap = study_parser(__doc__, OUT, quick="two cells at ε = 0.04, m ≤ 3", workers="",
                      report_only="")
    ap.add_argument("--refine", action="store_true",
                    help="make the flagged cells (unstable or marginal; --quick: every cell) "
                         "again at each of REFINED's meshes")
    args = ap.parse_args(argv)
    suffix = "_quick" if args.quick else ""
    if args.quick:
        todo = [{"v": v, "da0": d, "branch": b, "sharp": b, "lowest_any": b, "R0": R0,
                 "eps": QUICK_EPS} for v, d, b, R0 in QUICK]
        modes = QUICK_MODES
    else:
        todo = cells(json.loads(PLANE.read_text()))
        modes = MODES
    root = args.out / f"ade_azimuthal{suffix}"
    inline = args.quick or args.workers <= 1  # (the quick cells: in this process)
    if not args.report_only:
        make_all([(c, root / cell_name(c), modes, None) for c in todo], args.workers, inline)
    result = summarize(root, todo, modes)
    if args.refine and not args.report_only or (root / "refined").is_dir():
        result["refined"] = refine(root / "refined", result["cells"], modes, args,
                                   make=args.refine and not args.report_only, inline=inline)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / f"ade_azimuthal{suffix}.json", result, indent=None)
    draw(args.out / f"ade_azimuthal{suffix}.png", result)
    write_report(args.out, result, suffix)
    print(f"wrote {args.out / f'ade_azimuthal{suffix}.md'}")
    return result


def make_all(jobs: list, workers: int, inline: bool) -> None:
    """:func:`make_cell` for each job whose folder holds no point yet (on ``workers``
    processes, or in this one), a failure's reason in its folder's failed.txt."""
    jobs = [j for j in jobs if j[0]["branch"] is not None
            and not (j[1] / "branch.csv").is_file()]
    with ProcessPoolExecutor(max_workers=max(1, workers)) as pool:
        made = map(make_cell, jobs) if inline else pool.map(make_cell, jobs)
        for (cell, folder, _, per_eps), why in zip(jobs, made, strict=True):
            if why:
                folder.mkdir(parents=True, exist_ok=True)
                (folder / "failed.txt").write_text(why + "\n")
            mesh = "" if per_eps is None else f", ε = {cell['eps']:g}, {per_eps:g} per ε"
            print(f"  {cell_name(cell)} ({cell['branch']}{mesh}): {why or 'done'}", flush=True)


def refine(root: Path, made: list[dict], modes: int, args, make: bool, inline: bool) -> dict:
    """{REFINED folder: its cells summarized}: each made cell of its own branch that is
    unstable or marginal (``args.quick``: each made cell) at each of :data:`REFINED`'s
    meshes in turn (made there when ``make``), a tie-break mesh only at the cells the meshes
    before leave undecided."""
    flagged = [c for c in made if c["label"] is not None and c["same"]
               and (args.quick or c["modes_below"] or c["marginal"])]
    keep = ("v", "da0", "branch", "sharp", "lowest_any", "R0")
    out = {}
    for name, factor, per_eps, _, tiebreak in REFINED:
        todo = [{**{k: c[k] for k in keep}, "eps": round(c["eps"] * factor, 12),
                 "nodes_per_eps": per_eps} for c in flagged]
        if tiebreak:
            todo = [c for c in todo if decided([x for x, _ in refined_at(out, cell_name(c))])
                    == "undecided"]
        if make:
            make_all([(c, root / name / cell_name(c), modes, per_eps) for c in todo],
                     args.workers, inline)
        out[name] = summarize(root / name, todo, modes)["cells"]
    return out


if __name__ == "__main__":
    main()
