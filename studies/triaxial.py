"""The v = 0.7 window of the ADE plane, where neither the oblate nor the prolate is stable in
m = 2: the triaxial (D2h) branch born at the oblate's m = 2 bifurcation, followed on the
Fourier–(r, z) geometry (issue 44).

``ade_bifurcations.md`` found, at v = 0.7, ε = 0.01 (κ̄/κ = 1.4, R₀ = 0.195, order 8, 400
nodes per L), the oblate unstable in m = 2 beyond Δa₀ = 1.0859 and the prolate unstable in
m = 2 below 1.0957: between them no axisymmetric shape is stable. The octant at its default
1.92 nodes per ε does not see this window (its mesh makes the two bistable,
``ade_octant_notes.md``), and at 2.56 per ε one point took over 19 min of CPU.

- **The lines** (the (r, z) FEM, the sweep's mesh): the oblate and the prolate from Δa₀ =
  1.08 to 1.10 (step 0.01, blocks m ≤ 2).
- **The branch**: from the oblate's last point, along its m = 2 eigenvector ψ, on the
  Fourier–(r, z) geometry with fold m₀ = 2 (cosines of 2jθ: the mirror planes x = 0, y = 0)
  and its amplitude a as the parameter (:mod:`fem_ade.campaigns.fourier_branch`): at each
  a the Δa₀ where the pinned state is steady, n_θ doubled until the highest cosine is below
  1e-3 of the first. **Then Δa₀ held** (``HELD``), the amplitude free (natural
  continuation, Newton with its line search: the branch's stable part), where the
  amplitude's first cosine saturates and Δa₀(a) steepens.
- **Beside it**: the (r, z) oblate and prolate made steady at each point's Δa₀ (Newton from
  the lines' nearest point), their e against the branch's.

**Hypothesis**: a triaxial branch joins the oblate's m = 2 end to the prolate's, inside the
window, and lies below both there: the window's lowest shape is a triaxial ellipsoid.
**Control**: the branch's Δa₀ as a → 0 is the oblate's bifurcation as the (r, z) blocks
locate it, and its e there is the oblate's.

    python studies/triaxial.py --out studies/results   # hours on one core (the notes)
    python studies/triaxial.py --quick                 # the ε = 0.04 oblate, ~17 s
"""

from __future__ import annotations

from _lib.cli import one_thread, results, study_parser, write_report

one_thread()

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from _lib.branches import branch_rows, make_branch  # noqa: E402

OUT = Path("runs") / "studies"
V, KBAR, R0, EPS, N = 0.7, 1.4, 0.195, 0.01, 400
#: the lines: (branch, Δa₀ from, to, step)
LINES = (("oblate", 1.08, 1.10, 0.01), ("prolate", 1.08, 1.10, 0.01))
#: the branch's amplitudes (max |ψ| = 1; φ's range is 2); 1.3, 1.6, 1.9 on n_θ = 16 (on 8,
#: 1.3's top cosine was 3.2e-3 of the first)
AMPLITUDES = (0.05, 0.1, 0.2, 0.4, 0.7, 1.0, 1.3, 1.6, 1.9)
#: then Δa₀ held, the amplitude free (natural continuation: the first cosine saturates, 0.85 …
#: 1.20 at a = 1.0 … 1.9, while Δa₀ rises ever faster)
HELD = (1.103, 1.107, 1.112)
#: the branch born at the prolate's m = 2 bifurcation (the window's other end), in the
#: prolate's own frame: its first amplitudes
PROLATE_AMPLITUDES = (0.05, 0.1, 0.2, 0.4)
#: the points whose stability in the sector (the fields with the mirror planes x = 0, y = 0:
#: cos 2jθ) is computed (their amplitudes), and the eigenvalues nearest SIGMA found
STABILITY, SIGMA, K_LOWEST = (0.05, 1.0), -2e-6, 3
#: the quick mode: the oblate at ε = 0.04, v = 0.85, R₀ = 0.25 (unstable in m = 2), two
#: amplitudes, in v
QUICK = {"v": 0.85, "eps": 0.04, "R0": 0.25, "amplitudes": (0.1, 0.2)}


