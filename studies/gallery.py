"""The paper's gallery, settled: what the model makes of each of the thirteen shapes.

For every paper scene and both backends (spectral at the paper's resolution; FEM Q1 on the
same uniform mesh with the ``fft`` solver; the committed ``fem`` column was made with the
earlier consistent-stiffness Q1, before order-p elements with nodal quadrature replaced it;
``--fem-order P`` runs today's order-P FEM on the same nodes beside them as ``fem-pP`` and
writes ``pairs-fem-pP.md``), the variants

* ``a``      the paper's recipe: its scheme, penalties and Δt, from its initial condition,
             for a stated number of steps, the shape recorded along the way (a transient
             shows as a label that comes and goes);
* ``b``      the best numerics: stabilized scheme at 100× Δt, exact constraints, the paper's
             initial condition with a smooth perturbation (``perturb`` 0.05, seed 1), iterated
             with momentum (``accelerate``) to a steady state, with the paper's volume
             functional; ``b-loc`` the same with the localized one (``--volume localized``);
* ``c``      the same numerics from the paper's own shape (``--ic seeded``), perturbed the
             same way: does it stay? Its energy beside ``b``'s end; ``c-loc`` the same
             with the localized volume functional;
* ``d``      (``discocyte``, ``torus``; spectral) ε halved (ΔA₀ halved with D, so that the
             reduced targets stay) and n doubled in the variant the scene's verdict rests
             on: ``b`` for ``discocyte``, ``c`` (seeded) for ``torus``: the sharp-interface
             check.

Steady means: the relative change of E_M per step over a record interval below ``TOL``
and the same shape label over the last records. A steady state can be a saddle (the energy
rate cannot tell): every steady end of ``b``, ``b-loc``, ``c``, ``c-loc``, ``d`` is kicked
with another smooth perturbation (0.05, seed 2) and run to a steady state again (``kick``);
it is stable if the kick returns to the same label and E (to 1e-4), else the kick's end is
reported too.

The runs are one sweep (:mod:`fem_ade.campaigns.sweep`): each case a listed point — the paper's
scene with its variant's changes and run options (:func:`point_spec`) — and each kick a
point that starts from its case's end (``after``), run on a local Dask cluster of
``--workers`` processes (default 2, one thread each). Resumable: a finished run is skipped,
an interrupted one resumes from its checkpoint, a failed one is recorded with its reason
(``NAME.failed.json``), a folder made with other settings is refused.

Results in ``--out`` (default ``runs/gallery``; the committed gallery is
``studies/results/gallery/``, and only a report into it updates ``fem_ade/verdicts.json``,
which ``python -m fem_ade.run --list`` reads): the sweep's folder ``sweep/`` (a run folder
per case, ``points/VARIANT_BACKEND_SCENE``, with summary.json, history.csv, shapes.csv,
shape.png and analysis.json, and ``…_kick`` beside it; not committed: the analyses are kept
in ``analyses.json`` and the pictures as ``thumbs/``, from which ``--report-only`` rebuilds
the report without the folders), the table ``gallery.md``, a montage per backend
(``montage-BACKEND.png``: rows are scenes, columns variants) and the phase diagram
``phase-diagram.png``. Large files (final.npz, series, checkpoints) are deleted once a case
and its kick are analysed (``--keep`` keeps them). ``--scenes``, ``--backend`` and
``--variants`` choose what runs; the report always covers every run analysed in the results
folder.

    python studies/gallery.py                                # everything (hours)
    python studies/gallery.py --backend spectral --variants a b
    python studies/gallery.py --report-only                  # table, montages, diagram
    python studies/gallery.py --quick --out /tmp/g           # a smoke run (seconds)

One long file on purpose: it is one study's catalogue of cases (thirteen scenes × the
variants × two backends) with the plan, archive, verdicts and report that read only that
catalogue, and none of it is shared with another study.
"""

from __future__ import annotations

import argparse
import json
import math
import os
from pathlib import Path

import numpy as np

from fem_ade.engine.jobs import status_of
from fem_ade.model.params import ModelError
from fem_ade.plots.figures import compact_png, save_figure
from fem_ade.store.status import ENDED, Status

#: the committed gallery (its verdicts also go to fem_ade/verdicts.json when it is --out)
RESULTS = Path(__file__).resolve().parent / "results" / "gallery"
OUT = Path("runs") / "gallery"
VARIANTS = ("a", "b", "b-loc", "c", "c-loc", "d")
BACKENDS = ("spectral", "fem")
TOL = 1e-9
#: steps of the paper's recipe (variant a) per backend, and the cap of the steady-state runs
STEPS_A = {"spectral": 20000, "fem": 20000}
MAX_STEPS = 20000
PERTURB, KICK = (0.05, 1), (0.05, 2)
#: variant d halves ε in the variant each scene's verdict rests on: b for the discocyte (from
#: the paper's ellipsoid), c for the torus (its b from the paper's sphere had not settled after
#: 7000 steps at 64³; the seeded torus is the question)
SCENES_D = {"discocyte": "b", "torus": "c"}


