"""Where the ADE plane's axisymmetric branches lose stability in 3D (issue 43): every genus-0
line of ``studies/ade_branches.py`` (κ̄/κ = 1.4, the same v, spans, R₀ and step) followed
again with the azimuthal modes m = 0 … 8 at each point, at 4 nodes per ε, and the ends of
each branch's 3D-stable part refined at smaller ε and extrapolated to ε → 0.

* **Lines** (ε = 0.01): the prolate, the pear (up and down), the oblate and the stomatocyte
  on each v (the torus left out: a phase-field competitor a membrane cannot reach), each
  to its first fold (``_lib.lines.kept``: the points that are the branch). Each point's
  lowest eigenvalue per mode m (the blocks of docs/model.md §13; m ≥ 1 counts twice in 3D).
  4 nodes per ε, not the default 2.5: an eigenvalue near zero needs it
  (``ade_azimuthal_notes.md``: 2.5 per ε was off by up to 0.39 (ε/R₀)⁴ at ε = 0.01).
* **Crossings.** Where a mode's lowest eigenvalue changes sign along a line: a cubic spline of
  lowest_m through the kept points (linear through fewer than four), its root by Brent on
  each sign change (``crossings``); a branch's **3D-stable part** is where every mode's is
  positive, and its **ends** are the crossings that bound it (the mode that turns first).
* **Refined** at ``--fine`` ε (0.005), the same R₀ (ε/R₀ halves): each end of a stable
  part at ε = 0.01 followed again from ``WINDOW`` below to ``WINDOW`` above it (the pear
  down from above) in steps of ``FINE_STEP``, the same modes and nodes per ε; its crossing
  in the same mode located the same way, the one nearest the coarse end. The windows run in
  groups (``GROUP``), the m ≥ 1 ends first, each group archived as it ends.
* **ε → 0**: with two ε, x₀ = x(0.005) + (x(0.005) − x(0.01))/(2^p − 1) with p **assumed** = 2
  (the energies' order, ``sharp_limit.md``; the minimal model's oblate m = 2 bifurcation
  showed 1.63 over three ε, ``azimuthal.md``); with three ε the order is fitted too and both
  are given.

The lines at each ε are one branch sweep (``OUT/ade_bifurcations/eps=E/sweep``, resumable),
archived in ``OUT/ade_bifurcations/eps=E/lines.json`` as each sweep ends (``_lib.lines``).
Needs ``OUT/ade_branches/`` (its sharp cache and R0.json: ``ade_branches.py`` run first).

Writes ``OUT/ade_bifurcations.md`` (with the hand-written ``ade_bifurcations_notes.md``),
``OUT/ade_bifurcations.json`` and ``OUT/ade_bifurcations.png``.

    python studies/ade_bifurcations.py --out studies/results --fine  # ε = 0.01: 39 min, 2 cores
    python studies/ade_bifurcations.py --out studies/results   # and the windows at 0.005
    python studies/ade_bifurcations.py --out studies/results --report-only
    python studies/ade_bifurcations.py --quick       # the code: one line at ε = 0.04, 0.02

One BLAS thread and one FFT worker per process.
"""

from __future__ import annotations

from _lib.cli import one_thread, study_parser

one_thread()

import math  # noqa: E402
from pathlib import Path  # noqa: E402
from types import SimpleNamespace  # noqa: E402

from _lib import lines as adl  # noqa: E402

OUT = Path("runs") / "studies"
#: the genus-0 branches (the torus left out)
BRANCHES = ("prolate", "pear", "oblate", "stomatocyte")
MODES = 8
NODES_PER_EPS = 4.0
#: the refined windows: how far either side of an ε = 0.01 end, and the step there
WINDOW = 0.03
FINE_STEP = 0.015
#: the windows run in groups of this many lines per worker, each group archived as it ends
#: (a run stopped between groups keeps what it made); the m ≥ 1 ends first
GROUP = 2
#: the order in ε assumed where two ε are known (``_lib.fits.extrapolate``'s, where no order is
#: observed)
ORDER = 2
FULL = SimpleNamespace(eps=adl.EPS, v=adl.V, step=adl.STEP, quick=False, fine=(0.005,),
                       window=WINDOW, fine_step=FINE_STEP, branches=BRANCHES)
