"""How close to the sharp membrane: the axisymmetric sharp reference (``sharp_ref``) along its
branches, and where its lowest-energy branch changes.

Stage ``branches`` (the minimal model: bending only, fixed area and volume): the prolate,
oblate and stomatocyte branches and the axisymmetric torus at v = 0.50, 0.55, …, 0.95 (where
each exists), the sphere and the Willmore torus; the lowest-energy branch of genus 0 at each
v and the reduced volumes where it changes, each found as the root of the energy difference
of the two branches (a quadratic through three solves 0.01 apart around the sign change).
Classic values to compare with (Seifert, Berndl & Lipowsky, Phys. Rev. A 44, 1182 (1991)):
prolate ↔ oblate at v ≈ 0.652, oblate ↔ stomatocyte at v ≈ 0.592.

Stage ``eps`` (the limit ε → 0): for the sphere, the Clifford torus, and the prolate, oblate
and stomatocyte branches at v ∈ {0.95, 0.8, 0.65, 0.6, 0.55} where the branch exists, a
phase-field steady state seeded from the sharp meridian (initial condition ``meridian``: the
tanh profile of the signed distance to it), the minimal model (bending, volume, area; no
ADE), exact constraints with the localized volume (α and β those of the sharp shape of R₀
chosen to fit the box with a margin of ≥ 4.75 ε at the largest ε), the ``steady`` recipe
(stabilized scheme at 100× Δt = 0.75 ε³, momentum, until the relative change of E per step
is below 1e-9), at ε ∈ {0.04, 0.032, 0.02, 0.016} (and 0.0128, 0.01 for the cases that keep
their branch at 0.016, ``--fine``) with n = 1.28/ε points per axis (nodes per ε held fixed:
ε/h = 1.28), on the spectral backend, and for six cases that keep their branch on the FEM
too (order 4 on the same nodes, ε ≥ 0.016). e = W / (16√2π/3), the bending energy over that
of a sharp sphere in the model's units. The observed order p from the three smallest ε, then
Richardson over the two smallest: e₀ = e(ε₂) − (e(ε₁) − e(ε₂)) / ((ε₁/ε₂)^p − 1). A run
keeps its branch if its surface is one body of genus 0 (1 for the torus) with the branch's
label (prolate/cylinder/gourd/chain, oblate/discocyte; any genus-0 label for the sphere and
the stomatocyte) and reduced area difference within 0.12 of the sharp one (see
``_lib.seeded.LABELS``). With two such ε only, p = 2 is assumed (marked).

Results: ``OUT/sharp_limit.md`` (tables), ``OUT/sharp_limit.json`` (``rows``: one per
(backend, branch, v) with e_sharp, e_extrapolated, rel_diff, eps, e_phase_field,
kept_branch; ``branches``, ``transitions``: the sharp stage), ``OUT/sharp-branches.png`` (w
along each branch; meridians), ``OUT/sharp-eps.png`` (e against ε², extrapolations) and
``OUT/sharp-sections.png`` (the phase field's φ = 0 at the smallest ε over the sharp
meridian). Every solve and run is cached in ``OUT/sharp/solves.json`` and
``OUT/sharp/runs.json`` (resumable: nothing cached is redone); the phase-field runs of a
stage are one sweep (:mod:`fem_ade.campaigns.sweep`: two Dask workers, each run in
``OUT/sharp/sweep/points/NAME``, resumed where it was killed).

    python studies/sharp_limit.py --out studies/results     # everything (~2 h on 2 cores)
    python studies/sharp_limit.py --out studies/results --stages eps --backends fem
    python studies/sharp_limit.py --out studies/results --report-only   # from the caches
    python studies/sharp_limit.py --quick          # a look in seconds (under runs/studies)
"""


from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from _lib.cli import study_parser
from _lib.limit_ade import ADE_CASES, ADE_KBAR, ade_report, ade_rows, run_ade
from _lib.limit_eps import (
    AXI_EPS,
    EPS,
    EPS_CASES,
    FINE_CASES,
    eps_figures,
    eps_of,
    eps_rows,
    eps_section,
    run_eps,
)
from _lib.limit_transitions import (
    MINIMAL_TRANSITIONS,
    PEAR_TRANSITION,
    TRANSITION_EPS,
    run_transitions,
    transition_rows,
    transitions_report,
)
from _lib.sharp import Cache, ade_sharp, crossing
from fem_ade.plots.figures import save_figure

