"""Are starfish born on the discocyte? Its azimuthal modes m = 2 … 6 along Δa₀ at low v
(κ̄/κ = 1.4), where each unstable mode lives, and where the m = 3 instability leads in 3D
(issue 44: the paper's starfish).

Starfish vesicles (Wintz, Döbereiner & Seifert 1996) are flat shapes with m arms; one
expects them to branch off the discocyte where its rim turns unstable to m-fold
undulations as Δa₀ grows. The azimuthal blocks of the (r, z) geometry (``fem_ade.branch
--modes``) give the discocyte's instabilities exactly:

- **Lines.** The discocyte followed in Δa₀ from 1.0 (``--branch oblate``, R₀ = 0.2) at
  v = 0.5 and 0.7, at ε = 0.02 and 0.01, with blocks m ≤ 6 at each point. A window of an m
  is the range of Δa₀ where block m is unstable; its lower end is where an m-armed branch is
  born (bifurcations.json).
- **Where it leads.** From the v = 0.5 lines (ε = 0.02 and 0.01), at the point where block
  m = 3 is most unstable, the 3D flow from φ + 0.1 ψ₃ cos 3(θ − π/12) (``fem_ade.switch
  --point I --mode 3``, 64³ and 128³ nodes of order 4). Its end: label, genus, arms,
  symmetry, and e beside the discocyte's.

Hypothesis: the m-fold windows open one after another as Δa₀ grows (m = 2, 3, 4, …), the
unstable modes are undulations of the rim (max |ψ_m| at the rim), and the m = 3 instability
leads to a 3-armed starfish. Control: where each mode lives (``mode_site``) and how far
apart the body's two membranes are there, in units of ε — the phase field joins membranes
closer than a few ε.

Writes ``OUT/starfish.md`` (with the hand-written ``OUT/starfish_notes.md``), ``.json`` and
``starfish.png`` (each line's lowest eigenvalue per block against Δa₀); the full run also
``starfish-switch-eps=E.png`` (the 3D ends). The branch and run folders go in ``OUT/starfish/``
(not committed).

    python studies/starfish.py --out studies/results     # ~1.5 h on one core
    python studies/starfish.py --quick                   # one short line at ε = 0.02, ~1 min
"""

from __future__ import annotations

from _lib.cli import one_thread, results, study_parser, write_report

one_thread(fft=False)

import json  # noqa: E402
import shutil  # noqa: E402
from pathlib import Path  # noqa: E402

from _lib.branches import branch_rows, make_branch  # noqa: E402

OUT = Path("runs") / "studies"
KBAR, R0, MODES = 1.4, 0.2, 6
#: the lines: (v, ε, Δa₀ from, to, step)
LINES = ((0.5, 0.02, 1.0, 1.8, 0.05), (0.5, 0.01, 1.0, 1.8, 0.05),
         (0.7, 0.02, 1.0, 1.8, 0.05), (0.7, 0.01, 1.0, 1.8, 0.05))
QUICK_LINES = ((0.5, 0.02, 1.35, 1.46, 0.05),)
#: a mode whose max |ψ_m| lies beyond this fraction of the rim's r is the rim's (its
#: "thickness" there is the edge's, not two membranes' distance)
RIM = 0.9
#: the switches: (the line's v and ε, the mode); 64³ and 128³ nodes of order 4 (1.28 per ε)
SWITCHES = ((0.5, 0.02, 3), (0.5, 0.01, 3))


def _name(v: float, eps: float) -> str:
    return f"discocyte-v={v:g}-eps={eps:g}"


def line(root: Path, v: float, eps: float, start: float, stop: float, step: float) -> dict:
    """One line: its points' blocks and its windows (ModelError's line where the seed is no
    discocyte)."""
    made = make_branch(root / _name(v, eps),
                       ["vesicle", "--branch", "oblate", "--v", str(v), "--kbar", str(KBAR),
                        "--eps", str(eps), "--R0", str(R0), "--param", "da0", "--from",
                        str(start), "--to", str(stop), "--step", str(step), "--modes",
                        str(MODES)])
    out = {"v": v, "eps": eps}
    if isinstance(made, str):
        return {**out, "failed": made}
    rows = branch_rows(made)
    bifs = json.loads((made / "bifurcations.json").read_text())["bifurcations"]
    ended = json.loads((made / "ended.json").read_text())["why"]
    sites = {}
    for m in range(2, MODES + 1):
        k = min(range(len(rows)), key=lambda i: float(rows[i][f"lowest_m{m}"]))
        if float(rows[k][f"lowest_m{m}"]) < 0:
            sites[str(m)] = {"point": k, "da0": float(rows[k]["da0"]),
                             **mode_site(made / "points" / f"{k:04d}", m)}
    return {**out, "failed": None, "ended": ended, "sites": sites,
            "points": [{"da0": float(r["da0"]), "e": float(r["e"]), "label": r["label"],
                        "lowest": [float(r[f"lowest_m{m}"]) for m in range(MODES + 1)],
                        "unstable_3d": int(r["unstable_3d"])} for r in rows],
            "bifurcations": [{"m": b["m"], "da0": b["da0"], "opens": b["unstable"][1] >
                              b["unstable"][0]} for b in bifs]}