#: --quick: ade_branches.py --quick's v = 0.85 at ε = 0.04 (its R₀ and sharp lines), the
#: prolate and the oblate over Δa₀ 0.84 … 1.0 with the modes (the oblate turns unstable in
#: m = 2 near 0.9), its ends refined at ε = 0.02
QUICK = SimpleNamespace(eps=adl.QUICK.eps, v=adl.QUICK.v, step=adl.QUICK.step, quick=True,
                        fine=(0.02,), window=0.04, fine_step=0.04,
                        branches=adl.QUICK.branches, span=(0.84, 1.0))


def eps_base(out: Path, eps: float, quick: bool) -> Path:
    return out / ("ade_bifurcations_quick" if quick else "ade_bifurcations") / f"eps={eps:g}"


# ---------------------------------------------------------------------------------------------
# crossings
# ---------------------------------------------------------------------------------------------
def mode_lows(row: dict, modes: int = MODES) -> dict[int, float]:
    """{m: the point's lowest eigenvalue in mode m}, for the modes it has."""
    return {m: float(row[f"lowest_m{m}"]) for m in range(modes + 1)
            if row.get(f"lowest_m{m}") not in (None, "")}


def crossings(rows: list[dict], modes: int) -> list[dict]:
    """Each sign change of a mode's lowest eigenvalue along the points (sorted in Δa₀): the
    root of a cubic spline of it through the points (:func:`_lib.lines.curve`) between the
    two (Brent), ``turns`` 'unstable' or 'stable' as Δa₀ grows; sorted in Δa₀."""
    from scipy.optimize import brentq

    rows = sorted(rows, key=lambda r: r["da0"])
    lows = [(r["da0"], mode_lows(r, modes)) for r in rows]
    out = []
    for m in range(modes + 1):
        pts = [(x, low[m]) for x, low in lows if m in low]
        c = adl.curve([{"da0": x, "y": y} for x, y in pts], value="y")
        if c is None:
            continue
        for (xa, ya), (xb, yb) in zip(pts, pts[1:], strict=False):
            if ya == 0.0 or ya * yb >= 0:
                continue
            fa, fb = float(c[0](xa)), float(c[0](xb))
            x = float(brentq(c[0], xa, xb)) if fa * fb < 0 else xa - ya * (xb - xa) / (yb - ya)
            out.append({"m": m, "da0": x, "turns": "unstable" if yb < 0 else "stable",
                        "between": [xa, xb]})
    return sorted(out, key=lambda c: c["da0"])


def stable_parts(rows: list[dict], cross: list[dict], modes: int) -> list[dict]:
    """The branch's 3D-stable parts: maximal runs of points with every mode's lowest
    eigenvalue positive, each with its ends among its :func:`crossings` ``cross`` — the
    one that opens it (None: it starts at the line's first point) and the one that closes
    it (None: to the line's last)."""
    rows = sorted(rows, key=lambda r: r["da0"])
    parts, run = [], []
    for r in rows + [None]:
        ok = r is not None and all(x > 0 for x in mode_lows(r, modes).values())
        if ok:
            run.append(r)
            continue
        if run:
            lo, hi = run[0]["da0"], run[-1]["da0"]
            first = [c for c in cross if c["between"][1] == lo and c["turns"] == "stable"]
            last = [c for c in cross if c["between"][0] == hi and c["turns"] == "unstable"]
            parts.append({"from": lo, "to": hi, "points": len(run),
                          "opens": max(first, key=lambda c: c["da0"]) if first else None,
                          "closes": min(last, key=lambda c: c["da0"]) if last else None})
        run = []
    return parts


# ---------------------------------------------------------------------------------------------
# the runs
# ---------------------------------------------------------------------------------------------
def coarse_keys(cfg, sharp: dict, R0: dict) -> list[dict]:
    """The plane's genus-0 lines with the modes (``cfg.span`` for each branch: --quick)."""
    more = {"modes": MODES, "nodes_per_eps": NODES_PER_EPS}
    if getattr(cfg, "span", None):
        return [adl.line_key(v, b, b, cfg.span, R0[v], cfg.eps, cfg.step, **more)
                for v in cfg.v for b in cfg.branches]
    return adl.plane_lines(sharp, R0, cfg.v, cfg.branches, cfg.eps, cfg.step, False,
                           **more)[1]