def _line(root: Path, branch: str, start: float, stop: float, step: float) -> dict:
    made = make_branch(root / f"{branch}-v={V:g}-eps={EPS:g}",
                       ["vesicle", "--branch", branch, "--v", str(V), "--kbar", str(KBAR),
                        "--eps", str(EPS), "--R0", str(R0), "--n", str(N), "--param", "da0",
                        "--from", str(start), "--to", str(stop), "--step", str(step),
                        "--modes", "2"])
    if isinstance(made, str):
        return {"branch": branch, "failed": made}
    rows = [{"da0": float(r["da0"]), "e": float(r["e"]),
             "lowest_m2": float(r["lowest_m2"])} for r in branch_rows(made)]
    bif = made / "bifurcations.json"
    found = json.loads(bif.read_text())["bifurcations"] if bif.is_file() else []
    return {"branch": branch, "failed": None, "folder": str(made), "rows": rows,
            "bifurcations": [b for b in found if b["m"] == 2]}


def _quick_line(root: Path) -> dict:
    q = QUICK
    made = make_branch(root / "oblate-quick",
                       ["vesicle", "--branch", "oblate", "--eps", str(q["eps"]), "--R0",
                        str(q["R0"]), "--param", "v", "--from", str(q["v"]), "--to",
                        str(q["v"] - 0.01), "--step", "0.01", "--modes", "2"])
    if isinstance(made, str):
        return {"branch": "oblate", "failed": made}
    rows = [{"v": float(r["v"]), "e": float(r["e"]), "lowest_m2": float(r["lowest_m2"])}
            for r in branch_rows(made)]
    return {"branch": "oblate", "failed": None, "folder": str(made), "rows": rows,
            "bifurcations": []}


def axisymmetric_e(folder: Path, param: str, value: float) -> float | None:
    """e of the (r, z) state of the branch ``folder`` made steady at ``param`` = ``value``
    from the branch's nearest point (None if Newton does not converge)."""
    from fem_ade.analysis.sharp import reduced_energy
    from fem_ade.backends.fem.newton import solve_steady
    from fem_ade.campaigns.stability import load_state
    from fem_ade.scenes.vesicle import set_parameter

    near = min(branch_rows(folder), key=lambda r: abs(float(r[param]) - value))
    be, _ = load_state(folder / "points" / f"{int(near['point']):04d}")  # that one only
    be.stepper.params = be.params = set_parameter(be.stepper.params, param, value)
    res = solve_steady(be)
    if not res.converged:
        return None
    return reduced_energy(be.diagnostics(), be.params.kappa)


def run_branch(root: Path, line: dict, param: str, amplitudes,
               name: str = "branch", held=()) -> list[dict]:
    """The m = 2 branch from the line's last point (:func:`fem_ade.campaigns.fourier_branch.
    follow`), born where the line's blocks located it (else at the point), kept in
    ``root/name``."""
    from fem_ade.backends.fem.modes import lowest_mode
    from fem_ade.backends.fem.newton import NewtonSystem, linearize
    from fem_ade.campaigns.fourier_branch import follow
    from fem_ade.campaigns.stability import load_state

    folder = Path(line["folder"])
    be, _ = load_state(sorted((folder / "points").iterdir())[-1])
    sys_ = NewtonSystem(be)
    _, psi = lowest_mode(sys_, linearize(sys_, be.phi), 2)
    birth = line["bifurcations"][0][param] if line["bifurcations"] else None
    return follow(be, psi, amplitudes, root / name, m0=2, param=param, p_birth=birth,
                  quiet=False, held=held)


def sector_lowest(root: Path, line: dict, k: int, row: dict, param: str,
                  name: str = "branch") -> list[float]:
    """The K_LOWEST eigenvalues nearest SIGMA of branch point ``k`` in its sector
    (:func:`fem_ade.backends.fem.fourier.lowest`), from its cosines on the line's mesh."""
    import numpy as np

    from fem_ade.backends.fem.fourier import FourierState, lowest
    from fem_ade.campaigns.stability import load_state

    kept = root / name / f"{k:04d}.lowest.json"  # kept: 650 s at n_θ = 4
    if kept.is_file():
        return json.loads(kept.read_text())
    be, _ = load_state(sorted((Path(line["folder"]) / "points").iterdir())[-1])
    with np.load(root / name / f"{k:04d}.npz") as z:
        A = np.array(z["cosines"])
    st = FourierState.of(be, 2, A.shape[0])
    st.phi = st.space.from_modes({j: A[j] for j in range(A.shape[0])})
    st.set_parameter(param, row[param])
    found = [float(x) for x in lowest(st, k=K_LOWEST, sigma=SIGMA)]
    kept.write_text(json.dumps(found))
    return found


