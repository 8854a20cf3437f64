"""Transitions from branch crossings (issue 32): the minimal model's prolate → oblate and
oblate → stomatocyte transitions as the v where two branches followed by continuation
(``fem_ade.campaigns.branch``, axisymmetric, Newton on every point) have equal energy, at each ε,
beside the sharp membrane's (``sharp_ref``) and the seeded steady states' of
``studies/sharp_limit.py``.

The branches are the points of a branch sweep, ``studies/sweeps/branches.toml``
(:mod:`fem_ade.campaigns.sweep`: one Dask task per branch, two workers): each pair of branches is
followed at one R₀ (the two branches' ε/R₀ equal), the prolate and the oblate at R₀ = 0.17
(the largest at which the prolate at v = 0.62 fits the box) from v = 0.70 down to 0.62
(0.645 at ε = 0.005), the oblate and the stomatocyte at R₀ = 0.25 from v = 0.62 down to
0.56 (at ε = 0.005: the oblate to 0.58, the stomatocyte from 0.60 to 0.585). The crossing is
:func:`fem_ade.campaigns.branch_analysis.crossing` (linear between points ~0.002 apart); ε → 0
by Richardson
with p = 2 (the order every kept branch shows in ``sharp_limit.md``) over
the two smallest ε with a crossing. The folds (turning points in v) of every branch are
reported: where a branch ends at finite ε.

Writes ``OUT/branches.md``, ``OUT/branches.json``, ``OUT/branches.png`` and
``OUT/branches/minimal.json`` (the transitions, ε = 0 for the extrapolation); the sweep's
branch folders in ``OUT/branches/points/NAME`` (their ``points/`` are not committed) —
resumable, as a sweep is: a finished branch is read back, a stopped one goes on.
``--report-only`` rebuilds the report from the folders.

    python studies/branches.py --out studies/results           # ~2 h (below)
    python studies/branches.py --quick                         # the code (a minute)
    python studies/branches.py --out studies/results --report-only

Its time is the ε = 0.005 prolate's (42 points from v = 0.70 to 0.645): a point there took
~2.5 min, 119 s of it the stability, before the direct solver (measured 2026-12-03); with it
~12.5 s with the m = 0 stability by SuperLU, 8.7 s by PARDISO
(`studies/results/solver_bench.json`), so 6–10 min.

One thread: ``OPENBLAS_NUM_THREADS=1``, ``FEM_ADE_FFT_WORKERS=1`` unless set.
"""

from __future__ import annotations

from _lib.cli import one_thread, study_parser

one_thread()

from pathlib import Path  # noqa: E402

from _lib.fits import extrapolate  # noqa: E402

OUT = Path("runs") / "studies"
SWEEPS = Path(__file__).resolve().parent / "sweeps"
#: the branches (a point per branch, pair and ε; a pair is the points of one R₀, its first
#: seed the upper branch), and --quick's: the same code on short stretches at ε = 0.04
SWEEP, QUICK_SWEEP = SWEEPS / "branches.toml", SWEEPS / "branches_quick.toml"
SHARP = {"prolate → oblate": 0.6511, "oblate → stomatocyte": 0.5912}  # sharp_limit.md


def pairs_of(sweep) -> list[dict]:
    """The sweep's pairs, in its points' order: each ``{"R0", "branches": (upper, lower),
    "eps": {ε: {branch: point}}}`` (the points of one R₀)."""
    pairs = {}
    for point in sweep.points():
        R0, eps = point.values["R0"], point.values["eps"]
        pair = pairs.setdefault(R0, {"R0": R0, "branches": [], "eps": {}})
        if point.seed not in pair["branches"]:
            pair["branches"].append(point.seed)
        pair["eps"].setdefault(eps, {})[point.seed] = point
    for pair in pairs.values():
        if len(pair["branches"]) != 2:
            raise SystemExit(f"branches: the points at R0 = {pair['R0']} are not a pair of "
                             f"branches: {pair['branches']}")
    return list(pairs.values())


def line(root: Path, point) -> list[dict]:
    """A branch point's rows (its branch.csv) once it has ended, else none."""
    from fem_ade.campaigns.branch_folder import read_branch_table
    from fem_ade.engine.jobs import read_summary
    from fem_ade.store.status import Status

    folder = root / "points" / point.name
    summary = read_summary(folder)
    if summary is None or summary.get("status") != Status.COMPLETED:
        return []
    return read_branch_table(folder)


