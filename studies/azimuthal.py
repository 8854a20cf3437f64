"""Is it stable in 3D? The minimal model's axisymmetric branches, their stability in every
azimuthal mode m = 0 … 8, and where non-axisymmetric shapes are born (issue 43).

Each branch — the prolate (R₀ = 0.17, from v = 0.95), the oblate (R₀ = 0.25, from 0.95) and
the stomatocyte (R₀ = 0.25, from 0.62) — is followed down in v by ``fem_ade.campaigns.branch`` with
``modes = 8`` at ε = 0.02 and 0.01, and at 0.005 over windows around the bifurcations found
there (:data:`WINDOWS`; a branch sweep of listed points, :mod:`fem_ade.campaigns.sweep`, two Dask
workers, resumable): at every point the lowest eigenvalue of each block m and the count of
unstable 3D directions (m ≥ 1 counted twice: cos mθ and sin mθ), and the bifurcations where
a block's count changes (``bifurcations.json``: m ≥ 1 a non-axisymmetric branch is born;
m = 0 away from a fold an axisymmetric symmetry breaking). A bifurcation found at two ε is
extrapolated to ε → 0 by Richardson with p = 2 assumed (the order of the branches' energies,
``sharp_limit.md``; with three ε the order is observed and said).

Writes ``OUT/azimuthal.md`` (what is stable in 3D along each branch and where that changes, at
each ε; the extrapolations; the hand-written notes of ``OUT/azimuthal_notes.md``),
``OUT/azimuthal.json`` and ``OUT/azimuthal.png`` (e against v, stable in 3D solid, unstable
dashed, each bifurcation marked with its m); the branch folders in
``OUT/azimuthal/points/NAME`` (their ``points/`` are not committed). ``--report-only``
rebuilds the report from the folders; ``--eps`` chooses the ε (default 0.02 0.01 0.005).

    python studies/azimuthal.py --out studies/results
    python studies/azimuthal.py --quick           # ε = 0.04, short stretches: the code

One thread per worker: ``OPENBLAS_NUM_THREADS=1``, ``FEM_ADE_FFT_WORKERS=1`` unless set.
"""

from __future__ import annotations

from _lib.cli import one_thread, study_parser

one_thread()

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from _lib.fits import extrapolate  # noqa: E402

OUT = Path("runs") / "studies"
#: the branches: (seed, R₀, from, to); the step in v; the modes
BRANCHES = [("prolate", 0.17, 0.95, 0.58), ("oblate", 0.25, 0.95, 0.52),
            ("stomatocyte", 0.25, 0.62, 0.50)]
QUICK = [("prolate", 0.2, 0.85, 0.8), ("oblate", 0.25, 0.85, 0.78)]
STEP, MODES = 0.01, 8
EPS, QUICK_EPS = (0.02, 0.01, 0.005), (0.04,)
#: the step in v at each ε (Newton takes 8-10 iterations a point at ε ≤ 0.01, so the step
#: does not grow there: a coarser one halves the points; the bifurcations are located
#: between points by the eigenvalue's zero)
STEPS = {0.02: 0.01, 0.01: 0.02, 0.005: 0.02}
#: nodes per ε of the windows. The branches take the FEM's default, 2.5 (E to ~1e-5); the
#: oblate's m = 2 eigenvalue near its zero is not resolved there (at v = 0.79, ε = 0.01:
#: -1.79e-6 at 2.56 nodes per ε, -8.03e-7 at 3.2, -8.32e-7 at 3.84, -8.30e-7 at 4.48 and
#: 5.12; the m = 0 block's lowest 2 % off at 2.56), so a bifurcation is located again over a
#: window at this resolution
WINDOW_NODES_PER_EPS = 4.0
#: whole branches down to this ε (at 0.005 a point costs ~30 s and the points are ~0.002
#: apart in v: windows only)
WHOLE_DOWN_TO = 0.01
#: the windows around the oblate's m = 2 bifurcation: (seed, ε) → (from, to). At 2.5 nodes
#: per ε it was at 0.7624 (ε = 0.02), 0.7902 (0.01), ~0.807 (0.005); at 4 nodes per ε the
#: m = 2 eigenvalue at v = 0.80 is -1.50e-5, -1.02e-6, -6.7e-8 (ratios 14.7, 15.2: the
#: (ε/R₀)⁴ of the shape modes), so the ε = 0.005 window is where ε = 0.01 crosses
WINDOWS = {("oblate", 0.02): (0.80, 0.70), ("oblate", 0.01): (0.80, 0.72),
           ("oblate", 0.005): (0.775, 0.735)}