def compute(root: Path, quick: bool) -> dict:
    root.mkdir(parents=True, exist_ok=True)
    if quick:
        line = _quick_line(root)
        lines = [line]
        param, amplitudes = "v", QUICK["amplitudes"]
    else:
        lines = [_line(root, *x) for x in LINES]
        line, param, amplitudes = lines[0], "da0", AMPLITUDES
    if line["failed"]:
        return {"lines": lines, "points": []}
    points = run_branch(root, line, param, amplitudes, held=() if quick else HELD)
    for k, x in enumerate(points):
        if not quick and x["amplitude"] in STABILITY:
            x["lowest"] = sector_lowest(root, line, k, x, param)
    other_end = [] if quick or lines[1]["failed"] else run_branch(
        root, lines[1], param, PROLATE_AMPLITUDES, name="branch-prolate")
    for k, x in enumerate(other_end):
        if x["amplitude"] in STABILITY:
            x["lowest"] = sector_lowest(root, lines[1], k, x, param, "branch-prolate")
    for x in points + other_end:
        for other in lines:
            if not other["failed"]:
                x[f"e_{other['branch']}"] = axisymmetric_e(Path(other["folder"]), param,
                                                           x[param])
    return {"param": param, "lines": lines, "points": points, "prolate_points": other_end}


def _sections(root: Path, line: dict, k: int):
    """The k-th point's φ on the plane z = z_c, (x, y, φ), and in the meridian planes θ = 0
    and θ = π/2, ((r, z, φ) each): from its cosines on the line's (r, z) mesh."""
    import numpy as np

    from fem_ade.campaigns.stability import load_state

    be, _ = load_state(sorted((Path(line["folder"]) / "points").iterdir())[-1])
    with np.load(root / "branch" / f"{k:04d}.npz") as z:
        A = np.array(z["cosines"])
    space = be.space
    r, zz = space.doflocs
    w = space.weights * (be.phi + 1.0)
    zc = float(np.sum(w * zz) / np.sum(w))
    ar, az = space.axes
    rs = np.linspace(0.0, ar.nodes[-1], 400)
    zs = np.linspace(az.nodes[0], az.nodes[-1], 400)
    at_zc = space.interpolate_to([rs, np.array([zc])])
    radial = np.array([at_zc(a)[:, 0] for a in A])  # a_j(r, z_c)
    x = np.linspace(-rs[-1], rs[-1], 401)
    X, Y = np.meshgrid(x, x, indexing="ij")
    R, T = np.hypot(X, Y), np.arctan2(Y, X)
    j = np.arange(A.shape[0])
    cos = np.cos(2 * j[:, None, None] * T[None])
    plane = sum(np.interp(R, rs, radial[i]) * cos[i] for i in j)
    plane[R > rs[-1]] = np.nan  # beyond the (r, z) domain
    grid = space.interpolate_to([rs, zs])
    meridians = [sum(grid(A[i]) * s ** i for i in j) for s in (1.0, -1.0)]
    return (X, Y, plane), (rs, zs - zc, meridians)


