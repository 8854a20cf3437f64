"""Does a steady state at ε start best from the steady state at 2ε? (the sharp limit's cost)

Hypothesis: going to small ε along a ladder — each ε started from the steady state at 2ε —
needs fewer steps than starting each ε from the sharp shape, because the start is already a
diffuse steady state of nearly the same shape. Control: the same runs started from the sharp
shape (the vesicle family's seed). The prolate at v = 0.8, minimal model, axisymmetric
geometry, order 8 at the default nodes per ε, the ``steady`` recipe; ε = 0.04 … 0.005 (at
0.0025 the re-profiled start had not settled after 3710 steps, 8 minutes, when it was stopped).

Five starts per ε:

* ``seed``       the sharp prolate (the sweep's grid, ``studies/sweeps/eps_ladder.toml``);
* ``from 2ε``    the end of the ladder's run at 2ε as it is (its listed points, ``after``);
* ``re-profiled`` the end of the seeded run at 2ε with its profile made ε's,
                 φ → tanh((2ε/ε)·artanh φ): the same membrane without the wrong width
                 (the second hypothesis: the wrong width is what costs);
* ``re-seeded``  the φ = 0 meridian of that end, seeded as the sharp shape is (a tanh
                 profile of ε on this mesh: no field carried between meshes — the third
                 hypothesis: the transfer between meshes is what costs);
* ``own shape``  the control of the last: the φ = 0 meridian of the seeded run's own end at
                 ε, seeded the same way (the procedure, at the shape it must reach).

All must reach the same state: their energies' spread is the steady-state criterion's own
error. Their steps and CPU seconds are the comparison (one BLAS thread, one run at a time).

Writes ``OUT/eps_ladder/``: the sweep's folder (sweep.csv, sweep.json; the run folders under
points/ and reprofiled/ are not committed), ``ladder.json`` (the rows, written before the
report) and ``OUT/eps_ladder.md`` with ``eps-ladder.png``.

    python studies/eps_ladder.py --out studies/results        # ~5 min on one core
    python studies/eps_ladder.py --out studies/results --report-only
    python studies/eps_ladder.py --quick                      # ε = 0.08, 0.04 (runs/studies)
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from fem_ade.campaigns.sweep import run_sweep
from fem_ade.campaigns.sweep_file import Sweep, load_sweep
from fem_ade.store.output import write_json_atomic

HERE = Path(__file__).resolve().parent
SWEEP = HERE / "sweeps" / "eps_ladder.toml"
ARMS = ("seed", "from 2ε", "re-profiled", "re-seeded", "own shape")


def quick(sweep: Sweep) -> Sweep:
    """The same ladder at ε = 0.08 and 0.04 (seconds)."""
    first = f"eps=0.08_seed={sweep.seeds[0]}"
    return Sweep(sweep.name + "-quick", sweep.base, {"eps": [0.08, 0.04]}, sweep.fixed,
                 sweep.seeds, sweep.run, listed=[{"name": "from-2eps_eps=0.04",
                                                  "seed": sweep.seeds[0],
                                                  "scene": {"eps": 0.04}, "run": {},
                                                  "after": first}])


def _cost(folder: Path) -> dict:
    """A finished run's steps, CPU seconds (set-up included), first and last energies."""
    import json

    from fem_ade.analysis.sharp import reduced_energy
    from fem_ade.store.output import read_history

    s = json.loads((folder / "summary.json").read_text())
    E = read_history(folder / "history.csv")["E"]
    return {"status": s["status"], "steps": s["steps"],
            "cpu_s": round(s["cpu_s"] + (s.get("setup_cpu_s") or 0.0), 2),
            "E0": float(E[0]), "E": float(E[-1]),
            "e": reduced_energy(s["final"], s["parameters"]["kappa"]),
            "v_surface": ((s.get("shape") or {}).get("sharp") or {}).get("reduced_volume"),
            "label": (s.get("shape") or {}).get("label")}


