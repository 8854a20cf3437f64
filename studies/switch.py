"""Where the axisymmetric states' instabilities lead in 3D (issue 44): branch switching
(``python -m fem_ade.switch``) from the minimal model's oblate, and a control of the ADE
plane's one m ≥ 1 instability of a lowest branch.

**Switching.** The oblate (κ̄ = 0, R₀ = 0.2) is a saddle in m = 2 above v_c (the azimuthal
study); from a point on that side the 3D start φ + δψ₂ cos 2(θ − π/8) (δ = 0.1) is run by the
steady recipe in 3D until E changes by less than 1e-13 per step. Hypothesis (Heinrich,
Svetina & Žekš 1993: the non-axisymmetric intermediates between oblate and prolate are
unstable): the flow passes the triaxial shapes and ends on the axisymmetric prolate of the
same v. Test: the end's shape (semi-axes: b = c for a prolate), its 3D stability (Newton
first: a steady state; the six lowest eigenvalues of the 3D Hessian with the rigid motions
out) and its E beside the axisymmetric prolate's at the same v, ε and R₀ (``fem_ade.branch``,
order 8, 2.5 nodes per ε). Two cases: ε = 0.04 on 64³ nodes of order 8 (2.56 nodes per ε,
where the blocks equal the 3D spectrum to 2e-4: ``tests/test_modes.py``) and ε = 0.02 on 64³
of order 4 (1.28 nodes per ε: what 3D affords at ε = 0.02).

**Control of a claim.** The ADE plane's stability (``ade_azimuthal.md``) found the
stomatocyte at (v, Δa₀) = (0.6, 0.8), κ̄/κ = 1.4, ε = 0.01, R₀ = 0.162 unstable in m = 2
(−41 (ε/R₀)⁴), the only cell where the sharp and the phase-field lowest genus-0 branch agree
and the lowest is not stable in 3D. If that is the membrane's, it holds at smaller ε/R₀: the
same point's blocks at ε = 0.0075 and at R₀ = 0.25 (ε/R₀ = 0.046 and 0.04) must be unstable
in m = 2 too.

**The sweep's starfish, refined.** The 3D ADE sweep (``phase_diagram/ade``, ε = 0.04,
spectral 32³) ended in steady 4- and 3-armed starfish at (v, Δa₀) = (0.8, 1.64) from the
oblate's seed and (0.7, 1.64) from the prolate's. Each is made again there, then run at
ε = 0.02 (FEM 64³, order 4) from its end; hypothesis (issue 44): the starfish stays a steady
state, and is not the lowest state of its cell. Test: its label and arms at ε = 0.02, Newton
from it and its 3D eigenvalues (a minimum or a saddle), and its e beside the ends of the
cell's other seeds (prolate, pear, oblate) on the same mesh.

Writes ``OUT/switch.md`` (with the hand-written ``OUT/switch_notes.md``), ``.json`` and each
switched run's picture ``OUT/switch-CASE.png``; the branch folders and the 3D run folders in
``OUT/switch/`` (not committed). A measurement: 3D
runs and their stability, timed, one after another in one process.

    python studies/switch.py --out studies/results     # ~40 min on 2 cores
    python studies/switch.py --quick                   # ε = 0.04 on 32³, ~30 s
"""

from __future__ import annotations

from _lib.cli import one_thread, results, study_parser

one_thread(fft=False)

import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from _lib.branches import branch_rows, make_branch  # noqa: E402
from fem_ade.campaigns.stability import count_text  # noqa: E402

OUT = Path("runs") / "studies"
#: the switches: (name, ε, R₀, the oblate branch's v from, to, step, the point switched
#: from, the 3D mesh's nodes per axis and order)
CASES = (("eps=0.04", 0.04, 0.2, 0.9, 0.78, 0.02, 0, 64, 8),
         ("eps=0.02", 0.02, 0.2, 0.9, 0.74, 0.02, 2, 64, 4))