def figure(result: dict, root: Path, out: Path) -> Path:
    """triaxial.png: Δa₀ against the amplitude; e less that of the branch each was born from,
    against the amplitude; the z = z_c section and the meridians θ = 0, π/2 of three points
    of the oblate's branch; e less the oblate's against Δa₀ (:func:`_against_oblate`)."""
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts, param = result["points"], result["param"]
    line = result["lines"][0]
    fig, ax = plt.subplots(1, 5, figsize=(21, 4.2))
    a = [x["amplitude"] for x in pts]
    ax[0].plot(a, [x[param] for x in pts], "s-", color="C3", label="from the oblate")
    other = result.get("prolate_points") or []
    if other:
        ax[0].plot([x["amplitude"] for x in other], [x[param] for x in other], "^-",
                   color="C1", label="from the prolate (its frame)")
    for ln, color in zip(result["lines"], ("C0", "C2"), strict=False):
        for b in ln.get("bifurcations", []):
            ax[0].axhline(b[param], color=color, ls="--",
                          label=f"{ln['branch']}: m = 2 bifurcation")
    ax[0].set(xlabel="amplitude a (max |ψ| = 1)", ylabel="Δa₀")
    ax[0].legend(fontsize=8)
    for rows, parent, color, marker in ((pts, "oblate", "C3", "s-"),
                                        (other, "prolate", "C1", "^-")):
        xs = [(x["amplitude"], x["e"] - x[f"e_{parent}"]) for x in rows
              if x.get(f"e_{parent}") is not None]
        if xs:
            ax[1].plot(*zip(*xs, strict=True), marker, color=color, ms=4,
                       label=f"from the {parent}: e − e_{parent}")
    ax[1].axhline(0.0, color="0.5", lw=1)
    ax[1].set_yscale("symlog", linthresh=1e-10)
    ax[1].set(xlabel="amplitude a", ylabel="e less the parent's at the same Δa₀")
    ax[1].legend(fontsize=8, loc="center right")
    _against_oblate(ax[4], pts, other, param, result["lines"])
    shown = sorted({0, len(pts) // 2, len(pts) - 1})
    sizes = []
    for k, color in zip(shown, ("C0", "C1", "C3"), strict=False):
        (X, Y, plane), (rs, zs, mer) = _sections(root, line, k)
        inside = np.nan_to_num(plane, nan=-1.0) > 0
        sizes.append({"extent": float(np.max(np.hypot(X, Y)[inside]))})
        ax[2].contour(X, Y, plane, [0.0], colors=color)
        for m, ls in zip(mer, ("-", "--"), strict=True):
            ax[3].contour(rs, zs, m.T, [0.0], colors=color, linestyles=ls)
            ax[3].contour(-rs, zs, m.T, [0.0], colors=color, linestyles=ls)
        ax[2].plot([], [], color=color, label=f"a = {pts[k]['amplitude']:g}")
    size = 1.15 * max(x["extent"] for x in sizes)
    ax[2].set(aspect="equal", title="z = z_c (equator)", xlabel="x", ylabel="y",
              xlim=(-size, size), ylim=(-size, size))
    ax[3].set(xlim=(-size, size), ylim=(-0.6 * size, 0.6 * size))
    ax[2].legend(fontsize=8)
    ax[3].set(aspect="equal", title="meridians: θ = 0 (solid), π/2 (dashed)",
              xlabel="r", ylabel="z − z_c")
    fig.tight_layout()
    path = out / "triaxial.png"
    fig.savefig(path, dpi=64)
    plt.close(fig)
    return path


def _against_oblate(ax, pts, other, param, lines) -> None:
    """e less the (r, z) oblate's at the same parameter, against it: both branches and the
    prolate (where the two branches meet, if they are one, their curves join)."""
    for rows, label, marker, color in ((pts, "from the oblate", "s-", "C3"),
                                       (other, "from the prolate", "^-", "C1")):
        xs = sorted((x[param], x["e"] - x["e_oblate"]) for x in rows
                    if x.get("e_oblate") is not None)
        if xs:
            ax.plot(*zip(*xs, strict=True), marker, color=color, ms=4, label=label)
    xs = sorted({(x[param], x["e_prolate"] - x["e_oblate"]) for x in pts + other
                 if x.get("e_oblate") is not None and x.get("e_prolate") is not None})
    if xs:
        ax.plot(*zip(*xs, strict=True), "o:", color="C2", ms=3, label="the prolate")
    for ln, color in zip(lines, ("C0", "C2"), strict=False):
        for b in ln.get("bifurcations", []):
            ax.axvline(b[param], color=color, ls="--", lw=1)
    ax.axhline(0.0, color="C0", lw=1, label="the oblate")
    ax.set(xlabel=param, ylabel="e − e_oblate (the (r, z) oblate at the same Δa₀)")
    ax.legend(fontsize=8)


def _fmt(x, spec: str) -> str:
    return "–" if x is None else format(x, spec)


def birth(pts: list[dict], param: str) -> tuple[float, float] | None:
    """(p_b, c) of p = p_b + c a² through the branch's two smallest amplitudes (two points,
    two unknowns: no residual), the branch's birth by its pitchfork's law; None with fewer
    points."""
    if len(pts) < 2:
        return None
    (a1, p1), (a2, p2) = sorted((x["amplitude"], x[param]) for x in pts)[:2]
    c = (p2 - p1) / (a2**2 - a1**2)
    return p1 - c * a1**2, c


def _birth_line(pts: list[dict], param: str, located: list[dict]) -> list[str]:
    found = birth(pts, param)
    if found is None:
        return []
    where = ", ".join(f"{b[param]:.7f}" for b in located) or "none"
    side = "up" if found[1] > 0 else "down"
    return ["", f"The birth, by p = p_b + c a² through the two smallest amplitudes (2 points, "
            f"exact fit): {param} = {found[0]:.7f}, c = {found[1]:.3e} (the branch goes "
            f"{side} in {param}); the (r, z) blocks located it at {where}."]


def _crossing(pts: list[dict], param: str, lines: list[dict]) -> list[str]:
    """Where the oblate's branch passes the prolate's m = 2 bifurcation, between two
    computed points (a linear interpolation in a), or that it has not yet."""
    far = [b[param] for ln in lines[1:] for b in ln.get("bifurcations", [])]
    if not far or not pts:
        return []
    x_p, near = far[0], [b[param] for b in lines[0].get("bifurcations", [])]
    rows = sorted((x["amplitude"], x[param]) for x in pts)
    done = f" ({100 * (rows[-1][1] - near[0]) / (x_p - near[0]):.0f} % of the window)" \
        if near else ""
    for (a0, p0), (a1, p1) in zip(rows, rows[1:], strict=False):
        if p0 < x_p <= p1:
            a = a0 + (a1 - a0) * (x_p - p0) / (p1 - p0)
            return ["", f"It passes the prolate's bifurcation ({param} = {x_p:.7f}) between "
                    f"a = {a0:g} and {a1:g} (a ≈ {a:.2f}, linear between the two): it spans "
                    "the window, computed."]
    return ["", f"It has not reached the prolate's bifurcation ({param} = {x_p:.7f}) at its "
            f"last point, a = {rows[-1][0]:g}, {param} = {rows[-1][1]:.7f}{done}."]


def _stability(pts: list[dict]) -> list[str]:
    stab = [x for x in pts if "lowest" in x]
    if not stab:
        return []
    return ["", "Its stability in the sector (the fields with the mirror planes x = 0, y = 0), "
            f"the {K_LOWEST} eigenvalues of H v = λ P v nearest {SIGMA:g}:", "",
            *[f"- a = {x['amplitude']:g}: " + ", ".join(f"{v:.3g}" for v in x["lowest"])
              for x in stab]]


def _branch_table(pts: list[dict], param: str) -> list[str]:
    rows = [f"| a | {param} | e | e − e_oblate | e − e_prolate | n_θ | cosines j = 1, 2, 3 "
            f"| {param} by | solves | s |", "|---|---|---|---|---|---|---|---|---|---|"]
    for x in pts:
        eo, ep = x.get("e_oblate"), x.get("e_prolate")
        c = x["cosines"] + [0.0] * 4
        rows.append(
            f"| {x['amplitude']:g} | {x[param]:.7f} | {x['e']:.7f} | "
            f"{_fmt(None if eo is None else x['e'] - eo, '.2e')} | "
            f"{_fmt(None if ep is None else x['e'] - ep, '.2e')} | {x['n_theta']} | "
            f"{c[1]:.3g}, {c[2]:.3g}, {c[3]:.3g} | {x.get('method', 'secant')} | "
            f"{x['solves']} | {x['seconds']:.0f} |")
    return rows


def report(result: dict, out: Path, suffix: str) -> None:
    """triaxial.md: the lines' bifurcations, the branch's table, what it shows."""
    pts, param = result["points"], result.get("param", "da0")
    lines = ["# The triaxial branch of the v = 0.7 window (Fourier–(r, z))", "",
             "Made by `python studies/triaxial.py` (issue 44); the method and the "
             "hypothesis: its docstring. e = (W + G)/W_sphere.", "", "## The (r, z) lines", ""]
    for ln in result["lines"]:
        if ln["failed"]:
            lines.append(f"- {ln['branch']}: failed: {ln['failed']}")
            continue
        bif = ", ".join(f"{param} = {b[param]:.5f}" for b in ln["bifurcations"]) or "none"
        lines.append(f"- {ln['branch']}: {len(ln['rows'])} points; m = 2 bifurcation: {bif}")
    lines += ["", "## The branch born at the oblate's m = 2 bifurcation", ""]
    lines += _branch_table(pts, param)
    lines += _birth_line(pts, param, result["lines"][0].get("bifurcations", []))
    lines += _crossing(pts, param, result["lines"])
    lines += _stability(pts)
    if result.get("prolate_points"):
        lines += ["", "## The branch born at the prolate's m = 2 bifurcation", "",
                  "In the prolate's frame (its axis the long one), along its own m = 2 "
                  "eigenvector.", ""]
        lines += _branch_table(result["prolate_points"], param)
        lines += _birth_line(result["prolate_points"], param,
                             result["lines"][1].get("bifurcations", []))
        lines += _stability(result["prolate_points"])
    if not suffix and pts:
        lines += ["", "![the branch](triaxial.png)"]
    write_report(out, f"triaxial{suffix}", lines)


def main(argv=None) -> dict:
    ap = study_parser(__doc__, OUT, quick="the oblate at eps = 0.04, two amplitudes in v",
                      report_only="rewrite the report from triaxial.json")
    args = ap.parse_args(argv)
    suffix = "_quick" if args.quick else ""
    root = args.out / f"triaxial{suffix}"
    result = results(args, "triaxial", lambda: compute(root, args.quick))
    if not args.report_only and not args.quick and result["points"]:
        figure(result, root, args.out)
    report(result, args.out, suffix)
    return result


if __name__ == "__main__":
    main()
