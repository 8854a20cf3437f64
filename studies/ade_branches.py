"""The ADE plane from branches (issue 32): at κ̄/κ = 1.4, the lowest branch at each point of
the 8 × 8 (v, Δa₀) grid of ``studies/sweeps/ade.toml`` and the transition lines, from
branches followed in Δa₀ along lines of fixed v — the phase field's (``fem_ade.campaigns.branch``,
axisymmetric, Newton on every point) beside the sharp membrane's (``sharp_ref``, each
branch continued along a finer m₀ grid).

* **Phase field**: at each v, the prolate, oblate, stomatocyte and torus followed up in Δa₀
  from 0.8 and the pear down from 1.64 (where it buds off the prolate at large Δa₀), each to
  its first fold (``folds=0``: the stable part) or to the grid's other end, at ε = 0.01 and
  one R₀ for every branch of the line (the largest with which every branch's seed fits the
  box: ε/R₀ = 0.04–0.07). A point counts for a branch where its φ = 0 surface is that branch:
  one body of its genus whose reduced area difference is nearest that branch's sharp one
  (within ``DA_TOL``); e at the grid's Δa₀ is interpolated along the branch (cubic; the
  points are ~0.1 apart, e is near-quadratic in Δa₀).
* **Sharp**: each branch solved at an anchor and continued along m₀ = 0.8, 0.84, …, 1.64
  (``studies/ade_plane.py``'s ``follow``) until it is lost.
* The lowest of all (the torus included) at each grid point, and the transitions along each
  line: where the lowest branch's e crosses the next one's, both as cubic splines in Δa₀
  (phase field) or m₀ (sharp) through their points (``_lib.lines.cross``).

The lines are the points of one branch sweep built from this plan (:mod:`fem_ade.campaigns.sweep`,
``OUT/ade_branches/sweep/points/v=V_LINE``: a Dask task per line, resumable, a line that
cannot start recorded with its reason; the pear's seed is made here, as its point's own
scene). As the sweep ends, each line's rows (or why it has none) and its seconds are
archived in ``OUT/ade_branches/lines.json`` under what the line is (:func:`line_key`): an
archived line is not followed again, and the report is made from the archive.

Writes ``OUT/ade_branches.md``, ``OUT/ade_branches.json`` and ``OUT/ade-branches.png``,
``OUT/ade_branches/lines.json``, the lines' R₀ (``R0.json``) and the sharp solves in
``OUT/ade_branches/sharp/`` (a cache file per branch and v). ``--report-only`` rebuilds the
report from those three, solving and following nothing.

    python studies/ade_branches.py --out studies/results        # the lines ~20 min on 2 cores
    python studies/ade_branches.py --quick                      # the code (a few minutes)
    python studies/ade_branches.py --out studies/results --report-only

Two processes (``--workers``), each with one BLAS thread and one FFT worker.
"""

from __future__ import annotations

from _lib.cli import one_thread, study_parser

one_thread()

import json  # noqa: E402
import math  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

from _lib.lines import (  # noqa: E402
    BRANCHES,
    DEFAULT_SPAN,
    EPS,
    KBAR,
    QUICK,
    STEP,
    V,
    archived,
    archived_sharp,
    archived_sizes,
    at,
    cross,
    curve,
    kept,
    kept_lines,
    load_archive,
    plane_lines,
    run_lines,
)
from _lib.sharp import sharp_line  # noqa: E402

OUT = Path("runs") / "studies"
DA0 = tuple(round(0.8 + 0.12 * i, 2) for i in range(8))
#: the sharp m₀ grid and where each sharp branch is solved first (then continued both ways)
SHARP_M0 = tuple(round(0.8 + 0.04 * i, 2) for i in range(22))
ANCHORS = {"prolate": (1.2, 1.0, 1.6), "pear": (1.64, 1.6, 1.52), "oblate": (1.0, 0.8, 1.2),
           "stomatocyte": (0.8, 0.92, 1.04), "torus": (1.2, 1.0, 1.4)}


# ---------------------------------------------------------------------------------------------
# one line of one branch
# ---------------------------------------------------------------------------------------------
def common_R0(v: float, eps: float, branches, span) -> float:
    """The largest R₀ (≤ 0.25) with which every branch's seed at both ends of the line keeps
    the ``vesicle`` family's margin (0.1 L + 2ε) from the unit box's faces."""
    import numpy as np

    from fem_ade.scenes.vesicle import Vesicle, seed_meridian

    R0 = 0.25
    for b in branches:
        for da0 in span:
            try:
                r, z, _ = seed_meridian(Vesicle(v=v, da0=da0, kbar=KBAR, eps=eps, branch=b), 0.0)
            except Exception:  # noqa: BLE001 (no seed of this branch here: it does not count)
                continue
            extent = max(float(np.ptp(z)), 2.0 * float(np.max(r)))
            R0 = min(R0, (1.0 - 2.0 * (0.1 + 2.0 * eps)) / extent)
    return math.floor(R0 * 1000) / 1000