def main(argv=None) -> dict:
    from fem_ade.campaigns.sweep import report_rows, run_sweep
    from fem_ade.campaigns.sweep_file import load_sweep
    from fem_ade.store.output import write_json_atomic

    ap = study_parser(__doc__, OUT, quick="short stretches at eps = 0.04: the code, not the "
                      "result", workers="Dask workers (a branch each)",
                      report_only="from the branches' folders; follow nothing")
    args = ap.parse_args(argv)
    sweep = load_sweep(QUICK_SWEEP if args.quick else SWEEP)
    suffix = "_quick" if args.quick else ""
    base = args.out / f"branches{suffix}"
    if args.report_only:
        report_rows(sweep, base)
    else:
        run_sweep(sweep, base, workers=args.workers)
    pairs = pairs_of(sweep)
    eps_list = list(dict.fromkeys(e for pair in pairs for e in pair["eps"]))
    results, curves = [], {}
    for pair in pairs:
        row = transition(base, pair, eps_list, curves)
        results.append(row)
        print(f"{row['transition']}: {row['at']} -> {row['extrapolated']} "
              f"(sharp {row['sharp']})", flush=True)
    payload = {"eps": eps_list, "pairs": results}
    write_json_atomic(args.out / f"branches{suffix}.json", payload)
    write_json_atomic(base / "minimal.json", minimal(payload))
    write_report(args.out, payload, curves, suffix)
    return payload


def transition(base: Path, pair: dict, eps_list: list, curves: dict) -> dict:
    """One pair's row: its crossing at each ε
    (:func:`fem_ade.campaigns.branch_analysis.crossing`), ε → 0 by
    Richardson with p = 2 over the two smallest ε with one, where each branch ended and its
    folds; its branches' (v, e, unstable) added to ``curves``."""
    from fem_ade.campaigns.branch_analysis import crossing, same_branch

    upper, lower = pair["branches"]
    name, R0 = f"{upper} → {lower}", pair["R0"]
    row = {"transition": name, "R0": R0, "at": {f"{e:g}": None for e in eps_list},
           "eps": list(pair["eps"]), "sharp": SHARP[name], "ended": {}, "folds": {}}
    for eps, points in pair["eps"].items():
        both = []
        for b in (upper, lower):
            rows, key = line(base, points[b]), f"{b} {eps:g}"
            if rows and not same_branch(b, rows[0]["label"]):
                row["ended"][key] = (f"its seed relaxed to a shape labelled "
                                     f"{rows[0]['label']}: not this branch")
                row.setdefault("last_v", {})[key] = None
                both.append([])
                continue
            both.append(rows)
            curves[(b, R0, eps)] = [(r["v"], r["e"], r["unstable"]) for r in rows]
            stop = points[b].branch["to"]
            row["ended"][key] = (f"v = {rows[-1]['v']:.4f}, {rows[-1]['label']}"
                                 + (" (the end of its range)" if rows[-1]["v"] <= stop else "")
                                 if rows else "no point")
            row.setdefault("last_v", {})[key] = rows[-1]["v"] if rows else None
            row["folds"][key] = [float(r["fold"]) for r in rows
                                 if r.get("fold") not in (None, "")]
        row["at"][f"{eps:g}"] = crossing(both[0], both[1], "v")
    have = [(e, row["at"][f"{e:g}"]) for e in eps_list if row["at"][f"{e:g}"] is not None]
    row["extrapolated"] = None
    if len(have) >= 2:  # p = 2 over the two smallest ε (sharp_limit's, given two)
        row["extrapolated"] = extrapolate(*zip(*have[-2:], strict=True))[0]
    return row


def minimal(payload: dict) -> dict:
    """The transitions as issue 32 asks for them: one entry per (pair, ε) with a crossing and
    one with ``eps`` = 0 for the extrapolation (``{"transitions": [{"from", "to", "eps",
    "v"}, ...]}``), the sharp value beside each."""
    out = []
    for r in payload["pairs"]:
        upper, lower = r["transition"].split(" → ")
        found = [(float(e), x) for e, x in r["at"].items() if x is not None]
        if r["extrapolated"] is not None:
            found.append((0.0, r["extrapolated"]))
        out += [{"from": upper, "to": lower, "eps": e, "v": x, "R0": r["R0"],
                 "sharp": r["sharp"]} for e, x in found]
    return {"transitions": out}


def write_report(out: Path, payload: dict, curves: dict, suffix: str = "") -> None:
    """Write ``OUT/branches{suffix}.md`` (the crossings, where each branch ended, the notes)
    and its figure."""
    lines = _crossings_table(payload) + _branch_ends(payload)
    lines += ["", f"![e along the branches](branches{suffix}.png)", ""]
    notes = out / "branches_notes.md"
    if notes.is_file() and not suffix:
        lines += [notes.read_text()]
    (out / f"branches{suffix}.md").write_text("\n".join(lines) + "\n")
    figure(out / f"branches{suffix}.png", payload, curves)


