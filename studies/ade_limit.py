"""The ADE plane at ε → 0 (issue 42): the transitions of ``studies/ade_branches.py``'s lines
(κ̄/κ = 1.4, ε = 0.01) followed again at ε = 0.005 near where they are, each extrapolated in
ε, and the plane's cells near them judged at ε → 0.

* **Where.** On each line of fixed v, every transition between two branches that cross (the
  phase field's at ε = 0.01, and the sharp membrane's where the phase field had none there):
  both branches followed at ε = 0.005 (the same R₀ as the line's, so ε/R₀ halves) up and down
  from the crossing predicted at ε = 0.005 — x₀.₀₁ + ¾ (x_sharp − x₀.₀₁), the p = 2 guess — to
  ``WINDOW`` either side. Where the sharp membrane has a pear, the pear and the prolate
  from the sharp pear's least m₀ up to the grid's end and down by ``WINDOW`` (the pear at
  Δa₀ = 1.64 budded off at ε = 0.01: does it at 0.005?); and the pear from each grid cell of
  that span, seeded there (``CELL_SPAN``: its span's lines stop within 0.004 of their start).
* **Crossings.** Each branch's points there (up to its first fold, while they are the
  branch: ``_lib.lines.kept``), e as a cubic spline in Δa₀, the crossing the root of the
  difference nearest the window's centre (Brent) — the same for ε = 0.01 from its lines.
* **Extrapolation.** x₀ = x₀.₀₀₅ + (x₀.₀₀₅ − x₀.₀₁)/(2² − 1): the order is **assumed** (p = 2:
  the sharp-limit study measured 1.77–1.88 on three transitions and 2.01–2.25 on 13 energies,
  ``sharp_limit.md``); it is not measured here, two ε give none.
* **Cells.** A grid cell inside a refined span is judged by the branches' energies
  extrapolated the same way, e₀ = e₀.₀₀₅ + (e₀.₀₀₅ − e₀.₀₁)/3, the lowest of those that exist at
  both ε; a branch that exists there at ε = 0.005 only (the pear at 1.64) competes with its
  ε = 0.005 energy against the others' at ε = 0.005, and the cell says so; a branch whose
  seed became another shape there at ε = 0.005 (no point of it; for the pear, its seed at the
  cell itself) is absent. A cell that a branch's ε = 0.005 line did not reach (it ended
  before: Newton did not converge) keeps its ε = 0.01 verdict and says why, as does a cell
  outside every span (≥ ``WINDOW`` from every predicted crossing).

The lines are one branch sweep, as ``ade_branches.py``'s: ``OUT/ade_limit/sweep`` (resumable;
each line archived in ``OUT/ade_limit/lines.json`` once the sweep ends). Needs
``OUT/ade_branches.json`` and ``OUT/ade_branches/`` (``ade_branches.py`` run first).

Writes ``OUT/ade_limit.md`` (with the hand-written ``OUT/ade_limit_notes.md``) and
``OUT/ade_limit.json``.

    python studies/ade_limit.py --out studies/results        # ~45 min on 2 cores (62 lines)
    python studies/ade_limit.py --out studies/results --report-only
    python studies/ade_limit.py --quick      # the code: ade_branches.py --quick, refined at 0.02

One BLAS thread and one FFT worker per process.
"""

from __future__ import annotations

from _lib.cli import one_thread, study_parser

one_thread()

import json  # noqa: E402
from pathlib import Path  # noqa: E402
from types import SimpleNamespace  # noqa: E402

from _lib import lines as adl  # noqa: E402

OUT = Path("runs") / "studies"
EPS = 0.005
#: how far either side of a predicted crossing both branches are followed (the sharp and
#: the ε = 0.01 crossings are up to 0.048 apart: the torus → prolate at v = 0.6)
WINDOW = 0.05
#: the order in ε assumed for the extrapolation (module docstring)
ORDER = 2
#: the pear's own line from each grid cell of its span, ``CELL_SPAN`` down in one step: its
#: span's lines end within 0.004 of their start at ε = 0.005 (corrections of 12–14 Newton
#: iterations), so the cells are reached by starting there (a cell's seed is the sharp pear
#: at its Δa₀); only the first point is used, the rest (steps of ~8e-4, ~30 s each: measured
#: at v = 0.75) says that it continues
CELL_SPAN = CELL_STEP = 0.003
#: the plane's settings (``ade_branches.py``'s) and this study's
FULL = SimpleNamespace(eps=EPS, window=WINDOW, coarse=SimpleNamespace(
    eps=adl.EPS, v=adl.V, branches=adl.BRANCHES, step=adl.STEP, quick=False))
