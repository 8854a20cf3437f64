"""Where the ADE plane's 3D-unstable states go in 3D (issue 44): each state the azimuthal
studies found unstable in m = 2 at ε = 0.01, switched into 3D on the octant
(``python -m fem_ade.switch --geometry octant``) and run by the steady recipe, beside the
revolved state alone (the control).

**Which states.** ``ade_azimuthal.md`` decided five cells of the genus-0 plane (κ̄/κ = 1.4,
ε = 0.01) unstable in m = 2, all prolates (the phase field's lowest genus-0 branch there;
the sharp one's is the oblate or the stomatocyte, which at ε = 0.01 do not hold): (v, Δa₀) =
(0.6, 1.04), (0.6, 1.16), (0.65, 0.8), (0.65, 0.92), (0.65, 1.04). ``ade_bifurcations.md``
found at v = 0.7 an interval where neither the oblate nor the prolate is stable in 3D
(Δa₀ = 1.0861 … 1.0957 at ε = 0.01). Run: three of the five cells (:data:`CASES`); the
other two and the v = 0.7 interval's two states are listed as not run, with why
(:data:`NOT_RUN`). The stomatocyte at (0.6, 0.8), also unstable in m = 2, has no equatorial
mirror: the octant cannot hold it.

**How.** Each state is made at its (v, Δa₀) and R₀ of the plane's lines by Newton on the
(r, z) mesh (4 nodes per ε, modes m ≤ 4); then two 3D runs on the octant (order 8, 1.92 nodes
per ε: 97³ unknowns, the box's 192³), both until E changes by less than 1e-13 per step: the
revolved state (δ = 0, the control: does the 3D mesh keep the (r, z) state, and its E?) and
the start φ + δψ₂ cos 2θ (δ = 0.1). The octant holds the shapes with the three mirror planes
(cos 2θ included); a state that breaks one of them is not seen — a bound this study states.

**Hypothesis** (H1): the kicked state ends on a non-axisymmetric steady state (D2h: three
unequal semi-axes) whose e is below the axisymmetric state's. (H2): below every axisymmetric
genus-0 state of the phase field at that point — then the plane's lowest genus-0 shape there
is not axisymmetric. Test: the end's symmetry group (``fem_ade.analysis.symmetry``), label,
semi-axes and e beside the control's and the (r, z) lines' e at that cell.

Writes ``OUT/ade_octant.md`` (with the hand-written ``OUT/ade_octant_notes.md``), ``.json``
and ``OUT/ade_octant.png`` (each case's end); the (r, z) points and 3D run folders in
``OUT/ade_octant/`` (not committed). Resumable: a finished run is read back.

    python studies/ade_octant.py --out studies/results   # ~45 min on 2 cores
    python studies/ade_octant.py --quick                 # ε = 0.04, an oblate, ~1 min
"""

from __future__ import annotations

from _lib.cli import one_thread, study_parser

one_thread(fft=False)

import json  # noqa: E402
import math  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

OUT = Path("runs") / "studies"
KBAR = 1.4
EPS = 0.01
#: the cases: (v, Δa₀, branch, R₀ of the plane's line at that v, why, with a control run)
CASES = ((0.6, 1.04, "prolate", 0.162, "cell, unstable in m = 2", True),
         (0.6, 1.16, "prolate", 0.162, "cell, unstable in m = 2", True),
         (0.65, 0.92, "prolate", 0.178, "cell, unstable in m = 2", False))
#: the cases not run (module docstring): the other two cells at v = 0.65, and the v = 0.7
#: interval's two states, whose m = 2 eigenvalues (−0.07 and −0.3 (ε/R₀)⁴ at Δa₀ = 1.091) a
#: flow leaves in 1e4–1e5 steps: they need the branch followed on the octant
NOT_RUN = ((0.65, 0.8, "prolate", "cell, unstable in m = 2: for time"),
           (0.65, 1.04, "prolate", "cell, unstable in m = 2: for time"),
           (0.7, 1.091, "oblate", "neither branch stable: λ₂ = −0.07 (ε/R₀)⁴, a flow too slow"),
           (0.7, 1.091, "prolate", "neither branch stable: λ₂ = −0.3 (ε/R₀)⁴, a flow too slow"))
