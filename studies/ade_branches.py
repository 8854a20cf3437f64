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
  line: where the lowest branch's e crosses the next one's
  (``fem_ade.campaigns.branch_analysis.crossing``;
  sharp: linear between the m₀ grid's points — the difference of two branches' e is nearly
  linear in m₀, as each is w + q(da − m₀)² with da slowly varying).

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

    python studies/ade_branches.py --out studies/results        # ~1 h on 2 cores
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
from types import SimpleNamespace  # noqa: E402

from _lib.lines import line_name  # noqa: E402
from _lib.sharp import sharp_line  # noqa: E402

OUT = Path("runs") / "studies"
KBAR = 1.4
EPS = 0.01
V = tuple(round(0.6 + 0.05 * i, 2) for i in range(8))
DA0 = tuple(round(0.8 + 0.12 * i, 2) for i in range(8))
BRANCHES = ("prolate", "pear", "oblate", "stomatocyte", "torus")
#: where each branch's phase-field line starts and ends; the pear (it exists at large Δa₀
#: only, and at 1.64 its neck is closed at ε = 0.01) is followed up and down from just above
#: the least m₀ at which the sharp pear was found (``PEAR_INSIDE``)
DEFAULT_SPAN = (0.8, 1.64)
PEAR_INSIDE = 0.02
#: the torus is also followed down from here (at v = 0.6, ε = 0.01, its seed at Δa₀ = 0.8
#: closes its hole: a discocyte, which opens into the torus at Δa₀ = 1.09)
TORUS_MIDDLE = 1.2
#: the genus-0 branches told apart by da where their labels do not (a pear whose label reads
#: gourd, a discocyte with deep dimples)
PAIRED = {"prolate": "pear", "pear": "prolate", "oblate": "stomatocyte",
          "stomatocyte": "oblate"}
STEP = 0.04
#: the sharp m₀ grid and where each sharp branch is solved first (then continued both ways)
SHARP_M0 = tuple(round(0.8 + 0.04 * i, 2) for i in range(22))
ANCHORS = {"prolate": (1.2, 1.0, 1.6), "pear": (1.64, 1.6, 1.52), "oblate": (1.0, 0.8, 1.2),
           "stomatocyte": (0.8, 0.92, 1.04), "torus": (1.2, 1.0, 1.4)}
#: a genus-0 point whose label names neither branch of its pair is the one whose sharp da is
#: nearest its surface's, within this (the pear's da is 0.17–0.2 above the prolate's, the
#: stomatocyte's 0.2–0.6 below the oblate's: ``studies/results/ade_plane.md``; at ε/R₀ = 0.06 the
#: stomatocyte's surface da is 0.1 below the sharp one's)
DA_TOL = 0.15
#: --quick: one line, two branches, a short span, coarse
QUICK = SimpleNamespace(eps=0.04, v=(0.85,), da0=(1.04, 1.16), branches=("prolate", "oblate"),
                        span=(1.04, 1.16), step=0.06, sharp_m0=(1.0, 1.04, 1.12, 1.16, 1.2))


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


def line_spans(branch: str, sharp_rows: list[dict], quick: bool) -> list[tuple]:
    """(name, (from, to)) of the phase-field lines of ``branch`` on one v: one from 0.8 up;
    the pear's two, up and down from just above the sharp pear's least m₀ (none where
    there is no sharp pear)."""
    if quick:
        return [(branch, QUICK.span)]
    if branch == "torus":  # where its hole closes at 0.8 (v = 0.6), it opens further up
        return [(branch, DEFAULT_SPAN), ("torus-down", (TORUS_MIDDLE, DEFAULT_SPAN[0])),
                ("torus-up", (TORUS_MIDDLE, DEFAULT_SPAN[1]))]
    if branch != "pear":
        return [(branch, DEFAULT_SPAN)]
    if not sharp_rows:
        return []
    start = round(sharp_rows[0]["m0"] + PEAR_INSIDE, 4)
    return [("pear-up", (start, DEFAULT_SPAN[1])), ("pear-down", (start, DEFAULT_SPAN[0]))]


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


def line_key(v: float, branch: str, name: str, span, R0: float, eps: float, step,
             **more) -> dict:
    """What a phase-field line is (its archived rows are reused only for the same): the
    branch followed in Δa₀ over ``span`` at v, R₀, ε and κ̄, its step, and the model's
    physics version; ``more``: what else a study's lines are followed with (``modes``, the
    branch code's ``version``; this study's lines have neither: version 1, e4098a1)."""
    from fem_ade.model.params import PHYSICS_VERSION

    return {"v": v, "branch": branch, "line": name, "from": span[0], "to": span[1],
            "R0": R0, "eps": eps, "kbar": KBAR, "step": step, "physics": PHYSICS_VERSION,
            **more}