def line_results(keys: list[dict], archive: dict, sharp: dict) -> dict:
    """{(v, branch): {"rows": the kept points of its lines, "missing": [why a line has
    none], "seconds": …}}."""
    by = {}
    for key in keys:
        got = adl.archived(archive, key)
        e = by.setdefault((key["v"], key["branch"]), {"lines": [], "missing": [],
                                                      "seconds": 0.0})
        if got is None:
            e["missing"].append(f"{key['line']}: not followed")
            continue
        e["lines"].append(got)
        e["seconds"] += got.get("seconds") or 0.0
        if got.get("missing"):
            e["missing"].append(f"{key['line']}: {got['missing']}")
    for (v, b), e in by.items():
        e["rows"] = adl.kept_lines(e, b, sharp[v])
    return by


def ends(parts: list[dict]) -> list[dict]:
    """The crossings that bound a branch's stable parts of two points or more, each once (a
    part of one point between crossings at one Δa₀: the eigenvalue at zero's noise, as where
    the pear's line joins the prolate at their bifurcation)."""
    got = {}
    for p in parts:
        if p["points"] < 2:
            continue
        for c in (p["opens"], p["closes"]):
            if c is not None:
                got[(c["m"], round(c["da0"], 9))] = c
    return sorted(got.values(), key=lambda c: c["da0"])


def fine_keys(coarse: dict, R0: dict, eps: float, cfg) -> list[dict]:
    """A window line at ``eps`` around each end of a stable part at the coarse ε: up in Δa₀
    from ``cfg.window`` below it, the pear down from above it (the pear exists at large Δa₀
    only)."""
    keys = []
    for (v, b), e in coarse.items():
        for c in ends(e["parts"]):
            x, w = c["da0"], cfg.window
            span = (round(x + w, 4), round(x - w, 4)) if b == "pear" else \
                (round(x - w, 4), round(x + w, 4))
            keys.append(adl.line_key(v, b, f"{b}-m{c['m']}-at-{x:.4f}", span, R0[v], eps,
                                     cfg.fine_step, modes=MODES, nodes_per_eps=NODES_PER_EPS,
                                     end={"m": c["m"], "da0": x}))
    return keys


def refined(keys: list[dict], archive: dict, sharp: dict) -> dict:
    """{(v, branch, m, coarse da0): the window's crossing in mode m nearest the coarse one
    (None: none there, with why)}."""
    out = {}
    for key in keys:
        got = adl.archived(archive, key)
        end = key["end"]
        entry = {"da0": None, "turns": None, "why": None, "seconds": None, "rows": []}
        if got is None:
            entry["why"] = "not followed"
        else:
            entry["seconds"] = got.get("seconds")
            rows = adl.kept(sorted(got["rows"], key=lambda r: r["da0"],
                                   reverse=key["from"] > key["to"]), key["branch"],
                            sharp[key["v"]])
            entry["rows"] = rows
            cs = [c for c in crossings(rows, MODES) if c["m"] == end["m"]]
            if cs:
                c = min(cs, key=lambda c: abs(c["da0"] - end["da0"]))
                entry.update(da0=c["da0"], turns=c["turns"])
            elif got["rows"] and not rows:
                labels = sorted({r["label"] for r in got["rows"]})
                entry["why"] = (f"none of its {len(got['rows'])} points is the "
                                f"{key['branch']} (labelled {', '.join(labels)})")
            else:
                entry["why"] = got.get("missing") or (
                    f"no sign change of m = {end['m']} over {len(rows)} points "
                    f"({min((r['da0'] for r in rows), default=math.nan):.4f} … "
                    f"{max((r['da0'] for r in rows), default=math.nan):.4f})")
        out[(key["v"], key["branch"], end["m"], round(end["da0"], 9))] = entry
    return out