def line_sizes(base: Path, v_list, eps: float, branches) -> dict:
    """R₀ of each line (:func:`common_R0`), computed once and kept in ``base/R0.json``: a
    line's branches, run now or later, all have its R₀."""
    path = base / "R0.json"
    known = {float(k): x for k, x in json.loads(path.read_text()).items()} \
        if path.is_file() else {}
    for v in v_list:
        if v not in known:
            known[v] = common_R0(v, eps, branches, sorted(set(DEFAULT_SPAN)))
    base.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({f"{v:g}": x for v, x in sorted(known.items())}, indent=1))
    return known


def energy_at(rows: list[dict], x: float, key="da0", value="e") -> float | None:
    """e at ``x`` along one branch (:func:`_lib.lines.curve`: cubic through the points where
    there are four, else linear), None outside the points."""
    return at(curve(rows, key, value), x)


def lowest(values: dict) -> str | None:
    have = {b: e for b, e in values.items() if e is not None}
    return min(have, key=have.get) if have else None


def transitions(curves: dict, key: str) -> list[dict]:
    """Along one line: where the lowest branch changes, as the crossing of the two branches'
    e (:func:`_lib.lines.cross` of their :func:`_lib.lines.curve`: cubic splines, as the
    cells' energies are; the points are 0.03–0.12 apart, over which linear interpolation of
    the convex e moved a crossing by up to 0.01) found on a fine grid of Δa₀."""
    import numpy as np

    fine = np.linspace(DEFAULT_SPAN[0], DEFAULT_SPAN[1], 421)
    values = [{b: energy_at(rows, x, key) for b, rows in curves.items()} for x in fine]
    low = [lowest(v) for v in values]
    out = []
    for i in range(len(fine) - 1):
        a, b = low[i], low[i + 1]
        if not (a and b and a != b):
            continue
        both = all(values[j].get(c) is not None for j in (i, i + 1) for c in (a, b))
        x = None
        if both:  # a crossing: where the two branches' e are equal
            x = cross(curve(curves[a], key), curve(curves[b], key), (fine[i] + fine[i + 1]) / 2)
            x = x if x is not None and fine[i] - 0.01 <= x <= fine[i + 1] + 0.01 else None
        out.append({"from": a, "to": b, "da0": x, "between": [float(fine[i]),
                                                              float(fine[i + 1])],
                    "note": "no crossing found" if both else
                            f"{a if values[i + 1].get(a) is None else b} ends (or begins) here"})
    return out


def plane(pf: dict, sharp: dict, v_list, da0_list) -> dict:
    """The grid's lowest branches and the lines' transitions, phase field and sharp."""
    points, lines = [], []
    for v in v_list:
        s = {b: [{"da0": r["m0"], "e": r["e"]} for r in rows]
             for b, rows in sharp[v].items() if rows}
        sharp_rows = {b: rows for b, rows in sharp[v].items() if rows}
        p = {b: kept_lines(res, b, sharp_rows) for b, res in pf[v].items()}
        p = {b: rows for b, rows in p.items() if len(rows) >= 2}
        for da0 in da0_list:
            e_pf = {b: energy_at(rows, da0) for b, rows in p.items()}
            e_sh = {b: energy_at(rows, da0) for b, rows in s.items()}
            points.append({"v": v, "da0": da0, "pf": lowest(e_pf), "sharp": lowest(e_sh),
                           "e_pf": e_pf, "e_sharp": e_sh})
        lines.append({"v": v, "pf": transitions(p, "da0"), "sharp": transitions(s, "da0"),
                      "ends": {b: _end(res, b, sharp_rows) for b, res in pf[v].items()}})
    return {"points": points, "lines": lines}


def _end(res: dict, branch: str, sharp: dict) -> str:
    """Where each line of a branch was followed, and why it ended there."""
    out = []
    for line in res["lines"]:
        head = f"{line['name']} " if len(res["lines"]) > 1 else ""
        if line["missing"]:
            out.append(f"{head}no start: {line['missing']}")
            continue
        rows = line["rows"]
        keep = kept(rows, branch, sharp)
        if not keep:
            first = rows[0] if rows else None
            out.append(f"{head}its seed did not stay on the branch" + (
                f" ({first['label']}, da {first['da_surface']:.3f})"
                if first and first.get("da_surface") is not None else ""))
            continue
        last = keep[-1]
        why = ("a fold" if last.get("fold") not in (None, "") else
               "the end of the grid" if len(keep) == len(rows) else
               f"it left the branch ({rows[len(keep)]['label']}, da "
               f"{rows[len(keep)]['da_surface']:.3f})")
        out.append(f"{head}{keep[0]['da0']:.3f} … {last['da0']:.3f}: {why}")
    return "; ".join(out)