DEFAULT_OUT = Path("runs/studies")  # the committed results: --out studies/results
GRID = tuple(round(0.50 + 0.05 * i, 2) for i in range(10))  # 0.50 … 0.95
BRANCHES = ("prolate", "oblate", "stomatocyte")  # genus 0: the classic diagram's
COLUMNS = BRANCHES + ("torus",)  # the table's: genus 1 beside them
#: (lower branch above, lower branch below, first guess of the v where they swap)
TRANSITIONS = (("prolate", "oblate", 0.65), ("oblate", "stomatocyte", 0.59))


#: what a run of the study covers (the full one, or ``--quick``'s): the grid of v and the
#: branches of the sharp stage, its transitions, the ε, the cases, those also at the finest
#: ε, and the FEM's column (order 4 on the same nodes, ε down to 0.016: the cases that keep
#: their branch)
Plan = SimpleNamespace
FULL = Plan(grid=GRID, columns=COLUMNS, transitions=TRANSITIONS, eps=EPS, cases=EPS_CASES,
            fine=FINE_CASES, fem_cases=("sphere@1.0000", "torus@free", "prolate@0.9500",
                                        "prolate@0.8000", "oblate@0.9500", "oblate@0.8000"),
            axi_eps=AXI_EPS, ade_cases=ADE_CASES, transition_eps=TRANSITION_EPS,
            minimal_transitions=MINIMAL_TRANSITIONS, pear_transition=PEAR_TRANSITION)
#: a look in seconds: the prolate and oblate at v = 0.8, three coarse ε, no transitions
QUICK = Plan(grid=(0.8,), columns=("prolate", "oblate"), transitions=(),
             eps=(0.08, 0.064, 0.05), cases=(("prolate", 0.8),), fine=(), fem_cases=(),
             axi_eps=(0.08, 0.064, 0.05), ade_cases=(), transition_eps=(),
             minimal_transitions=(), pear_transition=None)


def report(cache: Cache, out: Path, plan=FULL) -> dict:
    """sharp_limit.md, sharp_limit.json and the pictures from the caches (nothing is run)."""
    lines, rows, extra, table = branches_section(cache, plan)
    crossings = [crossing(cache, *t, compute=False) for t in plan.transitions]
    lines += crossings_section(crossings)
    runs_path = out / "sharp" / "runs.json"
    runs = json.loads(runs_path.read_text()) if runs_path.is_file() else {}
    eps_table = []
    for backend in ("spectral", "fem", "axisymmetric"):
        rows_b = eps_rows(runs, cache, backend, plan)
        if rows_b:
            eps_table += rows_b
            lines += eps_section(backend, rows_b, eps_of(plan, backend), runs)
    if eps_table:
        lines += ["", "![e over e_sharp against ε²](sharp-eps.png)", "",
                  "![the phase field's φ = 0 over the sharp meridian](sharp-sections.png)", ""]
    ade = ade_rows(cache, runs, plan)
    lines += ade_report(ade)
    trans = transition_rows(cache, runs, plan)
    lines += transitions_report(trans, plan)
    notes = out / "sharp" / "notes.md"
    if notes.is_file():
        lines += [notes.read_text().strip(), ""]
    (out / "sharp_limit.md").write_text("\n".join(lines))
    payload = {"rows": eps_table, "ade": ade, "phase_field_transitions": trans,
               "branches": [{k: r[k] for k in r if k not in ("r", "z")} for r in rows],
               "exact": [{k: r[k] for k in r if k not in ("r", "z")} for r in extra if r],
               "lowest": table, "transitions": crossings}
    (out / "sharp_limit.json").write_text(json.dumps(payload, indent=1) + "\n")
    figure(cache, out / "sharp-branches.png", crossings, plan)
    if eps_table:
        eps_figures(eps_table, runs, cache, out)
    return payload