def transitions(coarse: dict, windows: dict, cfg) -> list[dict]:
    """Per v where both the oblate and the prolate have an m = 2 end: where the oblate turns
    unstable (x_o), where the prolate turns stable (x_p) and where their energies cross
    (x_e: :func:`_lib.lines.cross` of e along the two, the oblate lower below it), at each ε
    (the finer from the windows' points, where the two windows overlap) and at ε → 0; and
    the Δa₀ where the lower of the two is unstable in 3D: (x_o, x_e) where the oblate turns
    unstable before the crossing, (x_e, x_p) where the prolate turns stable after it."""
    out = []
    for v in cfg.v:
        ob, pr = coarse.get((v, "oblate")), coarse.get((v, "prolate"))
        if not ob or not pr:
            continue
        eo = [c for c in ends(ob["parts"]) if c["m"] == 2 and c["turns"] == "unstable"]
        ep = [c for c in ends(pr["parts"]) if c["m"] == 2 and c["turns"] == "stable"]
        if not eo or not ep:
            continue
        xs = {"o": {}, "p": {}, "e": {}}
        rows = {cfg.eps: (ob["rows"], pr["rows"])}
        xs["o"][cfg.eps], xs["p"][cfg.eps] = eo[0]["da0"], ep[0]["da0"]
        for eps, got in windows.items():
            wo = got.get((v, "oblate", 2, round(eo[0]["da0"], 9)))
            wp = got.get((v, "prolate", 2, round(ep[0]["da0"], 9)))
            xs["o"][eps] = wo and wo["da0"]
            xs["p"][eps] = wp and wp["da0"]
            rows[eps] = (wo["rows"] if wo else [], wp["rows"] if wp else [])
        for eps, (ro, rp) in rows.items():
            xs["e"][eps] = adl.cross(adl.curve(ro), adl.curve(rp), xs["o"][cfg.eps])
        entry = {"v": v}
        for k in "ope":
            entry[k] = {f"{e:g}": x for e, x in sorted(xs[k].items(), reverse=True)}
            entry[k + "0"] = extrapolate(xs[k])["x0_assumed"]
        entry["unstable_lowest"] = {}
        for e in [*(f"{e:g}" for e in sorted(xs["o"], reverse=True)), "0"]:
            o, p_, x = ((entry[k + "0"] if e == "0" else entry[k][e]) for k in "ope")
            if None in (o, p_, x):
                entry["unstable_lowest"][e] = None
                continue
            spans = [[o, x]] if o < x else []
            spans += [[x, p_]] if x < p_ else []
            entry["unstable_lowest"][e] = spans
        out.append(entry)
    return out


def extrapolate(xs: dict) -> dict:
    """{eps: x} → x₀ by :func:`_lib.fits.extrapolate`: with p = ORDER assumed over the two
    smallest ε, and with three ε the observed order and its x₀ too."""
    from _lib.fits import extrapolate as richardson

    pts = sorted((e, x) for e, x in xs.items() if x is not None)
    out = {"x0_assumed": None, "order": None, "x0_fitted": None}
    if len(pts) < 2:
        return out
    eps, x = zip(*pts, strict=True)
    out["x0_assumed"] = richardson(list(eps[:2]), list(x[:2]))[0]
    if len(pts) >= 3:
        x0, p, observed = richardson(list(eps), list(x))
        if observed:
            out.update(order=p, x0_fitted=x0)
    return out


def summary(cfg, coarse: dict, windows: dict, R0: dict) -> dict:
    """The study's result: per line (v, branch) its kept points, every crossing and the
    stable parts at the coarse ε, and each end refined at each fine ε with its ε → 0."""
    lines = []
    for (v, b), e in sorted(coarse.items()):
        scale = (cfg.eps / R0[v]) ** 4
        ends_out = []
        for c in ends(e["parts"]):
            at = {f"{cfg.eps:g}": c["da0"]}
            why = {}
            for eps, got in windows.items():
                w = got.get((v, b, c["m"], round(c["da0"], 9)))
                at[f"{eps:g}"] = None if w is None else w["da0"]
                if w is not None and w["da0"] is None:
                    why[f"{eps:g}"] = w["why"]
            ex = extrapolate({float(k): x for k, x in at.items()})
            ends_out.append({"m": c["m"], "turns": c["turns"], "da0": at, "why": why, **ex})
        lines.append({"v": v, "branch": b, "R0": R0[v], "points": len(e["rows"]),
                      "span": [e["rows"][0]["da0"], e["rows"][-1]["da0"]] if e["rows"] else None,
                      "missing": e["missing"], "seconds": round(e["seconds"], 1),
                      "crossings": [{"m": c["m"], "da0": c["da0"], "turns": c["turns"]}
                                    for c in e["crossings"]],
                      "parts": [{k: p[k] for k in ("from", "to", "points")} for p in e["parts"]],
                      "ends": ends_out,
                      "lowest_first": _lows(e["rows"][0], scale) if e["rows"] else None})
    fine_seconds = {f"{eps:g}": round(sum(w["seconds"] or 0 for w in got.values()), 1)
                    for eps, got in windows.items()}
    return {"eps": cfg.eps, "fine": [float(e) for e in windows], "kbar": adl.KBAR,
            "modes": MODES, "nodes_per_eps": NODES_PER_EPS, "order_assumed": ORDER,
            "window": cfg.window, "lines": lines,
            "line_seconds": round(sum(e["seconds"] for e in coarse.values()), 1),
            "fine_seconds": fine_seconds}