def mode_site(point: Path, m: int) -> dict:
    """Where block m's softest mode ψ_m lives on a branch point: its eigenvalue, the (r, z)
    node of max |ψ_m|, r there over the body's largest r (the rim: 1), and the body's
    thickness along z there (the distance between its two membranes), in units of ε."""
    import numpy as np

    from fem_ade.campaigns.switch import start_fields

    params, f, lam = start_fields(point, m, 1.0, grid=8)
    r, z = f["points"]
    i = int(np.argmax(np.abs(f["azimuthal_psi"])))
    inside = f["phi"] > 0
    column = inside & (np.abs(r - r[i]) < 1e-12)
    gap = float(z[column].max() - z[column].min()) if column.any() else 0.0
    return {"eigenvalue": float(lam), "r": float(r[i]), "r_over_rim": float(r[i] /
                                                                              r[inside].max()),
            "thickness_eps": gap / params.eps}


def windows(result_line: dict) -> dict[int, list[tuple[float | None, float | None]]]:
    """Per m ≥ 1: the ranges of Δa₀ where block m is unstable (None: the line's end)."""
    found: dict[int, list] = {}
    for b in sorted(result_line["bifurcations"], key=lambda b: b["da0"]):
        if b["m"] < 1:
            continue
        spans = found.setdefault(b["m"], [])
        if b["opens"]:
            spans.append([b["da0"], None])
        elif spans and spans[-1][1] is None:
            spans[-1][1] = b["da0"]
        else:
            spans.append([None, b["da0"]])
    return {m: [tuple(s) for s in spans] for m, spans in sorted(found.items())}


def switch_case(root: Path, lines: list[dict], out: Path, v: float, eps: float,
                m: int) -> dict | None:
    """The 3D flow from the line (v, ε)'s point most unstable in block m."""
    from fem_ade.analysis.shape import symmetry_group
    from fem_ade.analysis.sharp import reduced_energy
    from fem_ade.campaigns.switch import switch

    chosen = next((x for x in lines if (x["v"], x["eps"]) == (v, eps) and not x["failed"]),
                  None)
    if chosen is None:
        return None
    k = min(range(len(chosen["points"])), key=lambda i: chosen["points"][i]["lowest"][m])
    point = chosen["points"][k]
    if point["lowest"][m] >= 0:
        return None
    run = root / (f"switched-m{m}" if eps == 0.02 else f"switched-m{m}-eps={eps:g}")
    if not (run / "summary.json").is_file():
        switch(root / _name(v, eps), None, run, point=k, mode=m, quiet=True)
    s = json.loads((run / "summary.json").read_text())
    picture = f"starfish-switch-eps={eps:g}.png"
    if (run / "shape.png").is_file():
        from fem_ade.plots.figures import compact_png

        shutil.copy(run / "shape.png", out / picture)
        compact_png(out / picture, 64, scale=0.6)  # the repository's 6 MB
    shape = s["shape"]
    body = shape.get("body") or {}
    return {"v": v, "eps": eps, "m": m, "point": k, "da0": point["da0"],
            "eigenvalue": point["lowest"][m], "discocyte_e": point["e"],
            "status": s["status"], "steps": s["steps"], "label": shape["label"],
            "genus": shape["genus"], "arms": shape["arms"],
            "symmetry": symmetry_group(shape),
            "semi_axes": body.get("semi_axes"), "e": reduced_energy(s["final"]),
            "cpu_s": round(s["cpu_s"], 1), "n": s.get("backend_info", {}).get("n"),
            "picture": picture}