def branches_section(cache: Cache, plan) -> tuple[list[str], list, list, list]:
    """The report's head, exact values and branch table: (lines, the branches' rows, the
    sphere's and Clifford torus's, the lowest branch per v)."""
    rows, table = [], []
    for branch in plan.columns:
        for v in plan.grid:
            r = cache.get(branch, v, compute=False)
            if r is not None:
                rows.append(r)
    extra = [cache.get("sphere", 1.0, compute=False), cache.get("torus", None, compute=False)]
    lines = ["# How close to the sharp membrane", "",
             "Written by `studies/sharp_limit.py` from `sharp_ref` (axisymmetric sharp "
             "membranes, the minimal model: bending only, fixed area and volume). Energies "
             "in units of a sphere's bending energy (w), reduced volume v and reduced area "
             "difference da (1 for a sphere).", "",
             "## Exact values", "",
             "| shape | v | w | exact | misfit |", "|---|---|---|---|---|"]
    for r, exact in zip(extra, (1.0, math.pi / 2), strict=True):
        if r is not None and "w" in r:
            lines.append(f"| {r['branch']} | {r['v']:.6f} | {r['w']:.12f} | {exact:.12f} | "
                         f"{abs(r['w'] - exact):.1e} |")
    lines += ["", "## Branches", "",
              "The lowest of genus 0 (the classic phase diagram's) and, beside it, the torus "
              "(axisymmetric, up-down symmetric).", "",
              "| v | " + " | ".join(f"w {b}" for b in plan.columns) + " | lowest of genus 0 |",
              "|---|" + "---|" * (len(plan.columns) + 1)]
    for v in plan.grid:
        ws = {b: cache.get(b, v, compute=False) for b in plan.columns}
        cells = [f"{r['w']:.8f}" if r and "w" in r else "—" for r in ws.values()]
        have = {b: r["w"] for b, r in ws.items() if r and "w" in r}
        genus0 = {b: w for b, w in have.items() if b in BRANCHES}
        lowest = min(genus0, key=genus0.get) if genus0 else "—"
        lines.append(f"| {v:.2f} | " + " | ".join(cells) + f" | {lowest} |")
        table.append({"v": v, "lowest_genus0": lowest,
                      **{b: have.get(b) for b in plan.columns}})
    lines += ["", "![w along the branches; meridians](sharp-branches.png)", "",
              "— : the branch is not found there; why:", ""]
    lines += [f"- {r['branch']} at v = {r['v']:.2f}: {r['missing']}" for r in rows
              if "missing" in r]
    return lines, rows, extra, table


def crossings_section(crossings) -> list[str]:
    lines = ["", "## Where the lowest branch changes", "",
             "| from (above) | to (below) | v | w there | literature |", "|---|---|---|---|---|"]
    for c, lit in zip(crossings, ("0.652", "0.592")[:len(crossings)], strict=True):
        v = "—" if c["v"] is None else f"{c['v']:.4f}"
        w = f"{c['w']:.6f}" if c.get("w") else c.get("note", "")
        lines.append(f"| {c['between'][0]} | {c['between'][1]} | {v} | {w} | {lit} |")
    return lines + ["", "Literature: Seifert, Berndl & Lipowsky, Phys. Rev. A 44, 1182 (1991).",
                    ""]


def figure(cache: Cache, path: Path, crossings, plan) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.4))
    colours = {"prolate": "tab:blue", "oblate": "tab:orange", "stomatocyte": "tab:green",
               "torus": "tab:purple"}
    for b in plan.columns:
        pts = sorted((r["v"], r["w"]) for r in cache.rows.values()
                     if r["branch"] == b and "w" in r)
        if pts:
            ax.plot(*zip(*pts, strict=True), "o-", ms=3, color=colours[b], label=b)
    for c in crossings:
        if c["v"] is not None:
            ax.axvline(c["v"], color="0.6", lw=0.8, ls="--")
            ax.annotate(f"{c['v']:.3f}", (c["v"], ax.get_ylim()[1]), fontsize=8,
                        ha="center", va="bottom")
    ax.set(xlabel="reduced volume v", ylabel="w = bending / sphere's",
           title="minimal model: the axisymmetric branches")
    ax.legend()
    for k, (b, v) in enumerate((("prolate", 0.8), ("oblate", 0.65), ("stomatocyte", 0.55))):
        r = cache.get(b, v, compute=False)
        if r and "r" in r:
            r_, z_ = np.array(r["r"]), np.array(r["z"])
            off = 3.0 * k
            bx.plot(off + r_, z_, color=colours[b])
            bx.plot(off - r_, z_, color=colours[b])
            bx.text(off, -1.9, f"{b}\nv = {v}", ha="center", va="top", fontsize=8)
    bx.set_aspect("equal")
    bx.set_ylim(-2.6, 2.0)
    bx.set_axis_off()
    bx.set_title("meridians (R₀ = 1)")
    fig.tight_layout()
    save_figure(fig, path, dpi=110, colours=64)
    plt.close(fig)


