"""The ADE plane: where area-difference elasticity moves the lowest sharp branch, and where the
phase field puts the same transitions.

At κ̄/κ = 1.4 (the paper's) and two reduced volumes — v = 0.85 (prolate ↔ pear) and v = 0.65
(oblate ↔ stomatocyte, with the prolate beside them) — the relaxed area difference m₀
(= ΔA₀/(8πDR₀), 1 for a sphere) is swept:

* **sharp** (``sharp_ref``): each branch followed along m₀ by continuation
  (``solve(..., start=previous)``) from an m₀ where its anchor reaches it, up and down the
  grid until it is lost (it relaxes to another branch); e = w + q(m − m₀)² per branch, the
  lowest per m₀, and the m₀ where the lowest changes (the root of the two energies'
  difference, linear between the grid's two bracketing points);
* **phase field** (spectral, ε = 0.02, n = 64: ε/h = 1.28, as in the sharp-limit study): at
  a few m₀ around each sharp transition, a steady state seeded from each branch's sharp shape
  there (initial condition ``meridian``), ADE on with ΔA₀ = 8πDR₀·m₀ and exact constraints
  with the localized volume (``_lib.seeded.make_runs``: one sweep on two Dask workers);
  e = (W + G)/W_sphere. A run keeps its seed's branch if it ends as one body whose
  sharp-surface reduced area difference is within 0.12 of its sharp shape's (the pear's da
  is 0.17–0.2 above the prolate's, the stomatocyte's 0.4–0.6 below the oblate's); the phase
  field's transition is where the lower of the kept seeds changes.

Results: ``OUT/ade_plane.md``, ``OUT/ade_plane.json``, ``OUT/ade-plane.png``; every solve and
run cached in ``OUT/ade/solves.json`` and ``OUT/ade/runs.json`` (resumable).

    python studies/ade_plane.py --out studies/results     # everything (~40 min on 2 cores)
    python studies/ade_plane.py --out studies/results --report-only
    python studies/ade_plane.py --quick                   # a look in a minute (runs/studies)
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

from _lib.cli import study_parser
from _lib.seeded import DA_TOL, make_runs
from _lib.sharp import follow
from fem_ade.plots.figures import save_figure
from fem_ade.store.output import write_json_atomic
from sharp_ref.branches import LEVELS
from sharp_ref.membrane import Q_ADE

DEFAULT_OUT = Path("runs/studies")
KBAR = 1.4
EPS = 0.02
#: per reduced volume: the branches, the m₀ grid, and the m₀ where each branch's own anchor
#: reaches it (the pear buds off the prolate only at large m₀; followed down from there)
Plane = SimpleNamespace
FULL = {
    0.85: Plane(branches=("prolate", "pear"), m0=tuple(round(1.0 + 0.04 * i, 2)
                                                       for i in range(26)),
                anchor={"prolate": 1.0, "pear": 1.8},
                pf={m: ("prolate", "pear") for m in (1.4, 1.48, 1.52, 1.56, 1.6, 1.64, 1.72)}),
    0.65: Plane(branches=("oblate", "stomatocyte", "prolate", "torus"),
                m0=tuple(round(0.5 + 0.04 * i, 2) for i in range(26)),
                anchor={"oblate": 1.0, "stomatocyte": 0.7, "prolate": 1.0, "torus": 1.0},
                pf={**{m: ("stomatocyte", "oblate") for m in (0.7, 0.78, 0.86, 0.94)},
                    **{m: ("oblate", "prolate") for m in (1.1, 1.18, 1.26)}}),
}
QUICK = {0.85: Plane(branches=("prolate", "pear"), m0=(1.76, 1.8), levels=LEVELS[:2],
                     anchor={"prolate": 1.8, "pear": 1.8}, pf={1.8: ("prolate", "pear")})}
#: the quick look's phase field: coarse and short
QUICK_EPS = 0.05


def _key(branch: str, v: float) -> str:
    return f"{branch}@{v:.4f}"


def lowest(rows_by_branch: dict[str, list[dict]], grid) -> list[dict]:
    """Per m₀: each branch's e, the lowest of genus 0 (``lowest``: the classic diagrams')
    and the lowest of all, the torus included (``lowest_all``)."""
    out = []
    for m0 in grid:
        have = {b: r["e"] for b, rows in rows_by_branch.items() for r in rows
                if r["m0"] == m0 and "e" in r}
        genus0 = {b: e for b, e in have.items() if b != "torus"}
        out.append({"m0": m0, "lowest": min(genus0, key=genus0.get) if genus0 else None,
                    "lowest_all": min(have, key=have.get) if have else None, **have})
    return out


def transitions(table: list[dict], key="lowest") -> list[dict]:
    """The m₀ where the lowest changes: the root of the two energies' difference, linear
    between the two grid points around it."""
    out = []
    for a, b in zip(table, table[1:], strict=False):
        x, y = a[key], b[key]
        if x and y and x != y and x in b and y in a:
            da, db = a[x] - a[y], b[x] - b[y]  # < 0 at a (x lower), > 0 at b
            m0 = a["m0"] + (b["m0"] - a["m0"]) * da / (da - db)
            out.append({"from": x, "to": y, "m0": m0, "between": [a["m0"], b["m0"]]})
        elif x and y and x != y:  # one of them ends in between: the lowest changes there
            out.append({"from": x, "to": y, "m0": None, "between": [a["m0"], b["m0"]],
                        "note": f"{x if x not in b else y} ends in between"})
    return out


def sharp_stage(out: Path, planes, say=print) -> dict:
    path = out / "ade" / "solves.json"
    cache = json.loads(path.read_text()) if path.is_file() else {}
    for v, plane in planes.items():
        for b in plane.branches:
            done = cache.get(_key(b, v), {})
            if done.get("grid") != list(plane.m0) or done.get("anchor") != plane.anchor[b]:
                rows = follow(b, v, plane, kbar=KBAR, say=say)
                for r in rows:  # the meridian only where a phase-field run starts from it
                    if r["m0"] not in plane.pf:
                        r.pop("r", None), r.pop("z", None)
                cache[_key(b, v)] = {"grid": list(plane.m0), "anchor": plane.anchor[b],
                                     "rows": rows}
                path.parent.mkdir(parents=True, exist_ok=True)
                write_json_atomic(path, cache, indent=None)
    return cache


def _rows(cache, b, v) -> list[dict]:
    return cache.get(_key(b, v), {}).get("rows", [])


def classify(run: dict, sharp_rows: dict[str, dict]) -> str | None:
    """The branch a run ended on: ``torus`` for one body of genus 1 (if the plane has that
    branch); for one body of genus 0, the genus-0 branch of the plane whose sharp da at its
    m₀ is nearest its own (within DA_TOL); else None."""
    if run["components"] != 1:
        return None
    if run["genus"] == [1]:
        return "torus" if "torus" in sharp_rows else None
    if run["genus"] != [0]:
        return None
    near = [(abs(run["da"] - s["da"]), b) for b, s in sharp_rows.items()
            if "da" in s and b != "torus"]
    near = [x for x in near if x[0] < DA_TOL]
    return min(near)[1] if near else None


def pf_stage(out: Path, planes, cache: dict, eps: float, say=print) -> dict:
    path = out / "ade" / "runs.json"
    runs = json.loads(path.read_text()) if path.is_file() else {}
    jobs = []
    for v, plane in planes.items():
        for m0, seeds in plane.pf.items():
            for b in seeds:
                sharp = _row(cache, b, v, m0)
                key = f"{b}@{v:.4f}@{m0:.4f}@{eps:.4f}"
                if sharp is not None and key not in runs:
                    jobs.append(SimpleNamespace(key=key, sharp=sharp, branch=b, eps=eps,
                                                backend="spectral",
                                                ade={"kbar": KBAR, "m0": m0}))
    say(f"  phase field: {len(jobs)} runs ({', '.join(job.key for job in jobs)})")
    for job, row in make_runs(out / "ade", jobs):
        row.pop("section")
        row["m0"] = job.ade["m0"]
        runs[job.key] = row
        write_json_atomic(path, runs, indent=None, make_folder=True)
    return runs


def _row(cache, b, v, m0) -> dict | None:
    r = next((r for r in _rows(cache, b, v) if r["m0"] == m0), None)
    return r if r is not None and "e" in r else None


def report(out: Path, planes, cache: dict, runs: dict, eps: float) -> dict:
    """Write ade_plane.md, ade_plane.json and the figure: each plane's sharp table and
    transitions, then its phase-field runs; returns the JSON's payload."""
    lines = ["# The ADE plane: sharp transitions and the phase field's", "",
             f"Written by `studies/ade_plane.py`. κ̄/κ = {KBAR} (the paper's); e = w + "
             f"q(m − m₀)², q = {KBAR * Q_ADE:.4f}, in units of a sphere's bending energy; m the "
             "reduced area difference, m₀ the relaxed one. Sharp: `sharp_ref`, each branch "
             "followed along m₀ by continuation; phase field: spectral, ε = "
             f"{eps}, n = {round(1.28 / eps)}, seeded from each branch's sharp shape.", ""]
    payload = {"kbar": KBAR, "eps": eps, "planes": []}
    for v, plane in planes.items():
        plane_lines, plane_payload = _plane_section(v, plane, cache, runs, eps)
        lines += plane_lines
        payload["planes"].append(plane_payload)
    lines += ["![e along m₀: sharp branches (lines), phase field (markers)](ade-plane.png)", ""]
    notes = out / "ade" / "notes.md"
    if notes.is_file():
        lines += [notes.read_text().strip(), ""]
    (out / "ade_plane.md").write_text("\n".join(lines))
    (out / "ade_plane.json").write_text(json.dumps(payload, indent=1) + "\n")
    figure(out / "ade-plane.png", planes, cache, runs, eps)
    return payload


