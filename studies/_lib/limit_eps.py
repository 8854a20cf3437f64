"""Stage ``eps`` of ``studies/sharp_limit.py``: phase-field steady states seeded from the sharp
shapes (:mod:`_lib.seeded`) at falling ε, per backend, their rows with the extrapolation to
ε → 0, their tables and their pictures."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from _lib.fits import extrapolate
from _lib.seeded import (
    AXI_CHECK_NODES_PER_EPS,
    AXI_NODES_PER_EPS,
    AXI_ORDER,
    NODES_PER_EPS,
    kept,
    make_runs,
)
from _lib.sharp import Cache, branch_key
from fem_ade.plots.figures import save_figure
from fem_ade.store.output import write_json_atomic

EPS = (0.04, 0.032, 0.02, 0.016, 0.0128, 0.01)
EPS_V = (0.95, 0.8, 0.65, 0.6, 0.55)
#: (branch, v) of the ε stage: the sphere and the Clifford torus first, then the genus-0
#: branches of the sharp stage
EPS_CASES = (("sphere", 1.0), ("torus", None)) + tuple(
    (b, v) for b in ("prolate", "oblate", "stomatocyte") for v in EPS_V)
#: the finest two only for the cases given with --fine (the cost grows like ε⁻⁴): by default
#: those that keep their branch at ε = 0.016; ``FINE_STOP``: where a case stops (the sphere's
#: steady state is slow to settle: 2350 steps at ε = 0.0128)
FINE = (0.0128, 0.01)
#: the axisymmetric FEM's column (docs/model.md §11): every case at ε = 0.04 … 0.0025, order
#: 8 at ``AXI_NODES_PER_EPS`` nodes per ε, and at the two smallest ε again at
#: ``AXI_CHECK_NODES_PER_EPS`` (the difference bounds the discretization error of the first;
#: it is largest against the ε effect, which falls like ε², where ε is smallest)
AXI_EPS = (0.04, 0.02, 0.01, 0.005, 0.0025)
#: where an axisymmetric case stops: the sphere, whose exact constraints at v = 1 leave only
#: a nearly free deformation (a prolate or oblate of vanishing excess), settles slowly: 2750
#: steps at ε = 0.01, and its e is 1 + O(ε²) on any near-sphere
AXI_STOP = {"sphere@1.0000": 0.01}
FINE_CASES = ("sphere@1.0000", "torus@free", "prolate@0.9500", "prolate@0.8000", "prolate@0.6500",
              "prolate@0.6000", "prolate@0.5500", "oblate@0.9500", "oblate@0.8000",
              "oblate@0.5500")
FINE_STOP = {"sphere@1.0000": 0.0128}


def eps_of(plan, backend: str) -> tuple[float, ...]:
    """The ε of a backend's column (the axisymmetric check: the two smallest)."""
    if backend == "axisymmetric-check":
        return tuple(sorted(plan.axi_eps)[:2])
    return plan.axi_eps if backend.startswith("axisymmetric") else plan.eps


def case_key(backend: str, branch: str, v, eps: float) -> str:
    """A run's key in runs.json: ``BACKEND/BRANCH@V/EPS``."""
    return f"{backend}/{branch_key(branch, v)}/{eps:.4f}"


def gap(sharp: dict) -> float | None:
    """The narrowest passage of the sharp surface (units of R₀): the smallest distance
    between two of its points that are far apart along it (straight distance below half the
    distance along the meridian, through a pole where that is shorter: a waist, a
    stomatocyte's neck, an oblate's thin centre); None for a shape without one."""
    r, z = np.asarray(sharp["r"]), np.asarray(sharp["z"])
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(r), np.diff(z)))])
    closed = r[0] > 1e-9  # a torus's tube
    best = math.inf
    for sign in (1.0, -1.0):  # the point itself, or its mirror across the axis
        d = np.hypot(r[:, None] - sign * r[None, :], z[:, None] - z[None, :])
        if sign > 0:
            sep = np.abs(s[:, None] - s[None, :])
            if closed:
                sep = np.minimum(sep, s[-1] - sep)
        else:  # through the top or the bottom pole
            sep = np.minimum(s[:, None] + s[None, :], 2 * s[-1] - s[:, None] - s[None, :])
            if closed:  # across the hole: the surface path goes round the tube
                sep = np.full_like(d, np.inf)
        narrow = d < 0.5 * sep
        if narrow.any():
            best = min(best, float(d[narrow].min()))
    return None if math.isinf(best) else best