QUICK_CASES = (("eps=0.04", 0.04, 0.2, 0.9, 0.78, 0.02, 0, 32, 4),)
#: the stomatocyte control: (ε, R₀) at (v, Δa₀) = (0.6, 0.8), κ̄/κ = 1.4
STOMATOCYTE = ((0.01, 0.162), (0.0075, 0.162), (0.01, 0.25), (0.005, 0.162))
KBAR = 1.4
#: the sweep's starfish: (v, Δa₀, the seed it grew from, the other seeds run beside it)
STARFISH = ((0.8, 1.64, "oblate", ("prolate", "pear")),
            (0.7, 1.64, "prolate", ("oblate",)))


def switch_case(root: Path, case: tuple) -> dict:
    """One switch: the oblate branch, the 3D run from its point, the end's stability and
    the axisymmetric prolate at the same v."""
    from fem_ade.analysis.sharp import reduced_energy
    from fem_ade.campaigns.stability import cartesian, load_state, polish
    from fem_ade.campaigns.switch import switch

    name, eps, R0, v0, v1, dv, point, n, order = case
    common = ["vesicle", "--eps", str(eps), "--R0", str(R0), "--param", "v"]
    oblate = make_branch(root / f"oblate-{name}", [*common, "--branch", "oblate", "--from",
                                               str(v0), "--to", str(v1), "--step", str(dv),
                                               "--modes", "3"])
    row = branch_rows(oblate)[point]
    run = root / f"switched-{name}"
    if not (run / "summary.json").is_file():
        switch(oblate, None, run, n=n, order=order, point=point, mode=2, quiet=True)
    s = json.loads((run / "summary.json").read_text())
    if (run / "shape.png").is_file():  # the picture a reader looks at, beside the report
        import shutil

        from fem_ade.plots.figures import compact_png

        picture = root.parent / f"{root.name}-{name}.png"
        shutil.copy(run / "shape.png", picture)
        compact_png(picture, 128)  # (in the repository: a palette, a third of the bytes)
    t0 = time.perf_counter()
    be, _ = load_state(run)
    steady = polish(be)
    stab = cartesian(be, 6)
    stability_s = time.perf_counter() - t0
    v = float(row["v"])
    prolate = make_branch(root / f"prolate-{name}", [*common, "--branch", "prolate", "--from",
                                                 repr(v), "--to", repr(v - 0.002), "--step",
                                                 "0.002", "--modes", "2"])
    pro = branch_rows(prolate)[0]
    body = s["shape"].get("body") or {}
    return {"name": name, "eps": eps, "R0": R0, "n": n, "order": order, "v": v,
            "oblate_e": float(row["e"]), "oblate_lowest_m2": float(row["lowest_m2"]),
            "status": s["status"], "steps": s["steps"], "label": s["shape"]["label"],
            "semi_axes": body.get("semi_axes"), "e": reduced_energy(s["final"]),
            "newton_iterations": steady["newton_iterations"],
            "eigenvalues_3d": list(stab.eigenvalues), "unstable_3d": stab.unstable_3d,
            "prolate_e": float(pro["e"]), "prolate_label": pro["label"],
            "prolate_lowest": [float(pro[f"lowest_m{m}"]) for m in range(3)],
            "run_cpu_s": round(s["cpu_s"], 1), "stability_s": round(stability_s, 1)}


def stomatocyte_case(root: Path, eps: float, R0: float) -> dict:
    """The stomatocyte at (0.6, 0.8) at (ε, R₀): its e and block m = 0 … 4 lowest, or why
    its seed is not one."""
    from fem_ade.campaigns.stability import shape_scale

    made = make_branch(root / f"stomatocyte-eps={eps:g}-R0={R0:g}",
                   ["vesicle", "--branch", "stomatocyte", "--v", "0.6", "--kbar", str(KBAR),
                    "--eps", str(eps), "--R0", str(R0), "--param", "da0", "--from", "0.8",
                    "--to", "0.79", "--step", "0.01", "--modes", "4"])
    out = {"eps": eps, "R0": R0}
    if isinstance(made, str):
        return {**out, "failed": made}
    row = branch_rows(made)[0]
    lowest = [float(row[f"lowest_m{m}"]) for m in range(5)]
    return {**out, "failed": None, "label": row["label"], "e": float(row["e"]),
            "lowest": lowest, "lowest_m2_scaled": lowest[2] / shape_scale(eps, R0),
            "unstable_3d": int(row["unstable_3d"])}