def figure(result: dict, out: Path, suffix: str) -> Path:
    """Each line's lowest eigenvalue per block m ≥ 2, over (ε/R₀)⁴, against Δa₀."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem_ade.plots.figures import save_figure

    made = [x for x in result["lines"] if not x["failed"]]
    fig, axes = plt.subplots(1, len(made), figsize=(4.2 * len(made), 3.8), squeeze=False)
    for ax, x in zip(axes[0], made, strict=True):
        scale = (x["eps"] / R0) ** 4
        da0 = [p["da0"] for p in x["points"]]
        for m in range(2, MODES + 1):
            ax.plot(da0, [p["lowest"][m] / scale for p in x["points"]], ".-", label=f"m = {m}")
        ax.axhline(0, color="0.6", lw=0.8)
        ax.set_title(f"v = {x['v']:g}, ε = {x['eps']:g}", fontsize=9)
        ax.set_xlabel("Δa₀")
        ax.set_ylim(-60, 60)
    axes[0][0].set_ylabel("lowest eigenvalue of block m / (ε/R₀)⁴")
    axes[0][-1].legend(frameon=False, fontsize=7)
    path = out / f"starfish{suffix}.png"
    save_figure(fig, path)
    plt.close(fig)
    return path


def report(result: dict, out: Path, suffix: str) -> None:
    lines = ["# Are starfish born on the discocyte? Its azimuthal modes along Δa₀", "",
             "Written by `studies/starfish.py` (its docstring says what it runs). κ̄/κ = 1.4, "
             f"R₀ = {R0:g}, the (r, z) FEM at order 8, 2.5 nodes per ε; a window: the Δa₀ "
             "where the discocyte's block m is unstable (… : to the line's end).", "",
             "| v | ε | the line's end | " + " | ".join(f"m = {m}" for m in range(2, MODES + 1))
             + " |", "|---|---|---|" + "---|" * (MODES - 1)]
    for x in result["lines"]:
        if x["failed"]:
            lines.append(f"| {x['v']:g} | {x['eps']:g} | {x['failed']} |"
                         + " |" * (MODES - 1))
            continue
        w = windows(x)
        last = x["points"][-1]["da0"]

        def span(s):
            lo = "…" if s[0] is None else f"{s[0]:.3f}"
            hi = "…" if s[1] is None else f"{s[1]:.3f}"
            return f"{lo}–{hi}"

        cells = [", ".join(span(s) for s in w.get(m, [])) or "stable" for m in
                 range(2, MODES + 1)]
        lines.append(f"| {x['v']:g} | {x['eps']:g} | Δa₀ = {last:.3f} "
                     f"({x['points'][-1]['label']}) | " + " | ".join(cells) + " |")
    lines += ["", "Where each block's softest mode lives, at the line's point where that block is "
              "most unstable: r of max |ψ_m| over the rim's r, and the body's thickness there "
              "(its two membranes' distance) in units of ε; at the rim (r/r_rim > "
              f"{RIM:g}) none.", "",
              "| v | ε | m | Δa₀ | λ | r/r_rim | thickness/ε |", "|---|---|---|---|---|---|---|"]
    for x in result["lines"]:
        for m, site in (x.get("sites") or {}).items():
            at_rim = site["r_over_rim"] > RIM
            lines.append(f"| {x['v']:g} | {x['eps']:g} | {m} | {site['da0']:.4f} | "
                         f"{site['eigenvalue']:.3g} | {site['r_over_rim']:.2f} | "
                         + ("— (the rim)" if at_rim else f"{site['thickness_eps']:.1f}")
                         + " |")
    for s in result.get("switches") or []:
        axes = ", ".join(f"{a:.4f}" for a in s["semi_axes"] or [])
        genus = ", ".join(str(g) for g in s["genus"])
        lines += ["", f"**Where m = {s['m']} leads** (v = {s['v']:g}, ε = {s['eps']:g}, from "
                  f"point {s['point']}, Δa₀ = {s['da0']:.4f}, block m = {s['m']} at "
                  f"{s['eigenvalue']:.3g}; 1.28 nodes per ε, order 4): {s['status']} after "
                  f"{s['steps']} steps ({s['cpu_s']:.0f} s CPU) — {s['label']}, genus "
                  f"{genus}, arms {s['arms']}, symmetry {s['symmetry']}, semi-axes "
                  f"({axes}); e = {s['e']:.4f} against the discocyte's {s['discocyte_e']:.4f}."]
    lines += ["", f"![the blocks' lowest eigenvalues along the lines](starfish{suffix}.png)"]
    for s in result.get("switches") or []:
        if not suffix and (out / s["picture"]).is_file():
            lines += ["", f"![where m = {s['m']} leads in 3D at ε = {s['eps']:g}]"
                      f"({s['picture']})"]
    write_report(out, f"starfish{suffix}", lines)


def main(argv=None) -> dict:
    ap = study_parser(__doc__, OUT, quick="one short line at ε = 0.02, no 3D run",
                      report_only="rewrite the report and figure from starfish.json")
    args = ap.parse_args(argv)
    suffix = "_quick" if args.quick else ""
    root = args.out / f"starfish{suffix}"

    def compute():
        root.mkdir(parents=True, exist_ok=True)
        made = [line(root, *x) for x in (QUICK_LINES if args.quick else LINES)]
        switches = [] if args.quick else [switch_case(root, made, args.out, *c)
                                          for c in SWITCHES]
        return {"lines": made, "switches": [c for c in switches if c is not None]}

    result = results(args, "starfish", compute)
    figure(result, args.out, suffix)
    report(result, args.out, suffix)
    for x in result["lines"]:
        where = x["failed"] or ", ".join(f"m = {m}: {w}" for m, w in windows(x).items())
        print(f"v = {x['v']:g}, eps = {x['eps']:g}: {where}", flush=True)
    return result


if __name__ == "__main__":
    main()