def _plane_section(v, plane, cache: dict, runs: dict, eps: float) -> tuple[list[str], dict]:
    """The section of the plane at reduced volume ``v`` and its entry of the payload."""
    rows = {b: _rows(cache, b, v) for b in plane.branches}
    table = lowest(rows, plane.m0)
    sharp_t = transitions(table)
    torus = "torus" in plane.branches
    sharp_all = transitions(table, "lowest_all") if torus else []
    lines = [f"## v = {v}", ""] + _sharp_table(v, plane, cache, table, torus)
    lines += ["", "Where a branch ends (— above): "]
    for b, rs in rows.items():
        lost = [r for r in rs if "missing" in r]
        for r in lost:
            lines.append(f"- {b} at m₀ = {r['m0']}: {r['missing']}")
    lines += ["", "Sharp transitions of the lowest branch of genus 0: " + (", ".join(
        _say(t, 4) for t in sharp_t) or "none") + (
        "; of the lowest, the torus included: " + (", ".join(_say(t, 4) for t in sharp_all)
                                                  or "none") if torus else ""), ""]
    pf = [r for r in runs.values() if abs(r["v"] - v) < 1e-6 and r["eps"] == eps]
    pf_table, pf_t = [], []
    if pf:
        pf_lines, pf_table = _phase_field_table(v, plane, cache, pf, eps)
        pf_t = transitions(pf_table)
        ref = sharp_all if torus else sharp_t
        lines += pf_lines + ["", "Phase-field transitions of the lowest end state: " + (", ".join(
            _say(t, 3) + " (sharp: " + _sharp_at(ref, t) + ")" for t in pf_t)
            or "none found on these m₀"), ""]
    return lines, {"v": v, "sharp": table, "sharp_transitions": sharp_t,
                   "sharp_transitions_with_torus": sharp_all,
                   "phase_field": pf_table, "phase_field_transitions": pf_t}