def _lows(row: dict, scale: float) -> dict:
    return {str(m): round(x / scale, 3) for m, x in mode_lows(row).items()}


def _f(x, digits=4) -> str:
    return "—" if x is None else f"{x:.{digits}f}"


def write_report(out: Path, result: dict, suffix: str = "") -> None:
    """OUT/ade_bifurcations.md: the stable parts and their ends per line, refined and
    extrapolated, and every crossing at the coarse ε; the notes appended."""
    eps, fine = result["eps"], result["fine"]
    head = [f"ε = {eps:g}", *(f"ε = {e:g}" for e in fine)]
    text = [
        "# Where the ADE plane's branches lose stability in 3D",
        "",
        "Generated by `studies/ade_bifurcations.py` (issue 43); the hypotheses and controls are "
        "in `ade_bifurcations_notes.md` (below). κ̄/κ = "
        f"{result['kbar']:g}; the lines of `ade_branches.py` (the same v, spans, step and R₀), "
        f"genus 0, with the modes m = 0 … {result['modes']} at every point, "
        f"{result['nodes_per_eps']:g} nodes per ε. A branch's points are those that are the "
        "branch, up to its first fold. A crossing: where a mode's lowest eigenvalue changes "
        "sign along the line (a cubic spline in Δa₀ through the points, its root); m ≥ 1 is "
        "a non-axisymmetric branch born there (a pair of directions in 3D), m = 0 an "
        "axisymmetric one.",
        "",
        f"Line time at ε = {eps:g}: {result['line_seconds']:.0f} s"
        + "".join(f"; the windows at ε = {k}: {v:.0f} s" for k, v in
                  result["fine_seconds"].items()) + ".",
        "",
        "## The 3D-stable part of each branch and its ends",
        "",
        "Each end's Δa₀ at each ε (its window at the finer ε: "
        f"±{result['window']:g} around the ε = {eps:g} end), and at ε → 0: with two ε, "
        f"p = {result['order_assumed']} **assumed**; with three, the fitted p and its limit.",
        "",
        f"| v | branch | points | 3D-stable (ε = {eps:g}) | end: m, turns | "
        + " | ".join(head) + " | ε → 0 (p = 2) | fitted p, ε → 0 |",
        "|---|---|---|---|---|" + "---|" * len(head) + "---|---|",
    ]
    for ln in result["lines"]:
        stable = ", ".join(f"{p['from']:.3f} … {p['to']:.3f}" for p in ln["parts"]) or "nowhere"
        lead = f"| {ln['v']:g} | {ln['branch']} | {ln['points']} | {stable} |"
        if not ln["points"]:
            text.append(lead + " " + "; ".join(ln["missing"]) + " |" + " |" * (len(head) + 2))
            continue
        if not ln["ends"]:
            text.append(lead + " — |" + " |" * (len(head) + 2))
            continue
        for i, end in enumerate(ln["ends"]):
            cols = [_f(end["da0"].get(k)) + ("*" if k in end["why"] else "")
                    for k in [f"{eps:g}", *(f"{e:g}" for e in fine)]]
            fit = "—" if end["order"] is None else f"{end['order']:.2f}, {_f(end['x0_fitted'])}"
            text.append((lead if i == 0 else "| | | | |")
                        + f" m = {end['m']}, {end['turns']} | " + " | ".join(cols)
                        + f" | {_f(end['x0_assumed'])} | {fit} |")
    text += _transition_table(result, head)
    notes = [f"- v = {ln['v']:g} {ln['branch']}, m = {end['m']} at ε = {k}: {why}"
             for ln in result["lines"] for end in ln["ends"] for k, why in end["why"].items()]
    if notes:
        text += ["", r"\* no crossing of that mode in the window:", "", *notes]
    text += _crossing_table(result)
    path_notes = out / f"ade_bifurcations{suffix}_notes.md"
    if path_notes.is_file():
        text += ["", path_notes.read_text().rstrip()]
    (out / f"ade_bifurcations{suffix}.md").write_text("\n".join(text) + "\n")