def eps_rows(runs: dict, cache: Cache, backend: str, plan) -> list[dict]:
    rows = []
    for branch, v in plan.cases:
        sharp = cache.get(branch, v, compute=False)
        if sharp is None or "w" not in sharp:
            continue
        found = [runs[k] for k in (case_key(backend, branch, v, e)
                                   for e in eps_of(plan, backend)) if k in runs]
        if not found:
            continue
        for r in found:  # the rule of today, not of when the run was made
            r["kept_branch"] = kept(r, sharp)
        good = [r for r in found if r["kept_branch"]]
        narrowest = gap(sharp)
        row = {"backend": backend, "branch": branch, "v": sharp["v"], "e_sharp": sharp["w"],
               "eps": [r["eps"] for r in found], "e_phase_field": [r["e"] for r in found],
               "kept_branch": [r["kept_branch"] for r in found],
               "labels": [r["label"] for r in found], "R0": found[0]["R0"],
               "e_extrapolated": None, "rel_diff": None, "order": None,
               "gap_over_eps": None if narrowest is None
               else narrowest * found[0]["R0"] / min(r["eps"] for r in found)}
        if len(good) >= 2 and good[-1]["eps"] == min(r["eps"] for r in found):
            e0, p, observed = extrapolate([r["eps"] for r in good], [r["e"] for r in good])
            row.update(e_extrapolated=e0, order=p, order_observed=observed,
                       rel_diff=e0 / sharp["w"] - 1.0)
        if backend == "axisymmetric":  # the discretization error over the ε effect
            ratios = []
            for r in found:
                check = runs.get(case_key("axisymmetric-check", branch, v, r["eps"]))
                if check is not None and r["kept_branch"] and abs(r["e"] - sharp["w"]) > 0:
                    ratios.append(abs(r["e"] - check["e"]) / abs(r["e"] - sharp["w"]))
            row["disc_over_eps_effect"] = max(ratios) if ratios else None
        rows.append(row)
    return rows


#: the ε sections' titles, per backend
EPS_NAMES = {"spectral": "spectral", "fem": "FEM, order 4 on the same nodes",
             "axisymmetric": f"axisymmetric FEM, order {AXI_ORDER}, {AXI_NODES_PER_EPS:g} "
                             "nodes per ε"}