def _sharp_table(v, plane, cache: dict, table: list[dict], torus: bool) -> list[str]:
    """The sharp branches' e (and da) at each m₀, with the lowest of genus 0 (and, with a
    torus, the lowest of all)."""
    lines = ["| m₀ | " + " | ".join(f"e {b} (da)" for b in plane.branches)
             + " | lowest of genus 0 |" + (" lowest |" if torus else ""),
             "|---|" + "---|" * (len(plane.branches) + 1 + torus)]
    for t in table:
        cells = []
        for b in plane.branches:
            r = _row(cache, b, v, t["m0"])
            cells.append(f"{r['e']:.5f} ({r['da']:.4f})" if r else "—")
        lines.append(f"| {t['m0']:.2f} | " + " | ".join(cells) + f" | {t['lowest'] or '—'} |"
                     + (f" {t['lowest_all'] or '—'} |" if torus else ""))
    return lines


def _phase_field_table(v, plane, cache: dict, pf: list[dict],
                       eps: float) -> tuple[list[str], list[dict]]:
    """The phase-field runs of the plane: e of each seed's steady state at each m₀ and the
    lowest end state; returns the table's lines and its rows (m₀, lowest, e of each end
    state)."""
    seeds = [b for b in plane.branches if any(r["branch"] == b for r in pf)]
    lines = [f"Phase field at ε = {eps}: e of the steady state from each seed, with "
             "the sharp-surface da and the diffuse da the ADE term sees (dA/(8πDR₀)); "
             "† it left its seed's branch for the one named (or its label)", "",
             "| m₀ | " + " | ".join(f"from {b}" for b in seeds)
             + " | lowest end state |", "|---|" + "---|" * (len(seeds) + 1)]
    pf_table = []
    for m0 in plane.pf:
        cells, ended_e = [], {}
        sharp_rows = {b: _row(cache, b, v, m0) or {} for b in plane.branches}
        for b in seeds:
            r = next((r for r in pf if r["branch"] == b and r["m0"] == m0), None)
            if r is None:
                cells.append("—")
                continue
            ended = classify(r, sharp_rows)
            state = ended or r["label"]  # a state of no branch counts too (buds)
            ended_e[state] = min(ended_e.get(state, math.inf), r["e"])
            cells.append(_pf_cell(r, b, ended))
        low = min(ended_e, key=ended_e.get) if ended_e else None
        pf_table.append({"m0": m0, "lowest": low, **ended_e})
        lines.append(f"| {m0:.2f} | " + " | ".join(cells) + f" | {low or '—'} |")
    return lines, pf_table