def _crossing_table(result: dict) -> list[str]:
    """Every crossing along each line at the coarse ε, and each mode's lowest eigenvalue at
    the line's first point."""
    eps = result["eps"]
    text = []
    text += ["", f"## Every crossing along each line (ε = {eps:g})", "",
             "Where each mode's lowest eigenvalue changes sign as Δa₀ grows (↓: turns "
             "unstable, ↑: turns stable); the lowest eigenvalue of each mode at the line's "
             "first point in units of (ε/R₀)⁴.", "",
             "| v | branch | span | crossings (m: Δa₀) | first point's lowest per m |",
             "|---|---|---|---|---|"]
    for ln in result["lines"]:
        if not ln["points"]:
            continue
        cs = ", ".join(f"{c['m']}{'↓' if c['turns'] == 'unstable' else '↑'}: {c['da0']:.3f}"
                       for c in ln["crossings"]) or "none"
        lows = " ".join(f"{x:+.2f}" for x in ln["lowest_first"].values())
        text.append(f"| {ln['v']:g} | {ln['branch']} | {ln['span'][0]:.3f} … "
                    f"{ln['span'][1]:.3f} | {cs} | {lows} |")
    return text


def _transition_table(result: dict, head: list[str]) -> list[str]:
    """The oblate ↔ prolate transition against the two branches' m = 2 ends."""
    if not result.get("transitions"):
        return []
    text = ["", "## The oblate ↔ prolate transition and the two m = 2 ends", "",
            "x_o: the oblate turns unstable in m = 2 (Δa₀ growing); x_p: the prolate turns "
            "stable in m = 2; x_e: their energies cross (the oblate lower below it; e of "
            "the same points, cubic splines; at the finer ε where the two windows overlap). "
            "Where x_o < x_e the oblate is the lower branch and unstable in 3D on (x_o, x_e); "
            "where x_e < x_p the prolate is, on (x_e, x_p); where x_p < x_o both are stable "
            "between (bistable, the transition discontinuous). ε → 0 with p = 2 assumed, "
            "each of the three on its own.", "",
            "| v | | " + " | ".join(head) + " | ε → 0 |",
            "|---|---|" + "---|" * len(head) + "---|"]
    keys = [h.removeprefix("ε = ") for h in head]
    for t in result["transitions"]:
        for k, name in (("o", "x_o"), ("p", "x_p"), ("e", "x_e")):
            text.append(f"| {t['v']:g} | {name} | "
                        + " | ".join(_f(t[k].get(e)) for e in keys) + f" | {_f(t[k + '0'])} |")
        spans = [t["unstable_lowest"].get(e) for e in [*keys, "0"]]
        text.append(f"| {t['v']:g} | lowest unstable on | " + " | ".join(
            "—" if sp is None else ("none" if not sp else ", ".join(
                f"{a:.4f} … {b:.4f}" for a, b in sp)) for sp in spans) + " |")
    return text