def reprofiled(root: Path, point, coarse: Path) -> dict:
    """The re-profiled start: the seeded run at 2ε's end, its profile made ε's, run to a
    steady state in ``root/reprofiled/NAME`` (:func:`fem_ade.engine.jobs.ensure`)."""
    from fem_ade.engine.jobs import ensure

    folder = root / "reprofiled" / point.name
    start = folder.with_name(point.name + ".start.npz")
    if not start.is_file():
        with np.load(coarse / "final.npz") as z:
            fields = {k: np.array(z[k]) for k in z.files}
        for k in ("phi", "phi_grid"):  # the same level set, the width of ε's profile
            fields[k] = np.tanh(2.0 * np.arctanh(np.clip(fields[k], -1 + 1e-15, 1 - 1e-15)))
        start.parent.mkdir(parents=True, exist_ok=True)
        np.savez(start, **fields)
    ensure(folder, point.scene, options=point.options, after=start).check()
    return _cost(folder)


def meridian_of(folder: Path, eps: float):
    """The φ = 0 meridian of an axisymmetric run's end as a ``meridian`` initial condition
    (its shape, the new ε's profile: what the sharp seed is, for a diffuse steady state)."""
    from fem_ade.analysis.axishape import meridians
    from fem_ade.backends.fem.axisym import SavedField
    from fem_ade.scenes.initial import Meridian

    with np.load(folder / "final.npz") as z:
        data = {k: np.array(z[k]) for k in z.files}
    (curve,) = meridians(SavedField(data, eps)).curves  # one pole-to-pole curve: a prolate
    if curve[0, 1] > curve[-1, 1]:
        curve = curve[::-1]
    return Meridian(centre=(float(data["axis"][0]), float(data["axis"][1]), 0.0),
                    r=tuple(curve[:, 0]), z=tuple(curve[:, 1]), scale=1.0)


def reseeded(root: Path, point, source: Path, eps: float, arm: str) -> dict:
    """A start made from the φ = 0 meridian of ``source``'s end (at its ``eps``), run to a
    steady state in ``root/ARM/NAME``."""
    from fem_ade.engine.jobs import ensure

    folder = root / arm / point.name
    ensure(folder, lambda: point.scene().with_(ic=meridian_of(source, eps)),
           options=point.options).check()
    return _cost(folder)


def run(sweep: Sweep, root: Path) -> list[dict]:
    """The sweep (seeded and from-2ε starts), then the re-profiled, re-seeded and own-shape
    starts; the rows, one per ε, written to ``ladder.json`` before anything is reported."""
    run_sweep(sweep, root, workers=1, quiet=True)
    points = sweep.points()  # (a listed point's values are its scene keys: its ε)
    grid = {p.values["eps"]: p for p in points if not p.after}
    ladder = {p.values["eps"]: p for p in points if p.after}
    rows = []
    for eps in sorted(grid, reverse=True):
        row = {"eps": eps, "seed": _cost(root / "points" / grid[eps].name)}
        if eps in ladder:
            row["from 2ε"] = _cost(root / "points" / ladder[eps].name)
            coarse = root / "points" / grid[2 * eps].name
            row["re-profiled"] = reprofiled(root, grid[eps], coarse)
            row["re-seeded"] = reseeded(root, grid[eps], coarse, 2 * eps, "reseeded")
            row["own shape"] = reseeded(root, grid[eps], root / "points" / grid[eps].name,
                                        eps, "own-shape")
        rows.append(row)
        print(f"  eps {eps:g}: " + ", ".join(f"{arm} {row[arm]['steps']} steps "
                                              f"{row[arm]['cpu_s']} s" for arm in ARMS
                                              if arm in row), flush=True)
    write_json_atomic(root / "ladder.json", {"sweep": sweep.name, "rows": rows}, indent=None)
    return rows


