"""Transitions from branch crossings (issue 32): the minimal model's prolate → oblate and
oblate → stomatocyte transitions as the v where two branches followed by continuation
(``fem_ade.branch``, axisymmetric, Newton on every point) have equal energy, at each ε,
beside the sharp membrane's (``sharp_ref``) and the seeded steady states' of
``studies/sharp_limit.py``.

Each pair of branches is followed at one R₀ (the two branches' ε/R₀ equal): the prolate and
the oblate at R₀ = 0.17 (the largest at which the prolate at v = 0.62 fits the box), from
v = 0.70 down to 0.62 (0.645 at ε = 0.005); the oblate and the stomatocyte at R₀ = 0.25 from
v = 0.62 down to 0.56 (at ε = 0.005: the oblate to 0.58, the stomatocyte from 0.60 to
0.585): ``PAIRS``. The crossing is
:func:`fem_ade.branch.crossing` (linear between points ~0.002 apart); ε → 0 by Richardson
with p = 2 (the order every kept branch shows in ``sharp_limit.md``) over
the two smallest ε with a crossing. The folds (turning points in v) of every branch are
reported: where a branch ends at finite ε.

Writes ``OUT/branches.md``, ``OUT/branches.json``, ``OUT/branches.png`` and
``OUT/branches/minimal.json`` (the transitions, ε = 0 for the extrapolation); the branch
folders in ``OUT/branches/EPS/NAME`` (their ``points/`` are not committed) — resumable, as
``fem_ade.branch`` is: a finished branch is read back, a stopped one goes on.

    python studies/branches.py --out studies/results           # ~1 h
    python studies/branches.py --quick                         # the code (a minute)

One thread: ``OPENBLAS_NUM_THREADS=1``, ``FEM_ADE_FFT_WORKERS=1`` unless set.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("FEM_ADE_FFT_WORKERS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
from pathlib import Path  # noqa: E402

OUT = Path("runs") / "studies"
EPS = (0.02, 0.01, 0.005)
#: (upper branch, lower branch, R₀, {ε: (v from, v to), or per branch}): the pairs whose
#: crossing is a transition (at ε = 0.02 the oblates' seeds open into tori). The stomatocyte
#: at ε = 0.005 starts at v = 0.60: from 0.62 its Newton corrections stop converging at
#: 0.6123 (studies/results/branches_notes.md)
PAIRS = (("prolate", "oblate", 0.17, {0.02: (0.70, 0.62), 0.01: (0.70, 0.62),
                                     0.005: (0.70, 0.645)}),
         ("oblate", "stomatocyte", 0.25, {0.02: (0.62, 0.56), 0.01: (0.62, 0.56),
                                          0.005: {"oblate": (0.62, 0.58),
                                                  "stomatocyte": (0.60, 0.585)}}))
#: --quick: the same code on short stretches at ε = 0.04 (no crossing expected; the second
#: pair's seeds are tori there: the exclusion of a seed not on its branch)
QUICK_PAIRS = (("prolate", "oblate", 0.2, {0.04: (0.90, 0.88)}),
               ("oblate", "stomatocyte", 0.25, {0.04: (0.62, 0.61)}))
SHARP = {"prolate → oblate": 0.6511, "oblate → stomatocyte": 0.5912}  # sharp_limit.md


def follow_one(out: Path, branch: str, R0: float, eps: float, start: float, stop: float,
               step: float) -> list[dict]:
    from fem_ade.branch import follow
    from fem_ade.scenes import vesicle_scene

    folder = out / f"{eps:g}" / f"{branch}-R0={R0:g}"
    if (folder / "ended").is_file():  # followed to its end before: read back
        with open(folder / "branch.csv") as fh:
            return [{k: _num(v) for k, v in r.items()} for r in csv.DictReader(fh)]
    scene = vesicle_scene(v=start, branch=branch, eps=eps, R0=R0)
    print(f"{branch} at R0 = {R0}, eps = {eps}: v = {start} -> {stop}", flush=True)
    rows = follow(scene, param="v", start=start, stop=stop, step=step, out=folder)
    (folder / "ended").write_text("")
    return rows


def _num(text: str):
    try:
        return float(text)
    except ValueError:
        return text


def main(argv=None) -> dict:
    import sys

    from fem_ade.branch import crossing, same_branch
    from fem_ade.output import write_json_atomic

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from sharp_limit import extrapolate

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--quick", action="store_true",
                    help="short stretches at eps = 0.04: the code, not the result")
    args = ap.parse_args(argv)
    eps_list, pairs = ((0.04,), QUICK_PAIRS) if args.quick else (EPS, PAIRS)
    base = args.out / "branches"
    results = []
    curves = {}
    for upper, lower, R0, ranges in pairs:
        name = f"{upper} → {lower}"
        row = {"transition": name, "R0": R0, "at": {f"{e:g}": None for e in eps_list},
               "eps": list(ranges), "sharp": SHARP[name], "ended": {}, "folds": {}}
        for eps, span in ranges.items():
            pair = []
            for b in (upper, lower):
                start, stop = span[b] if isinstance(span, dict) else span
                rows = follow_one(base, b, R0, eps, start, stop, 0.01)
                if rows and not same_branch(b, rows[0]["label"]):
                    row["ended"][f"{b} {eps:g}"] = (f"its seed relaxed to a shape labelled "
                                                   f"{rows[0]['label']}: not this branch")
                    row.setdefault("last_v", {})[f"{b} {eps:g}"] = None
                    pair.append([])
                    continue
                pair.append(rows)
                curves[(b, R0, eps)] = [(r["v"], r["e"], r["unstable"]) for r in rows]
                row["ended"][f"{b} {eps:g}"] = (
                    f"v = {rows[-1]['v']:.4f}, {rows[-1]['label']}"
                    + (" (the end of its range)" if rows[-1]["v"] <= stop else "")
                    if rows else "no point")
                row.setdefault("last_v", {})[f"{b} {eps:g}"] = rows[-1]["v"] if rows else None
                row["folds"][f"{b} {eps:g}"] = [float(r["fold"]) for r in rows
                                                 if r.get("fold") not in (None, "")]
            row["at"][f"{eps:g}"] = crossing(pair[0], pair[1], "v")
        have = [(e, row["at"][f"{e:g}"]) for e in eps_list if row["at"][f"{e:g}"] is not None]
        row["extrapolated"] = None
        if len(have) >= 2:  # p = 2 over the two smallest ε (sharp_limit's, given two)
            row["extrapolated"] = extrapolate(*zip(*have[-2:], strict=True))[0]
        results.append(row)
        print(f"{name}: {row['at']} -> {row['extrapolated']} (sharp {row['sharp']})",
              flush=True)
    payload = {"eps": list(eps_list), "pairs": results}
    suffix = "_quick" if args.quick else ""
    write_json_atomic(args.out / f"branches{suffix}.json", payload)
    write_json_atomic(base / f"minimal{suffix}.json", minimal(payload))
    write_report(args.out, payload, curves, suffix)
    return payload


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
             "`fem_ade.branch` (axisymmetric, order 8, 2.5 nodes per ε, Newton on every "
             "point), at one R₀ for both; the transition is where their e = (W + G)/W_sphere "
             "are equal. ε → 0: Richardson with p = 2 over the two ε.", "",
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

    from fem_ade.render import save_figure

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
