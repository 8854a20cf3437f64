"""The non-axisymmetric branch born where the oblate loses its stability in m = 2, followed
in 3D (issue 44: continuation in 3D; ``python -m fem_ade.switch BRANCH --follow N``).

The minimal model's oblate (κ̄ = 0, R₀ = 0.2, ε = 0.04) is a saddle in block m = 2 above
v_c (``fem_ade.branch --modes``: a bifurcation at v_c). There a branch of shapes with the
mode's symmetry — two mirror planes through the axis, a triaxial "D2" body — is born. The
switch study (``switch.md``) found that the gradient flow from the unstable oblate goes to
the prolate, and so that this branch is no minimum near the oblate; where it goes it could
not say. Hypothesis (Heinrich, Svetina & Žekš 1993: the non-axisymmetric shapes between the
oblate and the prolate are unstable): the branch is subcritical (it exists for v < v_c, on
the oblate's stable side), a saddle with one unstable direction, its e above the oblate's
and the prolate's at the same v. Test: the branch followed by 3D continuation from the
bifurcation, each point's 3D stability (the rigid motions out), its e beside the oblate's
and the prolate's axisymmetric branches at the same v, ε and R₀, its semi-axes and its
symmetry. Two cases: ε = 0.04 on 64³ nodes of order 8 (2.56 per ε, where the blocks equal
the 3D spectrum: ``switch.md``), up to 40 points; ε = 0.02 on 96³ nodes of order 8 (1.92
per ε), 3 points (~15 min a point with its stability).

Writes ``OUT/branch3d.md`` (with the hand-written ``OUT/branch3d_notes.md``), ``.json`` and
``branch3d.png`` (e and the semi-axes against v); the full run also
``branch3d-shapes-CASE.png`` (three points of each branch); the branch folders in
``OUT/branch3d/`` (not committed). A measurement: each point's Newton and stability
seconds, one point after another in one process.

    python studies/branch3d.py --out studies/results     # ~1.5 h on one core
    python studies/branch3d.py --quick                   # 32³ nodes, 3 points, ~1 min
"""

from __future__ import annotations

from _lib.cli import one_thread, results, study_parser, write_report

one_thread(fft=False)

import json  # noqa: E402
import math  # noqa: E402
from pathlib import Path  # noqa: E402

from _lib.branches import branch_rows, e_at, make_branch, three_points  # noqa: E402
from fem_ade.campaigns.stability import count_text  # noqa: E402

OUT = Path("runs") / "studies"
#: (name, ε, R₀, the oblate branch's v from, to, step, the 3D mesh's nodes and order, the
#: points of the 3D branch, the prolate's branch beside it: v from, to (None: none — the
#: quick case's R₀ = 0.25 prolate does not fit the box))
CASES = (("eps=0.04", 0.04, 0.2, 0.9, 0.74, 0.02, 64, 8, 40, (0.9, 0.6)),
         ("eps=0.02", 0.02, 0.2, 0.9, 0.74, 0.02, 96, 8, 3, (0.9, 0.6)))
QUICK_CASES = (("eps=0.04", 0.04, 0.25, 0.85, 0.80, 0.01, 32, 8, 3, None),)


def _interpolated(rows: list[dict], v: float) -> float | None:
    """e of an axisymmetric branch's rows at v (:func:`_lib.branches.e_at`)."""
    return e_at([(float(r["v"]), float(r["e"])) for r in rows
                 if r.get("e") not in ("", None)], v)