def main(argv=None) -> dict:
    ap = study_parser(__doc__, DEFAULT_OUT, out_help="results folder (default runs/studies; "
                      "the committed: studies/results)", report_only="",
                      quick="prolate and oblate at v = 0.8, ε = 0.08 … 0.05 (seconds)")
    ap.add_argument("--stages", nargs="+", choices=("branches", "eps", "ade", "transitions"),
                    default=["branches", "eps", "ade", "transitions"])
    ap.add_argument("--backends", nargs="+", choices=("spectral", "fem", "axisymmetric"),
                    default=["spectral", "fem", "axisymmetric"],
                    help="the FEM runs the plan's fem_cases only, without the finest ε; the "
                    "axisymmetric FEM every case at ε = 0.04 … 0.0025, twice (its check)")
    ap.add_argument("--cases", nargs="+", default=None, metavar="BRANCH[@V]",
                    help="only these branches or cases, e.g. torus prolate@0.8000 (stage eps)")
    ap.add_argument("--fine", nargs="*", default=None, metavar="BRANCH@V",
                    help="the cases run at ε = 0.0128 and 0.01 too (default: those that keep "
                    "their branch at 0.016)")
    args = ap.parse_args(argv)
    plan = QUICK if args.quick else FULL
    fine = set(plan.fine if args.fine is None else args.fine)
    lock = None
    if not args.report_only:  # one process at a time: the caches are read, then rewritten
        from fem_ade.store.lock import FolderLock

        (args.out / "sharp").mkdir(parents=True, exist_ok=True)
        lock = FolderLock(args.out / "sharp").acquire()
    try:
        return _main(args, plan, fine)
    finally:
        if lock is not None:
            lock.release()


def _main(args, plan, fine) -> dict:
    cache = Cache(args.out / "sharp" / "solves.json")
    if not args.report_only and "branches" in args.stages:
        if not args.quick:
            cache.get("sphere", 1.0)
            cache.get("torus", None)
        for v in plan.grid:
            for b in plan.columns:
                if b == "stomatocyte" and v > 0.70:
                    continue  # left by the continuation (see the report's notes)
                cache.get(b, v)
        for t in plan.transitions:
            crossing(cache, *t)
    if not args.report_only and "eps" in args.stages:
        columns = []
        for backend in args.backends:
            if backend == "spectral":
                columns.append((backend, args.cases, fine))
            elif backend == "axisymmetric":
                columns += [(b, args.cases, ()) for b in ("axisymmetric", "axisymmetric-check")]
            else:
                only = set(plan.fem_cases) & set(args.cases or plan.fem_cases)
                if only:
                    columns.append((backend, only, ()))
        run_eps(cache, args.out, plan, columns)
    if not args.report_only and "ade" in args.stages:
        run_ade(cache, args.out, plan)
    if not args.report_only and "transitions" in args.stages:
        if plan.pear_transition:  # the sharp ones first (the report reads them)
            v, branches, m0s = plan.pear_transition
            for m0 in m0s:
                for b in branches:
                    ade_sharp(cache, b, v, m0, ADE_KBAR)
        run_transitions(cache, args.out, plan)
    payload = report(cache, args.out, plan)
    print(f"wrote {args.out / 'sharp_limit.md'}")
    return payload


if __name__ == "__main__":
    main()