#: the sharp membrane's transitions of the lowest branch (sharp_limit.md), for the report
SHARP = {"prolate → oblate": 0.6511, "oblate → stomatocyte": 0.5912}


def name_of(seed: str, R0: float, eps: float, n: int | None = None) -> str:
    return f"{seed}-R0={R0:g}-eps={eps:g}" + (f"-n={n}" if n else "")


def window_n(eps: float, order: int = 8) -> int:
    """The nodes per L of a window at ε: :data:`WINDOW_NODES_PER_EPS` per ε, whole cells."""
    import math

    return order * math.ceil(WINDOW_NODES_PER_EPS / (eps * order))


def runs_of(eps_list, branches, windows: dict | None = None) -> list[tuple]:
    """(seed, R₀, from, to, ε, n): the branches at each ε (n None: the default resolution;
    at ε = 0.005 only where a window is), then the windows at those ε."""
    windows = WINDOWS if windows is None else windows
    out = [(seed, R0, start, stop, eps, None) for eps in eps_list if eps >= WHOLE_DOWN_TO
           for seed, R0, start, stop in branches]
    for eps in eps_list:
        for seed, R0, _, _ in branches:
            if (seed, eps) in windows:
                start, stop = windows[(seed, eps)]
                out.append((seed, R0, start, stop, eps, window_n(eps)))
    return out


def plan(eps_list, branches, step: float = STEP, modes: int = MODES,
         windows: dict | None = None) -> list[dict]:
    """The sweep's listed branch points: the branches, and the windows at their resolution."""
    out = []
    for seed, R0, start, stop, eps, n in runs_of(eps_list, branches, windows):
        point = {"name": name_of(seed, R0, eps, n), "seed": seed,
                 "scene": {"eps": eps, "R0": R0},
                 "branch": {"param": "v", "from": start, "to": stop,
                            "step": STEPS.get(eps, step), "folds": None, "modes": modes}}
        if n:
            point["run"] = {"n": n}
        out.append(point)
    return out


def rows_of(root: Path, name: str) -> tuple[list[dict], list[dict]]:
    """A finished branch's rows (branch.csv) and bifurcations, or ([], [])."""
    from fem_ade.campaigns.branch_folder import read_branch_table
    from fem_ade.engine.jobs import read_summary
    from fem_ade.store.status import Status

    folder = root / "points" / name
    summary = read_summary(folder)
    if summary is None or summary.get("status") != Status.COMPLETED:
        return [], []
    forks = folder / "bifurcations.json"
    found = json.loads(forks.read_text())["bifurcations"] if forks.is_file() else []
    return read_branch_table(folder), found


def stable_stretches(rows: list[dict]) -> list[list[float]]:
    """The stretches of v (first, last point) where a branch is stable in 3D."""
    out, current = [], None
    for r in rows:
        ok = r.get("unstable_3d") == 0
        if ok and current is None:
            current = [r["v"], r["v"]]
        elif ok:
            current[1] = r["v"]
        elif current is not None:
            out.append(current)
            current = None
    if current is not None:
        out.append(current)
    return out