def case(root: Path, c: tuple) -> dict:
    """One branch: the oblate with its modes, the prolate beside it, the 3D branch."""
    from fem_ade.campaigns.switch_branch import follow_switched

    name, eps, R0, v0, v1, dv, n, order, points, beside = c
    common = ["vesicle", "--eps", str(eps), "--R0", str(R0), "--param", "v"]
    oblate = make_branch(root / f"oblate-{name}", [*common, "--branch", "oblate", "--from",
                                                   str(v0), "--to", str(v1), "--step",
                                                   str(dv), "--modes", "3"])
    pro = [] if beside is None else branch_rows(make_branch(
        root / f"prolate-{name}", [*common, "--branch", "prolate", "--from", str(beside[0]),
                                   "--to", str(beside[1]), "--step", "0.02"]))
    bif = json.loads((oblate / "bifurcations.json").read_text())["bifurcations"][0]
    folder = root / f"d2-{name}"
    rows = follow_switched(oblate, 0, folder, points=points, n=n, order=order,
                           stability=True, quiet=True)
    ob = branch_rows(oblate)
    _symmetries(oblate, folder, rows, n, order)
    keep = ("v", "e", "amplitude", "label", "symmetry", "semi_axes", "eigenvalues", "unstable_3d",
            "newton", "newton_s", "seconds")
    out_rows = [{**{k: r.get(k) for k in keep}, "e_oblate": _interpolated(ob, r["v"]),
                 "e_prolate": _interpolated(pro, r["v"])} for r in rows]
    ended = json.loads((folder / "ended.json").read_text())["why"]
    return {"name": name, "eps": eps, "R0": R0, "n": n, "order": order, "m": bif["m"],
            "v_bifurcation": bif["v"], "rows": out_rows, "ended": ended,
            "oblate": [(float(r["v"]), float(r["e"])) for r in ob],
            "prolate": [(float(r["v"]), float(r["e"])) for r in pro]}


def _symmetries(oblate: Path, folder: Path, rows: list[dict], n: int, order: int) -> None:
    """Each row's symmetry group where its point was saved without one (by a version of
    follow_switched before it measured it): measured on the point's field."""
    import numpy as np

    from fem_ade.analysis.symmetry import symmetry
    from fem_ade.campaigns.switch_branch import switched_start

    missing = [k for k, r in enumerate(rows) if "symmetry" not in r]
    if not missing:
        return
    _, be, _ = switched_start(oblate, 0, None, None, n, order)
    for k in missing:
        with np.load(folder / "points" / f"{k:04d}" / "final.npz") as z:
            be._set(np.array(z["phi"]), None)
        found = symmetry(be.grid_phi(), be.params.L)
        rows[k] = {**rows[k], "symmetry": None if found is None else found["group"]}


def shapes(root: Path, c: dict, out: Path) -> Path | None:
    """Three of the branch's points (its first, middle and last) as 3D pictures in one
    PNG."""
    from fem_ade.campaigns.switch_branch import switched_start

    _, be, _ = switched_start(root / f"oblate-{c['name']}", 0, None, None, c["n"],
                              c["order"])
    return three_points(
        be, root / f"d2-{c['name']}", c["rows"],
        lambda k, r: (f"point {k}: v = {r['v']:.4f}, e = {r['e']:.4f}, "
                      f"{count_text(r['unstable_3d'], r['eigenvalues'])} unstable in 3D"),
        out / f"branch3d-shapes-{c['name']}.png", 64, 0.6)  # the repository's 6 MB


