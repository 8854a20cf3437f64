"""What a branch's rows show (:mod:`fem_ade.campaigns.branch` follows the branch): its folds,
its bifurcations, its shape's topology and sharp branch, where two branches' energies
cross, and its pictures (``branch.png``: e against the parameter, stable solid, unstable
dashed, folds and bifurcations marked; ``shapes.png``: the meridians).

A fold (turning point) is where the tangent's t_p changes sign; its parameter is the
extremum of the quadratic through the three points around it (:func:`mark_folds`). A branch
ends at a topology change (:func:`same_topology`: an oblate opening into a torus, a neck
closing into two vesicles; a genus-0 shape whose label changes — pear to gourd, discocyte to
stomatocyte — goes on).

Why a module of its own: these read rows, the driver's as it goes and a finished branch's
table (:func:`fem_ade.campaigns.branch_folder.read_branch_table`) in the studies, with no
solver and no folder to vouch for.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def mark_folds(rows: list[dict], name: str) -> list[dict]:
    """``fold``: at a point where the parameter turns (its neighbours on the same side), the
    extremum of the quadratic through the three (arclength, parameter) points."""
    for r in rows:
        r["fold"] = ""
    for i in range(1, len(rows) - 1):
        a, b, c = (rows[j][name] for j in (i - 1, i, i + 1))
        if (b - a) * (c - b) < 0:
            s = np.array([rows[j].get("s", j) for j in (i - 1, i, i + 1)], dtype=float)
            q = np.polyfit(s, [a, b, c], 2)
            rows[i]["fold"] = (f"{np.polyval(q, -q[1] / (2 * q[0])):.6g}"
                               if q[0] != 0 else f"{b:.6g}")
    return rows


def bifurcations(rows: list[dict], name: str) -> list[dict]:
    """Where a mode's count of unstable directions changes between two neighbouring points
    (``unstable_modes``, the LU's inertia): a branch point of mode m — m ≥ 1 a
    non-axisymmetric branch is born (in 3D a circle of them, cos mθ and sin mθ), m = 0
    without a fold between the two points an axisymmetric symmetry-breaking one (at a fold
    the m = 0 count changes too: that is the fold, in ``fold``). Located like the folds: the
    zero of the mode's lowest eigenvalue, linear in the arclength, where the count changed
    from 0 or to 0 (else the midpoint, ``located`` False), and the parameter there. The
    count is taken below a threshold (:func:`fem_ade.campaigns.stability.threshold`), so a point
    whose eigenvalue lies between it and 0 moves the change one interval away from the
    zero: the zero is then looked for in the neighbouring interval too (``between``: the
    interval where it is)."""
    out = []
    for i in range(len(rows) - 1):
        a, b = rows[i], rows[i + 1]
        ca, cb = a.get("unstable_modes"), b.get("unstable_modes")
        if not (isinstance(ca, dict) and isinstance(cb, dict)):
            continue
        for key in sorted(set(ca) & set(cb), key=int):
            if ca[key] == cb[key]:
                continue
            m = int(key)
            if m == 0 and (a.get("fold") or b.get("fold")):
                continue
            j, t = i, None
            if min(ca[key], cb[key]) == 0:
                j, t = _zero_near(rows, i, f"lowest_m{m}", rising=ca[key] > cb[key])
            located = t is not None
            t = 0.5 if t is None else t
            ra, rb = rows[j], rows[j + 1]
            sa, sb = float(ra.get("s", j)), float(rb.get("s", j + 1))
            out.append({"m": m, name: float(ra[name] + t * (rb[name] - ra[name])),
                        "s": sa + t * (sb - sa), "between": [j, j + 1],
                        "unstable": [ca[key], cb[key]], "located": bool(located),
                        "kind": f"non-axisymmetric (m = {m})" if m else
                        "axisymmetric symmetry breaking (m = 0, no fold)"})
    return out


def _zero_near(rows: list[dict], i: int, column: str, rising: bool) -> tuple[int, float | None]:
    """(j, t): the zero of ``column`` at the fraction t of rows j … j+1, looked for between
    rows i, i+1 and then in the intervals beside them, crossing upwards (``rising``: the
    count fell) or downwards; (i, None) where none of them holds it."""
    for j in (i, i - 1, i + 1):
        if not 0 <= j < len(rows) - 1:
            continue
        la, lb = rows[j].get(column), rows[j + 1].get(column)
        if la is None or lb is None or la == "" or lb == "":
            continue
        la, lb = float(la), float(lb)
        if (la < 0.0 <= lb) if rising else (lb < 0.0 <= la):
            return j, la / (la - lb)
    return i, None


def branch_of_label(label):
    """The sharp branch a point's shape label stands for
    (:data:`fem_ade.analysis.sharp.BRANCH_OF_LABEL`,
    where a prolate whose waists multiply, gourd → chain, is still the prolate: one body of
    genus 0, two necks, seen at eps/R0 = 0.06-0.12 from v = 0.67 down), or None."""
    from fem_ade.analysis.sharp import BRANCH_OF_LABEL

    return {**BRANCH_OF_LABEL, "chain": "prolate"}.get(label)


def same_topology(first, label) -> bool:
    """Whether a point's shape has its branch's topology: one body of genus 0 (whatever its
    label: a prolate that grows a second waist, a pear whose label flips to gourd, an oblate
    whose dimples deepen into a stomatocyte, a prolate that turns triaxial (``ellipsoid``)
    are each still one branch), a torus, or the same label otherwise (two vesicles,
    nested)."""
    def kind(text):
        if text == "torus":
            return "torus"
        genus0 = branch_of_label(text) in ("prolate", "oblate", "stomatocyte", "pear")
        return "one body of genus 0" if genus0 or text in ("sphere", "ellipsoid") else text

    return kind(first) == kind(label)


def same_branch(first, label) -> bool:
    """Whether a point's label is its branch's: the same sharp branch
    (:func:`branch_of_label`; a label of no branch only equals itself)."""
    return (branch_of_label(first) or first) == (branch_of_label(label) or label)


def draw(out: Path, name: str, rows: list[dict], meridians: list) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem_ade.plots.figures import save_figure

    paths = []
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    x = np.array([r[name] for r in rows])
    e = np.array([r["e"] for r in rows])
    count = "unstable_3d" if any(r.get("unstable_3d") not in (None, "") for r in rows) \
        else "unstable"  # stable in 3D where the azimuthal modes were computed
    stable = np.array([r.get(count) in (0, None, "") for r in rows])  # None: not computed
    for i in range(len(rows) - 1):
        both = stable[i] and stable[i + 1]
        ax.plot(x[i:i + 2], e[i:i + 2], "-" if both else "--", color="tab:blue" if both
                else "tab:red", lw=1.8)
    known = any(r["unstable"] not in (None, "") for r in rows)
    ax.plot(x[stable], e[stable], "o", ms=3, color="tab:blue",
            label=("stable in 3D" if count == "unstable_3d" else "stable (axisymmetric "
                   "perturbations)") if known else "stability not computed")
    ax.plot(x[~stable], e[~stable], "o", ms=3, color="tab:red", label="unstable")
    for r in rows:
        if r.get("fold"):
            ax.plot([float(r["fold"])], [r["e"]], "k*", ms=11)
    for b in bifurcations(rows, name):
        i, j = b["between"]
        t = (b[name] - x[i]) / (x[j] - x[i]) if x[j] != x[i] else 0.5
        eb = e[i] + t * (e[j] - e[i])
        ax.plot([b[name]], [eb], "D", ms=7, mfc="none", mec="tab:green")
        ax.annotate(f"m={b['m']}", (b[name], eb), textcoords="offset points",
                    xytext=(4, 6), fontsize=8, color="tab:green")
    ax.set(xlabel=name, ylabel="e = (W + G) / W_sphere",
           title=f"branch ({rows[0].get('label')} at {name} = {rows[0][name]:.4g}); ★ fold, "
                 "◇ bifurcation (its mode m)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, out / "branch.png", dpi=110, colours=64)
    plt.close(fig)
    paths.append(out / "branch.png")
    if meridians:
        step = max(1, len(meridians) // 10)
        chosen = meridians[::step][:10]
        fig, axes = plt.subplots(1, len(chosen), figsize=(1.6 * len(chosen), 3.0))
        for axis, (value, curves) in zip(np.atleast_1d(axes), chosen, strict=False):
            for pts in curves:
                axis.plot(pts[:, 0], pts[:, 1], "k", lw=1)
                axis.plot(-pts[:, 0], pts[:, 1], "k", lw=1)
            axis.set_aspect("equal")
            axis.set_axis_off()
            axis.set_title(f"{name} = {value:.3g}", fontsize=8)
        fig.tight_layout()
        save_figure(fig, out / "shapes.png", dpi=100, colours=32)
        plt.close(fig)
        paths.append(out / "shapes.png")
    return paths


def crossing(a: list[dict], b: list[dict], name: str) -> float | None:
    """Where two branches' energies cross: the parameter at which e_a = e_b, or None if they
    do not cross where both were followed. Each branch is taken up to its first fold (one e
    per parameter value) and its e interpolated linearly between its points (with points
    Δp ≈ 0.002 apart and e'' ~ 5: ~2e-6 in e); the crossing nearest the branches' start."""
    def up_to_fold(rows):
        out = rows[:2]
        for r in rows[2:]:
            if (r[name] - out[-1][name]) * (out[1][name] - out[0][name]) <= 0:
                break
            out.append(r)
        out = sorted(out, key=lambda r: r[name])
        return np.array([r[name] for r in out]), np.array([r["e"] for r in out])

    if len(a) < 2 or len(b) < 2:
        return None
    (pa, ea), (pb, eb) = up_to_fold(a), up_to_fold(b)
    grid = np.unique(np.concatenate([pa, pb]))
    grid = grid[(grid >= max(pa[0], pb[0])) & (grid <= min(pa[-1], pb[-1]))]
    if a[0][name] > a[1][name]:
        grid = grid[::-1]  # from the start
    d = np.interp(grid, pa, ea) - np.interp(grid, pb, eb)
    for i in range(len(grid) - 1):
        if d[i] == 0.0 or d[i] * d[i + 1] < 0:
            return float(grid[i] - d[i] * (grid[i + 1] - grid[i]) / (d[i + 1] - d[i]))
    return None