#: --quick: ``ade_branches.py --quick``'s line (v = 0.85 at ε = 0.04, prolate and oblate over
#: Δa₀ 1.04 … 1.16, no transition) refined at ε = 0.02 in one span of its pair
QUICK = SimpleNamespace(eps=0.02, window=0.06, centre=1.1, coarse=SimpleNamespace(
    eps=adl.QUICK.eps, v=adl.QUICK.v, branches=adl.QUICK.branches, step=adl.QUICK.step,
    quick=True))


def predicted(x_pf: float | None, x_sharp: float | None) -> float:
    """Where a crossing is expected at ε = 0.005: ε = 0.01's moved ¾ of the way to the
    sharp one (order 2), or whichever of the two is known."""
    if x_pf is None:
        return x_sharp
    if x_sharp is None:
        return x_pf
    return x_pf + (1.0 - 0.5**ORDER) * (x_sharp - x_pf)


def regions(coarse: dict, sharp: dict) -> list[dict]:
    """The spans refined at ε = 0.005: {v, branches, centre, span, x_pf, x_sharp}. The pear's
    span covers its crossing with the prolate, so that pair has no window of its own."""
    out = []
    for line in coarse["lines"]:
        v = line["v"]
        pear = sharp[v].get("pear") or []
        pairs = {}
        for side in ("pf", "sharp"):
            for t in line[side]:
                if t["da0"] is not None:
                    pairs.setdefault(frozenset((t["from"], t["to"])),
                                     {"from": t["from"], "to": t["to"]})[side] = t["da0"]
        with_pear = pairs.pop(frozenset(("prolate", "pear")), {}) if pear else {}
        for p in pairs.values():
            x = predicted(p.get("pf"), p.get("sharp"))
            out.append({"v": v, "branches": (p["from"], p["to"]), "centre": round(x, 3),
                        "span": (round(x - WINDOW, 3), round(x + WINDOW, 3)),
                        "x_pf": p.get("pf"), "x_sharp": p.get("sharp")})
        if pear:
            start = round(pear[0]["m0"] + adl.PEAR_INSIDE, 3)
            out.append({"v": v, "branches": ("prolate", "pear"), "centre": start,
                        "span": (round(start - WINDOW, 3), adl.DEFAULT_SPAN[1]),
                        "x_pf": with_pear.get("pf"), "x_sharp": with_pear.get("sharp")})
    return out


def quick_regions() -> list[dict]:
    c = QUICK.centre
    return [{"v": QUICK.coarse.v[0], "branches": ("oblate", "prolate"), "centre": c,
             "span": (c - QUICK.window, c + QUICK.window), "x_pf": None, "x_sharp": None}]


def region_keys(reg: dict, R0: float, cfg=FULL) -> list[dict]:
    """The lines of one refined span: each branch up and down from its centre."""
    keys = []
    for b in reg["branches"]:
        for name, span in ((f"{b}@{reg['centre']:.3f}-up", (reg["centre"], reg["span"][1])),
                           (f"{b}@{reg['centre']:.3f}-down",
                            (reg["centre"], reg["span"][0]))):
            keys.append(adl.line_key(reg["v"], b, name, span, R0, cfg.eps, cfg.coarse.step,
                                    modes=0))
    return keys


def cell_keys(reg: dict, R0: float, grid, cfg=FULL) -> dict:
    """{Δa₀: key} of the pear's lines from the grid's cells in a pear span (:data:`CELL_SPAN`;
    none in other spans)."""
    if "pear" not in reg["branches"]:
        return {}
    lo, hi = sorted(reg["span"])
    return {x: adl.line_key(reg["v"], "pear", f"pear@{x:.3f}-cell", (x, round(x - CELL_SPAN, 3)),
                            R0, cfg.eps, CELL_STEP, modes=0)
            for x in grid if lo - 1e-9 <= x <= hi + 1e-9}