def line_point(key: dict) -> dict:
    """A line as a listed point of the branch sweep: the vesicle of its branch at the line's
    start, or the pear's seed (:func:`fem_ade.scenes.pear.pear_scene`, by continuation where
    it must) as the point's own scene; ModelError where the pear has none."""
    branch = {"param": "da0", "from": key["from"], "to": key["to"], "step": key["step"],
              "folds": 0, "modes": key.get("modes", 0)}
    spec = {"name": line_name(key["v"], key["line"]), "seed": key["branch"],
            "branch": branch, "base": "vesicle",
            "scene": {"v": key["v"], "kbar": KBAR, "eps": key["eps"], "R0": key["R0"]}}
    if key["branch"] == "pear":
        from fem_ade.scenes.catalogue import scene_to_mapping
        from fem_ade.scenes.pear import pear_scene

        spec.update(base=scene_to_mapping(pear_scene(key["v"], key["from"], key["eps"],
                                                     key["R0"], KBAR)), scene={})
    return spec


def run_lines(base: Path, keys: list[dict], archive: dict, workers: int) -> None:
    """Follow the lines not in ``archive`` (or archived with another key) as one branch
    sweep in ``base/sweep`` (:mod:`fem_ade.campaigns.sweep`: a Dask task per line, resumable, a
    failure recorded with its reason), and archive each line's outcome in
    ``base/lines.json`` as soon as the sweep has ended (:func:`archive_line`)."""
    from fem_ade.campaigns.sweep import run_sweep
    from fem_ade.campaigns.sweep_file import listed_sweep
    from fem_ade.model.params import ModelError
    from fem_ade.store.output import write_json_atomic

    specs, todo = [], []
    for key in keys:
        name = line_name(key["v"], key["line"])
        if archive.get(name, {}).get("key") == key:
            continue
        try:
            specs.append(line_point(key))
            todo.append(key)
        except ModelError as err:  # no pear to start from, even by continuation
            archive[name] = {"key": key, "rows": [], "missing": str(err), "seconds": None}
    if specs:
        run_sweep(listed_sweep(base.name, specs), base / "sweep", workers=workers, quiet=True)
    for key in todo:
        name = line_name(key["v"], key["line"])
        archive[name] = archive_line(base / "sweep" / "points" / name, key)
    write_json_atomic(base / "lines.json", archive, indent=None, make_folder=True)


def archive_line(folder: Path, key: dict) -> dict:
    """A followed line's archive entry: its rows (branch.csv, the columns the report reads),
    or why it has none (its failure record's reason), and its seconds (the task's wall
    time: the seed and every Newton point)."""
    from fem_ade.campaigns.branch_folder import read_branch_table
    from fem_ade.engine.jobs import failure_record, read_failure, read_summary

    failed, summary = read_failure(folder), read_summary(folder)
    if failed is not None or summary is None:
        reason = failed["reason"] if failed else "not run"
        record = json.loads(failure_record(folder).read_text()) if failed else {}
        return {"key": key, "rows": [], "seconds": record.get("seconds"),
                "missing": reason.removeprefix("ModelError: ")}
    rows = [_plain(r) for r in read_branch_table(folder)]
    return {"key": key, "rows": rows, "missing": None, "seconds": summary.get("seconds")}


def _plain(row: dict) -> dict:
    keep = ("da0", "e", "E", "W", "G", "v_surface", "da_surface", "label", "unstable",
            "lowest_eigenvalue", "fold", "newton", "seconds")
    return {k: row.get(k) for k in keep}


# ---------------------------------------------------------------------------------------------
# the plane
# ---------------------------------------------------------------------------------------------
def on_branch(row: dict, branch: str, sharp: dict) -> bool:
    """Whether a phase-field point is ``branch``: a torus is labelled one; a genus-0 shape
    must be labelled as ``branch`` or its pair's other branch (:data:`PAIRED`), and where both
    have a sharp shape near this Δa₀ its surface's da must be nearer ``branch``'s, else
    (only ``branch``'s) within DA_TOL or labelled ``branch``."""
    from fem_ade.campaigns.branch_analysis import branch_of_label

    family = branch_of_label(row["label"])
    if branch == "torus" or family == "torus":
        return branch == family == "torus"
    if family not in (branch, PAIRED[branch]):
        return False
    own, other = (_da_distance(row, sharp.get(b, [])) for b in (branch, PAIRED[branch]))
    if own is None:
        return family == branch and other is None
    if other is None:
        return family == branch or own < DA_TOL
    return own < other