def summarize(root: Path, eps_list, branches, modes: int = MODES) -> dict:
    """Per branch and ε: its points, where it ended, its folds, its stretches stable in 3D,
    its bifurcations; per (branch, m, k-th of that m) the bifurcations' v at each ε and their
    extrapolation."""
    from fem_ade.campaigns.branch_analysis import same_branch

    table, curves = [], {}
    for seed, R0, start, stop, eps, n in runs_of(eps_list, branches):
        rows, forks = rows_of(root, name_of(seed, R0, eps, n))
        other = bool(rows) and not same_branch(seed, rows[0]["label"])
        if other:  # its seed relaxed into another shape: not this branch (set aside)
            forks = []
        curves[(seed, eps, n)] = [] if other else [(r["v"], r["e"], r.get("unstable_3d"))
                                                   for r in rows]
        table.append({
            "branch": seed, "R0": R0, "eps": eps, "n": n,
            "nodes_per_eps": None if n is None else round(n * eps, 3),
            "points": len(rows), "from": start, "to": stop,
            "end": rows[-1]["v"] if rows else None,
            "end_label": rows[-1]["label"] if rows else None,
            "first_label": rows[0]["label"] if rows else None,
            "not_this_branch": other,
            "folds": [float(r["fold"]) for r in rows if r.get("fold") not in (None, "")],
            "stable_3d": stable_stretches(rows),
            "unstable_3d_at_start": rows[0].get("unstable_3d") if rows else None,
            "bifurcations": [{"m": b["m"], "v": b["v"], "unstable": b["unstable"],
                              "located": b["located"], "between": b["between"]}
                             for b in forks],
            "seconds": round(sum(float(r.get("seconds") or 0.0) for r in rows), 1)})
    extrapolated = []
    for seed, _, _, _ in branches:
        series = {}
        for row in (t for t in table if t["branch"] == seed):
            seen = {}
            where = "window" if row["n"] else "branch"
            for b in row["bifurcations"]:
                k = seen.get(b["m"], 0)
                seen[b["m"]] = k + 1
                series.setdefault((where, b["m"], k), {})[row["eps"]] = b["v"]
        for (where, m, k), at in sorted(series.items()):
            entry = {"branch": seed, "run": where, "m": m, "k": k,
                     "at": {f"{e:g}": v for e, v in at.items()},
                     "extrapolated": None, "order": None}
            if len(at) >= 2:
                eps_sorted = sorted(at)
                e0, p, observed = extrapolate(eps_sorted, [at[e] for e in eps_sorted])
                entry.update(extrapolated=e0, order=p if observed else None)
            extrapolated.append(entry)
    return {"eps": list(eps_list), "modes": modes, "branches": table,
            "bifurcations": extrapolated}, curves


def draw(path: Path, curves: dict, result: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem_ade.plots.figures import save_figure

    colours = {"prolate": "tab:blue", "oblate": "tab:orange", "stomatocyte": "tab:green"}
    fig, axes = plt.subplots(1, len(result["eps"]), figsize=(5.2 * len(result["eps"]), 4.4),
                             squeeze=False, sharey=True)
    for ax, eps in zip(axes[0], result["eps"], strict=True):
        for row in (b for b in result["branches"] if b["eps"] == eps):
            seed, window = row["branch"], bool(row["n"])
            pts = curves.get((seed, eps, row["n"]), [])
            colour = "k" if window else colours.get(seed, "k")
            for (v0, e0, u0), (v1, e1, u1) in zip(pts, pts[1:], strict=False):
                ok = u0 == 0 and u1 == 0
                ax.plot([v0, v1], [e0, e1], "-" if ok else "--", color=colour,
                        lw=(1.2 if window else 2.0) if ok else 1.0)
            if pts:
                ax.plot([], [], color=colour, label=(f"{seed}, {row['nodes_per_eps']:g} "
                                                     "nodes per ε" if window else seed))
            for b in row["bifurcations"]:
                e_at = _e_at(pts[b["between"][0]:b["between"][1] + 1], b["v"])
                if e_at is not None:
                    ax.plot([b["v"]], [e_at], "D", mfc="k" if window else "none", mec="k",
                            ms=6)
                    ax.annotate(f"m={b['m']}", (b["v"], e_at), textcoords="offset points",
                                xytext=(3, -11 if window else 5), fontsize=7)
        ax.set(xlabel="v", title=f"ε = {eps:g}: solid stable in 3D, dashed not; ◇ bifurcation")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("e = W / W_sphere")
    for ax in axes[0]:
        ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=100, colours=96)  # 48 merged the short green line into grey
    plt.close(fig)


def _e_at(pts, v):
    for (v0, e0, _), (v1, e1, _) in zip(pts, pts[1:], strict=False):
        if min(v0, v1) <= v <= max(v0, v1) and v1 != v0:
            return e0 + (v - v0) * (e1 - e0) / (v1 - v0)
    return None