def grid_of(coarse: dict, v: float) -> list[float]:
    """The plane's Δa₀ at ``v`` (its cells)."""
    return sorted({p["da0"] for p in coarse["points"] if p["v"] == v})


def seeded_pear(x: float, regs: list[dict], R0: float, sharp_rows: dict, archive: dict,
                cfg=FULL) -> tuple[float | None, str | None]:
    """The pear's e at the cell ``x`` from its own line (:func:`cell_keys`: its first point,
    where that is the pear; None where the cell has no such line or it was not followed),
    and why a line there gave none (its seed became another shape: the pear is absent)."""
    keys = [k for k in (cell_keys(r, R0, [x], cfg).get(x) for r in regs) if k]
    got = adl.archived(archive, keys[0]) if keys else None
    if not got:
        return None, None
    if got["missing"]:
        return None, got["missing"]
    if not got["rows"]:
        return None, "no point"
    first = got["rows"][0]
    if not adl.kept(got["rows"][:1], "pear", sharp_rows):
        return None, f"its seed there became a {first['label']}"
    return first["e"], None


def fine_energy(br: str, x: float, have: list, regs: list[dict], R0: float, sharp_rows: dict,
                archive: dict, cfg=FULL) -> tuple[float | None, str | None]:
    """A branch's e at the cell ``x`` at the finer ε: on its span's curves ``have``, else (the
    pear) from its line seeded there (:func:`seeded_pear`, with why it gave none)."""
    fine = [f for f in (adl.at(c, x) for c in have) if f is not None]
    if fine or br != "pear":
        return (fine[0] if fine else None), None
    return seeded_pear(x, regs, R0, sharp_rows, archive, cfg)


# ---------------------------------------------------------------------------------------------
# crossings and energies
# ---------------------------------------------------------------------------------------------
def sharp_crossing(sharp_v: dict, a: str, b: str, reg: dict) -> float | None:
    """The sharp branches' crossing on their cubic splines in m₀ (as the phase field's),
    where the span was placed at one (``reg["x_sharp"]``, which kept the crossing of the
    report it was placed from: until 2026-12-07 linear between the m₀ grid's points)."""
    if reg["x_sharp"] is None:
        return None
    a_rows, b_rows = ([{"da0": r["m0"], "e": r["e"]} for r in sharp_v.get(c, [])] for c in (a, b))
    return adl.cross(adl.curve(a_rows), adl.curve(b_rows), reg["x_sharp"])


def extrapolate(fine: float | None, coarse: float | None) -> float | None:
    """The ε → 0 value from ε = 0.005 and 0.01 at the assumed order."""
    if fine is None or coarse is None:
        return None
    return fine + (fine - coarse) / (2**ORDER - 1)


def coarse_rows(v: float, b: str, sharp_rows: dict, keys01: list[dict], archive01: dict):
    """A branch's kept points at ε = 0.01 (the ADE-lines study's lines of it at v)."""
    res = {"lines": []}
    for key in keys01:
        if key["v"] == v and key["branch"] == b:
            got = adl.archived(archive01, key)
            if got:
                res["lines"].append({"rows": got["rows"]})
    return adl.kept_lines(res, b, sharp_rows)


def fine_rows(reg: dict, b: str, sharp_rows: dict, archive: dict, R0: float, cfg=FULL):
    """A branch's kept points at ε = 0.005 in one refined span (its up and down lines); and
    why a line has none."""
    rows, missing = [], []
    for key in region_keys(reg, R0, cfg):
        if key["branch"] != b:
            continue
        got = adl.archived(archive, key)
        if not got:
            missing.append(f"{key['line']}: not followed")
            continue
        if got["missing"]:
            missing.append(f"{key['line']}: {got['missing']}")
        kept = adl.kept(got["rows"], b, sharp_rows)
        if got["rows"] and not kept:
            first = got["rows"][0]
            missing.append(f"{key['line']}: its seed became a {first['label']}")
        rows += kept
    return sorted({round(r["da0"], 12): r for r in rows}.values(), key=lambda r: r["da0"]), \
        missing


