"""What the axisymmetric geometry cannot see: are its branch points stable to non-axisymmetric
perturbations? (issue 32, stability). The axisymmetric stability count (``fem_ade.branch``)
covers the m = 0 modes only; this study bounds the others by experiment.

For a few points of the ADE plane's branches (``studies/ade_branches.py``, ε = 0.01), the
point's φ = 0 meridian is revolved into a 3D scene with the same parameters (the
``meridian`` initial condition, the box's centre on the axis) and run to a steady state by
the 3D spectral backend twice: as it is (the **control**: where the 3D discretization puts
the same axisymmetric state) and with a smooth non-axisymmetric random perturbation of
amplitude ``KICK`` added to φ (the **kicked** run: every angular mode m ≥ 1 is in it). The
hypothesis "the point is stable to non-axisymmetric modes" predicts that the kicked run
returns to the control's state: the same label and arms and e within ``SAME`` of it; a
kicked run that ends lower, or as another shape, refutes it (the point is unstable, or the
kick was large enough to leave its basin: a saddle of the full 3D problem either way for
the axisymmetric lowest branch's claim).

The points: two controls (a prolate and an oblate far from any transition, where the
seed-based 3D ADE sweep, ``studies/results/phase_diagram/ade``, ended axisymmetric), then
the two where that sweep ended in non-axisymmetric shapes (starfish-3 at v = 0.7,
Δa₀ = 1.64; starfish-4 at v = 0.8, Δa₀ = 1.64) while the sharp lowest there is axisymmetric
(prolate; pear) — the candidates for a non-axisymmetric instability.

Writes ``OUT/nonaxisymmetric.md`` and ``.json``; the 3D run folders in
``OUT/nonaxisymmetric/`` (not committed; a finished run is read back).

    python studies/nonaxisymmetric.py --out studies/results    # ~1 h (3D at 128³)
    python studies/nonaxisymmetric.py --quick                  # the code, ε = 0.04
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import replace
from pathlib import Path

OUT = Path("runs") / "studies"
#: (v, Δa₀ of the grid, branch) of the ADE plane's lines
CASES = ((0.85, 1.04, "prolate"), (0.8, 0.8, "oblate"), (0.7, 1.64, "prolate"),
         (0.8, 1.64, "pear"))
QUICK_CASES = ((0.85, 1.1, "prolate"),)
KICK = 0.1
#: a kicked run ends "the same" as its control when its e is within this (relative) and its
#: label and arms are the control's
SAME = 1e-3
MAX_STEPS = 6000


def point_of(line: Path, da0: float) -> tuple[dict, object]:
    """The branch point of a line folder nearest ``da0``: (its row, its φ)."""
    from fem_ade.branch import load_points

    done = load_points(line)
    if not done:
        raise FileNotFoundError(f"{line} holds no branch points (run ade_branches.py first)")
    return min(done, key=lambda p: abs(p[0]["da0"] - da0))


def revolved(line: Path, row: dict, phi):
    """The 3D ``vesicle`` scene of a branch point, seeded with its φ = 0 meridian."""
    from fem_ade.axishape import meridians
    from fem_ade.backend import make_backend
    from fem_ade.branch import set_parameter
    from fem_ade.initial import Meridian
    from fem_ade.scenes import vesicle_scene

    info = json.loads((line / "branch.json").read_text())
    ended = json.loads((line / "ended.json").read_text())
    scene = vesicle_scene(v=ended["v"], da0=row["da0"], kbar=1.4, eps=ended["eps"],
                          branch=ended["branch"], R0=ended["R0"])
    be = make_backend("fem", scene, n=info["n"], **info["options"], scheme="stabilized",
                      constraints="exact")
    params = set_parameter(be.params, "da0", row["da0"])
    be.stepper.params = be.params = params
    be._set(phi, None)
    curves = meridians(be).curves
    if len(curves) != 1:
        raise ValueError(f"{len(curves)} φ = 0 curves: not one membrane to revolve")
    r, z = curves[0][:, 0], curves[0][:, 1]
    L, R0 = scene.params.L, ended["R0"]
    ic = Meridian(centre=(0.5 * L,) * 3, r=tuple(float(x) / R0 for x in r),
                  z=tuple((float(x) - 0.5 * L) / R0 for x in z), scale=R0)
    ic.check(3)
    return replace(scene, params=params, ic=ic), scene.n


def run_3d(scene, n: int, kick: float, out: Path) -> dict:
    from fem_ade.runs import recipe, simulate
    from fem_ade.sharp import reduced_energy

    if not (out / "summary.json").is_file():
        options = {**recipe("steady", scene), "max_steps": MAX_STEPS}
        simulate(scene, backend="spectral", n=n, perturb=kick, seed=1, render=False,
                 quiet=True, out=out, force=out.is_dir(), **options)
    s = json.loads((out / "summary.json").read_text())
    shape = s.get("shape") or {}
    return {"status": s["status"], "steps": s["steps"], "cpu_s": round(s["cpu_s"], 1),
            "e": reduced_energy(s["final"], s["parameters"]["kappa"]),
            "label": shape.get("label"), "arms": shape.get("arms"),
            "semi_axes": (shape.get("body") or {}).get("semi_axes")}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--quick", action="store_true", help="one case of ade_branches --quick")
    args = ap.parse_args(argv)
    suffix = "_quick" if args.quick else ""
    lines = args.out / f"ade_branches{suffix}"
    if args.quick and not lines.is_dir():  # the quick ADE line first (a minute)
        import sys

        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from ade_branches import main as ade_branches

        ade_branches(["--quick", "--out", str(args.out)])
    base = args.out / f"nonaxisymmetric{suffix}"
    rows = []
    for v, da0, branch in (QUICK_CASES if args.quick else CASES):
        line = lines / f"v={v:g}" / branch
        if not line.is_dir():  # the pear's lines: up and down from where it starts
            line = line.with_name(f"{branch}-up")
        t0 = time.perf_counter()
        row, phi = point_of(line, da0)
        scene, n = revolved(line, row, phi)
        name = f"v={v:g}_da0={row['da0']:.4f}_{branch}"
        control = run_3d(scene, n, 0.0, base / name / "control")
        kicked = run_3d(scene, n, KICK, base / name / "kicked")
        same = (kicked["label"] == control["label"] and kicked["arms"] == control["arms"]
                and abs(kicked["e"] / control["e"] - 1.0) < SAME)
        rows.append({"v": v, "da0": row["da0"], "branch": branch, "e_axisymmetric": row["e"],
                     "unstable_axisymmetric": row["unstable"], "control": control,
                     "kicked": kicked, "same": same,
                     "verdict": ("stable to the kick" if same else
                                 "left the axisymmetric state"
                                 + (" (lower)" if kicked["e"] < control["e"] else "")),
                     "seconds": round(time.perf_counter() - t0, 1)})
        print(f"{name}: axisymmetric e = {row['e']:.5f}; 3D control {control['e']:.5f} "
              f"({control['label']}), kicked {kicked['e']:.5f} ({kicked['label']}): "
              f"{rows[-1]['verdict']}", flush=True)
    from fem_ade.output import write_json_atomic

    write_json_atomic(args.out / f"nonaxisymmetric{suffix}.json", {"kick": KICK, "rows": rows})
    write_report(args.out / f"nonaxisymmetric{suffix}.md", rows)
    return {"rows": rows}


def write_report(path: Path, rows: list[dict]) -> None:
    lines = ["# Non-axisymmetric perturbations of axisymmetric branch points", "",
             "Written by `studies/nonaxisymmetric.py`: a branch point of the ADE plane "
             "(`ade_branches.md`, axisymmetric FEM) revolved into 3D (spectral, ε/h = 1.28, "
             "κ̄/κ = 1.4) and run to a steady state as it is (control) and with a smooth "
             f"random perturbation of amplitude {KICK} in φ (kicked: every angular mode). "
             f"Same: label and arms equal, e within {SAME:g}.", "",
             "| v | Δa₀ | branch | e axisymmetric (unstable m = 0) | 3D control e (label, "
             "steps) | 3D kicked e (label, steps) | verdict |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        c, k = r["control"], r["kicked"]
        lines.append(f"| {r['v']:g} | {r['da0']:.4f} | {r['branch']} | "
                     f"{r['e_axisymmetric']:.5f} ({r['unstable_axisymmetric']}) | "
                     f"{c['e']:.5f} ({c['label']}, {c['steps']} {c['status']}) | "
                     f"{k['e']:.5f} ({k['label']}, {k['steps']} {k['status']}) | "
                     f"{r['verdict']} |")
    cpu = sum(r["control"]["cpu_s"] + r["kicked"]["cpu_s"] for r in rows)
    lines += ["", f"3D runs: {cpu:.0f} s CPU in all ({math.fsum(r['seconds'] for r in rows):.0f}"
              " s wall).", ""]
    notes = path.with_name(path.stem + "_notes.md")
    if notes.is_file():
        lines += [notes.read_text()]
    path.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