def _run(folder: Path, **kw) -> dict:
    """A vesicle run by the steady recipe (made once: a finished folder is read back)."""
    from fem_ade.engine.runs import recipe, simulate
    from fem_ade.scenes.catalogue import vesicle_scene

    if not (folder / "summary.json").is_file():
        scene_kw = {k: kw.pop(k) for k in ("v", "da0", "eps", "branch")}
        scene = vesicle_scene(kbar=KBAR, **scene_kw)
        simulate(scene, out=folder, **{**recipe("steady", scene), **kw, "quiet": True,
                                       "force": True})
    return json.loads((folder / "summary.json").read_text())


def starfish_case(root: Path, v: float, da0: float, seed: str, others: tuple) -> dict:
    """A sweep starfish made again at ε = 0.04, refined to ε = 0.02, its steadiness and 3D
    eigenvalues, and the cell's other seeds at ε = 0.02 on the same mesh."""
    from fem_ade.analysis.sharp import reduced_energy
    from fem_ade.campaigns.stability import cartesian, load_state, polish
    from fem_ade.model.params import ModelError

    name = f"v={v:g}_da0={da0:g}"
    coarse = _run(root / f"starfish-{name}-eps=0.04", v=v, da0=da0, eps=0.04, branch=seed,
                  backend="spectral", n=32, max_steps=3000, render=False)
    fine_dir = root / f"starfish-{name}-eps=0.02"
    fine = _run(fine_dir, v=v, da0=da0, eps=0.02, branch=seed, n=64, max_steps=6000,
                phi0=str(root / f"starfish-{name}-eps=0.04"), checkpoint_every=200)
    t0 = time.perf_counter()
    try:
        be, _ = load_state(fine_dir)
        steady = polish(be)
        stab = cartesian(be, 4)
        verdict = {"newton_iterations": steady["newton_iterations"],
                   "eigenvalues_3d": list(stab.eigenvalues), "unstable_3d": stab.unstable_3d}
    except ModelError as err:
        verdict = {"not_steady": str(err)}
    ends = {}
    for other in others:
        s = _run(root / f"{other}-{name}-eps=0.02", v=v, da0=da0, eps=0.02, branch=other,
                 n=64, max_steps=6000, checkpoint_every=200)
        ends[other] = {"label": s["shape"]["label"], "e": reduced_energy(s["final"])}
    return {"v": v, "da0": da0, "seed": seed,
            "coarse": {"label": coarse["shape"]["label"], "e": reduced_energy(coarse["final"])},
            "fine": {"label": fine["shape"]["label"], "arms": fine["shape"]["arms"],
                     "e": reduced_energy(fine["final"]), "steps": fine["steps"]},
            **verdict, "others": ends, "stability_s": round(time.perf_counter() - t0, 1)}