# ---------------------------------------------------------------------------------------------
# the study
# ---------------------------------------------------------------------------------------------
def main(argv=None) -> dict:
    ap = study_parser(__doc__, OUT, quick="ade_branches.py --quick's line refined at "
                      "eps = 0.02", workers="", report_only="from the archived lines; "
                      "follow nothing")
    args = ap.parse_args(argv)
    from fem_ade.store.output import write_json_atomic

    cfg, suffix = (QUICK, "_quick") if args.quick else (FULL, "")
    co = cfg.coarse
    if args.quick and not args.report_only:  # the plane's quick line first, by its study
        adl.run_quick_plane(args.out, args.workers)
    base01, base = args.out / f"ade_branches{suffix}", args.out / f"ade_limit{suffix}"
    coarse = json.loads((args.out / f"ade_branches{suffix}.json").read_text())
    sharp = adl.archived_sharp(base01, co.v, co.branches)
    R0 = adl.archived_sizes(base01, co.v)
    # the spans are fixed at the first run: remaking ε = 0.01's report cannot rename lines
    path = base / "regions.json"
    if path.is_file():
        regs = json.loads(path.read_text())
    else:
        regs = quick_regions() if args.quick else regions(coarse, sharp)
        write_json_atomic(path, regs, make_folder=True)
    keys = [k for reg in regs for k in region_keys(reg, R0[reg["v"]], cfg)]
    keys += [k for reg in regs
             for k in cell_keys(reg, R0[reg["v"]], grid_of(coarse, reg["v"]), cfg).values()]
    archive = adl.load_archive(base)
    if not args.report_only:
        adl.run_lines(base, keys, archive, args.workers)
    _, keys01 = adl.plane_lines(sharp, R0, co.v, co.branches, co.eps, co.step, co.quick)
    archive01 = json.loads((base01 / "lines.json").read_text())
    result = judged(coarse, sharp, regs, R0, archive, keys01, archive01, cfg)
    result["seconds"] = {
        "fine": round(sum(archive.get(adl.line_name(k["v"], k["line"]), {})
                          .get("seconds") or 0.0 for k in keys), 1),
        "coarse": coarse.get("line_seconds")}
    write_json_atomic(args.out / f"ade_limit{suffix}.json", result)
    write_report(args.out, result, suffix)
    print(f"at eps -> 0 the lowest branch is the sharp one's at {result['agree']} of "
          f"{len(result['cells'])} cells")
    return result


def judged(coarse, sharp, regs, R0, archive, keys01, archive01, cfg=FULL) -> dict:
    """The refined transitions and the cells, from both ε's lines."""
    curves = {}  # (v, branch, "coarse" | region index) -> curve
    fine_eps, coarse_eps = f"ε = {cfg.eps:g}", f"ε = {cfg.coarse.eps:g}"
    outside = f"{coarse_eps} (outside the refined spans)"

    def sharp_rows(v):
        return {b: rows for b, rows in sharp[v].items() if rows}

    def c01(v, b):
        if (v, b, "coarse") not in curves:
            curves[(v, b, "coarse")] = adl.curve(coarse_rows(v, b, sharp_rows(v), keys01,
                                                         archive01))
        return curves[(v, b, "coarse")]

    transitions, notes = [], []
    for i, reg in enumerate(regs):
        v, (a, b) = reg["v"], reg["branches"]
        fine = {}
        for br in (a, b):
            rows, missing = fine_rows(reg, br, sharp_rows(v), archive, R0[v], cfg)
            curves[(v, br, i)] = fine[br] = adl.curve(rows)
            notes += [f"v = {v:g}, {m}" for m in missing]
        x01 = adl.cross(c01(v, a), c01(v, b), reg["centre"])
        x005 = adl.cross(fine[a], fine[b], reg["centre"])
        x0, xs = extrapolate(x005, x01), sharp_crossing(sharp[v], a, b, reg)
        transitions.append({"v": v, "from": a, "to": b, "centre": reg["centre"],
                            "coarse": x01, "fine": x005, "limit": x0, "sharp": xs,
                            "error": None if x0 is None or xs is None else x0 - xs,
                            "torus": "torus" in (a, b)})
    cells = []
    for p in coarse["points"]:
        v, x = p["v"], p["da0"]
        inside = [i for i, r in enumerate(regs) if r["v"] == v
                  and min(r["span"]) - 1e-9 <= x <= max(r["span"]) + 1e-9]
        branches = sorted({br for i in inside for br in regs[i]["branches"]})
        cell = {"v": v, "da0": x, "coarse": p["pf"], "sharp": p["sharp"],
                "limit": p["pf"], "how": outside, "e": {}}
        if inside and p["pf"] in branches:
            e, unreached = {}, []
            for br in branches:
                have = [curves[(v, br, i)] for i in inside if br in regs[i]["branches"]]
                fine, why = fine_energy(br, x, have, [regs[i] for i in inside], R0[v],
                                        sharp_rows(v), archive, cfg)
                notes += [f"v = {v:g}, pear@{x:.3f}-cell: {why}"] if why else []
                if fine is None and why is None and any(c is not None for c in have):
                    unreached.append(br)
                e[br] = {"coarse": adl.at(c01(v, br), x), "fine": fine}
                e[br]["limit"] = extrapolate(e[br]["fine"], e[br]["coarse"])
            cell.update(e=e, **verdict(e, unreached, fine_eps, coarse_eps))
        elif inside:
            cell["how"] = f"{coarse_eps} (its lowest is not of the refined pair)"
        cells.append(cell)
    agree = sum(c["limit"] == c["sharp"] for c in cells if c["sharp"])
    agree01 = sum(c["coarse"] == c["sharp"] for c in cells if c["sharp"])
    return {"eps": cfg.eps, "coarse_eps": cfg.coarse.eps, "order": ORDER,
            "window": cfg.window, "regions": regs,
            "transitions": transitions, "cells": cells, "agree": agree, "agree_coarse": agree01,
            "notes": notes}


