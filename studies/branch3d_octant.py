"""The oblate's m = 2 branch in 3D at ε = 0.02 and 0.01, on the octant: which way it leaves
the oblate, and where it goes (issue 44: continuation in 3D;
``python -m fem_ade.switch BRANCH --follow N --geometry octant``).

``branch3d.py`` followed the branch born where the minimal model's oblate (κ̄ = 0, R₀ = 0.2)
turns stable in m = 2, on the periodic box: at ε = 0.04 (64³ nodes of order 8, 2.56 per ε) a
subcritical pitchfork, a saddle, to a hole at v = 0.628; at ε = 0.02 three points on 96³
nodes (1.92 per ε), where v *rose* with the mode's amplitude — supercritical, the opposite —
and the 2.56 per ε that had decided ε = 0.04 was beyond that session (15 min a point). The
branch's shapes have the mode's mirror planes x and y and the oblate's equatorial one, so
they lie in the octant's sector (:mod:`fem_ade.backends.fem.octant`), an eighth of the
unknowns at the same spacing.

**Hypothesis**: the supercritical start at ε = 0.02 is the mesh's (as 1.28 nodes per ε
flipped ε = 0.04), and the branch is subcritical there as at 0.04. **Test** (the mesh
ladder): the branch's first points on 1.92, 2.56 and 3.84 nodes per ε (order 8), each
point's v against the mode's amplitude a, v = v_c + c a² fitted to them (3 points, 2
parameters); the sign of c is the direction (c < 0: subcritical), v_c beside the (r, z)
block's zero, located on a window of steps of 0.002 in v about it. The (r, z) branches here
are at 4 nodes per ε (their bifurcation resolved:
measured, the m = 2 zero of this oblate at ε = 0.02 with steps of 0.002 in v was 0.767464,
0.763568, 0.766249, 0.766175, 0.766180, 0.766180 on 1.92, 2.56, 3.2, 3.84, 5.12, 7.68
nodes per ε: the default 2.5 per ε does not resolve where an eigenvalue this small crosses
zero). **Control**: the octant on 96 nodes per L equals
the box's three points (``branch3d.json``), as the two are the same discretization. Then the
branch followed on 2.56 nodes per ε (the finest mesh a point of which costs under a minute at
ε = 0.02) to where it ends or ``FOLLOW`` points; at ε = 0.01 on 2.56 nodes per ε (129³
unknowns), as far as ``FOLLOW`` allows. Each point's stability is the sector's (perturbations
even in x, y and z): a lower bound on the 3D count.

Writes ``OUT/branch3d_octant.md`` (with the hand-written ``OUT/branch3d_octant_notes.md``),
``.json``, ``branch3d_octant.png`` (v against a², e against v) and, in the full run,
``branch3d_octant-shapes.png``; the branch folders in ``OUT/branch3d_octant/`` (not
committed; each resumes). A measurement: each point's Newton and stability seconds, one
point after another in one process, one BLAS thread.

    python studies/branch3d_octant.py --out studies/results     # ~2 h on one core
    python studies/branch3d_octant.py --quick                   # eps = 0.04, ~20 s
"""

from __future__ import annotations

from _lib.cli import one_thread, results, study_parser, write_report

one_thread(fft=False)

import json  # noqa: E402
import math  # noqa: E402
from pathlib import Path  # noqa: E402

from _lib.branches import branch_rows, e_at, make_branch, three_points  # noqa: E402

OUT = Path("runs") / "studies"
ORDER = 8
#: the (r, z) branches' nodes per ε (module docstring)
RZ_NODES_PER_EPS = 4.0
#: the window about the oblate's m = 2 zero (its v ± WINDOW, steps of WINDOW_STEP) where the
#: zero is located (linear in the eigenvalue between two points: over steps of 0.01 in v it
#: was 7e-4 off at eps = 0.02) and from which the 3D branch starts
WINDOW, WINDOW_STEP = 0.006, 0.002
#: the points of each mesh of the ladder
LADDER_POINTS = 3
#: (name, ε, R₀, the oblate's v from, to, step, the prolate's v from, to (None: none), the
#: ladder's nodes per L, the followed mesh's nodes per L, its points, each point's stability
#: or not: at ε = 0.01 on 129³ unknowns a point with its stability passed 25 min (stopped in
#: ARPACK), its Newton alone took 13-15 min)
CASES = (("eps=0.02", 0.02, 0.2, 0.9, 0.7, 0.01, (0.9, 0.6), (96, 128, 192), 128, 50, True),
         ("eps=0.01", 0.01, 0.2, 0.9, 0.7, 0.01, (0.9, 0.6), (256,), 256, 2, False))