def eps_section(backend: str, rows_b: list[dict], eps_b, runs: dict) -> list[str]:
    """One backend's table of e against ε, its extrapolation, and what a run cost."""
    axi = backend == "axisymmetric"
    grid_note = (f"(n = {', '.join(str(round(NODES_PER_EPS / e)) for e in eps_b)})"
                 if not axi else f"(order {AXI_ORDER}, {AXI_NODES_PER_EPS:g} nodes per ε; "
                 f"disc/Δε: the largest |e(3.5/ε) − e({AXI_CHECK_NODES_PER_EPS:g}/ε)| over "
                 "|e − e_sharp| along ε, a bound on the discretization error over the ε "
                 "effect)")
    lines = ["", f"## The limit ε → 0 ({EPS_NAMES[backend]})", "",
             f"e = W / W_sphere,sharp at ε = {', '.join(str(e) for e in eps_b)} "
             f"{grid_note}; † the run left the branch (its label); p the observed order; "
             "e₀ the extrapolation; gap/ε the sharp surface's narrowest passage (a "
             "waist, a neck, a thin centre, a torus's hole) over the smallest ε run.", "",
             "| branch | v | R₀ | gap/ε | " + " | ".join(f"ε = {e}" for e in eps_b)
             + " | p | e₀ | sharp | e₀/sharp − 1 |" + (" disc/Δε |" if axi else ""),
             "|---|---|---|---|" + "---|" * len(eps_b) + "---|---|---|---|"
             + ("---|" if axi else "")]
    lines += [eps_line(r, eps_b, axi) for r in rows_b]
    lines.append("")
    for eps in eps_b:
        costs = [x for k, x in runs.items() if k.startswith(backend + "/") and x["eps"] == eps]
        if costs:
            cpu = [c["cpu_s"] for c in costs if "cpu_s" in c]
            lines += [f"- ε = {eps} (n = {costs[0]['n']}): a run took "
                      f"{min(c['seconds'] for c in costs):.0f}–"
                      f"{max(c['seconds'] for c in costs):.0f} s, "
                      f"{min(c['steps'] for c in costs)}–{max(c['steps'] for c in costs)} "
                      "steps (wall, this 2-core machine"
                      + (f"; {min(cpu):.2g}–{max(cpu):.2g} s CPU of the set-up and loop"
                         if cpu else "") + ")"]
    return lines


def eps_line(r: dict, eps_b, axi: bool) -> str:
    """One branch point's row of the ε table."""
    cells = []
    for e in eps_b:
        if e in r["eps"]:
            i = r["eps"].index(e)
            cells.append(f"{r['e_phase_field'][i]:.5f}" + (
                "" if r["kept_branch"][i] else f" † {r['labels'][i]}"))
        else:
            cells.append("")
    ex = r["e_extrapolated"]
    g = "—" if r["gap_over_eps"] is None else f"{r['gap_over_eps']:.1f}"
    disc = ""
    if axi:
        d = r.get("disc_over_eps_effect")
        disc = " " + ("—" if d is None else f"{d:.1e}") + " |"
    return (f"| {r['branch']} | {r['v']:.4f} | {r['R0']:.3f} | {g} | " + " | ".join(cells)
            + (f" | {r['order']:.2f}{'' if r['order_observed'] else ' (assumed)'} | "
               f"{ex:.5f} | {r['e_sharp']:.5f} | {r['rel_diff']:+.2%} |" if ex is not None
               else f" | | | {r['e_sharp']:.5f} | — |") + disc)