def plan(scene_names, backends, variants, quick: bool,
         max_steps: int = MAX_STEPS, steps_a: int | None = None) -> list[dict]:
    """The runs: one dict of simulate() keyword arguments (and bookkeeping) per case."""
    from fem_ade.scenes.catalogue import PAPER_SCENES

    cases = []
    for name in scene_names:
        scene = PAPER_SCENES[name]
        for variant in variants:
            for backend in backends:
                if variant == "d" and (backend != "spectral" or name not in SCENES_D):
                    continue
                if no_seed(variant, name):
                    continue
                n = scene.n * (2 if variant == "d" else 1)
                if quick:
                    n = 12 if scene.params.L == 1.0 else 24
                options = {"solver": "fft", "order": 1} if backend == "fem" else {}
                order = fem_order(backend)
                if order is not None:  # fem-pP: order P on the same nodes (n/P cells)
                    n, options = max(3, round(n / order)) * order, {"order": order}
                kw = {"backend": "spectral" if backend == "spectral" else "fem", "n": n,
                      "every": 50, "backend_options": options,
                      "allow_underresolved": quick, "checkpoint_every": 1000}
                if variant == "a":
                    steps = 20 if quick else (steps_a or STEPS_A[kw["backend"]])
                    kw.update(steps=steps, every=max(1, steps // 100),
                              shape_every=max(1, steps // 40))
                else:
                    kw.update(scheme="stabilized", constraints="exact", accelerate=True,
                              until_steady=3e-3 if quick else TOL,
                              max_steps=60 if quick else max_steps, shape_every=10 if quick
                              else 250, perturb=PERTURB[0], seed=PERTURB[1])
                    kw["every"] = 10 if quick else 50
                    kw["dt"] = 100 * scene.dt / (8 if variant == "d" else 1)
                    if variant in ("c", "c-loc") or (variant == "d"
                                                      and SCENES_D[name] == "c"):
                        kw["ic"] = "seeded"
                cases.append({"variant": variant, "backend": backend, "scene": name,
                              "kwargs": kw})
    return cases


def fem_order(backend: str) -> int | None:
    """P of a results backend ``fem-pP`` (the FEM of order P on the scene's nodes; ``fem``
    is the order-1 FEM the table compares), else None."""
    if backend.startswith("fem-p"):
        return int(backend[len("fem-p"):])
    return None


def scene_changes(case: dict) -> dict:
    """What the case's variant changes in the paper's scene: the localized volume functional
    (``b-loc``, ``c-loc``), ε halved with ΔA₀ (``d``: D = 2ε/3 follows, the same Δa₀)."""
    if case["variant"] in ("b-loc", "c-loc"):
        return {"volume_functional": "localized"}
    if case["variant"] == "d":
        from fem_ade.scenes.catalogue import PAPER_SCENES

        p = PAPER_SCENES[case["scene"]].params
        return {"eps": p.eps / 2, "delta_A0": p.delta_A0 / 2}
    return {}


def scene_for(case: dict):
    from fem_ade.scenes.catalogue import PAPER_SCENES

    return PAPER_SCENES[case["scene"]].with_(**scene_changes(case))


#: the run folders: one fem_ade.campaigns.sweep folder (``OUT/sweep/points/VARIANT_BACKEND_SCENE``
# and
#: ``…_kick``; not committed)
SWEEP_DIR = "sweep"


def point_name(variant: str, backend: str, name: str) -> str:
    return f"{variant}_{backend}_{name}"


def run_dir(root: Path, variant: str, backend: str, name: str) -> Path:
    return root / SWEEP_DIR / "points" / point_name(variant, backend, name)


def case_dir(root: Path, case: dict) -> Path:
    return run_dir(root, case["variant"], case["backend"], case["scene"])


def kick_dir(folder: Path) -> Path:
    """The run folder of the kick of the run in ``folder``."""
    return folder.with_name(folder.name + "_kick")


def point_spec(case: dict) -> dict:
    """The case as a listed point of a sweep (:mod:`fem_ade.campaigns.sweep`): the paper's scene
    with
    the variant's changes, its run options, its perturbation's seed."""
    run = dict(case["kwargs"], render=True)
    return {"name": point_name(case["variant"], case["backend"], case["scene"]),
            "base": case["scene"], "seed": run.pop("seed", 0), "scene": scene_changes(case),
            "run": run}


def kick_spec(spec: dict) -> dict:
    """The kick of a case's point: from its end, if that is steady, perturbed by ``KICK``,
    to a steady state."""
    return {**spec, "name": spec["name"] + "_kick", "seed": KICK[1],
            "run": {**spec["run"], "perturb": KICK[0], "ic": "consistent"},
            "after": spec["name"], "when": [Status.STEADY.value]}


def as_sweep(specs: list[dict]):
    """The listed points as one sweep, checked
    (:func:`fem_ade.campaigns.sweep_file.check_sweep`)."""
    from fem_ade.campaigns.sweep_file import listed_sweep

    return listed_sweep("gallery", specs, base=specs[0]["base"])


def far_field(phi: np.ndarray, L: float, eps: float, far: float = 6.0) -> float:
    """Median of φ over grid points farther than ``far``·ε from {φ ≥ 0} (periodic)."""
    from scipy import ndimage

    n = phi.shape[0]
    k = int(math.ceil(far * eps * n / L))
    inside = np.pad(phi >= 0, k, mode="wrap")
    near = ndimage.distance_transform_edt(~inside) * (L / n) <= far * eps
    near = near[(slice(k, -k),) * phi.ndim]
    return float(np.median(phi[~near])) if (~near).any() else math.nan


def read_shapes(folder: Path) -> list[dict]:
    """The rows of a run's shapes.csv (``--shape-every``) as dicts of strings; [] without."""
    path = folder / "shapes.csv"
    if not path.is_file():
        return []
    lines = path.read_text().strip().splitlines()
    head = lines[0].split(",") if lines else []
    return [dict(zip(head, line.split(","), strict=True)) for line in lines[1:]]


def analyse(folder: Path, scene) -> dict:
    """What the table needs from a finished run folder: the summary, the far field, the
    shapes along the way; written to analysis.json so the large files can go."""
    summary = json.loads((folder / "summary.json").read_text())
    out = {"status": summary["status"], "steps": summary["steps"], "t": summary["t"],
           "wall_s": summary["wall_s"], "final": summary["final"], "shape": summary["shape"],
           "verdict": summary.get("verdict"), "restarts": summary.get("momentum_restarts", 0)}
    final, before = folder / "final.npz", folder / "analysis.json"
    if not final.is_file() and before.is_file():  # slimmed: the field is gone, its figure not
        kept = json.loads(before.read_text()).get("far_field")
        if kept is not None:
            out["far_field"] = kept
    if final.is_file():
        with np.load(final) as z:
            phi = np.array(z["phi_grid"] if "phi_grid" in z.files else z["phi"])
        out["far_field"] = far_field(phi, scene.params.L, scene.params.eps)
    if (folder / "shapes.csv").is_file():
        out["shapes"] = read_shapes(folder)
    history = folder / "history.csv"
    if history.is_file():
        from fem_ade.store.output import read_history

        h = read_history(history)
        E = h["E"]
        k = max(1, len(E) // 10)
        out["last_rate"] = (float(abs(E[-1] - E[-1 - k]) / ((h["step"][-1] - h["step"][-1 - k])
                                                            * abs(E[-1])))
                            if len(E) > k and h["step"][-1] > h["step"][-1 - k] else math.nan)
        out["E_rises"] = int(np.sum(np.diff(E) > 1e-12 * np.abs(E[1:])))
    (folder / "analysis.json").write_text(json.dumps(out, indent=1, default=str))
    return out


def slim(folder: Path) -> None:
    """Delete what the results do not need (fields, series, checkpoints) and make the
    pictures compact (256 colours)."""
    from fem_ade.store.output import series_files

    for name in ("final.npz", "checkpoint.npz", "run.json", "initial.npz"):
        (folder / name).unlink(missing_ok=True)
    for p in series_files(folder):
        p.unlink()
    for png in folder.glob("*.png"):
        try:
            compact_png(png, 64)
        except OSError:
            pass


def _archived(root: Path, case: dict, kept: dict) -> dict | None:
    """The case's analysis if it is finished: analysed in its folder (with its kick's, when
    it has one), or kept in the archive with its folder gone (it is not run again; remove its
    archive entry to); None otherwise."""
    folder = case_dir(root, case)
    path = folder / "analysis.json"
    if not path.is_file():
        entry = kept.get(_key(case["variant"], case["backend"], case["scene"]))
        if entry is not None and (case["variant"] == "a" or "kick" in entry
                                  or entry.get("status") != Status.STEADY):
            return {k: v for k, v in entry.items() if k != "kick"}
        return None
    analysis = json.loads(path.read_text())
    if case["variant"] == "a" or analysis["status"] != Status.STEADY or (
            kick_dir(folder) / "analysis.json").is_file():
        return analysis
    return None


def run_cases(root: Path, cases: list[dict], kept: dict, *, workers: int, quiet: bool,
              scheduler: str | None = None, rerun_changed: bool = False) -> None:
    """The unfinished cases and their kicks as one sweep on Dask (``workers`` processes:
    resumable, each run once; a kick runs once its case has ended, if it ended steady)."""
    from fem_ade.campaigns.sweep import run_sweep

    todo = [c for c in cases if _archived(root, c, kept) is None]
    if todo:
        specs = [point_spec(c) for c in todo]
        kicks = [kick_spec(s) for c, s in zip(todo, specs, strict=True) if c["variant"] != "a"]
        run_sweep(as_sweep(specs + kicks), root / SWEEP_DIR, workers=workers, quiet=quiet,
                  scheduler=scheduler, rerun_changed=rerun_changed)


def finish_case(root: Path, case: dict, kept: dict, *, keep: bool) -> dict | None:
    """The case's analysis (and its kick's), its large files then deleted unless ``keep``;
    None (and a line saying why) for a case that failed. A run stopped by a signal keeps its
    checkpoint for the next sitting: it is not analysed or slimmed, and the gallery stops."""
    from fem_ade.engine.jobs import read_failure

    done = _archived(root, case, kept)
    if done is not None:
        return done
    folder, scene = case_dir(root, case), scene_for(case)
    what = f"{case['variant']:5s} {case['backend']:8s} {case['scene']:16s}"
    kick = kick_dir(folder)
    kicked = case["variant"] != "a" and status_of(folder) == Status.STEADY
    runs = (folder, kick) if kicked else (folder,)
    for run in runs:
        failed = read_failure(run)
        if failed is not None:
            print(f"{what} FAILED: {failed['reason']}", flush=True)
            return None
    for run in runs:
        if status_of(run) not in ENDED:
            print(f"  {run}: {status_of(run) or 'not run'}; `studies/gallery.py` resumes it",
                  flush=True)
            raise KeyboardInterrupt
    result = analyse(folder, scene)
    if kicked:
        analyse(kick, scene)
    if not keep:
        for run in runs:
            slim(run)
    print(f"{what} {result['status']:9s} {result['steps']:6d} steps  "
          f"{result['shape']['label'] if result['shape'] else '-':14s}"
          f" E {result['final']['E']:.6g}  ({result['wall_s']:.0f} s)", flush=True)
    return result


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(OUT), help="results folder (default %(default)s)")
    ap.add_argument("--scenes", nargs="*", default=None)
    ap.add_argument("--backend", nargs="*", default=None, choices=BACKENDS,
                    help="default: both (--quick: spectral)")
    ap.add_argument("--fem-order", type=int, default=None, metavar="P",
                    help="also run the FEM of order P on the same nodes (results backend "
                    "fem-pP) and write pairs-fem-pP.md: its ends against the spectral ones")
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=VARIANTS)
    ap.add_argument("--quick", action="store_true", help="tiny grids and runs (also when CI)")
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--keep", action="store_true", help="keep fields, series and checkpoints")
    ap.add_argument("--verbose", action="store_true", help="the sweep's progress")
    ap.add_argument("--workers", type=int, default=2,
                    help="runs at once (Dask worker processes, one thread each; default 2)")
    ap.add_argument("--rerun-changed", action="store_true",
                    help="run anew the cases whose run folder was made with other settings "
                    "(refused otherwise, with the difference)")
    ap.add_argument("--scheduler", metavar="ADDRESS", default=None,
                    help="run on this Dask scheduler instead (tcp://HOST:PORT or its scheduler "
                    "file; docs/cluster.md)")
    ap.add_argument("--max-steps", type=int, default=MAX_STEPS,
                    help="cap of the steady-state runs (default %(default)s); a run that "
                    "reaches it is reported as not converged")
    ap.add_argument("--steps-a", type=int, default=None,
                    help="steps of the paper's recipe (variant a; default 20000); a finished "
                    "run keeps its own count, which the table shows")
    return ap


def main(argv=None) -> dict:
    ap = _parser()
    args = ap.parse_args(argv)
    for flag, value in (("--max-steps", args.max_steps), ("--steps-a", args.steps_a),
                        ("--workers", args.workers)):
        if value is not None and value < 1:
            ap.error(f"{flag} must be a positive integer, got {value}")
    from fem_ade.scenes.catalogue import PAPER_SCENES

    quick = args.quick or bool(os.environ.get("CI"))
    root = Path(args.out)
    names = args.scenes or (["discocyte"] if quick else list(PAPER_SCENES))
    backends = args.backend or (["spectral"] if quick else list(BACKENDS))
    if args.fem_order is not None and not 1 <= args.fem_order <= 16:
        ap.error(f"--fem-order must be 1 to 16, got {args.fem_order}")
    extra = [f"fem-p{args.fem_order}"] if args.fem_order else []
    cases = plan(names, backends + extra, args.variants, quick, args.max_steps, args.steps_a)
    kept = json.loads((root / ARCHIVE).read_text()) if (root / ARCHIVE).is_file() else {}
    results, failed = {}, 0
    try:
        if not args.report_only:
            run_cases(root, cases, kept, workers=args.workers, quiet=not args.verbose,
                      scheduler=args.scheduler, rerun_changed=args.rerun_changed)
        for case in cases:
            key = (case["variant"], case["backend"], case["scene"])
            if args.report_only:
                a = _load(root, *key, kept)
                if a is not None:
                    results[key] = {k: v for k, v in a.items() if k not in ("folder", "kick")}
                continue
            a = finish_case(root, case, kept, keep=args.keep)
            failed += a is None
            if a is not None:
                results[key] = a
    except KeyboardInterrupt:
        print("gallery interrupted: finished runs are kept, an interrupted one resumes "
              "from its checkpoint next time", flush=True)
        raise SystemExit(130) from None
    except ModelError as err:  # a changed run folder, a scheduler, a lock (FolderBusy)
        ap.exit(2, f"gallery: error: {err}\n")
    report = write_report(root, names, backends, args.variants, quick=quick)
    if extra:
        report["pairs"] = write_pairs(root, extra[0])
    if failed:
        raise SystemExit(f"gallery: {failed} case(s) failed (their reasons above); the report "
                         "shows the others")
    return {"results": results, "report": report}


def write_pairs(root: Path, backend: str) -> dict:
    """``pairs-BACKEND.md``: every case run on both the spectral backend and ``backend``
    (``fem-pP``): the two ends' labels, pieces, genus and energies."""
    from fem_ade.scenes.catalogue import PAPER_SCENES

    rows, same, close = [], 0, 0
    entries = archive(root)
    for v in VARIANTS:
        for name in PAPER_SCENES:
            a = _load(root, v, "spectral", name, entries)
            b = _load(root, v, backend, name, entries)
            if a is None or b is None or not a.get("shape") or not b.get("shape"):
                continue
            Ea, Eb = a["final"]["E"], b["final"]["E"]
            rel = abs(Eb - Ea) / abs(Ea)
            sa, sb = a["shape"], b["shape"]
            label = (sa["label"], sa["components"]) == (sb["label"], sb["components"])
            same += label
            close += rel <= 1e-3
            rows.append({"variant": v, "scene": name, "spectral": sa["label"],
                         "fem": sb["label"], "pieces": (sa["components"], sb["components"]),
                         "status": (a["status"], b["status"]), "E": (Ea, Eb), "rel": rel,
                         "same_label": label})
    lines = [f"# The gallery on {backend} against the spectral backend", "",
             f"Written by `studies/gallery.py --fem-order {fem_order(backend)}`: every case "
             f"run on both, the FEM of order {fem_order(backend)} on the scene's nodes (n/"
             f"{fem_order(backend)} cells per axis). {len(rows)} pairs, {same} with the same "
             f"label and number of pieces, {close} with energies within 1e-3.", "",
             "| variant | scene | spectral | " + backend + " | pieces | status | E spectral | "
             "E " + backend + " | rel. diff |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['variant']} | {r['scene']} | {r['spectral']} | {r['fem']} | "
                     f"{r['pieces'][0]} / {r['pieces'][1]} | {r['status'][0]} / "
                     f"{r['status'][1]} | {r['E'][0]:.8g} | {r['E'][1]:.8g} | "
                     f"{r['rel']:.1e} |")
    (root / f"pairs-{backend}.md").write_text("\n".join(lines) + "\n")
    return {"pairs": len(rows), "same_label": same, "within_1e-3": close, "rows": rows}


# ---------------------------------------------------------------------------------------
# the report: verdicts, tables, montages, phase diagram
# ---------------------------------------------------------------------------------------
#: what a reader of the gallery needs, kept beside the report: every run's analysis (and its
#: kick's) in one file, and a thumbnail of each run's picture; the run folders themselves
#: (``sweep/``) are regenerated on demand and not committed
ARCHIVE, THUMBS = "analyses.json", "thumbs"
THUMB_WIDTH = 420


def _key(variant: str, backend: str, name: str) -> str:
    return f"{variant}/{backend}/{name}"


def _thumb(root: Path, variant: str, backend: str, name: str) -> Path:
    return root / THUMBS / f"{variant}-{backend}-{name}.png"


#: what the archive keeps of each shape recorded along a run: what the verdicts read (a
#: transient is a label that comes and goes); the run folder's analysis.json has them all
SHAPE_RECORD = ("step", "t", "label")


def _compact(a: dict) -> dict:
    """An analysis as the archive keeps it (its kick's too)."""
    out = dict(a)
    if "shapes" in out:
        out["shapes"] = [{k: r[k] for k in SHAPE_RECORD if k in r} for r in out["shapes"]]
    if isinstance(out.get("kick"), dict):
        out["kick"] = _compact(out["kick"])
    return out


def archive(root: Path) -> dict:
    """Bring ``ARCHIVE`` and the thumbnails up to date with the analysed run folders under
    ``root`` (kept entries of runs whose folders are gone stay); returns the archive."""
    from PIL import Image

    from fem_ade.scenes.catalogue import PAPER_SCENES

    path = root / ARCHIVE
    old = json.loads(path.read_text()) if path.is_file() else {}
    entries = {k: _compact(a) for k, a in old.items()}
    changed = entries != old
    backends = sorted({p.name.split("_")[1] for p in (root / SWEEP_DIR / "points").glob("*_*_*")
                       if p.is_dir()})
    for v in VARIANTS:
        for b in backends:
            for n in PAPER_SCENES:
                folder = run_dir(root, v, b, n)
                if not (folder / "analysis.json").is_file():
                    continue
                a = json.loads((folder / "analysis.json").read_text())
                kick = kick_dir(folder) / "analysis.json"
                if kick.is_file():
                    a["kick"] = json.loads(kick.read_text())
                a = _compact(a)
                if entries.get(_key(v, b, n)) != a:
                    entries[_key(v, b, n)] = a
                    changed = True
                png, thumb = folder / "shape.png", _thumb(root, v, b, n)
                if b in BACKENDS and png.is_file() and (not thumb.is_file()  # the montages
                                      or thumb.stat().st_mtime < png.stat().st_mtime):
                    thumb.parent.mkdir(parents=True, exist_ok=True)
                    with Image.open(png) as im:
                        w, h = im.size
                        cell = im.convert("RGB").crop((0, int(0.17 * h), w, h))
                        cell = cell.resize((THUMB_WIDTH, round(THUMB_WIDTH * cell.size[1]
                                                               / cell.size[0])),
                                           Image.Resampling.LANCZOS)
                    cell.quantize(32).save(thumb, optimize=True)
    if changed:
        path.write_text(json.dumps(entries, separators=(",", ":"), sort_keys=True, default=str)
                        + "\n")
    return entries


def _load(root: Path, variant: str, backend: str, name: str,
          entries: dict | None = None) -> dict | None:
    """A run's analysis (and its kick's): from its folder, else from the archive."""
    folder = run_dir(root, variant, backend, name)
    path = folder / "analysis.json"
    if path.is_file():
        a = json.loads(path.read_text())
        kick = kick_dir(folder) / "analysis.json"
        if kick.is_file():
            a["kick"] = json.loads(kick.read_text())
        a["folder"] = str(folder)
        return a
    if entries and _key(variant, backend, name) in entries:
        return dict(entries[_key(variant, backend, name)], folder=None)
    return None


def _picture(root: Path, variant: str, backend: str, name: str, a: dict) -> Path:
    """The run's committed thumbnail, else (a run not archived yet) its shape.png: the
    montage is then the same from a fresh clone as from the folder that ran the gallery."""
    thumb = _thumb(root, variant, backend, name)
    if thumb.is_file() or not a.get("folder"):
        return thumb
    return Path(a["folder"]) / "shape.png"


def interrupted(root: Path, variant: str, backend: str, name: str) -> str | None:
    """The verdict of a run that was stopped before it finished (no analysis.json, a
    history): where it got to and the last shape recorded; None otherwise."""
    folder = run_dir(root, variant, backend, name)
    if (folder / "analysis.json").is_file() or not (folder / "history.csv").is_file():
        return None
    from fem_ade.store.output import read_history

    steps = int(read_history(folder / "history.csv")["step"][-1])
    rows = read_shapes(folder)
    label = f"{rows[-1]['label']} at step {rows[-1]['step']}" if rows else "-"
    again = ("resumable" if (folder / "checkpoint.npz").is_file()
             else "no checkpoint: a rerun starts again")
    return f"interrupted at step {steps} ({label}); {again}"


def no_seed(variant: str, name: str) -> str | None:
    """Why a seeded variant (c, c-loc) of scene ``name`` cannot run, or None."""
    from fem_ade.scenes.seeds import SIZES

    if variant in ("c", "c-loc") and name not in SIZES:
        return "no seed at ε = 0.05 (fem_ade/scenes/seeds.py)"
    return None


def _label(a: dict | None) -> str:
    return a["shape"]["label"] if a and a.get("shape") else "-"


def verdict(a: dict | None, paper: str, variant: str) -> str:
    """reproduced / transient (window) / different steady shape (which) / not converged,
    with the stability the kick showed. Variant a (a fixed number of steps at the paper's
    Δt) is never called steady: its shape is reported at its final time, and a paper shape
    seen only along the way as a transient."""
    if a is None:
        return "not run"
    label = _label(a)
    if a["status"] == Status.DIVERGED:
        return f"diverged at step {a['steps']}"
    if variant == "a":  # a fixed number of steps at the paper's Δt: never called steady
        seen = [r for r in a.get("shapes", []) if r["label"] == paper]
        t = f"t = {float(a['t']):.2g}"
        if label == paper:  # the b criterion at 1/100 of b's Δt: TOL/100 per step
            moving = a.get("last_rate", 1.0) > TOL / 100
            return f"reproduced at {t}" + (" (still evolving)" if moving else " (steady)")
        if seen:
            t0, t1 = float(seen[0]["t"]), float(seen[-1]["t"])
            return f"transient: {paper} for t in [{t0:.2g}, {t1:.2g}], then {label}"
        return f"not seen by {t} ({label} at the end)"
    if a["status"] != Status.STEADY:
        return f"not converged ({label} after {a['steps']} steps)"
    kick = a.get("kick")
    stable = None
    if kick is not None and kick.get("shape"):
        dE = abs(kick["final"]["E"] - a["final"]["E"]) / abs(a["final"]["E"])
        stable = _label(kick) == label and dE < 1e-4
    what = "reproduced" if label == paper else f"different steady shape: {label}"
    if stable is None:
        return what + " (stability not tested)"
    if stable:
        return what + ", stable"
    lower = "lower" if kick["final"]["E"] < a["final"]["E"] else "higher"
    return (what + f" — a saddle: a kick ends as {_label(kick)} at E = "
            f"{kick['final']['E']:.5g} ({lower})")


def _f(x, fmt="{:.4g}"):
    try:
        return fmt.format(float(x)) if x is not None and math.isfinite(float(x)) else "-"
    except (TypeError, ValueError):
        return "-"


def _row(scene, variant, backend, a) -> str:
    p = scene.params
    if a is None:
        return f"| {scene.name} | {variant} | {backend} | not run |" + " |" * 19
    sh, fin = a.get("shape") or {}, a["final"]
    body = sh.get("body") or {}
    dA0 = fin["dA"] / p.delta_A0 if p.delta_A0 and fin.get("dA") else None
    t = _f(a["t"], "{:.3g}") if variant == "a" else "—"
    cells = [scene.name, variant, backend, a["status"], str(a["steps"]), t, sh.get("label", "-"),
             str(sh.get("components", "-")), ",".join(map(str, sh.get("genus", []))) or "-",
             str(sh.get("arms", "-")), _f(sh.get("reduced_volume"), "{:.3f}"),
             _f(sh.get("reduced_area_difference"), "{:.3f}"),
             _f(body.get("elongation"), "{:.2f}"), _f(body.get("flatness"), "{:.2f}"),
             str(body.get("necks", "-")), _f(body.get("dimple"), "{:.2f}"),
             _f(fin["V"] / p.alpha, "{:.4f}"), _f(fin["A"] / p.beta, "{:.4f}"),
             _f(dA0, "{:.3f}"), _f(a.get("far_field"), "{:.4f}"), _f(fin["E"], "{:.5g}"),
             _f(fin["W"], "{:.5g}"), _f(fin["G"], "{:.4g}"), _f(a["wall_s"], "{:.0f}"),
             verdict(a, scene.shape, variant)]
    return "| " + " | ".join(cells) + " |"


HEADER = ("| scene | variant | backend | status | steps | t | label | comps | genus | arms | "
          "v | Δa | a₁/a₂ | a₃/a₂ | necks | dimple | V/α | A/β | ΔA/ΔA₀ | φ far | E | W | G | "
          "wall s | verdict |")


def _with_analysed(root: Path, names, backends, variants) -> tuple[list, list, list]:
    """The selection widened to every scene, backend and variant analysed under ``root``, in
    the catalogue's order: a run of a few cells rewrites the whole report, not a report of
    those cells alone."""
    from fem_ade.scenes.catalogue import PAPER_SCENES

    kept = json.loads((root / ARCHIVE).read_text()) if (root / ARCHIVE).is_file() else {}
    found = [(v, b, n) for v in VARIANTS for b in BACKENDS for n in PAPER_SCENES
             if (run_dir(root, v, b, n) / "analysis.json").is_file() or _key(v, b, n) in kept]
    vs = set(variants) | {v for v, _, _ in found}
    bs = set(backends) | {b for _, b, _ in found}
    ns = set(names) | {n for _, _, n in found}
    return ([n for n in PAPER_SCENES if n in ns], [b for b in BACKENDS if b in bs],
            [v for v in VARIANTS if v in vs])


def write_report(root: Path, names, backends, variants, quick: bool = False) -> dict:
    """gallery.md, montage-BACKEND.png and phase-diagram.png from the analysed runs: those
    of the selection and every other one under ``root``."""
    from fem_ade.scenes.catalogue import PAPER_SCENES

    root.mkdir(parents=True, exist_ok=True)
    entries = archive(root)
    names, backends, variants = _with_analysed(root, names, backends, variants)
    data = {(v, b, n): _load(root, v, b, n, entries) for v in variants for b in backends
            for n in names}
    lines = ["# The paper's gallery, settled", "",
             "Generated by `studies/gallery.py` (its docstring says what each variant runs). "
             "Labels are those of `fem_ade.analysis.shape.classify`; v and Δa are the sharp "
             "surface's reduced volume and area difference; V/α, A/β, ΔA/ΔA₀ the diffuse "
             "values; φ far the median of φ farther than 6ε from the vesicle.", "",
             *_verdicts_table(root, data, names, backends, variants),
             *_runs_table(data, names, backends, variants),
             *_backends_table(data, names, variants),
             *_pictures(root, data, names, backends, variants)]
    (root / "gallery.md").write_text("\n".join(lines) + "\n")
    verdicts = {k: verdict(a, PAPER_SCENES[k[2]].shape, k[0]) if a is not None
                else interrupted(root, *k) for k, a in data.items()}
    verdicts = {k: v for k, v in verdicts.items() if v is not None}
    if root.resolve() == RESULTS.resolve() and not quick:
        write_verdicts(verdicts)
    return {"verdicts": verdicts}


def _verdicts_table(root: Path, data: dict, names, backends, variants) -> list[str]:
    """The report's first section: each scene's verdict per variant and backend."""
    from fem_ade.scenes.catalogue import PAPER_SCENES

    columns = [(v, b) for v in variants for b in backends if (v, b) != ("d", "fem")]
    lines = ["## Verdicts", "",
             "| scene | paper | " + " | ".join(f"{v} ({b})" for v, b in columns) + " |",
             "|---|---|" + "---|" * len(columns)]
    for n in names:
        scene = PAPER_SCENES[n]
        cells = [verdict(data[(v, b, n)], scene.shape, v) if data[(v, b, n)]
                 else interrupted(root, v, b, n) or no_seed(v, n) or "—" for v, b in columns]
        lines.append(f"| {n} ({scene.figure}) | {scene.shape} | " + " | ".join(cells) + " |")
    return lines


def _runs_table(data: dict, names, backends, variants) -> list[str]:
    """Every run (and its kick) with its numbers."""
    lines = ["", "## Every run", "", HEADER, "|" + "---|" * (HEADER.count("|") - 1)]
    for n in names:
        for v in variants:
            for b in backends:
                if (v, b) == ("d", "fem") or (v == "d" and n not in SCENES_D):
                    continue
                case = {"variant": v, "backend": b, "scene": n}
                a = data[(v, b, n)]
                if a is None and no_seed(v, n):
                    continue
                lines.append(_row(scene_for(case), v, b, a))
                if a is not None and a.get("kick"):
                    lines.append(_row(scene_for(case), v + " kick", b, a["kick"]))
    return lines


def _backends_table(data: dict, names, variants) -> list[str]:
    """The FEM's end against the spectral one, per variant and scene."""
    lines = ["", "## FEM against spectral (same variant, same scene)", "",
             "| scene | variant | label spectral | label FEM | E spectral | E FEM | rel. diff |",
             "|---|---|---|---|---|---|---|"]
    for n in names:
        for v in variants:
            s, f = data.get((v, "spectral", n)), data.get((v, "fem", n))
            if s and f:
                Es, Ef = s["final"]["E"], f["final"]["E"]
                lines.append(f"| {n} | {v} | {_label(s)} | {_label(f)} | {Es:.6g} | {Ef:.6g} | "
                             f"{abs(Ef - Es) / abs(Es):.2e} |")
    return lines


def _pictures(root: Path, data: dict, names, backends, variants) -> list[str]:
    """The montages and the phase diagram (drawn), then the notes."""
    lines = []
    for b in backends:
        path = montage(root, data, names, b, [v for v in variants if v != "d" or b == "spectral"])
        if path:
            lines += ["", f"![montage {b}]({path.name})"]
    path = phase_diagram(root, data, names)
    if path:
        lines += ["", f"![phase diagram]({path.name})"]
    notes = root / "notes.md"
    if notes.is_file():
        lines += ["", notes.read_text()]
    return lines


#: where ``python -m fem_ade.run --list`` reads each scene's verdict
VERDICTS = Path(__file__).resolve().parents[1] / "fem_ade" / "verdicts.json"
#: the run a scene's one-line verdict comes from, in order of preference
HEADLINE = (("c", "spectral"), ("b", "spectral"), ("c", "fem"), ("b", "fem"),
            ("a", "spectral"), ("a", "fem"))


def write_verdicts(verdicts: dict) -> None:
    """fem_ade/verdicts.json: per scene, its headline verdict and every run's (merged with
    what is there, so a partial gallery run keeps the others)."""
    old = json.loads(VERDICTS.read_text()) if VERDICTS.is_file() else {}
    VERDICTS.write_text(json.dumps(merged_verdicts(verdicts, old), indent=1, sort_keys=True)
                        + "\n")


def archived_verdicts(root: Path = RESULTS) -> dict:
    """{(variant, backend, scene): verdict} of every run in ``root``'s archive (the
    gallery's two backends; what fem_ade/verdicts.json is made of)."""
    from fem_ade.scenes.catalogue import PAPER_SCENES

    entries = json.loads((root / ARCHIVE).read_text())
    out = {}
    for key, a in entries.items():
        v, b, n = key.split("/")
        if b in BACKENDS:
            out[(v, b, n)] = verdict(a, PAPER_SCENES[n].shape, v)
    return out


def merged_verdicts(verdicts: dict, old: dict) -> dict:
    """``old`` (verdicts.json's content) with ``verdicts`` merged in and the headlines
    rewritten."""
    old = json.loads(json.dumps(old))
    for (v, b, n), text in verdicts.items():
        old.setdefault(n, {"runs": {}})["runs"][f"{v} ({b})"] = text
    for entry in old.values():
        for v, b in HEADLINE:
            if f"{v} ({b})" in entry["runs"]:
                entry["headline"] = f"{v} ({b}): {entry['runs'][f'{v} ({b})']}"
                break
        paper = entry["runs"].get("a (spectral)", "")
        if paper.startswith(("transient", "reproduced")):  # what the paper's recipe shows
            entry["headline"] += f"; paper's recipe (a): {paper}"
        if "d (spectral)" in entry["runs"]:  # the sharp-interface check, where it ran
            entry["headline"] += f"; with eps halved (d): {entry['runs']['d (spectral)']}"
    return old


def montage(root: Path, data, names, backend, variants) -> Path | None:
    """Rows: scenes; columns: variants; each cell the run's shape.png (3D view and section)."""
    from matplotlib.figure import Figure
    from PIL import Image

    cells = {(n, v): _picture(root, v, backend, n, data[(v, backend, n)])
             for n in names for v in variants if data.get((v, backend, n))}
    cells = {k: p for k, p in cells.items() if p.is_file()}
    if not cells:
        return None
    names = [n for n in names if any((n, v) in cells for v in variants)]  # rows and columns
    variants = [v for v in variants if any((n, v) in cells for n in names)]  # that were run
    # captions large enough to read when the README shows the montage ~900 px wide
    fig = Figure(figsize=(3.4 * len(variants) + 1.8, 2.15 * len(names) + 0.7), dpi=70)
    grid = fig.subplots(len(names), len(variants), squeeze=False)
    for i, n in enumerate(names):
        for j, v in enumerate(variants):
            ax = grid[i][j]
            ax.set_axis_off()
            if (n, v) in cells:
                with Image.open(cells[(n, v)]) as im:
                    w, h = im.size
                    full = cells[(n, v)].parent.name != THUMBS  # a thumbnail is cropped
                    ax.imshow(np.asarray(im.convert("RGB").crop(
                        (0, int(0.17 * h) if full else 0, w, h))))
                a = data[(v, backend, n)]
                status = {"diverged": f"diverged at step {a['steps']}",
                          "max_steps": f"at the cap, step {a['steps']}"}.get(a["status"])
                ax.set_title(_label(a) + (f" ({status})" if status else ""), fontsize=15)
            if i == 0:
                ax.text(0.5, 1.35, f"variant {v}", transform=ax.transAxes, ha="center",
                        fontsize=18, fontweight="bold")
            if j == 0:
                ax.text(-0.05, 0.5, n, transform=ax.transAxes, ha="right", va="center",
                        fontsize=16, fontweight="bold")
    fig.subplots_adjust(left=0.15, right=0.995, top=0.965, bottom=0.005, wspace=0.02,
                        hspace=0.32)
    path = root / f"montage-{backend}.png"
    save_figure(fig, path, colours=64)  # a palette: a fifth of the bytes, no visible change
    return path


def spheroid_branches(k: int = 200):
    """(v, Δa) of prolate and oblate spheroids: the reference branches of the diagram."""
    th = np.linspace(1e-4, np.pi - 1e-4, 4001)
    out = {}
    for kind, ratios in (("prolate spheroids", np.linspace(1.0, 6.0, k)),
                         ("oblate spheroids", np.linspace(1.0, 0.15, k))):
        pts = []
        for c in ratios:  # polar semi-axis c, equatorial 1
            rho = np.sin(th)
            dr, dz = np.cos(th), -c * np.sin(th)
            ddr, ddz = -np.sin(th), -c * np.cos(th)
            ds = np.sqrt(dr**2 + dz**2)
            k1 = (dr * ddz - dz * ddr) / ds**3
            k2 = -dz / (rho * ds)
            dA = 2 * np.pi * rho * ds
            A = np.trapezoid(dA, th)
            H = np.trapezoid(0.5 * np.abs(k1 + k2) * dA, th)
            V = 4.0 / 3.0 * np.pi * c
            R = math.sqrt(A / (4 * np.pi))
            pts.append((V / (4.0 / 3.0 * np.pi * R**3), H / (4 * np.pi * R)))
        out[kind] = np.array(pts)
    return out


def phase_diagram(root: Path, data, names) -> Path | None:
    """Every steady end state on the sharp-interface axes (v, Δa), with the targets."""
    from matplotlib.figure import Figure

    from fem_ade.scenes.catalogue import PAPER_SCENES

    fig = Figure(figsize=(11.5, 6.5), dpi=100)
    ax = fig.subplots()
    for kind, pts in spheroid_branches().items():
        ax.plot(pts[:, 0], pts[:, 1], color="0.6", lw=1.2,
                ls="-" if kind.startswith("prolate") else "--", label=kind)
    ax.plot([1 / math.sqrt(2)], [math.sqrt(2)], "s", color="0.4", ms=7,
            label="two equal spheres (limit)")
    ax.plot([1], [1], "o", color="0.4", ms=7, label="sphere")
    marks = {"b": "o", "b-loc": "^", "c": "D", "c-loc": "s", "d": "*"}
    colours = {}
    palette = ["#c0392b", "#2980b9", "#27ae60", "#8e44ad", "#d35400", "#16a085", "#2c3e50",
               "#f39c12", "#7f8c8d", "#e84393", "#6c5ce7", "#00b894", "#b33939"]
    shown = False
    for i, n in enumerate(names):
        colours[n] = palette[i % len(palette)]
        v0, m0 = PAPER_SCENES[n].params.reduced_targets()
        ax.plot([v0], [m0], "x", color=colours[n], ms=9, mew=2, label=n)
        for v, mk in marks.items():
            a = data.get((v, "spectral", n))
            if a and a.get("shape") and a["status"] == Status.STEADY:
                sh = a["shape"]
                ax.plot([sh["reduced_volume"]], [sh["reduced_area_difference"]], mk,
                        color=colours[n], ms=7, mfc="none" if v.endswith("-loc") else colours[n])
                shown = True
    if not shown:
        return None
    for v, mk in marks.items():
        ax.plot([], [], mk, color="k", mfc="none" if v.endswith("-loc") else "k",
                label=f"end of variant {v} (spectral)")
    ax.plot([], [], "x", color="k", label="targets v₀, Δa₀ (diffuse α, β, ΔA₀)")
    ax.set_xlabel("reduced volume v (sharp surface)")
    ax.set_ylabel("reduced area difference Δa (sharp surface)")
    ax.set_title("steady end states on the sharp-interface phase-diagram axes")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    path = root / "phase-diagram.png"
    save_figure(fig, path, colours=64, bbox_inches="tight")
    return path


if __name__ == "__main__":
    main()
