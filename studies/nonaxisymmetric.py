"""What the axisymmetric geometry cannot see: are its branch points stable to non-axisymmetric
perturbations? (issue 32, stability). The axisymmetric stability count
(``fem_ade.campaigns.branch``)
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
(prolate; pear) — the candidates for a non-axisymmetric instability (the pear at Δa₀ = 1.58:
at 1.64 its neck is closed at ε = 0.01).

Writes ``OUT/nonaxisymmetric.md`` and ``.json``. The 3D runs are one sweep
(:mod:`fem_ade.campaigns.sweep`, two Dask workers): each run a listed point whose base is its
revolved
scene, in ``OUT/nonaxisymmetric/[eps=EPS/]sweep/points/CASE_{control,kicked}`` (their
summary.json committed; a finished run is read back, a stopped one resumed from its
checkpoint).

    python studies/nonaxisymmetric.py --out studies/results --eps 0.02   # ~20 min (64³)
    python studies/nonaxisymmetric.py --quick                            # ε = 0.04

At the lines' own ε = 0.01 (128³) one kicked run took more than 20 min of this machine
(stopped at step 890, not yet steady): the committed check runs the points' membranes at
ε = 0.02, the same R₀, v and Δa₀ (``--eps``).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from _lib.lines import line_name

OUT = Path("runs") / "studies"
#: (v, Δa₀ of the grid, branch) of the ADE plane's lines
CASES = ((0.85, 1.04, "prolate"), (0.8, 0.8, "oblate"), (0.7, 1.64, "prolate"),
         (0.8, 1.58, "pear"))
QUICK_CASES = ((0.85, 1.1, "prolate"),)
KICK = 0.1
#: a kicked run ends "the same" as its control when its e is within this (relative) and its
#: label and arms are the control's
SAME = 1e-3
MAX_STEPS = 6000


def line_of(lines: Path, v: float, branch: str) -> tuple[Path, dict]:
    """The ADE line of ``branch`` at ``v`` (the pear's: its line up from where it starts):
    its run folder in ``ade_branches.py``'s sweep and its entry in lines.json (what the line
    is, its ``key``, and its archived ``rows``)."""
    path = lines / "lines.json"
    archive = json.loads(path.read_text()) if path.is_file() else {}
    for name in (line_name(v, branch), line_name(v, f"{branch}-up")):
        if name in archive:
            return lines / "sweep" / "points" / name, archive[name]
    raise FileNotFoundError(f"{path} has no {branch} line at v = {v:g} (run "
                            "ade_branches.py first)")


def point_of(line: Path, entry: dict, da0: float) -> tuple[dict, object, object]:
    """The branch point of a line nearest ``da0``: (its row, its φ, its nodes) from its run
    folder; where the points are not kept (a committed line: its archived rows), (its row,
    None, None)."""
    import numpy as np

    folders = sorted((line / "points").glob("[0-9][0-9][0-9][0-9]"))
    rows = [(json.loads((f / "summary.json").read_text()), f) for f in folders
            if (f / "summary.json").is_file()]
    if not rows and entry["rows"]:
        return min(entry["rows"], key=lambda r: abs(r["da0"] - da0)), None, None
    if not rows:
        raise FileNotFoundError(f"{line} holds no branch points (run ade_branches.py first)")
    row, folder = min(rows, key=lambda p: abs(p[0]["da0"] - da0))
    with np.load(folder / "final.npz") as z:
        return row, np.array(z["phi"]), np.array(z["points"])


def revolved(line: Path, entry: dict, row: dict, phi, nodes, eps: float | None = None):
    """The 3D ``vesicle`` scene of a branch point, seeded with its φ = 0 meridian (at the
    line's ε, or at ``eps``: the same membrane with another interface width)."""
    import numpy as np

    from fem_ade.analysis.axishape import meridians
    from fem_ade.backends.base import make_backend
    from fem_ade.campaigns.branch import set_parameter
    from fem_ade.campaigns.branch_folder import read_identity
    from fem_ade.model.params import ModelError
    from fem_ade.scenes.catalogue import vesicle_scene
    from fem_ade.scenes.initial import Meridian

    info = read_identity(line)
    ended = entry["key"]
    for da0 in (info["from"], row["da0"]):  # the line's mesh: graded around its first seed
        try:
            scene = vesicle_scene(v=ended["v"], da0=da0, kbar=1.4, eps=ended["eps"],
                                  branch=ended["branch"], R0=ended["R0"])
        except ModelError:  # (a pear seeded by continuation: no sharp pear from scratch)
            continue
        be = make_backend("fem", scene, n=info["n"], **info["options"],
                          scheme="stabilized", constraints="exact")
        mine = be.fields()["points"]
        if mine.shape == nodes.shape and np.allclose(mine, nodes, rtol=0, atol=1e-12):
            break
    else:
        raise ValueError(f"{line}: cannot rebuild the mesh of its points")
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
    n = scene.n
    if eps is not None and eps != ended["eps"]:  # the same vesicle (v, Δa₀, R₀), another ε
        params = set_parameter(params.with_(eps=eps, D=2.0 * eps / 3.0), "da0", row["da0"])
        n = max(16, round(1.28 * L / eps))
    return replace(scene, params=params, ic=ic), n


#: the two 3D runs of each case: the control (as it is) and the kicked one
KINDS = {"control": 0.0, "kicked": KICK}


def folder_of(base: Path, name: str, kind: str) -> Path:
    """The run folder of a case's run: a point of the study's sweep."""
    return base / "sweep" / "points" / f"{name}_{kind}"


def point_spec(name: str, kind: str, scene, n: int) -> dict:
    """A case's run as a listed point of a sweep (:mod:`fem_ade.campaigns.sweep`): the revolved
    scene
    as its own base (a scene file's table), the steady recipe on the spectral backend."""
    from fem_ade.scenes.catalogue import scene_to_mapping

    return {"name": f"{name}_{kind}", "base": scene_to_mapping(scene), "seed": 1,
            "run": {"recipe": "steady", "max_steps": MAX_STEPS, "checkpoint_every": 200,
                    "backend": "spectral", "n": n, "perturb": KINDS[kind], "render": False,
                    "sharp": False}}  # compared with the axisymmetric run, not sharp_ref


def run_all(specs: list[dict], base: Path) -> None:
    """The cases' runs as one sweep on two Dask workers (a control beside its kicked run):
    resumable, each run once, a failure recorded with its reason."""
    from fem_ade.campaigns.sweep import run_sweep
    from fem_ade.campaigns.sweep_file import listed_sweep

    run_sweep(listed_sweep("nonaxisymmetric", specs), base / "sweep", workers=2, quiet=True)


def result_3d(folder: Path) -> dict:
    """What the report needs of a finished 3D run (its summary.json; a failure raises)."""
    from fem_ade.analysis.sharp import reduced_energy
    from fem_ade.engine.jobs import read_failure, read_summary

    s = read_summary(folder)
    if s is None:
        failed = read_failure(folder)
        raise RuntimeError(f"{folder}: {failed['reason'] if failed else 'not run'}")
    shape = s.get("shape") or {}
    return {"status": s["status"], "steps": s["steps"], "cpu_s": round(s["cpu_s"], 1),
            "eps": s["parameters"]["eps"],
            "e": reduced_energy(s["final"], s["parameters"]["kappa"]),
            "label": shape.get("label"), "arms": shape.get("arms"),
            "semi_axes": (shape.get("body") or {}).get("semi_axes")}


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--quick", action="store_true", help="one case of ade_branches --quick")
    ap.add_argument("--case", type=int, action="append",
                    help="run only these cases (0-based indices of CASES); the report is of "
                         "the cases done")
    ap.add_argument("--report-only", action="store_true", help="the cases already run")
    ap.add_argument("--eps", type=float, default=None,
                    help="the 3D runs' eps (default: the line's; 0.02 costs 1/16 of 0.01)")
    return ap


def main(argv=None) -> dict:
    args = _parser().parse_args(argv)
    suffix = "_quick" if args.quick else ""
    lines = args.out / f"ade_branches{suffix}"
    if args.quick and not lines.is_dir():  # the quick ADE line first (a minute), as a script
        import subprocess
        import sys

        subprocess.run([sys.executable, str(Path(__file__).with_name("ade_branches.py")),
                        "--quick", "--out", str(args.out)], check=True)
    base = args.out / f"nonaxisymmetric{suffix}" / ("" if args.eps is None else
                                                     f"eps={args.eps:g}")
    cases = QUICK_CASES if args.quick else CASES
    chosen = set(range(len(cases))) if args.case is None else set(args.case)
    found, specs = [], []
    for i, (v, da0, branch) in enumerate(cases):
        line, entry = line_of(lines, v, branch)
        row, phi, nodes = point_of(line, entry, da0)
        name = f"v={v:g}_da0={row['da0']:.4f}_{branch}"
        done = all((folder_of(base, name, k) / "summary.json").is_file() for k in KINDS)
        if i not in chosen and not done or args.report_only and not done:
            continue
        if not done:
            scene, n = revolved(line, entry, row, phi, nodes, args.eps)
            specs += [point_spec(name, k, scene, n) for k in KINDS]
        found.append((v, branch, row, name))
    if specs:
        run_all(specs, base)
    rows = [case_row(v, branch, row, name, base) for v, branch, row, name in found]
    from fem_ade.store.output import write_json_atomic

    write_json_atomic(args.out / f"nonaxisymmetric{suffix}.json", {"kick": KICK, "rows": rows})
    write_report(args.out / f"nonaxisymmetric{suffix}.md", rows)
    return {"rows": rows}


def case_row(v: float, branch: str, row: dict, name: str, base: Path) -> dict:
    """A case's row: its control and kicked runs, and whether the kick returned."""
    control, kicked = (result_3d(folder_of(base, name, k)) for k in KINDS)
    same = (kicked["label"] == control["label"] and kicked["arms"] == control["arms"]
            and abs(kicked["e"] / control["e"] - 1.0) < SAME)
    out = {"v": v, "da0": row["da0"], "branch": branch, "eps_3d": control["eps"],
           "e_axisymmetric": row["e"], "unstable_axisymmetric": row["unstable"],
           "control": control, "kicked": kicked, "same": same,
           "verdict": ("stable to the kick" if same else "left the axisymmetric state"
                       + (" (lower)" if kicked["e"] < control["e"] else ""))}
    print(f"{name}: axisymmetric e = {row['e']:.5f}; 3D control {control['e']:.5f} "
          f"({control['label']}), kicked {kicked['e']:.5f} ({kicked['label']}): "
          f"{out['verdict']}", flush=True)
    return out


def write_report(path: Path, rows: list[dict]) -> None:
    lines = ["# Non-axisymmetric perturbations of axisymmetric branch points", "",
             "Written by `studies/nonaxisymmetric.py`: a branch point of the ADE plane "
             "(`ade_branches.md`, axisymmetric FEM) revolved into 3D (spectral, ε/h = 1.28, "
             "κ̄/κ = 1.4) and run to a steady state as it is (control) and with a smooth "
             f"random perturbation of amplitude {KICK} in φ (kicked: every angular mode). "
             f"Same: label and arms equal, e within {SAME:g}.", "",
             "| v | Δa₀ | branch | e axisymmetric, its line's ε (unstable m = 0) | 3D ε | "
             "3D control e (label, steps) | 3D kicked e (label, steps) | verdict |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        c, k = r["control"], r["kicked"]
        lines.append(f"| {r['v']:g} | {r['da0']:.4f} | {r['branch']} | "
                     f"{r['e_axisymmetric']:.5f} ({r['unstable_axisymmetric']}) | "
                     f"{r['eps_3d']:g} | "
                     f"{c['e']:.5f} ({c['label']}, {c['steps']} {c['status']}) | "
                     f"{k['e']:.5f} ({k['label']}, {k['steps']} {k['status']}) | "
                     f"{r['verdict']} |")
    cpu = sum(r["control"]["cpu_s"] + r["kicked"]["cpu_s"] for r in rows)
    lines += ["", f"3D runs: {cpu:.0f} s CPU in all (FFTs on one worker each).", ""]
    notes = path.with_name(path.stem + "_notes.md")
    if notes.is_file():
        lines += [notes.read_text()]
    path.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