#: the quick case: the minimal-like oblate at ε = 0.04 past its m = 2 bifurcation
QUICK_CASES = ((0.84, 1.0, "oblate", 0.25, "quick: an oblate unstable in m = 2", True),)
QUICK_EPS = 0.04
#: the 3D runs: their names and the kick's δ (the mesh: the switch's octant default)
KICKS = (("control", 0.0), ("kicked", 0.1))
#: a 3D run stops here if E has not settled (0.37 s a step at 97³, one thread: 25 min)
MAX_STEPS = 4000
#: the (r, z) point's nodes per ε and modes
PER_EPS, MODES = 4.0, 4


def case_name(case: tuple) -> str:
    v, da0, branch = case[:3]
    return f"{branch}-v={v:g}_da0={da0:g}"


def make_point(folder: Path, case: tuple, eps: float) -> str | None:
    """The case's (r, z) state and its modes: a one-point branch in Δa₀; None, or why not."""
    from fem_ade.backends.fem.axisym import DEFAULT_ORDER, default_nodes
    from fem_ade.campaigns.branch import follow
    from fem_ade.model.params import ModelError
    from fem_ade.scenes.catalogue import vesicle_scene

    if (folder / "branch.csv").is_file():
        return None
    v, da0, branch, R0 = case[:4]
    try:
        scene = vesicle_scene(v=v, da0=da0, kbar=KBAR, eps=eps, R0=R0, branch=branch)
        follow(scene, param="da0", start=da0, stop=da0 - 0.002, step=0.002, out=folder,
               quiet=True, max_points=1, modes=MODES,
               n=default_nodes(eps, scene.params.L, DEFAULT_ORDER, PER_EPS))
    except (ModelError, ArithmeticError) as err:
        return f"{type(err).__name__}: {err}"
    return None


def run_3d(job: tuple) -> str | None:
    """One octant run (``job``: the point's branch folder, the run folder, δ); None, or why
    not. A finished run is kept, an interrupted one resumed from its checkpoint."""
    from fem_ade.campaigns.switch import switch
    from fem_ade.model.params import ModelError

    branch, run, delta = job
    summary = run / "summary.json"
    if summary.is_file() and json.loads(summary.read_text())["status"] != "interrupted":
        return None  # ended: kept without making the start again
    try:  # a new run, or the interrupted one resumed (switch continues its own folder)
        switch(branch, None, run, mode=2, point=0, delta=delta, geometry="octant",
               quiet=True, max_steps=MAX_STEPS)
    except ModelError as err:
        return str(err)
    return None


def summary_of(run: Path) -> dict:
    """A 3D run's end: e, label, symmetry group, semi-axes, steps, CPU seconds."""
    from fem_ade.analysis.sharp import reduced_energy

    s = json.loads((run / "summary.json").read_text())
    body = s["shape"].get("body") or {}
    return {"e": reduced_energy(s["final"]), "E": s["final"]["E"], "status": s["status"],
            "steps": s["steps"], "label": s["shape"]["label"],
            "genus": s["shape"].get("genus"),
            "group": (body.get("symmetry") or {}).get("group"),
            "semi_axes": body.get("semi_axes"), "cpu_s": round(s["cpu_s"], 1)}


def plane_energies(v: float, da0: float) -> dict | None:
    """The (r, z) lines' e of each branch at a grid cell of ade_branches.json (ε = 0.01), or
    None off the grid."""
    path = Path(__file__).parent / "results" / "ade_branches.json"
    if not path.is_file():
        return None
    for p in json.loads(path.read_text())["points"]:
        if abs(p["v"] - v) < 1e-9 and abs(p["da0"] - da0) < 1e-9:
            return {k: x for k, x in p["e_pf"].items() if x is not None}
    return None