QUICK_CASES = (("eps=0.04", 0.04, 0.25, 0.85, 0.80, 0.01, None, (48,), 48, 4, True),)
#: the box's points of branch3d.json (the control): its case, mesh, and its (r, z) oblate's
#: arguments (branch3d.py's: the default 2.5 nodes per ε)
BOX = ("eps=0.02", 96, ["vesicle", "--eps", "0.02", "--R0", "0.2", "--param", "v", "--branch",
                        "oblate", "--from", "0.9", "--to", "0.74", "--step", "0.02",
                        "--modes", "3"])


def rz_nodes(eps: float) -> int:
    """The (r, z) branches' nodes per L: :data:`RZ_NODES_PER_EPS` per ε, whole cells."""
    return ORDER * math.ceil(RZ_NODES_PER_EPS / (eps * ORDER) - 1e-9)


def first_sheet(rows: list[dict]) -> list[tuple[float, float]]:
    """(v, e) of a branch followed down in v, up to its first fold (where v turns: the rows
    past it are another sheet — the oblate's turns at v = 0.707 at ε = 0.02 — on which e at
    the same v is another state's)."""
    out = []
    for r in rows:
        if not r.get("e"):
            continue
        if out and float(r["v"]) >= out[-1][0]:
            break
        out.append((float(r["v"]), float(r["e"])))
    return out


def onset(rows: list[dict]) -> dict:
    """v = v_c + c a² by least squares on the rows' (a², v); the largest residual."""
    import numpy as np

    a2 = np.array([r["amplitude"] ** 2 for r in rows])
    v = np.array([r["v"] for r in rows])
    A = np.stack([np.ones_like(a2), a2], axis=1)
    (vc, c), *_ = np.linalg.lstsq(A, v, rcond=None)
    return {"v_c": float(vc), "c": float(c),
            "residual": float(np.max(np.abs(A @ np.array([vc, c]) - v)))}


def _kept(r: dict) -> dict:
    """A row as the JSON keeps it: :data:`KEEP`, the two lowest eigenvalues (the report's)."""
    out = {k: r.get(k) for k in KEEP}
    if out["eigenvalues"]:
        out["eigenvalues"] = out["eigenvalues"][:2]
    return out


def _follow(oblate: Path, folder: Path, n: int, points: int, stability: bool) -> list[dict]:
    from fem_ade.campaigns.switch_branch import follow_switched

    return follow_switched(oblate, 0, folder, points=points, n=n, order=ORDER,
                           stability=stability, quiet=True, geometry="octant")


KEEP = ("v", "e", "amplitude", "label", "symmetry", "semi_axes", "eigenvalues", "unstable_3d",
        "newton", "newton_s", "seconds")