def eps_figures(table: list[dict], runs: dict, cache: Cache, out: Path) -> None:
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = ([r for r in table if r["backend"] == "axisymmetric"]
             or [r for r in table if r["backend"] == "spectral"] or table)
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    for ax, branches in zip(axes, (("sphere", "torus", "prolate"), ("oblate",),
                                   ("stomatocyte",)), strict=True):
        for k, r in enumerate(c for c in cases if c["branch"] in branches):
            colour = f"C{k}"
            x2 = np.array(r["eps"]) ** 2
            y = np.array(r["e_phase_field"]) / r["e_sharp"]
            kept = np.array(r["kept_branch"])
            ax.plot(x2[kept], y[kept], "o-", color=colour, ms=4,
                    label=f"{r['branch']} v = {r['v']:.2f}")
            ax.plot(x2[~kept], y[~kept], "x", color=colour, ms=7)
            if r["e_extrapolated"] is not None:
                ax.plot([0.0], [r["e_extrapolated"] / r["e_sharp"]], "*", color=colour, ms=9)
        ax.axhline(1.0, color="0.4", lw=0.8)
        top = max(e ** 2 for r in cases for e in r["eps"])
        ax.set(xlabel="ε²", ylabel="e / e_sharp", xlim=(-0.03 * top, 1.03 * top))
        ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(4))
        ax.ticklabel_format(axis="x", style="sci", scilimits=(0, 0))
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    axes[0].set_title("phase field over sharp (★ extrapolated, × left the branch)", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out / "sharp-eps.png", dpi=100, colours=64)
    plt.close(fig)

    finest = {}  # per case, the run of the smallest ε whose section is kept
    for k, x in runs.items():
        path = out / "sharp" / "sections" / (k.replace("/", "_") + ".npy")
        case = (x["branch"], round(x["v"], 4))
        if (k.startswith(cases[0]["backend"] + "/") and path.is_file()
                and (case not in finest or x["eps"] < finest[case]["eps"])):
            finest[case] = {**x, "section": np.load(path)}
    finest = list(finest.values())
    if not finest:
        return
    cols = 6
    rows_n = math.ceil(len(finest) / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(2.4 * cols, 2.5 * rows_n))
    for ax in np.ravel(axes):
        ax.set_axis_off()
    for ax, x in zip(np.ravel(axes), finest, strict=False):
        sec = np.array(x["section"])
        m = sec.shape[0]
        g = np.arange(m) / m
        ax.contour(g, g, sec.T, levels=[0.0], colors="k", linewidths=1.2)
        sharp = cache.get(x["branch"], None if x["branch"] == "torus" else x["v"],
                          compute=False)
        if sharp and "r" in sharp:
            r_, z_ = np.array(sharp["r"]) * x["R0"], np.array(sharp["z"]) * x["R0"]
            for sgn in (1, -1):
                ax.plot(0.5 + sgn * r_, 0.5 + z_, color="tab:red", lw=0.8, ls="--")
        ax.set_aspect("equal")
        ax.set_title(f"{x['branch']} v = {x['v']:.2f}, ε = {x['eps']}"
                     f"{'' if x['kept_branch'] else ' †'}", fontsize=8)
    fig.suptitle("φ = 0 at the smallest ε run (black) over the sharp meridian (red, dashed); "
                 "section y = ½; † left the branch", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out / "sharp-sections.png", dpi=90, colours=64)
    plt.close(fig)


def run_eps(cache: Cache, out: Path, plan, columns) -> None:
    """Stage ``eps``: the seeded steady states of each column (backend, the cases it is
    limited to or None, the cases also at the finest ε) not yet in runs.json, as one sweep."""
    path = out / "sharp" / "runs.json"
    runs = json.loads(path.read_text()) if path.is_file() else {}
    jobs = [job for backend, only, fine in columns
            for job in eps_jobs(cache, runs, backend, plan, only, fine)]
    for job, row in make_runs(out / "sharp", jobs):
        key = job.key
        print(f"  {key}: e = {row['e']:.6f} (sharp {job.sharp['w']:.6f}), {row['label']}"
              f"{'' if row['kept_branch'] else ' LEFT the branch'}, {row['steps']} steps, "
              f"{row['seconds']} s", flush=True)
        section = row.pop("section")
        runs[key] = row
        sections = out / "sharp" / "sections"
        sections.mkdir(parents=True, exist_ok=True)
        np.save(sections / (key.replace("/", "_") + ".npy"), section)
        write_json_atomic(path, runs, indent=None)


def eps_jobs(cache: Cache, runs: dict, backend: str, plan, only, fine) -> list:
    """The seeded steady states of one column of stage ``eps`` not yet in ``runs``."""
    jobs = []
    for branch, v in plan.cases:
        if only and branch not in only and branch_key(branch, v) not in only:
            continue
        sharp = cache.get(branch, v)
        if "w" not in sharp:
            continue
        for eps in eps_of(plan, backend):
            key = case_key(backend, branch, v, eps)
            axi = backend.startswith("axisymmetric")
            stop = (AXI_STOP if axi else FINE_STOP).get(branch_key(branch, v), 0.0)
            if key in runs or (not axi and eps in FINE and branch_key(branch, v) not in fine) or (
                    eps < stop):
                continue
            jobs.append(SimpleNamespace(key=key, sharp=sharp, branch=branch, eps=eps,
                                        backend=backend, ade={}))
    return jobs