def compute(root: Path, cases: tuple, eps: float, workers: int, inline: bool) -> dict:
    """The cases' points, their 3D runs (on ``workers`` processes, or in this one with
    ``inline``: the quick mode, which a test loads without a module name), their rows."""
    from _lib.branches import branch_rows

    out = []
    for case in cases:
        folder = root / case_name(case)
        failed = make_point(folder / "rz", case, eps)
        out.append({"case": case, "failed": failed})
    jobs = [(root / case_name(c["case"]) / "rz", root / case_name(c["case"]) / name, delta)
            for c in out if not c["failed"] for name, delta in KICKS
            if name == "kicked" or c["case"][5]]
    errors = {}
    with ProcessPoolExecutor(max(1, workers)) as pool:
        made = map(run_3d, jobs) if inline else pool.map(run_3d, jobs)
        for job, why in zip(jobs, made, strict=True):
            errors[job[1]] = why
            print(f"  {job[1].parent.name}/{job[1].name}: {why or 'done'}", flush=True)
    rows = []
    for c in out:
        v, da0, branch, R0, why, _ = c["case"]
        row = {"v": v, "da0": da0, "branch": branch, "R0": R0, "why": why, "eps": eps,
               "failed": c["failed"]}
        if not c["failed"]:
            folder = root / case_name(c["case"])
            r = branch_rows(folder / "rz")[0]
            row["rz"] = {"e": float(r["e"]), "E": float(r["E"]), "label": r["label"],
                         "lowest": [float(r[f"lowest_m{m}"]) for m in range(MODES + 1)],
                         "unstable_3d": int(r["unstable_3d"])}
            for name, _ in KICKS:
                run = folder / name
                if (run / "summary.json").is_file():
                    row[name] = summary_of(run)
                elif name == "kicked" or c["case"][5]:
                    row[name] = {"failed": errors.get(run) or "not run"}
                else:
                    row[name] = {"failed": "no control run"}
        row["plane"] = plane_energies(v, da0) if eps == EPS else None
        rows.append(row)
    return {"eps": eps, "kbar": KBAR, "kicks": dict(KICKS), "max_steps": MAX_STEPS,
            "cases": rows, "not_run": [] if eps != EPS else [list(c) for c in NOT_RUN]}


def verdict(row: dict) -> str:
    """What the kicked run says about the state and the plane's lowest genus-0 shape."""
    k, c = row.get("kicked") or {}, row.get("control") or {}
    if "e" not in k:
        return "not run"
    base, which = (c["e"], "the control's") if "e" in c else (row["rz"]["e"], "the (r, z) state's")
    axisymmetric = (k["group"] or "").startswith("D∞") or (k["group"] or "").startswith("C∞")
    what = ("ends axisymmetric" if axisymmetric else f"ends non-axisymmetric ({k['group']})")
    what += f", e {base - k['e']:.3g} below {which}"
    plane = row.get("plane") or {}
    if k["label"] in plane:  # the end is a branch of the (r, z) lines at this cell
        what += (f"; the lines' {k['label']} there: e {plane[k['label']]:.4f} "
                 f"({k['e'] - plane[k['label']]:+.4f})")
    elif (genus0 := {b: e for b, e in plane.items() if b != "torus"}):
        best = min(genus0, key=genus0.get)
        what += (f"; {'below' if k['e'] < genus0[best] else 'above'} the lines' lowest "
                 f"genus-0 ({best}, {genus0[best]:.4f})")
    return what