def case(root: Path, c: tuple) -> dict:
    """One ε: the (r, z) oblate (its modes) and prolate, the ladder, the followed branch."""
    name, eps, R0, v0, v1, dv, beside, ladder, n_follow, points, stability = c
    common = ["vesicle", "--eps", str(eps), "--R0", str(R0), "--param", "v", "--n",
              str(rz_nodes(eps))]
    oblate = make_branch(root / f"oblate-{name}", [*common, "--branch", "oblate", "--from",
                                                   str(v0), "--to", str(v1), "--step",
                                                   str(dv), "--modes", "3"])
    pro = [] if beside is None else branch_rows(make_branch(
        root / f"prolate-{name}", [*common, "--branch", "prolate", "--from", str(beside[0]),
                                   "--to", str(beside[1]), "--step", "0.02"]))
    coarse = json.loads((oblate / "bifurcations.json").read_text())["bifurcations"][0]["v"]
    ob = first_sheet(branch_rows(oblate))
    top, bottom = (round(coarse + s * WINDOW, 3) for s in (1, -1))
    oblate = make_branch(root / f"window-{name}", [*common, "--branch", "oblate", "--from",
                                                   str(top), "--to", str(bottom), "--step",
                                                   str(WINDOW_STEP), "--modes", "3"])
    bif = json.loads((oblate / "bifurcations.json").read_text())["bifurcations"][0]
    pr = first_sheet(pro)
    meshes = []
    for n in ladder:
        k = min(LADDER_POINTS, points) if n == n_follow else LADDER_POINTS
        rows = _follow(oblate, root / f"d2-{name}-n{n}", n, k, stability)[:k]
        meshes.append({"n": n, "nodes_per_eps": n * eps, "unknowns": (n // 2 + 1) ** 3,
                       **onset(rows), "rows": [_kept(r) for r in rows]})
    folder = root / f"d2-{name}-n{n_follow}"
    rows = _follow(oblate, folder, n_follow, points, stability)
    ended = json.loads((folder / "ended.json").read_text())["why"]
    gaps = clearances(oblate, folder, n_follow, len(rows))
    out_rows = [{**_kept(r), "e_oblate": e_at(ob, r["v"]),
                 "e_prolate": e_at(pr, r["v"]), "gap": g}
                for r, g in zip(rows, gaps, strict=True)]
    return {"name": name, "eps": eps, "R0": R0, "m": bif["m"], "v_bifurcation": bif["v"],
            "rz_n": rz_nodes(eps), "ladder": meshes, "n": n_follow, "rows": out_rows,
            "ended": ended}


def clearances(oblate: Path, folder: Path, n: int, points: int) -> list[float]:
    """Each point's distance to its periodic images in units of ε: L minus the body's
    longest extent along an axis (φ > 0 on the unfolded grid), over ε — the branch's shapes
    stretch, and within a few ε of its image a body feels the box."""
    import numpy as np

    from fem_ade.campaigns.switch_branch import switched_start

    _, be, _ = switched_start(oblate, 0, None, None, n, ORDER, "octant")
    out = []
    for k in range(points):
        with np.load(folder / "points" / f"{k:04d}" / "final.npz") as z:
            be._set(np.array(z["phi"]), None)
        g = be.grid_phi() > 0
        extent = max(int(np.count_nonzero(g.any(axis=tuple(j for j in range(3) if j != i))))
                     for i in range(3)) / g.shape[0]
        out.append(round((1.0 - extent) * be.params.L / be.params.eps, 2))
    return out


def control(root: Path, box_json: Path) -> dict | None:
    """The octant against the box on the same mesh from the same (r, z) branch: the box's
    points of ``branch3d.json`` (case :data:`BOX`, its oblate remade with branch3d's
    arguments), the octant's from there; the largest |Δv| and |Δe| over them. None where
    branch3d.json is not at hand."""
    from fem_ade.campaigns.switch_branch import follow_switched

    name, n, args = BOX
    if not box_json.is_file():
        return None
    box = next(c for c in json.loads(box_json.read_text())["cases"] if c["name"] == name)
    oblate = make_branch(root / f"branch3d-oblate-{name}", args)
    rows = follow_switched(oblate, 0, root / f"branch3d-d2-{name}-n{n}", n=n, order=ORDER,
                           points=len(box["rows"]), stability=True, quiet=True,
                           geometry="octant")
    pairs = list(zip(box["rows"], rows, strict=True))
    return {**_compared(name, n, pairs, "branch3d.json, an earlier session"),
            "box_unstable": [a["unstable_3d"] for a in box["rows"]],
            "octant_unstable": [b["unstable_3d"] for b in rows]}


def _compared(name: str, n: int, pairs: list, timed: str) -> dict:
    """The control's figures over the (box, octant) row pairs: |Δv|, |Δe|, the seconds of
    their Newton solves, and where the box's were timed."""
    box_s, oct_s = (sum(r["newton_s"] for r in side) for side in zip(*pairs, strict=True))
    return {"case": name, "n": n, "points": len(pairs),
            "dv": max(abs(a["v"] - b["v"]) for a, b in pairs),
            "de": max(abs(a["e"] - b["e"]) for a, b in pairs),
            "box_s": box_s, "octant_s": oct_s, "timed": timed}


def quick_box(root: Path, c: dict) -> dict:
    """The quick case's control: the box's first points on the same mesh, beside the
    octant's."""
    from fem_ade.campaigns.switch_branch import follow_switched

    name = c["name"]
    rows = follow_switched(root / f"window-{name}", 0, root / f"box-{name}", points=2,
                           n=c["ladder"][0]["n"], order=ORDER, quiet=True)
    pairs = list(zip(rows, c["ladder"][0]["rows"], strict=False))
    return _compared(name, c["ladder"][0]["n"], pairs, "this run")


def shapes(root: Path, c: dict, out: Path) -> Path:
    """Three of the followed branch's points (its first, middle and last) in one PNG."""
    from fem_ade.campaigns.switch_branch import switched_start

    _, be, _ = switched_start(root / f"window-{c['name']}", 0, None, None, c["n"], ORDER,
                              "octant")
    return three_points(
        be, root / f"d2-{c['name']}-n{c['n']}", c["rows"],
        lambda k, r: (f"{c['name']}, point {k}: v = {r['v']:.4f}, a = "
                      f"{r['amplitude']:.2f}, e = {r['e']:.4f}"),
        out / f"branch3d_octant-shapes-{c['name']}.png", 32, 0.4)  # the repository's 6.2 MB


def figure(result: dict, out: Path, suffix: str) -> Path:
    """Left: each ladder mesh's v against a² (the direction); right: e − e_oblate against v
    of the followed branches."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from fem_ade.plots.figures import save_figure

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.4))
    markers = "osd^v"
    colour = 0
    for c in result["cases"]:
        for m in c["ladder"]:
            a2 = [r["amplitude"] ** 2 for r in m["rows"]]
            line, = ax.plot(a2, [r["v"] - c["v_bifurcation"] for r in m["rows"]],
                            markers[colour % 5] + "-", ms=5, color=f"C{colour}",
                            label=f"{c['name']}, {m['nodes_per_eps']:.2f} nodes per ε")
            colour += 1
            x = np.linspace(0, max(a2), 20)
            ax.plot(x, m["v_c"] + m["c"] * x - c["v_bifurcation"], ":",
                    color=line.get_color(), lw=0.8)
        rows = [r for r in c["rows"] if r["e_oblate"] is not None]
        bx.plot([r["v"] for r in rows], [r["e"] - r["e_oblate"] for r in rows], "s-", ms=3,
                label=f"{c['name']} ({c['n'] * c['eps']:.2f} nodes per ε)")
        bx.axvline(c["v_bifurcation"], color="0.7", lw=0.8, ls=":")
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_xlabel("a² (the mode's amplitude, squared)")
    ax.set_ylabel("v − v_c (the (r, z) block's zero)")
    ax.legend(frameon=False, fontsize=7)
    ax.set_title("below 0: subcritical", fontsize=9)
    bx.set_xlabel("v")
    bx.set_ylabel("e − e_oblate (axisymmetric, the same ε)")
    bx.legend(frameon=False, fontsize=8)
    path = out / f"branch3d_octant{suffix}.png"
    save_figure(fig, path)
    plt.close(fig)
    return path


def _ladder(c: dict) -> list[str]:
    """The report's ladder table of case ``c``: each mesh's fit of v = v_c + c a²."""
    lines = ["**The ladder** (v = v_c + c a² fitted to each mesh's first "
             f"{len(c['ladder'][0]['rows'])} points; c < 0: subcritical):", "",
             "| n | nodes per ε | unknowns | v at the first a | v_c fitted | v_c − (r, z) | c "
             "| fit residual | direction | lowest λ (sector) | Newton s, median |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for m in c["ladder"]:
        secs = sorted(r["newton_s"] for r in m["rows"])
        lam = ", ".join(f"{r['eigenvalues'][0]:.2g}" for r in m["rows"]
                        if r.get("eigenvalues")) or "not computed"
        way = ("subcritical" if m["c"] < 0 else "supercritical") + (
            "" if len(m["rows"]) > 2 else " (2 points: no residual to judge the a² law by)")
        first = m["rows"][0]
        lines.append(f"| {m['n']} | {m['nodes_per_eps']:.2f} | {m['unknowns']} | "
                     f"{first['v']:.6f} (a = {first['amplitude']:.2f}) | {m['v_c']:.6f} | "
                     f"{m['v_c'] - c['v_bifurcation']:+.1e} | {m['c']:+.4f} | "
                     f"{m['residual']:.1e} | {way} | {lam} | {secs[len(secs) // 2]:.1f} |")
    return lines


def report(result: dict, out: Path, suffix: str) -> None:
    lines = ["# The oblate's m = 2 branch in 3D at small ε, on the octant", "",
             "Written by `studies/branch3d_octant.py` (its docstring says what it runs). "
             "Order 8; n nodes per L (the octant holds (n/2 + 1)³); a = the mode's "
             "amplitude; e = (W + G)/W_sphere; λ in units of the bulk Hessian P "
             "(docs/model.md §13), of perturbations even in x, y and z (the octant's "
             "sector: a lower bound on the 3D count); the oblate's and prolate's e at the "
             f"same v interpolated between (r, z) branch points at {RZ_NODES_PER_EPS:g} nodes "
             "per ε.", ""]
    ctl = result.get("control")
    if ctl:
        lines += [f"Control: the octant on {ctl['n']} nodes per L against the box's "
                  f"{ctl['points']} points on the same mesh from the same (r, z) branch "
                  f"({ctl['case']}): max |Δv| = {ctl['dv']:.1e}, max |Δe| = {ctl['de']:.1e}"
                  + ("" if "box_unstable" not in ctl else
                     f"; unstable directions in 3D {ctl['box_unstable']}, in the sector "
                     f"{ctl['octant_unstable']}")
                  + f". Their Newton solves took "
                  f"{ctl['box_s']:.0f} s on the box ({ctl['timed']}) and {ctl['octant_s']:.1f} "
                  f"s on the octant: {ctl['box_s'] / ctl['octant_s']:.0f}× (wall, one "
                  "thread).", ""]
    for c in result["cases"]:
        lines += [f"## {c['name']}, R₀ = {c['R0']:g}", "",
                  f"The (r, z) oblate's block m = {c['m']} crosses zero at v_c = "
                  f"{c['v_bifurcation']:.5f} ({c['rz_n']} nodes per L).", "",
                  *_ladder(c)]
        secs = sorted(r["newton_s"] for r in c["rows"])
        stab = sorted(r["seconds"] - r["newton_s"] for r in c["rows"])
        lines += ["", f"**The branch followed** on {c['n']} nodes per L "
                  f"({c['n'] * c['eps']:.2f} per ε, {(c['n'] // 2 + 1) ** 3} unknowns): "
                  f"{len(c['rows'])} points (where it stopped: {c['ended']}); gap: the "
                  "body's distance to its periodic image along its longest axis. A point's "
                  f"Newton: median {secs[len(secs) // 2]:.1f} s (wall, one thread)"
                  + (f", its sector's stability median {stab[len(stab) // 2]:.1f} s."
                     if c["rows"][0].get("eigenvalues") else "; no stability computed."),
                  "",
                  "| point | v | a | e | e − e_oblate | e − e_prolate | label | symmetry | "
                  "semi-axes | gap/ε | lowest λ (sector) | unstable (sector) | Newton | s |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]

        def diff(x, r):
            return "—" if x is None else f"{r['e'] - x:+.2e}"

        for k, r in enumerate(c["rows"]):
            axes = ", ".join(f"{a:.4f}" for a in r["semi_axes"])
            lam = ", ".join(f"{x:.3g}" for x in (r.get("eigenvalues") or [])[:2]) or "—"
            lines.append(f"| {k} | {r['v']:.5f} | {r['amplitude']:.3f} | {r['e']:.5f} | "
                         f"{diff(r['e_oblate'], r)} | {diff(r['e_prolate'], r)} | "
                         f"{r['label']} | {r.get('symmetry') or '—'} | ({axes}) | "
                         f"{r['gap']:.1f} | {lam} | "
                         f"{'—' if r['unstable_3d'] is None else r['unstable_3d']} | "
                         f"{r['newton']} | {r['seconds']:.0f} |")
        lines.append("")
    lines += [f"![v against a², e against v](branch3d_octant{suffix}.png)"]
    for c in result["cases"]:
        png = f"branch3d_octant-shapes-{c['name']}.png"
        if (out / png).is_file() and not suffix:
            lines += ["", f"![three points of the branch at {c['name']}]({png})"]
    write_report(out, f"branch3d_octant{suffix}", lines)


def main(argv=None) -> dict:
    ap = study_parser(__doc__, OUT, quick="eps = 0.04, R0 = 0.25 on 32 nodes per L: the "
                      "octant's first points against the box's",
                      report_only="rewrite the report and figure from branch3d_octant.json")
    args = ap.parse_args(argv)
    suffix = "_quick" if args.quick else ""
    root = args.out / f"branch3d_octant{suffix}"

    def compute():
        root.mkdir(parents=True, exist_ok=True)
        made = {"cases": [case(root, c) for c in (QUICK_CASES if args.quick else CASES)]}
        if args.quick:
            made["control"] = quick_box(root, made["cases"][0])
        else:
            made["control"] = control(root, args.out / "branch3d.json")
            for c in made["cases"]:
                if len(c["rows"]) >= 3:  # a branch, not its first points
                    shapes(root, c, args.out)
        return made

    result = results(args, "branch3d_octant", compute)
    figure(result, args.out, suffix)
    report(result, args.out, suffix)
    for c in result["cases"]:
        for m in c["ladder"]:
            print(f"{c['name']} on {m['n']} nodes per L: v_c {m['v_c']:.6f} (the (r, z) "
                  f"block's {c['v_bifurcation']:.6f}), c {m['c']:+.4f}", flush=True)
        last = c["rows"][-1]
        print(f"{c['name']}: {len(c['rows'])} points to v = {last['v']:.4f} ({c['ended']})",
              flush=True)
    assert all(math.isfinite(r["e"]) for c in result["cases"] for r in c["rows"])
    return result


if __name__ == "__main__":
    main()