def _pf_cell(r: dict, seed: str, ended: str | None) -> str:
    """A phase-field run's cell: its e, † and the state it ended in if not its seed's, and
    its sharp (and diffuse) da."""
    dd = f", diffuse {r['da_diffuse']:.3f}" if r.get("da_diffuse") is not None else ""
    return (f"{r['e']:.4f}" + ("" if ended == seed else f" † {ended or r['label']}")
            + f" (da {r['da']:.3f}{dd})")


def _say(t: dict, digits: int) -> str:
    where = (f"at m₀ = {t['m0']:.{digits}f}" if t["m0"] is not None else
             f"between m₀ = {t['between'][0]} and {t['between'][1]}, where {t['note']}")
    return f"{t['from']} → {t['to']} {where}"


def _sharp_at(sharp_t, t) -> str:
    same = [s for s in sharp_t if {s["from"], s["to"]} == {t["from"], t["to"]}]
    if not same:
        return "no such transition"
    s = same[0]
    return (f"{s['m0']:.3f}" if s["m0"] is not None
            else f"between {s['between'][0]} and {s['between'][1]}")


def figure(path: Path, planes, cache, runs, eps) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"prolate": "tab:blue", "pear": "tab:red", "oblate": "tab:orange",
               "stomatocyte": "tab:green", "torus": "tab:purple"}
    fig, axes = plt.subplots(1, len(planes), figsize=(5.5 * len(planes), 4.4), squeeze=False)
    for ax, (v, plane) in zip(axes[0], planes.items(), strict=True):
        for b in plane.branches:
            pts = [(r["m0"], r["e"]) for r in _rows(cache, b, v) if "e" in r]
            if pts:
                ax.plot(*zip(*pts, strict=True), "-", color=colours[b], label=f"{b} (sharp)")
            pf = [r for r in runs.values() if r["branch"] == b
                  and abs(r["v"] - v) < 1e-6 and r["eps"] == eps]
            for i, r in enumerate(sorted(pf, key=lambda r: r["m0"])):
                sharp_rows = {c: _row(cache, c, v, r["m0"]) or {} for c in plane.branches}
                ended = classify(r, sharp_rows)  # the face: the end state (white: no branch)
                ax.plot(r["m0"], r["e"], "o", ms=7, mec=colours[b], mew=1.5,
                        mfc=colours.get(ended, "white"),
                        label=f"from {b} (phase field, ε = {eps}; face: where it ended)"
                        if i == 0 else None)
        ax.set(xlabel="relaxed area difference m₀", ylabel="e = (bending + ADE) / sphere",
               title=f"v = {v}, κ̄/κ = {KBAR}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=100, colours=64)
    plt.close(fig)


def main(argv=None) -> dict:
    ap = study_parser(__doc__, DEFAULT_OUT, first_line=True,
                      out_help="default %(default)s; the committed results: studies/results",
                      quick="one point of v = 0.85, ε = 0.05", report_only="")
    args = ap.parse_args(argv)
    planes, eps = (QUICK, QUICK_EPS) if args.quick else (FULL, EPS)
    args.out.mkdir(parents=True, exist_ok=True)
    if args.report_only:
        cache = json.loads((args.out / "ade" / "solves.json").read_text())
        runs_path = args.out / "ade" / "runs.json"
        runs = json.loads(runs_path.read_text()) if runs_path.is_file() else {}
    else:
        cache = sharp_stage(args.out, planes)
        runs = pf_stage(args.out, planes, cache, eps)
    payload = report(args.out, planes, cache, runs, eps)
    for p in payload["planes"]:
        print(f"v = {p['v']}: sharp {p['sharp_transitions']}; phase field "
              f"{p['phase_field_transitions']}")
    return payload


if __name__ == "__main__":
    main()
