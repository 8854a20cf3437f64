"""Phase diagrams from the phase field: the sweeps ``studies/sweeps/minimal.toml`` (the minimal
model along v) and ``studies/sweeps/ade.toml`` (the ADE model on a (v, Δa₀) grid at κ̄/κ =
1.4), run with ``fem_ade.campaigns.sweep`` on a local Dask cluster, and their notes: the
lowest-energy
end state per point against the lowest sharp branch there (``sharp_ref``: the seeds' sharp
energies), and where the lowest changes.

    python studies/phase_diagram.py --out studies/results            # hours on 2 cores
    python studies/phase_diagram.py --out studies/results --report-only
    python studies/phase_diagram.py --quick                          # a minute (runs/studies)

Writes ``OUT/phase_diagram/{minimal,ade}/`` (each sweep's folder: sweep.csv, phase-diagram.png,
montage.png; the run folders under points/ are not committed) and
``OUT/phase_diagram/phase_diagram.md``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from _lib.cli import study_parser
from fem_ade.analysis.sharp import BRANCH_OF_LABEL
from fem_ade.campaigns.sweep import run_sweep
from fem_ade.campaigns.sweep_file import Sweep, load_sweep
from fem_ade.campaigns.sweep_points import read_sweep_table, row
from fem_ade.plots.sweep_plot import draw
from fem_ade.store.status import ENDED, HAS_RESULT, Status

HERE = Path(__file__).resolve().parent
DEFAULT_OUT = Path("runs/studies")
SWEEPS = {"minimal": HERE / "sweeps" / "minimal.toml", "ade": HERE / "sweeps" / "ade.toml"}
#: end-state labels as the sharp branches they stand for (a run's comparison's, and a
#: slender prolate whose long waist reads as two necks, "chain")
AS_BRANCH = {**BRANCH_OF_LABEL, "chain": "prolate"}


def quick(sweep: Sweep) -> Sweep:
    """The same sweep, small: the last two values of each axis (the most spherical: quick
    sharp seeds), two seeds, n = 16, ε = 0.08, 30 steps, no renders."""
    axes = {k: v[-2:] for k, v in sweep.axes.items()}
    return Sweep(sweep.name + "-quick", sweep.base, axes, {**sweep.fixed, "eps": 0.08},
                 sweep.seeds[:2], {**sweep.run, "n": 16, "max_steps": 30, "render": False,
                                   "checkpoint_every": 10})


def lowest(rows: list[dict], keys: list[str]) -> dict:
    """Per point (the axes' values): the lowest finished run's end state and e, and the
    lowest sharp branch among the seeds (by their sharp e where they exist)."""
    out = {}
    for r in rows:
        at = tuple(r[k] for k in keys)
        cell = out.setdefault(at, {"pf": None, "e": math.inf, "sharp": None,
                                   "e_sharp": math.inf, "ends": set()})
        if r.get("status") in HAS_RESULT and \
                r.get("e") is not None:
            cell["ends"].add(r.get("label"))
            if r["e"] < cell["e"]:
                cell["pf"], cell["e"] = r.get("label"), r["e"]
        if isinstance(r.get("e_sharp_seed"), float) and r["e_sharp_seed"] < cell["e_sharp"]:
            cell["sharp"], cell["e_sharp"] = r["seed"], r["e_sharp_seed"]
    return out


def sharp_torus(sweep: Sweep, at: dict) -> float | None:
    """The sharp axisymmetric torus's e at a point of a vesicle sweep (None: none there)."""
    from fem_ade.scenes.vesicle import sharp_of

    if sweep.base != "vesicle":
        return None
    res = sharp_of("torus", **sweep.fixed, **at)
    return None if res is None else float(res.e)


def notes(name: str, sweep: Sweep, rows: list[dict], out: Path) -> list[str]:
    keys = list(sweep.axes)
    cells = lowest(rows, keys)
    cache_path = out / "sharp_torus.json"  # the torus solves: minutes for the ADE grid
    cache = json.loads(cache_path.read_text()) if cache_path.is_file() else {}
    for at, c in cells.items():  # the torus beside the seeds' branches (not a seed itself)
        key = ",".join(f"{x:g}" if isinstance(x, float) else str(x) for x in at)
        if key not in cache:
            cache[key] = sharp_torus(sweep, dict(zip(keys, at, strict=True)))
        c["e_torus"] = cache[key]
    out.mkdir(parents=True, exist_ok=True)
    cache_path.write_text(json.dumps(cache, indent=0) + "\n")
    for c in cells.values():
        c["sharp_all"] = ("torus" if c["e_torus"] is not None and c["e_torus"] < c["e_sharp"]
                          else c["sharp"])
    done = sum(r.get("status") in ENDED for r in rows)
    failed = [r for r in rows if r.get("status") == Status.FAILED]
    lines = [f"## {name}", "",
             f"`studies/sweeps/{name}.toml`{' (--quick)' if sweep.name != name else ''}: "
             f"{len(rows)} runs ({len(cells)} points × "
             f"{len(sweep.seeds)} seeds: {', '.join(map(str, sweep.seeds))}), ε = "
             f"{sweep.fixed.get('eps')}, {sweep.run.get('backend')}; {done} finished, "
             f"{len(failed)} failed (a seed whose branch has no sharp shape there).", "",
             f"![{name}](phase_diagram/{sweep.name}/phase-diagram.png)", "",
             "| " + " | ".join(keys) + " | lowest end state (e) | sharp lowest of genus 0 (e) "
             "| sharp torus e | same | end states of the seeds |",
             "|" + "---|" * (len(keys) + 5)]
    agree = total = agree_all = 0
    for at in sorted(cells):
        c = cells[at]
        same = ""
        if c["pf"] is not None and c["sharp"] is not None:
            total += 1
            pf = AS_BRANCH.get(c["pf"], c["pf"])
            agree += pf == c["sharp"]
            agree_all += pf == c["sharp_all"]
            same = ("yes" if pf == c["sharp"] else
                    "yes, with the torus" if pf == c["sharp_all"] else "no")
        lines.append("| " + " | ".join(f"{x:g}" if isinstance(x, float) else str(x)
                                       for x in at)
                     + f" | {c['pf'] or '—'}" + (f" ({c['e']:.4f})" if c["pf"] else "")
                     + f" | {c['sharp'] or '—'}"
                     + (f" ({c['e_sharp']:.4f})" if c["sharp"] else "")
                     + (f" | {c['e_torus']:.4f}" if c["e_torus"] is not None else " | —")
                     + f" | {same} | {', '.join(sorted(str(e) for e in c['ends']))} |")
    lines += ["", f"The lowest end state is the sharp lowest branch of genus 0 at {agree} of "
              f"{total} points where both exist, and the sharp lowest with the torus at "
              f"{agree_all} of {total}.", ""]
    if len(keys) == 1:
        lines += _transitions(cells)
    return lines


def _transitions(cells: dict) -> list[str]:
    """Along one axis: where the lowest changes, phase field and sharp (between grid points)."""
    xs = sorted(cells)
    out = []
    for which, key in (("phase field", "pf"), ("sharp, genus 0", "sharp"),
                       ("sharp, with the torus", "sharp_all")):
        changes = [f"{cells[a][key]} → {cells[b][key]} between {a[0]:g} and {b[0]:g}"
                   for a, b in zip(xs, xs[1:], strict=False)
                   if cells[a][key] and cells[b][key] and
                   AS_BRANCH.get(cells[a][key], cells[a][key]) !=
                   AS_BRANCH.get(cells[b][key], cells[b][key])]
        out.append(f"- {which}: " + ("; ".join(changes) or "no change"))
    return out + [""]


def main(argv=None) -> dict:
    ap = study_parser(__doc__, DEFAULT_OUT, first_line=True,
                      out_help="default %(default)s; the committed results: studies/results",
                      quick="", workers="", report_only="")
    ap.add_argument("--only", nargs="*", choices=list(SWEEPS), default=list(SWEEPS))
    args = ap.parse_args(argv)
    root = args.out / "phase_diagram"
    lines = ["# Phase diagrams from the phase field", "",
             "Written by `studies/phase_diagram.py` from the sweeps' tables "
             "(`python -m fem_ade.sweep`). e = (W + G) / W_sphere; the sharp column is the "
             "lowest of the seeds' sharp branches at the point (`sharp_ref`, axisymmetric; a "
             "torus is not among the seeds). End-state labels: the run's shape "
             "classifier (cylinder/gourd/chain are prolate-like, discocyte oblate-like).", ""]
    result = {}
    for name in args.only:
        sweep = load_sweep(SWEEPS[name])
        if args.quick:
            sweep = quick(sweep)
        out = root / sweep.name
        if args.report_only:  # from the run folders, or without them from the table
            rows = ([row(p, out) for p in sweep.points()] if (out / "points").is_dir()
                    else read_sweep_table(out / "sweep.csv"))
        else:
            rows = run_sweep(sweep, out, workers=args.workers, quiet=False)
        draw(rows, sweep, out)
        lines += notes(name, sweep, rows, out)
        result[name] = rows
    handwritten = root / "notes.md"
    if handwritten.is_file():
        lines += [handwritten.read_text().strip(), ""]
    root.mkdir(parents=True, exist_ok=True)
    md = args.out / ("phase_diagram_quick.md" if args.quick else "phase_diagram.md")
    md.write_text("\n".join(lines))
    return result


if __name__ == "__main__":
    main()