def _da_distance(row: dict, rows: list[dict]) -> float | None:
    """|da of the point's surface − the sharp branch's da at its Δa₀| (None: no sharp shape
    within 0.2 of its Δa₀; a branch's da changes slowly along Δa₀)."""
    pts = [(r["m0"], r["da"]) for r in rows]
    if row.get("da_surface") is None or not pts or \
            not pts[0][0] - 0.2 <= row["da0"] <= pts[-1][0] + 0.2:
        return None
    m, d = zip(*pts, strict=True)
    return abs(row["da_surface"] - _interp(row["da0"], m, d))


def _interp(x, xs, ys):
    import numpy as np

    return float(np.interp(x, xs, ys))


def kept(rows: list[dict], branch: str, sharp: dict) -> list[dict]:
    """The line's points up to its first fold, from its start while they are the branch."""
    out = []
    for r in rows:
        if not on_branch(r, branch, sharp):
            break
        out.append(r)
        if r.get("fold") not in (None, ""):
            break
    return out


def kept_lines(res: dict, branch: str, sharp: dict) -> list[dict]:
    """The kept points of a branch's lines (the pear's two), in order of Δa₀, each once."""
    rows = [r for line in res["lines"] for r in kept(line["rows"], branch, sharp)]
    return sorted({round(r["da0"], 12): r for r in rows}.values(), key=lambda r: r["da0"])


def energy_at(rows: list[dict], x: float, key="da0", value="e") -> float | None:
    """e at ``x`` along one branch (cubic through the points where there are four, else
    linear), None outside the points."""
    import numpy as np
    from scipy.interpolate import CubicSpline

    pts = sorted({r[key]: r[value] for r in rows}.items())
    if len(pts) < 2 or not pts[0][0] - 1e-9 <= x <= pts[-1][0] + 1e-9:
        return None
    xs, ys = map(np.array, zip(*pts, strict=True))
    if len(pts) >= 4:
        return float(CubicSpline(xs, ys)(x))
    return float(np.interp(x, xs, ys))


def lowest(values: dict) -> str | None:
    have = {b: e for b, e in values.items() if e is not None}
    return min(have, key=have.get) if have else None


def transitions(curves: dict, key: str) -> list[dict]:
    """Along one line: where the lowest branch changes, as the crossing of the two branches
    (``fem_ade.campaigns.branch_analysis.crossing``) on a fine grid of Δa₀."""
    import numpy as np

    from fem_ade.campaigns.branch_analysis import crossing

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
            x = crossing(sorted(curves[a], key=lambda r: r[key]),
                         sorted(curves[b], key=lambda r: r[key]), key)
            x = x if x is not None and fine[i] - 0.01 <= x <= fine[i + 1] + 0.01 else None
        out.append({"from": a, "to": b, "da0": x, "between": [float(fine[i]),
                                                              float(fine[i + 1])],
                    "note": "" if both else f"{a if values[i + 1].get(a) is None else b} "
                                            "ends (or begins) here"})
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
    spans = {(v, b): line_spans(b, sharp[v].get(b, []), q) for v in v_list for b in branches}
    keys = [line_key(v, b, name, span, R0[v], eps, step)
            for (v, b), lines in spans.items() for name, span in lines]
    path = base / "lines.json"
    archive = json.loads(path.read_text()) if path.is_file() else {}
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


def archived_sharp(base: Path, v_list, branches) -> dict:
    """--report-only: the kept sharp lines (ModelError where one is missing)."""
    from fem_ade.model.params import ModelError

    sharp = {v: {} for v in v_list}
    for v in v_list:
        for b in branches:
            path = base / "sharp" / f"{b}-v={v:g}.json"
            if not path.is_file():
                raise ModelError(f"{path} is missing: run the study (without --report-only)")
            sharp[v][b] = json.loads(path.read_text())["rows"]
    return sharp


def archived_sizes(base: Path, v_list) -> dict:
    """--report-only: each line's R₀ as kept in ``base/R0.json``."""
    from fem_ade.model.params import ModelError

    path = base / "R0.json"
    known = {float(k): x for k, x in json.loads(path.read_text()).items()} \
        if path.is_file() else {}
    missing = [v for v in v_list if v not in known]
    if missing:
        raise ModelError(f"{path} has no R0 for v = {missing}: run the study first")
    return known


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
        res = archive.get(line_name(v, name))
        if res is None or res["key"] != key:
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
             "**Made with older branch code, not rerun**: the lines were followed at "
             "e4098a1, before the continuation's predictor (ef4c570, 62a7cce, 69ffa05) and "
             "its stability without the translation mode (91c4ae2) changed; the notes below "
             "say what moved where the branches were followed again.", "",
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