def write_report(out: Path, result: dict, suffix: str = "") -> None:
    lines = ["# Is it stable in 3D? The minimal model's branches in every azimuthal mode", "",
             "Written by `studies/azimuthal.py`: each branch followed down in v by "
             "`fem_ade.campaigns.branch` (axisymmetric, order 8, Newton on every point) with the "
             f"azimuthal modes m = 0 … {result['modes']} at every point "
             "(`fem_ade.backends.fem.modes`: the lowest eigenvalue of each block, the unstable "
             "count from the LU's inertia; docs/model.md §13). Stable in 3D: no unstable "
             "direction in any block (m ≥ 1 counted twice). A bifurcation: a block's "
             "unstable count changes between two points (its v where the block's lowest "
             "eigenvalue crosses zero; `*` where that is not the crossing eigenvalue, the "
             "midpoint). Whole branches at the default resolution (2.5 nodes per ε: E to "
             "~1e-5, but the eigenvalues near a bifurcation not resolved); windows around "
             f"the bifurcations at {WINDOW_NODES_PER_EPS:g} nodes per ε.", "",
             "| branch | R₀ | ε | nodes per ε | points | from → end (label) | folds | "
             "stable in 3D (v) | bifurcations (m at v) | s |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for b in result["branches"]:
        stretch = ", ".join(f"{a:.4f} → {z:.4f}" for a, z in b["stable_3d"]) or "nowhere"
        forks = ", ".join(f"m = {f['m']} at {f['v']:.4f}" + ("" if f["located"] else "*")
                          + f" ({f['unstable'][0]} → {f['unstable'][1]})"
                          for f in b["bifurcations"]) or "none"
        end = (f"{b['from']:g} ({b['first_label']}) → {b['end']:.4f} ({b['end_label']})"
               if b["points"] else "—")
        if b["not_this_branch"]:
            stretch = forks = (f"its seed relaxed into a {b['first_label']}: not this "
                               "branch, set aside")
        folds = ", ".join(f"{x:.4f}" for x in b["folds"]) or "—"
        nodes = "2.5" if b["n"] is None else f"{b['nodes_per_eps']:g} (window)"
        lines.append(f"| {b['branch']} | {b['R0']:g} | {b['eps']:g} | {nodes} | {b['points']} "
                     f"| {end} | {folds} | {stretch} | {forks} | {b['seconds']:.0f} |")
    lines += ["", "## The bifurcations as ε → 0", "",
              "Each bifurcation of a branch (whole, or its windows), by its mode m and its "
              "order k along the run (from its start), at each ε; extrapolated by "
              "Richardson over the two smallest ε with p = 2 assumed (observed where three "
              "ε give one in [0.5, 6]).", "",
              "| branch | run | m | k | " + " | ".join(f"ε = {e:g}" for e in result["eps"])
              + " | ε → 0 | p |", "|---|---|---|---|" + "---|" * (len(result["eps"]) + 2)]
    for f in result["bifurcations"]:
        cells = [f"{f['at'][f'{e:g}']:.4f}" if f"{e:g}" in f["at"] else "—"
                 for e in result["eps"]]
        ext = "—" if f["extrapolated"] is None else f"{f['extrapolated']:.4f}"
        p = "—" if f["extrapolated"] is None else ("2 (assumed)" if f["order"] is None
                                                   else f"{f['order']:.2f}")
        lines.append(f"| {f['branch']} | {f['run']} | {f['m']} | {f['k']} | "
                     + " | ".join(cells)
                     + f" | {ext} | {p} |")
    lines += ["", f"![e along the branches, stable in 3D or not](azimuthal{suffix}.png)", ""]
    notes = out / f"azimuthal{suffix}_notes.md"
    if notes.is_file():
        lines += [notes.read_text().rstrip(), ""]
    (out / f"azimuthal{suffix}.md").write_text("\n".join(lines))


def main(argv=None) -> dict:
    from fem_ade.campaigns.sweep import report_rows, run_sweep
    from fem_ade.campaigns.sweep_file import listed_sweep
    from fem_ade.store.output import write_json_atomic

    ap = study_parser(__doc__, OUT, quick="ε = 0.04, short stretches", workers="",
                      report_only="")
    ap.add_argument("--eps", type=float, nargs="+", help="the ε (default 0.02 0.01 0.005)")
    args = ap.parse_args(argv)
    suffix = "_quick" if args.quick else ""
    eps_list = tuple(args.eps) if args.eps else (QUICK_EPS if args.quick else EPS)
    branches = QUICK if args.quick else BRANCHES
    modes = 3 if args.quick else MODES
    sweep = listed_sweep(f"azimuthal{suffix}", plan(eps_list, branches, modes=modes))
    root = args.out / f"azimuthal{suffix}"
    if args.report_only:
        report_rows(sweep, root)
    else:
        run_sweep(sweep, root, workers=args.workers)
    result, curves = summarize(root, eps_list, branches, modes)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / f"azimuthal{suffix}.json", result)
    draw(args.out / f"azimuthal{suffix}.png", curves, result)
    write_report(args.out, result, suffix)
    print(f"wrote {args.out / f'azimuthal{suffix}.md'}")
    return result


if __name__ == "__main__":
    main()