def verdict(e: dict, unreached: list, fine_eps: str, coarse_eps: str) -> dict:
    """A refined cell's lowest branch at ε → 0 and how it was judged (module docstring);
    ``e`` each branch's energies there, ``unreached`` the branches followed at the finer ε
    but not to the cell. (An empty dict: the coarse ε's verdict stands, as it was.)"""
    both = {br: d["limit"] for br, d in e.items() if d["limit"] is not None}
    only = {br: d["fine"] for br, d in e.items() if d["limit"] is None and d["fine"] is not None}
    fine_all = {br: d["fine"] for br, d in e.items() if d["fine"] is not None}
    if unreached:  # followed at the finer ε, but not to this cell: not judged
        return {"how": f"{coarse_eps} ({', '.join(unreached)} followed at {fine_eps} but not "
                       "to this cell)"}
    if only and min(fine_all, key=fine_all.get) in only:
        return {"limit": min(fine_all, key=fine_all.get),
                "how": f"{fine_eps} (its branch does not exist there at {coarse_eps})"}
    if both:
        return {"limit": min(both, key=both.get), "how": "extrapolated"}
    return {"how": f"{coarse_eps} (no branch at both ε here)"}


#: the least |x − x_sharp| from which :func:`observed_order` is computed (the sharp crossings
#: are known to ~5e-4 at worst: ``sharp_limit.md``; here to the m₀ grid's interpolation)
ORDER_FLOOR = 2e-4


def observed_order(t: dict) -> float | None:
    """The order in ε that a transition's two crossings show against the sharp one."""
    import math

    if None in (t["coarse"], t["fine"], t["sharp"]):
        return None
    a, b = abs(t["coarse"] - t["sharp"]), abs(t["fine"] - t["sharp"])
    return math.log2(a / b) if min(a, b) > ORDER_FLOOR else None


def _f(x, digits=4):
    return "—" if x is None else f"{x:.{digits}f}"


def cell_grid(cells: list[dict], f: str) -> list[str]:
    """The cells' table: each cell's branch at ε → 0 and how it was judged (``f`` the finer
    ε, as printed)."""
    da0 = sorted({x["da0"] for x in cells})
    out = ["| v \\ Δa₀ | " + " | ".join(f"{a:g}" for a in da0) + " |",
           "|---|" + "---|" * len(da0)]
    for v in sorted({x["v"] for x in cells}, reverse=True):
        row = []
        for x in sorted((x for x in cells if x["v"] == v), key=lambda x: x["da0"]):
            mark = " ⁰" if x["how"] == "extrapolated" else \
                " ⁵" if x["how"].startswith(f"ε = {f} ") else \
                " ᶜ" if "but not to this cell" in x["how"] else ""
            text = x["limit"] or "—"
            if x["sharp"] and x["limit"] != x["sharp"]:
                text += f" / {x['sharp']} ✗"
            row.append(text + mark)
        out.append(f"| {v:g} | " + " | ".join(row) + " |")
    return out