def write_figure(out: Path, result: dict, coarse: dict, suffix: str = "") -> None:
    """OUT/ade_bifurcations.png: a panel per branch, each line at its v along Δa₀ — its
    points green where stable in 3D, orange where unstable in m = 0, red where in m ≥ 1
    only — the crossings marked with their m, the ends' ε → 0 as black ticks."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    branches = sorted({b for _, b in coarse}, key=BRANCHES.index)
    fig, axes = plt.subplots(1, len(branches), figsize=(3.6 * len(branches), 4.2),
                             sharey=True, squeeze=False)
    for ax, b in zip(axes[0], branches, strict=True):
        for (v, bb), e in coarse.items():
            if bb != b:
                continue
            for r in e["rows"]:
                lows = mode_lows(r)
                colour = "tab:green" if min(lows.values()) > 0 else (
                    "tab:orange" if lows.get(0, 0.0) < 0 else "tab:red")
                ax.plot(r["da0"], v, "o", ms=4, color=colour)
            for c in e["crossings"]:
                ax.plot([c["da0"]] * 2, [v - 0.012, v + 0.012], "-", color="0.3", lw=0.8)
                ax.annotate(str(c["m"]), (c["da0"], v + 0.013), ha="center", fontsize=6)
        for ln in result["lines"]:
            if ln["branch"] == b:
                for end in ln["ends"]:
                    if end["x0_assumed"] is not None:
                        ax.plot(end["x0_assumed"], ln["v"], "|", color="k", ms=12, mew=1.5)
        for t in result.get("transitions", []):
            x = t["e"].get(f"{result['eps']:g}")
            if b in ("oblate", "prolate") and x is not None:
                ax.plot(x, t["v"], "D", mfc="none", mec="k", ms=6)
        ax.set_title(b)
        ax.set_xlabel("Δa₀")
    axes[0][0].set_ylabel("v")
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], ls="", marker="o", color=c, label=t) for c, t in
               (("tab:green", f"stable in 3D (m ≤ {MODES})"),
                ("tab:orange", "unstable in m = 0"), ("tab:red", "unstable in m ≥ 1 only"))]
    handles.append(Line2D([], [], ls="", marker="|", color="k", ms=10,
                          label="end of the stable part, ε → 0"))
    handles.append(Line2D([], [], ls="", marker="D", mfc="none", mec="k",
                          label="oblate and prolate e equal"))
    fig.legend(handles=handles, loc="lower center", ncol=5, frameon=False, fontsize=8)
    fig.suptitle(f"ADE plane (κ̄/κ = {result['kbar']:g}, ε = {result['eps']:g}): stability "
                 "in 3D along each line; ticks: a mode's crossing, its m", fontsize=9)
    fig.tight_layout(rect=(0, 0.07, 1, 0.95))
    fig.savefig(out / f"ade_bifurcations{suffix}.png", dpi=110)
    plt.close(fig)


def main(argv=None) -> dict:
    ap = study_parser(__doc__, OUT, quick="one short line at eps = 0.04, its ends at 0.02",
                      workers="", report_only="from the archived lines; follow nothing")
    ap.add_argument("--fine", type=float, nargs="*", default=None,
                    help="the smaller eps at which the ends are refined (default: 0.005; "
                    "none: the lines at 0.01 only)")
    args = ap.parse_args(argv)
    cfg = QUICK if args.quick else FULL
    fine = cfg.fine if args.fine is None else tuple(args.fine)
    plane = args.out / ("ade_branches_quick" if cfg.quick else "ade_branches")
    if cfg.quick and not args.report_only and not (plane / "R0.json").is_file():
        adl.run_quick_plane(args.out, args.workers)
    sharp = adl.archived_sharp(plane, cfg.v, BRANCHES if not cfg.quick else cfg.branches)
    R0 = adl.archived_sizes(plane, cfg.v)
    keys = coarse_keys(cfg, sharp, R0)
    base = eps_base(args.out, cfg.eps, cfg.quick)
    archive = adl.load_archive(base)
    if not args.report_only:
        adl.run_lines(base, keys, archive, args.workers)
    coarse = line_results(keys, archive, sharp)
    for e in coarse.values():
        e["crossings"] = crossings(e["rows"], MODES)
        e["parts"] = stable_parts(e["rows"], e["crossings"], MODES)
    windows = {}
    for eps in fine:
        fkeys = fine_keys(coarse, R0, eps, cfg)
        fbase = eps_base(args.out, eps, cfg.quick)
        farchive = adl.load_archive(fbase)
        if not args.report_only:
            todo = sorted(fkeys, key=lambda k: (k["end"]["m"] == 0, k["v"], k["end"]["da0"]))
            size = GROUP * args.workers
            for i in range(0, len(todo), size):
                adl.run_lines(fbase, todo[i:i + size], farchive, args.workers)
                print(f"eps = {eps:g}: {min(i + size, len(todo))} of {len(todo)} windows",
                      flush=True)
        windows[eps] = refined(fkeys, farchive, sharp)
    result = summary(cfg, coarse, windows, R0)
    result["transitions"] = transitions(coarse, windows, cfg)
    suffix = "_quick" if cfg.quick else ""
    from fem_ade.store.output import write_json_atomic

    write_json_atomic(args.out / f"ade_bifurcations{suffix}.json", result)
    write_report(args.out, result, suffix)
    write_figure(args.out, result, coarse, suffix)
    return result


if __name__ == "__main__":
    main()