# ---------------------------------------------------------------------------------------------
# the study
# ---------------------------------------------------------------------------------------------
def main(argv=None) -> dict:
    ap = study_parser(__doc__, OUT, quick="one short line at eps = 0.04", workers="",
                      report_only="from the archived lines and sharp solves; solve and "
                      "follow nothing")
    args = ap.parse_args(argv)
    q = args.quick
    eps, v_list, da0_list = (QUICK.eps, QUICK.v, QUICK.da0) if q else (EPS, V, DA0)
    branches, step = (QUICK.branches, QUICK.step) if q else (BRANCHES, STEP)
    base = args.out / ("ade_branches_quick" if q else "ade_branches")
    grid = QUICK.sharp_m0 if q else SHARP_M0
    if args.report_only:
        sharp, R0 = archived_sharp(base, v_list, branches), archived_sizes(base, v_list)
    else:
        sharp = sharp_lines(base, v_list, branches, grid, args.workers)
        R0 = line_sizes(base, v_list, eps, branches)
    spans, keys = plane_lines(sharp, R0, v_list, branches, eps, step, q)
    archive = load_archive(base)
    if not args.report_only:
        run_lines(base, keys, archive, args.workers)
    pf = gathered(spans, keys, archive, R0)
    result = plane(pf, sharp, v_list, da0_list)
    result.update(eps=eps, kbar=KBAR, R0={f"{v:g}": R0[v] for v in v_list},
                  line_seconds=round(sum(r["seconds"] for v in v_list
                                         for r in pf[v].values()), 1))
    suffix = "_quick" if q else ""
    from fem_ade.store.output import write_json_atomic

    write_json_atomic(args.out / f"ade_branches{suffix}.json", result)
    write_report(args.out, result, pf, sharp, suffix)
    agree = sum(p["pf"] == p["sharp"] for p in result["points"] if p["sharp"])
    print(f"lowest branch as the sharp one's at {agree} of {len(result['points'])} points")
    return result


def sharp_lines(base: Path, v_list, branches, grid, workers: int) -> dict:
    """{v: {branch: rows}}: each sharp branch continued along the m₀ grid, one task per
    (v, branch) on ``workers`` processes, each kept in ``base/sharp/BRANCH-v=V.json``
    (:func:`_lib.sharp.sharp_line`, from the first of its ``ANCHORS`` that reaches it; a
    kept one is read back). These are ``sharp_ref`` solves, not runs: a cache file each, as
    the sharp-limit study keeps its solves, so they are not sweep points."""
    sharp = {v: {} for v in v_list}
    with ProcessPoolExecutor(max_workers=workers) as pool:
        jobs = {(v, b): pool.submit(sharp_line, str(base / "sharp" / f"{b}-v={v:g}.json"),
                                    b, v, grid, ANCHORS[b], KBAR)
                for v in v_list for b in branches}
        for (v, b), job in jobs.items():
            sharp[v][b] = job.result()["rows"]
            print(f"sharp {b} at v = {v}: {len(sharp[v][b])} points", flush=True)
    return sharp


def gathered(spans: dict, keys: list[dict], archive: dict, R0: dict) -> dict:
    """{v: {branch: {"lines": [...], "seconds"}}}: each line's archived rows, or why it has
    none (a line not archived with its key: not followed)."""
    pf = {v: {b: {"lines": [], "seconds": 0.0} for (w, b) in spans if w == v}
          for v, _ in spans}
    for (v, b), lines in spans.items():
        if not lines:  # (only the pear has none: where there is no sharp pear)
            pf[v][b]["lines"].append({"name": b, "rows": [], "missing":
                                      "no sharp pear on this line to start from"})
    for key in keys:
        v, b, name = key["v"], key["branch"], key["line"]
        res = archived(archive, key)
        if res is None:
            res = {"rows": [], "missing": "not followed (no archived line with its "
                                          "settings)", "seconds": None}
        pf[v][b]["lines"].append({"name": name, "rows": res["rows"],
                                  "missing": res["missing"]})
        pf[v][b]["seconds"] += res["seconds"] or 0.0
        print(f"phase field {name} at v = {v} (R0 = {R0[v]}): {len(res['rows'])} points, "
              f"{res['seconds']} s" + (f"; {res['missing']}" if res["missing"] else ""),
              flush=True)
    return pf