def report(result: dict, out: Path, suffix: str) -> None:
    lines = ["# The ADE plane's 3D-unstable states, followed in 3D on the octant", "",
             "Written by `studies/ade_octant.py` (its docstring says what runs). κ̄/κ = "
             f"{result['kbar']:g}, ε = {result['eps']:g}; e = (W + G)/W_sphere. (r, z): the "
             "state on the (r, z) mesh (4 nodes per ε), its lowest eigenvalue per mode "
             "m = 0 … 4; control: that state revolved onto the octant (order 8, 1.92 nodes "
             "per ε) and run to steady; kicked: the same plus 0.1 ψ₂ cos 2θ.", "",
             "| v | Δa₀ | branch (why) | (r, z): label, e, λ(m = 0 … 4) | control: label, "
             "group, e (steps) | kicked: label, group, semi-axes, e (steps) | lines' e at the "
             "cell | verdict |", "|---|---|---|---|---|---|---|---|"]
    for r in result["cases"]:
        head = f"| {r['v']:g} | {r['da0']:g} | {r['branch']} ({r['why']}) |"
        if r["failed"]:
            lines.append(f"{head} {r['failed']} | | | | |")
            continue
        rz = r["rz"]
        lam = ", ".join(f"{x:.2g}" for x in rz["lowest"])
        cells = []
        for name in ("control", "kicked"):
            x = r[name]
            if "e" not in x:
                cells.append(x["failed"])
                continue
            axes = (", semi-axes " + ", ".join(f"{a:.3f}" for a in x["semi_axes"])
                    if name == "kicked" and x["semi_axes"] else "")
            cells.append(f"{x['label']}, {x['group']}{axes}, {x['e']:.5f} ({x['steps']}, "
                         f"{x['status']})")
        plane = "; ".join(f"{b} {e:.4f}" for b, e in sorted((r["plane"] or {}).items(),
                                                            key=lambda t: t[1]))
        lines.append(f"{head} {rz['label']}, {rz['e']:.5f}, {lam} | {cells[0]} | {cells[1]} | "
                     f"{plane or '—'} | {verdict(r)} |")
    cpu = sum(r[n].get("cpu_s", 0) for r in result["cases"] if not r["failed"]
              for n in ("control", "kicked"))
    lines += ["", f"3D runs: {cpu:.0f} s CPU in all (one BLAS thread each, two at a time); a "
              f"run stops at {result['max_steps']} steps if E has not settled."]
    if result.get("not_run"):
        lines += ["", "Not run:", ""] + [f"- v = {v:g}, Δa₀ = {d:g}, {b}: {why}"
                                          for v, d, b, why in result["not_run"]]
    notes = out / f"ade_octant{suffix}_notes.md"
    if notes.is_file():
        lines += ["", notes.read_text().rstrip()]
    (out / f"ade_octant{suffix}.md").write_text("\n".join(lines) + "\n")


def draw(result: dict, root: Path, path: Path) -> None:
    """Each case's kicked end (the surface of its run's shape picture), side by side."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem_ade.plots.figures import compact_png

    cases = [r for r in result["cases"] if not r["failed"]
             and (root / case_name((r["v"], r["da0"], r["branch"])) / "kicked" /
                  "shape.png").is_file()]
    if not cases:
        return
    fig, axes = plt.subplots(1, len(cases), figsize=(3.0 * len(cases), 3.0), squeeze=False)
    for ax, r in zip(axes[0], cases, strict=True):
        img = plt.imread(root / case_name((r["v"], r["da0"], r["branch"])) / "kicked" /
                         "shape.png")
        h, w = img.shape[:2]
        ax.imshow(img[int(0.2 * h):int(0.95 * h), :w // 2])  # the surface, not the section
        ax.set_axis_off()
        k, c = r["kicked"], r.get("control") or {}
        base = (f"control {c['e']:.4f}" if "e" in c else f"(r, z) {r['rz']['e']:.4f}")
        ax.set_title(f"{r['branch']} v={r['v']:g}, Δa₀={r['da0']:g}\n→ {k['label']}, "
                     f"{k['group']}\ne {k['e']:.4f} ({base})", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    compact_png(path, 64)


def main(argv=None) -> dict:
    from _lib.cli import results

    ap = study_parser(__doc__, OUT, quick="one oblate at ε = 0.04", workers="",
                      report_only="rebuild the report from the json")
    args = ap.parse_args(argv)
    suffix = "_quick" if args.quick else ""
    root = args.out / f"ade_octant{suffix}"
    root.mkdir(parents=True, exist_ok=True)
    cases, eps = (QUICK_CASES, QUICK_EPS) if args.quick else (CASES, EPS)
    result = results(args, "ade_octant", lambda: compute(root, cases, eps, args.workers,
                                                                 inline=args.quick))
    report(result, args.out, suffix)
    if not args.report_only:
        draw(result, root, args.out / f"ade_octant{suffix}.png")
    for r in result["cases"]:
        print(f"{r['branch']} v = {r['v']:g}, da0 = {r['da0']:g}: {verdict(r)}", flush=True)
    assert all(math.isfinite(r["kicked"]["e"]) for r in result["cases"]
               if not r["failed"] and "e" in r["kicked"])
    return result


if __name__ == "__main__":
    main()