def _crossings_table(payload: dict) -> list[str]:
    """The report's head and its table: each transition's crossing at every ε, extrapolated
    and sharp."""
    eps_list = payload["eps"]
    lines = ["# Transitions from branch crossings", "",
             "Written by `studies/branches.py`: each pair of branches followed in v by "
             "`fem_ade.campaigns.branch` (axisymmetric, order 8, 2.5 nodes per ε, Newton on every "
             "point), at one R₀ for both; the transition is where their e = (W + G)/W_sphere "
             "are equal. ε → 0: Richardson with p = 2 over the two ε.", "",
             "**Made with older branch code**: these tables are the first run's (b732ffe … "
             "ce4559e), before the continuation's predictor and its stability without the "
             "translation "
             "mode changed; the notes below say what moved when the branches were followed "
             "again at the new code.", "",
             "| transition | R₀ | " + " | ".join(f"ε = {e:g} (ε/R₀)" for e in eps_list)
             + " | ε → 0 (p = 2) | sharp |",
             "|---|---|" + "---|" * (len(eps_list) + 2)]
    for r in payload["pairs"]:
        cells = []
        for e in eps_list:
            x = r["at"][f"{e:g}"]
            cells.append("not run" if e not in r["eps"] else
                         ("—" if x is None else f"{x:.4f}") + f" ({e / r['R0']:.3f})")
        ex = "—" if r["extrapolated"] is None else f"{r['extrapolated']:.4f}"
        lines.append(f"| {r['transition']} | {r['R0']:g} | " + " | ".join(cells)
                     + f" | {ex} | {r['sharp']:.4f} |")
    return lines


def _branch_ends(payload: dict) -> list[str]:
    """Where each branch of each pair ended, with its folds."""
    lines = ["", "— : the two branches do not cross where both were followed (one ended "
             "first). Where each branch ended (its last point: v, label) and its folds "
             "(turning points in v, where a stable branch meets an unstable one):", ""]
    for r in payload["pairs"]:
        for k, v in r["ended"].items():
            folds = r["folds"].get(k) or []
            lines.append(f"- {r['transition']}, {k.replace(' ', ' at ε = ')}: "
                         + (v if v.startswith("its seed") else f"last point at {v}")
                         + (f"; fold at v = {', '.join(f'{f:.4f}' for f in folds)}"
                            if folds else ""))
    return lines


COLOURS = {"prolate": "tab:blue", "oblate": "tab:orange", "stomatocyte": "tab:green"}


def figure(path: Path, payload: dict, curves: dict) -> None:
    """e along both branches of each pair (a panel per pair, a line style per ε), with the
    crossings and the sharp transition."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem_ade.plots.figures import save_figure

    eps_list = payload["eps"]
    fig, axes = plt.subplots(1, len(payload["pairs"]), figsize=(10, 4))
    styles = dict(zip(eps_list, ("--", "-", ":"), strict=False))
    for ax, r in zip(axes, payload["pairs"], strict=True):
        _plot_pair(ax, r, curves, eps_list, styles)
    fig.tight_layout()
    save_figure(fig, path, dpi=110, colours=64)
    plt.close(fig)


def _plot_pair(ax, r: dict, curves: dict, eps_list, styles: dict) -> None:
    """One pair's panel: its branches (unstable points marked ×), crossings and sharp
    transition."""
    upper, lower = r["transition"].split(" → ")
    for b in (upper, lower):
        for e in eps_list:
            pts = curves.get((b, r["R0"], e)) or []
            if not pts:
                continue
            v, en, _ = zip(*pts, strict=True)
            ax.plot(v, en, styles[e], color=COLOURS[b], label=f"{b}, ε = {e:g}")
            bad = [(a, c) for a, c, u in pts if u > 0]
            if bad:
                ax.plot(*zip(*bad, strict=True), "x", color=COLOURS[b], ms=3,
                        label=f"{b}, ε = {e:g}: unstable")
    for e in eps_list:
        x = r["at"][f"{e:g}"]
        if x is not None:
            ax.axvline(x, color="grey", ls=styles[e], lw=0.8)
    ax.axvline(r["sharp"], color="k", lw=1.2, label="sharp transition")
    ax.set(xlabel="v", ylabel="e", title=f"{r['transition']} (R₀ = {r['R0']:g})")
    ax.legend(fontsize=7)


if __name__ == "__main__":
    main()