def write_report(out: Path, result: dict, suffix: str = "") -> None:
    from _lib.cli import write_report as write

    cells, ts = result["cells"], result["transitions"]
    f, c = f"{result['eps']:g}", f"{result['coarse_eps']:g}"
    extrapolated = sum(x["how"] == "extrapolated" for x in cells)
    only = sum(x["how"].startswith(f"ε = {f} ") for x in cells)
    unreached = sum("but not to this cell" in x["how"] for x in cells)
    lines = ["# The ADE plane at ε → 0", "",
             "Written by `studies/ade_limit.py`: the transitions of the ADE plane's lines "
             f"(κ̄/κ = 1.4, `ade_branches.md`, ε = {c}) followed again at ε = {f} within "
             f"±{result['window']:g} in Δa₀ of where they were expected (each line's R₀ "
             "kept, so ε/R₀ halves), and extrapolated in ε with the order **assumed** "
             f"p = {result['order']} (x₀ = x_fine + (x_fine − x_coarse)/3; two ε measure no "
             "order).",
             "",
             f"**At ε → 0 the lowest branch is the sharp one's at {result['agree']} of "
             f"{len(cells)} cells** ({result['agree_coarse']} at ε = {c}): {extrapolated} "
             f"judged by extrapolated energies, {only} by ε = {f}'s (a branch there at that ε "
             f"only), {unreached} kept at ε = {c}'s verdict because a branch's line at "
             f"ε = {f} did not reach them, the others at ε = {c}'s (outside the refined "
             "spans).", "",
             "## The transitions", "",
             f"| v | transition | ε = {c} | ε = {f} | ε → 0 | sharp | ε → 0 − sharp | p |",
             "|---|---|---|---|---|---|---|---|"]
    for t in ts:
        err = "—" if t["error"] is None else f"{t['error']:+.4f}"
        p = observed_order(t)
        lines.append(f"| {t['v']:g} | {t['from']} → {t['to']} | {_f(t['coarse'])} | "
                     f"{_f(t['fine'])} | {_f(t['limit'])} | {_f(t['sharp'])} | {err} | "
                     f"{'—' if p is None else f'{p:.2f}'} |")
    genus0 = [abs(t["error"]) for t in ts if t["error"] is not None and not t["torus"]]
    torus = [abs(t["error"]) for t in ts if t["error"] is not None and t["torus"]]
    lines += ["", f"Extrapolated against sharp: {len(genus0)} genus-0 transitions, largest "
              f"|error| {_f(max(genus0) if genus0 else None)}; {len(torus)} with the torus, "
              f"largest {_f(max(torus) if torus else None)}. — : the two branches do not "
              "cross where both were followed at that ε. p: the order the two ε show with "
              "the sharp crossing taken as the limit, log₂(|x_coarse − x_sharp| / |x_fine − "
              f"x_sharp|), where both differences exceed {ORDER_FLOOR:g} (a check of the "
              "assumed p = 2, not used in the extrapolation).", "",
              "## The cells at ε → 0", "", *cell_grid(cells, f)]
    lines += ["", "A cell names the lowest branch at ε → 0 (where it differs from the sharp "
              "one's: phase field / sharp ✗); ⁰: judged by the branches' energies "
              f"extrapolated from ε = {c} and {f}; ⁵: by ε = {f}'s energies (a branch "
              f"there at ε = {f} only); ᶜ: ε = {c}'s verdict, a branch of its span followed "
              f"at ε = {f} but not to this cell; unmarked: ε = {c}'s verdict (outside every "
              "refined span, or its lowest branch not of the span's pair).", ""]
    if result["notes"]:
        lines += [f"Lines at ε = {f} that gave no points of their branch:", ""]
        lines += [f"- {n}" for n in result["notes"]] + [""]
    s = result["seconds"]
    lines.append(f"Branch runs: {s['fine']:g} s at ε = {f} (the refined lines) and "
                 f"{s['coarse']:g} s at ε = {c} (the plane's lines), each line's own time on "
                 "one BLAS thread, two lines at a time.")
    write(out, f"ade_limit{suffix}", lines)


if __name__ == "__main__":
    main()