def figure(result: dict, out: Path, suffix: str) -> Path:
    """e against v (the 3D branch, the oblate and the prolate) and the 3D branch's semi-axes
    against v."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem_ade.plots.figures import save_figure

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4.2))
    most = max(r["unstable_3d"] or 0 for c in result["cases"] for r in c["rows"])
    for i, c in enumerate(result["cases"]):
        for key, style, label in (("oblate", "o-", "oblate"), ("prolate", "^-", "prolate")):
            if not c[key]:
                continue
            v, e = zip(*c[key], strict=True)
            ax.plot(v, e, style, ms=3, color="0.5" if key == "oblate" else "0.25",
                    label=None if i else f"{label} (axisymmetric, each ε)")
        rows = c["rows"]
        unstable = [r["unstable_3d"] or 0 for r in rows]
        ax.plot([r["v"] for r in rows], [r["e"] for r in rows], "-", color="C3", lw=1)
        sc = ax.scatter([r["v"] for r in rows], [r["e"] for r in rows], c=unstable,
                        cmap="viridis", s=14, zorder=3, vmin=0, vmax=most,
                        label=None if i else f"m = {c['m']} branch in 3D")
        ax.axvline(c["v_bifurcation"], color="0.7", lw=0.8, ls=":")
        for k in range(3):
            bx.plot([r["v"] for r in rows], [r["semi_axes"][k] for r in rows], ".-",
                    color=f"C{k}", label=None if i else f"a{k + 1}")
    fig.colorbar(sc, ax=ax, label="unstable directions in 3D")
    ax.set_xlabel("v")
    ax.set_ylabel("e = (W + G) / W_sphere")
    ax.legend(frameon=False, fontsize=8)
    bx.set_xlabel("v")
    bx.set_ylabel("semi-axes of the 3D branch")
    bx.legend(frameon=False, fontsize=8)
    path = out / f"branch3d{suffix}.png"
    save_figure(fig, path)
    plt.close(fig)
    return path


def report(result: dict, out: Path, suffix: str) -> None:
    lines = ["# The oblate's m = 2 branch, followed in 3D", "",
             "Written by `studies/branch3d.py` (its docstring says what it runs). "
             "e = (W + G)/W_sphere; λ in units of the bulk Hessian P (docs/model.md §13); "
             "the oblate's and the prolate's e at the same v interpolated between their "
             "axisymmetric branch points (order 8, 2.5 nodes per ε).", ""]
    for c in result["cases"]:
        secs = sorted(r["newton_s"] for r in c["rows"])
        stab = sorted(r["seconds"] - r["newton_s"] for r in c["rows"])
        lines += [f"## {c['name']}, R₀ = {c['R0']:g}: {c['n']}³ nodes of order {c['order']}",
                  "", f"The oblate's block m = {c['m']} crosses zero at v = "
                  f"{c['v_bifurcation']:.4f} (the (r, z) branch). {len(c['rows'])} points "
                  f"(where it stopped: {c['ended']}). A point's Newton: median "
                  f"{secs[len(secs) // 2]:.1f} s "
                  f"(wall, one thread), its 3D stability median {stab[len(stab) // 2]:.1f} s.",
                  "", "| point | v | amplitude | e | e − e_oblate | e − e_prolate | label | "
                  "symmetry | semi-axes | lowest 3D λ | unstable in 3D | Newton | s |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]

        def diff(x, r):
            return "—" if x is None else f"{r['e'] - x:+.2e}"

        for k, r in enumerate(c["rows"]):
            axes = ", ".join(f"{a:.4f}" for a in r["semi_axes"])
            lam = ", ".join(f"{x:.3g}" for x in r["eigenvalues"][:2])
            lines.append(f"| {k} | {r['v']:.5f} | {r['amplitude']:.3f} | {r['e']:.5f} | "
                         f"{diff(r['e_oblate'], r)} | {diff(r['e_prolate'], r)} | "
                         f"{r['label']} | {r.get('symmetry') or '—'} | ({axes}) | {lam} | "
                         f"{count_text(r['unstable_3d'], r['eigenvalues'])} | "
                         f"{r['newton']} | {r['seconds']:.0f} |")
    lines += ["", f"![e and the semi-axes against v](branch3d{suffix}.png)"]
    for c in result["cases"]:
        shapes_png = f"branch3d-shapes-{c['name']}.png"
        if (out / shapes_png).is_file() and not suffix:
            lines += ["", f"![three points of the branch at {c['name']}]({shapes_png})"]
    write_report(out, f"branch3d{suffix}", lines)


def main(argv=None) -> dict:
    ap = study_parser(__doc__, OUT, quick="3 points on 32³ nodes of order 8, R₀ = 0.25",
                      report_only="rewrite the report and figure from branch3d.json")
    args = ap.parse_args(argv)
    suffix = "_quick" if args.quick else ""
    root = args.out / f"branch3d{suffix}"

    def compute():
        root.mkdir(parents=True, exist_ok=True)
        made = {"cases": [case(root, c) for c in (QUICK_CASES if args.quick else CASES)]}
        if not args.quick:
            for c in made["cases"]:
                shapes(root, c, args.out)
        return made

    result = results(args, "branch3d", compute)
    figure(result, args.out, suffix)
    report(result, args.out, suffix)
    for c in result["cases"]:
        last = c["rows"][-1]
        print(f"{c['name']}: {len(c['rows'])} points from v = {c['v_bifurcation']:.4f} to "
              f"{last['v']:.4f} (e {last['e']:.4f}, unstable in 3D "
              f"{count_text(last['unstable_3d'], last['eigenvalues'])})",
              flush=True)
    assert all(math.isfinite(r["e"]) for c in result["cases"] for r in c["rows"])
    return result


if __name__ == "__main__":
    main()