def write_report(out: Path, result: dict, pf: dict, sharp: dict, suffix: str) -> None:
    pts = result["points"]
    agree = sum(p["pf"] == p["sharp"] for p in pts if p["sharp"])
    lines = ["# The ADE plane from branches", "",
             f"Written by `studies/ade_branches.py`. κ̄/κ = {result['kbar']}; the phase field "
             f"at ε = {result['eps']:g} (axisymmetric FEM, `fem_ade.campaigns.branch`: every "
             "point a Newton-converged steady state with V and A exact), each line of fixed v "
             "at one R₀ for all its branches; the sharp membrane (`sharp_ref`) continued along m₀. "
             "e = (W + G)/W_sphere. The lowest branch among prolate, pear, oblate, "
             "stomatocyte and torus where each exists.", "",
             f"**The phase field's lowest branch is the sharp one's at {agree} of "
             f"{len(pts)} grid points.**", "",
             "| v | R₀ (ε/R₀) | " + " | ".join(f"Δa₀ = {d:g}" for d in
                                               sorted({p['da0'] for p in pts})) + " |",
             "|---|---|" + "---|" * len({p["da0"] for p in pts})]
    for line in result["lines"]:
        v = line["v"]
        R0 = result["R0"][f"{v:g}"]
        cells = []
        for p in (p for p in pts if p["v"] == v):
            mark = "" if p["pf"] == p["sharp"] else " ✗"
            cells.append(f"{p['pf'] or '—'}{mark}" if p["pf"] == p["sharp"] else
                         f"{p['pf'] or '—'} / {p['sharp'] or '—'}{mark}")
        lines.append(f"| {v:g} | {R0:g} ({result['eps'] / R0:.3f}) | " + " | ".join(cells)
                     + " |")
    lines += ["", "A cell names the phase field's lowest branch; where it differs, "
              "phase field / sharp and ✗.", "", "## Transitions along each line", "",
              "| v | phase field (Δa₀) | sharp (m₀) |", "|---|---|---|"]
    for line in result["lines"]:
        def fmt(ts):
            return "; ".join(f"{t['from']} → {t['to']} " + (
                f"at {t['da0']:.4f}" if t["da0"] is not None else
                f"between {t['between'][0]:.3f} and {t['between'][1]:.3f} ({t['note']})")
                for t in ts) or "none"
        lines.append(f"| {line['v']:g} | {fmt(line['pf'])} | {fmt(line['sharp'])} |")
    lines += ["", "## Where each phase-field branch was followed", ""]
    for line in result["lines"]:
        lines.append(f"- v = {line['v']:g}: " + "; ".join(f"{b} {why}"
                                                         for b, why in line["ends"].items()))
    lines += ["", f"Phase field: {result['line_seconds']:.0f} s of branch runs in all (the "
              "lines' own timings, one BLAS thread each, two at a time).", "",
              f"![the plane](ade-branches{suffix}.png)", ""]
    notes = out / "ade_branches_notes.md"
    if notes.is_file() and not suffix:
        lines += [notes.read_text()]
    (out / f"ade_branches{suffix}.md").write_text("\n".join(lines) + "\n")
    draw(out, result, suffix)


def draw(out: Path, result: dict, suffix: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem_ade.plots.figures import save_figure

    colours = {"prolate": "tab:blue", "pear": "tab:purple", "oblate": "tab:orange",
               "stomatocyte": "tab:green", "torus": "tab:red", None: "lightgrey"}
    fig, ax = plt.subplots(figsize=(9, 6))
    for p in result["points"]:
        ax.scatter(p["da0"], p["v"], s=260, color=colours.get(p["sharp"], "k"), alpha=0.35)
        ax.scatter(p["da0"], p["v"], s=60, color=colours.get(p["pf"], "k"),
                   marker="o" if p["pf"] == p["sharp"] else "X")
    for line in result["lines"]:
        for t in line["sharp"]:
            if t["da0"] is not None:
                ax.plot(t["da0"], line["v"], "|", color="k", ms=16, mew=2)
        for t in line["pf"]:
            if t["da0"] is not None:
                ax.plot(t["da0"], line["v"], "|", color="tab:grey", ms=10, mew=1.5)
    for b, c in colours.items():
        if b:
            ax.scatter([], [], color=c, label=b)
    ax.plot([], [], "|", color="k", ms=12, mew=2, label="sharp transition")
    ax.plot([], [], "|", color="tab:grey", ms=10, label=f"phase-field transition (ε = "
            f"{result['eps']:g})")
    ax.set(xlabel="Δa₀", ylabel="v", title="lowest branch: sharp (large, pale) and phase "
           "field (small; X where they differ)")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    save_figure(fig, out / f"ade-branches{suffix}.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