def report(rows: list[dict], out: Path, name: str) -> str:
    """``OUT/NAME.md`` and its figure from the rows; the markdown."""
    lines = [f"# A steady state at ε from the steady state at 2ε? ({name})", "",
             "Generated by `studies/eps_ladder.py` from `studies/sweeps/eps_ladder.toml`: the "
             "prolate at v = 0.8 (minimal model, axisymmetric, order 8, the `steady` recipe), "
             "each ε started five ways (the script's docstring): from the sharp prolate "
             "(seed), from the end of the run at 2ε as it is (from 2ε), from the seeded run "
             "at 2ε's end with its profile made ε's (re-profiled), from that end's φ = 0 "
             "meridian seeded as the sharp shape is (re-seeded), and, the control, from the "
             "seeded run's own end's meridian (own shape). Steps and CPU seconds to the "
             "steady state (one BLAS thread, one run at a time); E₀ the energy of the start; "
             "E − E(seed) the end's energy against the seeded end's, relative; v the reduced "
             "volume of the end's φ = 0 surface.", "",
             "| ε | start | steps | CPU s | E₀/E | E − E(seed) | v | end |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for arm in (a for a in ARMS if a in r):
            c = r[arm]
            dE = (c["E"] - r["seed"]["E"]) / r["seed"]["E"]
            lines.append(f"| {r['eps']:g} | {arm} | {c['steps']} | {c['cpu_s']:.1f} | "
                         f"{c['E0'] / c['E']:.3g} | {dE:+.1e} | {c['v_surface']:.4f} | "
                         f"{c['label']} |")
    lines += ["", *findings(rows), "", f"![steps and CPU per start]({name}.png)"]
    text = "\n".join(lines) + "\n"
    (out / f"{name}.md").write_text(text)
    figure(rows, out / f"{name}.png")
    return text


def findings(rows: list[dict]) -> list[str]:
    """What the table says, in numbers: the ratio of each start's steps and CPU to the
    seed's, over the ε where every start ran and ended as the same shape."""
    ran = [r for r in rows if all(a in r for a in ARMS)]
    both = [r for r in ran if len({r[a]["label"] for a in ARMS}) == 1]
    out = [f"- At ε = {r['eps']:g} the starts ended as different shapes: not compared."
           for r in ran if r not in both]
    if not both:
        return out
    eps = ", ".join(f"{r['eps']:g}" for r in both)
    for arm in ARMS[1:]:
        steps = [r[arm]["steps"] / r["seed"]["steps"] for r in both]
        cpu = sum(r[arm]["cpu_s"] for r in both) / sum(r["seed"]["cpu_s"] for r in both)
        out.append(f"- **{arm}** against the seed: {min(steps):.2g}–{max(steps):.2g}× the "
                   f"steps, {cpu:.2g}× the CPU time in all (ε = {eps}).")
    return out


def figure(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem_ade.plots.figures import save_figure

    fig, axes = plt.subplots(1, 2, figsize=(9.0, 3.6))
    for arm, marker in zip(ARMS, "os^vD", strict=True):
        pts = [(r["eps"], r[arm]) for r in rows if arm in r]
        for ax, key in zip(axes, ("steps", "cpu_s"), strict=True):
            ax.loglog([e for e, _ in pts], [c[key] for _, c in pts], marker + "-", label=arm)
    for ax, label in zip(axes, ("steps to steady", "CPU s to steady"), strict=True):
        eps = sorted({r["eps"] for r in rows})
        ax.set(xlabel="ε", ylabel=label, xticks=eps, xticklabels=[f"{e:g}" for e in eps])
        ax.minorticks_off()
        ax.invert_xaxis()
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=8)
    fig.suptitle("prolate v = 0.8, axisymmetric: where a run at ε starts", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=72, colours=16)
    plt.close(fig)


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="runs/studies",
                    help="results folder (default %(default)s; the committed: studies/results)")
    ap.add_argument("--quick", action="store_true",
                    help="ε = 0.08 and 0.04 (also when CI, unless --report-only)")
    ap.add_argument("--report-only", action="store_true", help="from ladder.json; run nothing")
    args = ap.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    sweep = load_sweep(SWEEP)
    if args.quick or (os.environ.get("CI") and not args.report_only):
        sweep = quick(sweep)
    out = Path(args.out)
    root = out / sweep.name
    if args.report_only:
        import json

        rows = json.loads((root / "ladder.json").read_text())["rows"]
    else:
        rows = run(sweep, root)
    report(rows, out, sweep.name)
    return rows


if __name__ == "__main__":
    main()