def report(result: dict, out: Path, suffix: str) -> None:
    lines = ["# Where the instabilities lead in 3D: branch switching", "",
             "Written by `studies/switch.py` (its docstring says what each case runs). "
             "e = (W + G)/W_sphere; λ in units of the bulk Hessian P (docs/model.md §13).", "",
             "## The oblate's m = 2 saddle, switched into 3D", "",
             "| case | 3D mesh | v | oblate: e, λ(m = 2) | 3D end: label, semi-axes | "
             "3D end: e | prolate (axisymmetric): e | 3D end / prolate − 1 | 3D end: six lowest "
             "λ | 3D run CPU s | stability s |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in result["switches"]:
        axes = ", ".join(f"{a:.4f}" for a in c["semi_axes"] or [])
        lam = ", ".join(f"{x:.3g}" for x in c["eigenvalues_3d"])
        lines.append(
            f"| {c['name']} (R₀ = {c['R0']:g}) | {c['n']}³, order {c['order']} | "
            f"{c['v']:.4f} | {c['oblate_e']:.5f}, {c['oblate_lowest_m2']:.3g} | "
            f"{c['label']}, ({axes}) | {c['e']:.5f} | {c['prolate_e']:.5f} | "
            f"{c['e'] / c['prolate_e'] - 1:+.2e} | {lam} "
            f"({count_text(c['unstable_3d'], c['eigenvalues_3d'])} unstable) | "
            f"{c['run_cpu_s']:.0f} | {c['stability_s']:.0f} |")
    if result["stomatocyte"]:
        lines += ["", "## Control: the stomatocyte at (v, Δa₀) = (0.6, 0.8), κ̄/κ = 1.4", "",
                  "| ε | R₀ | ε/R₀ | label | e | λ(m = 0 … 4) | λ(m = 2)/(ε/R₀)⁴ | unstable "
                  "in 3D |", "|---|---|---|---|---|---|---|---|"]
        for c in result["stomatocyte"]:
            head = f"| {c['eps']:g} | {c['R0']:g} | {c['eps'] / c['R0']:.3f} |"
            if c["failed"]:
                lines.append(f"{head} — | — | {c['failed']} | — | — |")
                continue
            lam = ", ".join(f"{x:.3g}" for x in c["lowest"])
            lines.append(f"{head} {c['label']} | {c['e']:.5f} | {lam} | "
                         f"{c['lowest_m2_scaled']:.1f} | {c['unstable_3d']} |")
    if result.get("starfish"):
        lines += ["", "## The sweep's starfish at ε = 0.02", "",
                  "| (v, Δa₀) | seed | ε = 0.04 (spectral 32³): label, e | ε = 0.02 (FEM 64³, "
                  "order 4): label, e | Newton, 3D lowest λ | the cell's other seeds at "
                  "ε = 0.02: label, e |", "|---|---|---|---|---|---|"]
        for c in result["starfish"]:
            if "not_steady" in c:
                verdict = c["not_steady"]
            else:
                lam = ", ".join(f"{x:.3g}" for x in c["eigenvalues_3d"])
                verdict = (f"converged in {c['newton_iterations']}; {lam} "
                           f"({count_text(c['unstable_3d'], c['eigenvalues_3d'])} unstable)")
            others = "; ".join(f"{k}: {o['label']}, {o['e']:.4f}"
                               for k, o in c["others"].items())
            lines.append(f"| ({c['v']:g}, {c['da0']:g}) | {c['seed']} | "
                         f"{c['coarse']['label']}, {c['coarse']['e']:.4f} | "
                         f"{c['fine']['label']}, {c['fine']['e']:.4f} | {verdict} | {others} |")
    notes = out / f"switch{suffix}_notes.md"
    if notes.is_file():
        lines += ["", notes.read_text().rstrip()]
    (out / f"switch{suffix}.md").write_text("\n".join(lines) + "\n")


def main(argv=None) -> dict:
    ap = study_parser(__doc__, OUT, quick="one switch at ε = 0.04 on 32³",
                      report_only="rewrite the report from switch.json")
    args = ap.parse_args(argv)
    suffix = "_quick" if args.quick else ""
    root = args.out / f"switch{suffix}"

    def compute():
        root.mkdir(parents=True, exist_ok=True)
        return {"switches": [switch_case(root, c)
                             for c in (QUICK_CASES if args.quick else CASES)],
                "stomatocyte": [] if args.quick else [stomatocyte_case(root, e, r)
                                                     for e, r in STOMATOCYTE],
                "starfish": [] if args.quick else [starfish_case(root, *c)
                                                   for c in STARFISH]}

    result = results(args, "switch", compute)
    report(result, args.out, suffix)
    for c in result["switches"]:
        print(f"{c['name']}: oblate v = {c['v']:.4f} -> {c['label']} e = {c['e']:.5f} "
              f"(prolate {c['prolate_e']:.5f}), unstable in 3D {c['unstable_3d']}",
              flush=True)
    assert all(math.isfinite(c["e"]) for c in result["switches"])
    return result


if __name__ == "__main__":
    main()
