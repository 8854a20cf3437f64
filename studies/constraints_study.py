"""Constraints study (issue 6, item 4): how well do the paper's shapes appear depending on
how the volume (α) and area (β) constraints are enforced?

For the scenes ``discocyte`` (n = 32), ``torus`` (n = 48, perturbation 0.05, seed 1) and
``gourd`` (n = 32), all with the spectral backend and the stabilized large-step scheme,
four variants are compared:

* ``M1x``   penalties at the paper's M₁ = 1e5, M₂ = 1e4;
* ``M10x``  penalties × 10;
* ``M100x`` penalties × 100;
* ``exact`` ``constraints="exact"``: V = α and A = β held at every step by Lagrange multipliers
  solved inside the step's implicit operator (``fem_ade/model/constraints.py``, commit cbc9968;
  before it, an L² projection after the step, whose steady states depended on Δt),
  penalties off.

Δt of each case: a short trial (``--trial-steps`` steps, a record every ``--every`` steps)
at 100×, 30×, 10×, 3×, 1× the scene's paper Δt, largest first; the first Δt at which the run
does not diverge and E_M decreases at every record is used (the same rule for the exact
variant). If none passes, the non-diverged trial Δt with the fewest E_M rises is used (ties:
the largest) and the report marks it with †.

Each case then runs with ``until_steady=1e-6`` (relative change of E_M per step, averaged
over a record interval) and a cap ``max_steps`` chosen from the step cost measured in the
trial so that one run takes about ``--budget`` seconds at most (the trial's outcome waits in
the case's trial.json until case.json holds it, so that a case interrupted after its trial
does not repeat it). The trials run one after another (their step costs are measured with
nothing beside them); the runs then run as one sweep of listed points on ``--workers`` Dask
processes (:mod:`fem_ade.campaigns.sweep`; the run folders ``OUT/constraints/sweep/points/NAME``,
resumable, a failure recorded with its reason). As the sweep ends, each case's results go
to ``OUT/constraints/<scene>-<variant>/`` (case.json, and the run's summary.json and
shape.png); the far-field (bulk) value of φ and the volume it carries are measured from
the final φ (:func:`bulk_offset`) and stored in case.json; final.npz and run.json are
deleted if larger than 1 MB (``--clean`` deletes every final.npz, run.json and
checkpoint.npz afterwards, so the committed results stay small). ``OUT/constraints.md``
gets the tables; the hand-written observations in ``OUT/constraints/notes.md`` (if present)
are included in it verbatim.

    python studies/constraints_study.py                 # until_steady 1e-6
    python studies/constraints_study.py --long --tol 1e-8 --budget 170   # stricter
    python studies/constraints_study.py --check --budget 170   # continuation check
    python studies/constraints_study.py --quick --out /tmp/q   # n = 16, 20 steps
    python studies/constraints_study.py --report-only   # rebuild constraints.md from results
    python studies/constraints_study.py --dt-trial --scenes torus --variants exact
                                        # the Δt trial at every factor
    python studies/constraints_study.py --clean --report-only   # measure the bulk offset of
                                        # every final.npz still present, then delete them

After the fix of the exact constraints (commit cbc9968) only the exact variant was rerun:
``--variants exact`` for both passes, then ``--check``, then ``--clean --report-only``.

The results in studies/results were made with exactly these commands (under ``nice -n 10``);
what each took is in constraints.md (``--budget`` caps a run's seconds).

One long file on purpose: one study's cases (three scenes × four ways of holding V and A)
through every step they take — the Δt trial, the run, the continuation check, the bulk
offset, the report's tables — none of which another study uses.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

from fem_ade.plots.figures import compact_png
from fem_ade.store.status import Status

DT_FACTORS = (100, 30, 10, 3, 1)
VARIANTS = {  # name: (penalty factor or None for exact, label)
    "M1x": (1, "penalty, paper M₁ = 1e5, M₂ = 1e4"),
    "M10x": (10, "penalty × 10 (M₁ = 1e6, M₂ = 1e5)"),
    "M100x": (100, "penalty × 100 (M₁ = 1e7, M₂ = 1e6)"),
    "exact": (None, "exact constraints (multipliers inside the step, penalties off)"),
}
SCENES = {  # name: (n, extra simulate kwargs)
    "discocyte": (32, {}),
    "torus": (48, {"perturb": 0.05, "seed": 1}),
    "gourd": (32, {}),
}
BIG = 1 << 20  # 1 MB


def scene_for(name: str, variant: str):
    from fem_ade.scenes.catalogue import get_scene

    scene = get_scene(name)
    factor = VARIANTS[variant][0]
    if factor is not None and factor != 1:
        p = scene.params
        scene = scene.with_(M1=p.M1 * factor, M2=p.M2 * factor)
    return scene


def common_kwargs(name: str, variant: str, n: int, extra: dict, allow: bool) -> dict:
    return dict(
        backend="spectral",
        n=n,
        scheme="stabilized",
        constraints="exact" if VARIANTS[variant][0] is None else "penalty",
        quiet=True,
        allow_underresolved=allow,
        **extra,
    )


def _compress(png: Path) -> None:
    """A picture the results keep: 0.45 of the render's size in 32 colours (a twelfth of the
    bytes; the captions and the section stay legible: looked at)."""
    if png.is_file():
        compact_png(png, 32, scale=0.45)


def energy_rises(history: list[dict], rel: float = 1e-12) -> int:
    """How many records have E_M above the previous record (beyond ``rel`` relative)."""
    Es = [float(r["E"]) for r in history]
    return sum(1 for a, b in zip(Es, Es[1:], strict=False) if b > a + rel * abs(a))


def find_dt(
    name: str,
    variant: str,
    n: int,
    extra: dict,
    *,
    trial_steps: int,
    every: int,
    allow: bool,
    stop_at_ok: bool = True,
) -> tuple[float, list[dict]]:
    """The largest Δt of DT_FACTORS × paper Δt with no divergence and E_M decreasing.

    ``stop_at_ok=False`` runs every factor (the full trial of ``--dt-trial``)."""
    from fem_ade.engine.runs import simulate
    from fem_ade.model.params import ModelError

    scene = scene_for(name, variant)
    log = []
    for f in DT_FACTORS:
        dt = f * scene.dt
        try:
            r = simulate(
                scene,
                dt=dt,
                steps=trial_steps,
                every=every,
                **common_kwargs(name, variant, n, extra, allow),
            )
            rises = energy_rises(r.history)
            ok = r.status != Status.DIVERGED and rises == 0
            Es = [float(h["E"]) for h in r.history]
            rel = [(b - a) / abs(a) for a, b in zip(Es, Es[1:], strict=False)]
            entry = {
                "factor": f,
                "dt": dt,
                "status": r.status,
                "steps": r.steps,
                "rises": rises,
                "ok": ok,
                "ms_per_step": 1e3 * r.wall_s / max(r.steps, 1),
                "message": r.message if r.status == Status.DIVERGED else "",
                "max_rise_rel": max(rel, default=math.nan),
                "E_first": Es[0] if Es else math.nan,
                "E_last": Es[-1] if Es else math.nan,
                "E_records": [[int(h["step"]), float(h["E"])] for h in r.history],
            }
        except ModelError as err:  # e.g. the initial projection fails
            entry = {
                "factor": f,
                "dt": dt,
                "status": "error",
                "steps": 0,
                "rises": 0,
                "ok": False,
                "ms_per_step": math.nan,
                "message": str(err),
            }
        log.append(entry)
        if entry["ok"] and stop_at_ok:
            return dt, log
    oks = [e["dt"] for e in log if e["ok"]]
    return (oks[0] if oks else math.nan), log


def dt_trial(name: str, variant: str, out_root: Path, *, trial_steps: int, every: int) -> dict:
    """Every Δt factor's trial (not only up to the first that passes) for one case; writes
    ``OUT/constraints/dt_trial/<scene>-<variant>.json``."""
    n, extra = SCENES[name]
    t0 = time.perf_counter()
    _, log = find_dt(
        name,
        variant,
        n,
        extra,
        trial_steps=trial_steps,
        every=every,
        allow=False,
        stop_at_ok=False,
    )
    rep = {
        "scene": name,
        "variant": variant,
        "n": n,
        "extra": extra,
        "trial_steps": trial_steps,
        "every": every,
        "trials": log,
        "wall_s": time.perf_counter() - t0,
    }
    path = out_root / "constraints" / "dt_trial" / f"{name}-{variant}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(rep, indent=1, default=str))
    return rep


def _volume_budget_table(out_root: Path, scenes, variants) -> list[str]:
    """Where the diffuse volume sits, for the until_steady = 1e-8 pass.

    V (diffuse) ≈ V_sharp + ΔV_interface + ΔV_bulk: ΔV_interface = (π²/6) ε² ∫H dA is the
    excess of ∫(φ + 1)/2 over the enclosed volume for a tanh profile across a surface of
    mean curvature H (second order in ε; for a sphere (π²/2)(ε/R)² of its volume), ΔV_bulk
    from :func:`bulk_offset`; *rest* is what these two do not account for.
    """
    from fem_ade.scenes.catalogue import get_scene

    out = [
        "# Where the diffuse volume sits (until_steady = 1e-8 pass)",
        "",
        "V/α (diffuse) ≈ V/α (sharp) + interface + bulk. *interface* = (π²/6) ε² ∫H dA / α, "
        "the excess of ∫(φ + 1)/2 over the enclosed volume for a tanh profile across a "
        "surface of mean curvature H (H from the extracted surface; for a sphere "
        "(π²/2)(ε/R)² of its volume); *bulk* = bulk ΔV/α of the tables above; *rest* = "
        "what the two do not account for (profile not tanh, far field not uniform).",
        "",
        "| scene | variant | V/α (diffuse) | V/α (sharp) | interface | bulk | rest | "
        "A/β (sharp) | bulk ΔA/β |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name in scenes:
        eps = get_scene(name).params.eps
        for variant in variants:
            cj = out_root / "constraints" / "long" / f"{name}-{variant}" / "case.json"
            if not cj.is_file():
                continue
            c = json.loads(cj.read_text())
            sharp = (c.get("shape") or {}).get("sharp") or {}
            bulk = c.get("bulk") or {}
            if not sharp or not bulk:
                continue
            a = c["alpha"]
            vd = c["final"]["V"] / a
            vs = sharp["V"] / a
            itf = math.pi**2 / 6 * eps**2 * sharp["mean_curvature_integral"] / a
            bv = bulk.get("dV_bulk_over_alpha", math.nan)
            out.append(
                f"| {name} | {variant} | {vd:.4f} | {vs:.4f} | {itf:+.4f} | {_f(bv, '{:+.4f}')} | "
                f"{_f(vd - vs - itf - bv, '{:+.4f}')} | {sharp['A'] / c['beta']:.4f} | "
                f"{_f(bulk.get('dA_bulk_over_beta'), '{:+.4f}')} |"
            )
    return out + [""]


def _dt_trial_table(out_root: Path) -> list[str]:
    files = sorted((out_root / "constraints" / "dt_trial").glob("*.json"))
    if not files:
        return []
    out = [
        "# Full Δt trials (`--dt-trial`): every factor, not only up to the first that passes",
        "",
        "| scene | variant | factor | Δt | status | records with E_M up | largest change "
        "ΔE/E record to record (> 0: a rise) | E_M first → last record |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for f in files:
        rep = json.loads(f.read_text())
        for e in rep["trials"]:
            out.append(
                f"| {rep['scene']} | {rep['variant']} | {e['factor']}× | {e['dt']:.3g} | "
                f"{e['status']} | {e['rises']} of {max(len(e.get('E_records', [])) - 1, 0)} | "
                f"{_f(e.get('max_rise_rel'), '{:+.1e}')} | "
                f"{_f(e.get('E_first'))} → {_f(e.get('E_last'))} |"
            )
    return out + [""]


def fallback_dt(log: list[dict]) -> float:
    """No Δt passed: the non-diverged trial with the fewest E_M rises (ties: the largest Δt)."""
    runs = [e for e in log if e["status"] == Status.COMPLETED]
    if not runs:
        return math.nan
    return min(runs, key=lambda e: (e["rises"], -e["dt"]))["dt"]


def trial_stage(name: str, variant: str, out: Path, n: int, extra: dict, *, trial_steps: int,
                every: int, tol: float, allow: bool) -> tuple[dict, float]:
    """The case's record so far (its settings and Δt trials) and the Δt to run at (NaN: no
    trial ran): the trial kept in ``out/trial.json`` if one was made for these settings
    before the run started (so that a run that has ended, or is resumed, is not preceded by
    a new trial), else a new one."""
    case = {
        "scene": name,
        "variant": variant,
        "n": n,
        "extra": extra,
        "trials": None,
        "trial_steps": trial_steps,
        "every": every,
        "tol": tol,
        "dt_passed": True,
    }
    kept = _kept_trial(out, case)
    if kept is not None:
        return kept
    dt, log = find_dt(name, variant, n, extra, trial_steps=trial_steps, every=every, allow=allow)
    case["trials"] = log
    if not math.isfinite(dt):
        dt = fallback_dt(log)
        case["dt_passed"] = False
    return case, dt


def _kept_trial(out: Path, case: dict) -> tuple[dict, float] | None:
    """The record and Δt in ``out/trial.json`` if its settings are ``case``'s, else None."""
    try:
        kept = json.loads((out / "trial.json").read_text())
        old, dt = kept["case"], float(kept["dt"])
    except (OSError, ValueError, TypeError, KeyError):
        return None
    same = isinstance(old, dict) and all(
        old.get(k) == v for k, v in case.items() if k not in ("trials", "dt_passed"))
    return (old, dt) if same else None


def case_point(case: dict, dt: float, *, quick: bool, budget: float) -> tuple[dict, dict]:
    """The case's production run as a listed point of the pass's sweep (its scene, variant
    and Δt, and a cap ``max_steps`` from the trial's step cost so that it takes about
    ``budget`` seconds) and the run's length options (``until_steady`` and ``max_steps``, or
    ``steps`` for ``--quick``)."""
    from fem_ade.scenes.catalogue import scene_to_mapping

    name, variant, n, every = case["scene"], case["variant"], case["n"], case["every"]
    ms = [e["ms_per_step"] for e in case["trials"] if e["dt"] == dt][0]
    if quick:
        run_kw = {"steps": 20}
    else:
        cap = int(budget / (1.3 * ms * 1e-3)) // every * every
        run_kw = {"until_steady": case["tol"], "max_steps": max(cap, every)}
    print(f"  {name}-{variant}: dt = {dt:.3g} ({dt / scene_for(name, variant).dt:g}x paper), "
          f"{ms:.2f} ms/step in trial, {run_kw}", flush=True)
    kw = common_kwargs(name, variant, n, case["extra"], quick)
    seed = kw.pop("seed", 0)
    kw.pop("quiet")
    run = dict(dt=dt, every=10 if quick else every, **run_kw, **kw, render=True)
    spec = {"name": f"{name}-{variant}", "base": scene_to_mapping(scene_for(name, variant)),
            "seed": seed, "run": run}
    return spec, run_kw


def run_points(specs: list[dict], root: Path, workers: int) -> None:
    """The pass's production runs as one sweep of listed points in ``root``
    (:mod:`fem_ade.campaigns.sweep`: ``root/points/NAME``, on ``workers`` Dask processes, resumable,
    a failure recorded with its reason)."""
    from fem_ade.campaigns.sweep import run_sweep
    from fem_ade.campaigns.sweep_file import listed_sweep

    run_sweep(listed_sweep(root.parent.name, specs), root, workers=workers, quiet=True)


def finish_case(case: dict, dt: float, out: Path, run: Path, run_kw: dict) -> dict:
    """A case whose run in ``run`` has ended: the bulk offset measured, large files dropped,
    the run's summary.json and shape.png beside case.json in ``out`` (what the report and
    the results keep), case.json written; a failed run's reason as a ModelError."""
    import shutil

    from fem_ade.engine.jobs import read_failure, read_summary
    from fem_ade.model.params import ModelError

    summary, failed = read_summary(run), read_failure(run)
    if summary is None or failed is not None:
        reason = failed["reason"] if failed else "not run"
        raise ModelError(f"{case['scene']}-{case['variant']}: {reason}")
    scene = scene_for(case["scene"], case["variant"])
    bulk = _final_bulk(run, scene.params)
    for f in ("final.npz", "run.json"):
        fp = run / f
        if fp.is_file() and fp.stat().st_size > BIG:
            fp.unlink()
    for f in ("summary.json", "shape.png"):
        if (run / f).is_file():
            shutil.copy2(run / f, out / f)
    case.update(_run_record(summary, run_history(run), scene, dt, run_kw), bulk=bulk)
    (out / "case.json").write_text(json.dumps(case, indent=1, default=str))
    (out / "trial.json").unlink(missing_ok=True)  # case.json has it now
    return case


def _final_bulk(out: Path, p) -> dict | None:
    """:func:`bulk_offset` of the run's final φ (None without final.npz)."""
    if not (out / "final.npz").is_file():
        return None
    import numpy as np

    with np.load(out / "final.npz") as z:
        return bulk_offset(np.array(z["phi"]), p.L, p.eps, p.alpha, p.beta)


def _run_record(r: dict, history: list[dict], scene, dt: float, run_kw: dict) -> dict:
    """What case.json keeps of a run: its Δt, outcome, final state, targets and energy
    record (in case.json's order, the bulk offset after it)."""
    p = scene.params
    return dict(
        dt=dt,
        dt_factor=dt / scene.dt,
        paper_dt=scene.dt,
        status=r["status"],
        steps=r["steps"],
        t=r["t"],
        message=r["message"],
        wall_s=r["wall_s"],
        max_steps=run_kw.get("max_steps"),
        final=r["final"],
        shape=r["shape"],
        alpha=p.alpha,
        beta=p.beta,
        delta_A0=p.delta_A0,
        M1=p.M1,
        M2=p.M2,
        rises=energy_rises(history),
        records=len(history),
        E0=float(history[0]["E"]),
        E_end=float(history[-1]["E"]),
        last_rate=_last_rate(history),
    )


CHECK_RUNS = (  # label, variant, Δt factor
    ("exact-100x-dt", "exact", 100),
    ("exact-10x-dt", "exact", 10),
    ("exact-1x-dt", "exact", 1),
    ("M100x-100x-dt", "M100x", 100),
)


def continuation_check(out_root: Path, *, budget: float, quiet: bool = False, labels=None) -> dict:
    """Is the exact variant's steady discocyte a property of the model or of the large Δt?

    (With the superseded L² projection it was not: the shape moved when continued at a
    smaller Δt. With the multipliers inside the step it should not move.)

    Takes the final φ of ``constraints/long/discocyte-exact`` (exact constraints, 100× Δt)
    and continues it (a) with exact constraints at 100× (the same Δt: a control for how much
    the state still drifts at its own Δt), 10× and 1× the paper's Δt (at 1× the scheme's
    operator is closest to 1/Δt), and (b) with penalties × 100 at 100× Δt (the M100x
    variant's scheme). ``labels``: run only these of :data:`CHECK_RUNS`, keeping the others'
    results already in continuation.json. Records E, W, G, V, A, the sharp shape descriptors and
    :func:`bulk_offset` before and after; writes
    ``OUT/constraints/check/continuation.json`` and a shape.png per continuation.
    """
    import numpy as np

    from fem_ade.engine.jobs import status_of
    from fem_ade.store.status import ENDED

    src = run_folder(out_root / "constraints" / "long" / "discocyte-exact") / "final.npz"
    with np.load(src) as z:
        phi0 = np.array(z["phi"])
    rep_path = out_root / "constraints" / "check" / "continuation.json"
    old = json.loads(rep_path.read_text())["runs"] if rep_path.is_file() else {}
    report = {"source": str(src), "runs": {}}
    for label, variant, factor in CHECK_RUNS:
        out = out_root / "constraints" / "check" / label
        wanted = not labels or label in labels
        if not wanted or (label in old and status_of(out) in ENDED):  # its row is kept
            if label in old:
                report["runs"][label] = old[label]
            continue
        report["runs"][label] = continue_from(phi0, out, variant, factor, budget=budget)
        _tidy_check_folder(out)
        if not quiet:
            print(label, json.dumps(report["runs"][label]["end"]), flush=True)
    rep_path.parent.mkdir(parents=True, exist_ok=True)
    rep_path.write_text(json.dumps(report, separators=(",", ":"), default=str))
    return report


def continue_from(phi0, out: Path, variant: str, factor: float, *, budget: float) -> dict:
    """Continue ``phi0`` into ``out`` with ``variant``'s constraints at ``factor`` × the
    paper's Δt for about ``budget`` seconds (whole 500-step records); returns its row of
    continuation.json: the run, its start and end states and its energy record."""
    import numpy as np

    from fem_ade.engine.jobs import ensure
    from fem_ade.engine.runs import simulate

    scene = scene_for("discocyte", variant)
    cons = "exact" if variant == "exact" else "penalty"
    dt = factor * scene.dt
    kw = dict(backend="spectral", n=phi0.shape[0], dt=dt, scheme="stabilized",
              constraints=cons, phi0=phi0, quiet=True)
    probe = simulate(scene, steps=20, every=20, **kw)  # the step cost sets the length
    steps = max(int(budget / (1.3 * probe.wall_s / 20)) // 500 * 500, 500)
    r = ensure(out, scene, options=dict(kw, steps=steps, every=500),
               restart=True).check().summary
    history = run_history(out)
    with np.load(out / "final.npz") as z:
        phi1 = np.array(z["phi"])
    return {
        "dt": dt,
        "steps": r["steps"],
        "status": r["status"],
        "wall_s": r["wall_s"],
        "start": _check_state(history[0], phi0, scene.params),
        "end": _check_state(r["final"], phi1, scene.params),
        "history": [{k: h[k] for k in ("step", "E", "W", "G", "V", "A")} for h in history],
        "rises": energy_rises(history),
    }


def _check_state(energies: dict, phi, p) -> dict:
    """One end of a continuation: E, W, G, V, A, ΔA, the sharp shape's descriptors and the
    bulk offset of ``phi``."""
    from fem_ade.analysis.shape import describe

    sh = describe(phi, p.L)
    keys = ("components", "genus", "reduced_volume", "reduced_area_difference")
    return {
        **{k: energies[k] for k in ("E", "W", "G", "V", "A", "dA")},
        **{k: sh[k] for k in keys},
        "sharp": sh["sharp"],
        "bulk": bulk_offset(phi, p.L, p.eps, p.alpha, p.beta),
    }


def _tidy_check_folder(out: Path) -> None:
    """Keep of a continuation's folder what the tables cite: its summary, history and a
    compressed shape.png."""
    from fem_ade.store.output import series_files

    for f in ("final.npz", "run.json", "initial.npz", "history.png"):
        (out / f).unlink(missing_ok=True)  # the tables cite shape.png only
    for f in series_files(out):
        f.unlink()
    _compress(out / "shape.png")


def bulk_offset(
    phi, L: float, eps: float, alpha: float, beta: float | None = None, *, far: float = 6.0
) -> dict:
    """The value of φ far from the vesicle and the diffuse volume it carries.

    The diffuse volume V = ∫(φ + 1)/2 is taken over the whole periodic box, so a bulk value
    φ_far ≠ −1 adds (φ_far + 1)/2 per unit volume of the outside. Returned: ``phi_corner``
    (φ at the box corner, the point farthest from a centred vesicle), ``phi_far`` (the median
    of φ over the grid points farther than ``far``·ε from {φ ≥ 0}, periodic distance),
    ``phi_far_min``/``phi_far_max`` (its range there), ``far_fraction`` (the fraction of the
    box they cover), ``outside_volume`` (the volume of {φ < 0}) and ``dV_bulk`` =
    (φ_far + 1)/2 × outside_volume, with ``dV_bulk_over_alpha``; with ``beta``, also the
    diffuse area the offset carries, ``dA_bulk`` = (3√2/4)(φ_far² − 1)²/(4ε) × outside_volume
    (the gradient term vanishes in a uniform bulk), and ``dA_bulk_over_beta``.
    """
    import numpy as np
    from scipy import ndimage

    phi = np.asarray(phi, dtype=float)
    n = phi.shape[0]
    h = L / n
    pad = n // 2
    tiled = np.pad(phi < 0, pad, mode="wrap")
    dist = ndimage.distance_transform_edt(tiled, sampling=h)[pad:-pad, pad:-pad, pad:-pad]
    mask = dist > far * eps
    out_vol = float(np.count_nonzero(phi < 0)) * h**3
    res = {"phi_corner": float(phi[0, 0, 0]), "far_eps": far, "outside_volume": out_vol}
    if not mask.any():
        return {**res, "phi_far": math.nan, "dV_bulk": math.nan, "dV_bulk_over_alpha": math.nan}
    vals = phi[mask]
    pf = float(np.median(vals))
    dv = (pf + 1) / 2 * out_vol
    if beta is not None:
        da = 0.75 * math.sqrt(2.0) * (pf * pf - 1.0) ** 2 / (4.0 * eps) * out_vol
        res.update(dA_bulk=da, dA_bulk_over_beta=da / beta)
    return {
        **res,
        "phi_far": pf,
        "phi_far_min": float(vals.min()),
        "phi_far_max": float(vals.max()),
        "far_fraction": float(mask.mean()),
        "dV_bulk": dv,
        "dV_bulk_over_alpha": dv / alpha,
    }


def add_bulk(case_dir: Path) -> bool:
    """Measure :func:`bulk_offset` on ``case_dir/final.npz`` into ``case.json`` (if both exist)."""
    import numpy as np

    from fem_ade.scenes.catalogue import get_scene

    cj, fz = case_dir / "case.json", run_folder(case_dir) / "final.npz"
    if not (cj.is_file() and fz.is_file()):
        return False
    c = json.loads(cj.read_text())
    if "status" not in c or c["status"] == "no stable dt":
        return False
    p = get_scene(c["scene"]).params
    with np.load(fz) as z:
        phi = np.array(z["phi"])
    c["bulk"] = bulk_offset(phi, p.L, p.eps, p.alpha, p.beta)
    cj.write_text(json.dumps(c, indent=1, default=str))
    return True


def run_folder(case_dir: Path) -> Path:
    """Where a case's run is: its pass's ``sweep/points/NAME``, or the case folder itself
    where it was run before the runs were a sweep (and its final.npz is still there)."""
    run = case_dir.parent / "sweep" / "points" / case_dir.name
    return case_dir if (case_dir / "final.npz").is_file() and not run.is_dir() else run


def clean(root: Path) -> list[Path]:
    """Delete every final.npz, run.json and checkpoint.npz under ``root`` (regenerable)."""
    gone = []
    for pattern in ("final.npz", "run.json", "checkpoint.npz"):
        for fp in sorted(root.rglob(pattern)):
            fp.unlink()
            gone.append(fp)
    return gone


def run_history(folder: Path) -> list[dict]:
    """A run folder's history.csv as one dict per record."""
    from fem_ade.store.output import read_history

    h = read_history(folder / "history.csv")
    return [dict(zip(h, values, strict=True)) for values in zip(*h.values(), strict=True)]


def _last_rate(history: list[dict]) -> float:
    """|ΔE|/(Δsteps·|E|) over the last record interval (the steady criterion's quantity)."""
    if len(history) < 2:
        return math.nan
    a, b = history[-2], history[-1]
    ds = max(int(b["step"]) - int(a["step"]), 1)
    return abs(float(b["E"]) - float(a["E"])) / (ds * max(abs(float(b["E"])), 1e-300))


# ---------------------------------------------------------------------------------------
# The report
# ---------------------------------------------------------------------------------------
def _f(x, fmt="{:.4f}"):
    try:
        x = float(x)
    except (TypeError, ValueError):
        return "–"
    return fmt.format(x) if math.isfinite(x) else "–"


def _targets(alpha, beta, delta_A0, D):
    v0 = alpha / (4 * math.pi / 3 * (beta / (4 * math.pi)) ** 1.5)
    m0 = delta_A0 / (8 * math.pi * D * math.sqrt(beta / (4 * math.pi)))
    return v0, m0


def _outcome(e: dict) -> str:
    if e["ok"]:
        return "ok"
    if e["status"] == Status.COMPLETED:
        return f"E rose at {e['rises']} records"
    return e["status"]


HEADER = """# Constraints study: penalties at 1×, 10×, 100× the paper's M vs exact constraints

Generated by `studies/constraints_study.py` (issue 6, item 4). Spectral backend, stabilized
scheme (`scheme="stabilized"`), records every 50 steps, stopped by `until_steady` (relative
change of E_M per step over a record interval) or by a step cap chosen from the step cost
measured in the Δt trial (status `max_steps (cap)`). Δt: the largest of 100×, 30×, 10×, 3×,
1× the paper's Δt at which a short trial run did not diverge and E_M decreased at every
record (applied to the exact variant too). The torus starts from the paper's sphere with a
smooth perturbation `perturb=0.05, seed=1` (identical for all four variants). Resolution:
n = 32 (discocyte, gourd), n = 48 (torus).

Columns: V/α, A/β, ΔA/ΔA₀ are the final diffuse (phase-field) values over the targets; *v*
and *Δa* are the reduced volume and reduced area difference of the **sharp** extracted
surface φ = 0 (sphere: v = Δa = 1); comps/genus/arms from the same surface; *E rises*
counts records at which E_M went up during the run; *last rate* is the steady criterion's
quantity |ΔE|/(50·|E|) over the last record interval; *t* = steps × Δt; wall is the run only
(not the Δt trials). For the exact variant E_M = W + G (the penalties are off).
*V/α (sharp)*, *A/β (sharp)*: volume and area enclosed by the extracted surface φ = 0 over
the targets. *φ far*: the median of the final φ over grid points farther than 6ε from
{φ ≥ 0} (periodic distance); *φ corner*: φ at the box corner; *bulk ΔV/α*: the diffuse
volume the far-field offset carries, (φ far + 1)/2 × vol{φ < 0}, over α (negative when the
far field lies below −1).

Code: exact variant rerun at commit cbc9968 ("Exact constraints: solve the multipliers inside
the step"); the penalty rows are the runs of the previous study, not rerun (cbc9968
refactored the penalty step into a reusable P⁻¹ but left it algebraically the same; rerun
at cbc9968, discocyte-M1x reproduces E, W, G, V, A, ΔA of its row bit for bit)."""

SETS = (
    ("constraints", "until_steady = 1e-6 (the brief's criterion)"),
    ("constraints/long", "until_steady = 1e-8 (a stricter confirmation pass)"),
)


def _row(c: dict, rel: str) -> str:
    fin, sh = c.get("final") or {}, c.get("shape") or {}
    sharp, bulk = sh.get("sharp") or {}, c.get("bulk") or {}
    genus = sh.get("genus")
    genus = ",".join(str(g) for g in genus) if isinstance(genus, list) else genus
    status = c["status"]
    if status == Status.MAX_STEPS:
        status = f"max_steps ({c.get('max_steps')})"
    dt = f"{c['dt']:.3g} ({c['dt_factor']:g}×)"
    if not c.get("dt_passed", True):
        dt += " †"
    return (
        f"| {c['variant']} | {dt} | {c['steps']} | {_f(c['t'], '{:.3g}')} | {status} | "
        f"{_f(fin.get('V', math.nan) / c['alpha'])} | "
        f"{_f(fin.get('A', math.nan) / c['beta'])} | "
        f"{_f(fin.get('dA', math.nan) / c['delta_A0'])} | {sh.get('components', '–')} | "
        f"{genus} | {sh.get('arms', '–')} | {_f(sh.get('reduced_volume'), '{:.3f}')} | "
        f"{_f(sh.get('reduced_area_difference'), '{:.3f}')} | "
        f"{_f(sharp.get('V', math.nan) / c['alpha'], '{:.3f}')} | "
        f"{_f(sharp.get('A', math.nan) / c['beta'], '{:.3f}')} | "
        f"{_f(bulk.get('phi_far'))} | {_f(bulk.get('phi_corner'))} | "
        f"{_f(bulk.get('dV_bulk_over_alpha'), '{:+.3f}')} | {c['rises']} | "
        f"{_f(c.get('last_rate'), '{:.1e}')} | {_f(c['wall_s'], '{:.0f}')} | [png]({rel}) |"
    )


TABLE_HEAD = (
    "| variant | Δt used | steps | t | status | V/α | A/β | ΔA/ΔA₀ | comps | genus | "
    "arms | v (sharp) | Δa (sharp) | V/α (sharp) | A/β (sharp) | φ far | φ corner | "
    "bulk ΔV/α | E rises | last rate | wall [s] | shape |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
)


def _check_table(out_root: Path) -> list[str]:
    path = out_root / "constraints" / "check" / "continuation.json"
    if not path.is_file():
        return []
    rep = json.loads(path.read_text())
    out = [
        "# Continuation check (`--check`): does the exact variant's steady discocyte depend on Δt?",
        "",
        "Start: the final φ of `constraints/long/discocyte-exact` (exact constraints, "
        "100× Δt, steady at 1e-8). Continued with the scheme named in the first column; "
        "E_M includes the penalty terms only for M100x; *last rate* as above (records "
        "every 500 steps).",
        "",
        "| continuation | Δt | steps | E start → end | W end | G end | V/α end | "
        "v (sharp) start → end | Δa (sharp) end | φ far end | bulk ΔV/α end | E rises | "
        "last rate | wall [s] | shape |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    alpha = 0.0289
    for label, r in rep["runs"].items():
        h = r["history"]
        rate = abs(h[-1]["E"] - h[-2]["E"]) / (500 * abs(h[-1]["E"])) if len(h) > 1 else math.nan
        a, b = r["start"], r["end"]
        out.append(
            f"| {label} | {r['dt']:.3g} | {r['steps']} | {a['E']:.4f} → {b['E']:.4f} | "
            f"{b['W']:.4f} | {b['G']:.4f} | {b['V'] / alpha:.4f} | "
            f"{a['reduced_volume']:.3f} → {b['reduced_volume']:.3f} | "
            f"{b['reduced_area_difference']:.3f} | "
            f"{_f((b.get('bulk') or {}).get('phi_far'))} | "
            f"{_f((b.get('bulk') or {}).get('dV_bulk_over_alpha'), '{:+.3f}')} | "
            f"{r['rises']} | {rate:.1e} | "
            f"{r['wall_s']:.0f} | [png](constraints/check/{label}/shape.png) |"
        )
    return out + [""]


def write_report(out_root: Path, scenes, variants) -> Path:
    """Write ``OUT/constraints.md`` from the cases' case.json files (and the notes); returns
    its path."""
    lines = [HEADER, ""]
    for subdir, title in SETS:
        if (out_root / subdir).is_dir():
            lines += _results_section(out_root, subdir, title, scenes, variants)
    lines += _trials_section(out_root, scenes, variants)
    lines += _volume_budget_table(out_root, scenes, variants)
    lines += _dt_trial_table(out_root)
    lines += _check_table(out_root)
    notes = out_root / "constraints" / "notes.md"
    if notes.is_file():
        lines += [notes.read_text().rstrip(), ""]
    path = out_root / "constraints.md"
    path.write_text("\n".join(lines))
    return path


def _results_section(out_root: Path, subdir: str, title: str, scenes, variants) -> list[str]:
    """One result set's section: a table per scene, a row per variant."""
    from fem_ade.scenes.catalogue import get_scene

    lines = [f"# Results with {title}", ""]
    for name in scenes:
        sc = get_scene(name)
        p = sc.params
        v0, m0 = _targets(p.alpha, p.beta, p.delta_A0, p.D)
        lines += [
            f"## {name} ({sc.figure}, ε = {p.eps:g}, paper Δt = {sc.dt:g}) — "
            f"{title.split(' (')[0]}",
            "",
            f"Targets: α = {p.alpha:g}, β = {p.beta:g}, ΔA₀ = {p.delta_A0:g}; "
            f"in reduced (diffuse) terms v₀ = {v0:.3f}, Δa₀ = {m0:.3f}.",
            "",
            TABLE_HEAD,
        ]
        for variant in variants:
            c = _read_case(out_root, subdir, name, variant)
            if c is None:
                lines.append(f"| {variant} | – | – | – | not run |" + " |" * 17)
            elif c["status"] == "no stable dt":
                lines.append(f"| {variant} | no Δt ran | – | – | not run |" + " |" * 17)
            else:
                lines.append(_row(c, f"{subdir}/{name}-{variant}/shape.png"))
        lines.append("")
    return lines


def _read_case(out_root: Path, subdir: str, name: str, variant: str) -> dict | None:
    """A case's case.json (None if it has none)."""
    cj = out_root / subdir / f"{name}-{variant}" / "case.json"
    return json.loads(cj.read_text()) if cj.is_file() else None


def _trials_section(out_root: Path, scenes, variants) -> list[str]:
    """The Δt trials of the first result set, one row per case, and the compute of both
    sets (production runs and trials)."""
    total_wall = total_trials = 0.0
    trial_lines, trial_desc = [], "?"
    for subdir, _ in SETS:
        if not (out_root / subdir).is_dir():
            continue
        for name in scenes:
            for variant in variants:
                c = _read_case(out_root, subdir, name, variant)
                if c is None:
                    continue
                total_trials += sum(
                    e["steps"] * e["ms_per_step"] * 1e-3
                    for e in c["trials"]
                    if math.isfinite(float(e["ms_per_step"]))
                )
                if subdir == SETS[0][0]:
                    trial_desc = f"{c.get('trial_steps')} (a record every {c.get('every')})"
                    trial_lines.append(_trial_line(name, variant, c))
                if c["status"] != "no stable dt":
                    total_wall += float(c.get("wall_s") or 0)
    return [
        "# Δt trials",
        "",
        f"Trial: {trial_desc} steps, largest factor first; the first `ok` is used. "
        "† = no factor passed; the run used the non-diverged trial Δt with the fewest "
        "E_M rises (ties: the largest).",
        "",
        "| scene | variant | trials (factor × paper Δt: outcome) | Δt used |",
        "|---|---|---|---|",
        *trial_lines,
        "",
        f"Compute: production runs {total_wall / 60:.1f} min, Δt trials ≈ "
        f"{total_trials / 60:.1f} min (sum of step times; both passes), on 2 cores "
        "shared with another benchmark (`nice -n 10`).",
        "",
    ]


def _trial_line(name: str, variant: str, c: dict) -> str:
    """A case's row of the Δt trials table: each factor's outcome and the Δt used."""
    return (
        f"| {name} | {variant} | "
        + "; ".join(f"{e['factor']}×: {_outcome(e)}" for e in c["trials"])
        + f" | {_f(c['dt'], '{:.3g}')}"
        + ("" if c.get("dt_passed", True) else " †")
        + " |"
    )


def parse_args(argv=None) -> argparse.Namespace:
    """The command line's options (see the module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="runs/studies",
                    help="results root (default %(default)s; the committed: studies/results)")
    ap.add_argument(
        "--quick", action="store_true", help="tiny smoke run: discocyte, n = 16, 20 steps (< 30 s)"
    )
    ap.add_argument("--scenes", nargs="*", default=None, choices=list(SCENES))
    ap.add_argument("--variants", nargs="*", default=None, choices=list(VARIANTS))
    ap.add_argument(
        "--budget",
        type=float,
        default=150.0,
        help="target wall seconds of one production run (sets max_steps)",
    )
    ap.add_argument("--trial-steps", type=int, default=1000)
    ap.add_argument("--every", type=int, default=50)
    ap.add_argument("--tol", type=float, default=1e-6)
    ap.add_argument(
        "--long", action="store_true", help="the confirmation pass: results in OUT/constraints/long"
    )
    ap.add_argument(
        "--check",
        action="store_true",
        help="continue the exact discocyte at 100x, 10x, 1x dt and with penalties x 100",
    )
    ap.add_argument(
        "--check-runs",
        nargs="*",
        default=None,
        choices=[c[0] for c in CHECK_RUNS],
        help="with --check: only these continuations (the others' results are kept)",
    )
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--workers", type=int, default=2,
                    help="Dask workers of the production runs (the trials run one at a time)")
    ap.add_argument(
        "--dt-trial",
        action="store_true",
        help="run the Δt trial at every factor for --scenes × --variants (no production run)",
    )
    ap.add_argument(
        "--clean",
        action="store_true",
        help="measure the bulk offset of every case with a final.npz, then delete every "
        "final.npz, run.json and checkpoint.npz under OUT/constraints",
    )
    return ap.parse_args(argv)


def main(argv=None) -> list[dict]:
    """Run the study (see the module docstring); return the cases run (their case.json)."""
    args = parse_args(argv)
    out_root = Path(args.out)
    scenes = args.scenes or (["discocyte"] if args.quick else list(SCENES))
    variants = args.variants or list(VARIANTS)
    trial_steps, every = (10, 5) if args.quick else (args.trial_steps, args.every)
    if args.check:
        report = continuation_check(out_root, budget=args.budget, labels=args.check_runs)
        return list(report["runs"].values())
    if args.dt_trial:
        full_dt_trials(out_root, scenes, variants, trial_steps=trial_steps, every=every)
        return []
    if args.clean:
        measure_and_clean(out_root / "constraints")
    cases = []
    if not args.report_only:
        cases = run_cases(args, out_root, scenes, variants, trial_steps=trial_steps,
                          every=every)
    path = write_report(
        out_root, list(SCENES) if args.report_only or not args.quick else scenes, variants
    )
    print(f"wrote {path}")
    return cases


def full_dt_trials(out_root: Path, scenes, variants, *, trial_steps: int, every: int) -> None:
    """``--dt-trial``: every factor's trial of each case, printed as it ends."""
    for name in scenes:
        for variant in variants:
            rep = dt_trial(name, variant, out_root, trial_steps=trial_steps, every=every)
            for e in rep["trials"]:
                print(
                    f"{name}-{variant} {e['factor']}x: {e['status']}, {e['rises']} rises, "
                    f"largest {e.get('max_rise_rel')}",
                    flush=True,
                )


def measure_and_clean(root: Path) -> None:
    """``--clean``: the bulk offset of every case with a final.npz, then the large files
    deleted (each printed)."""
    for cj in sorted(root.rglob("case.json")):
        if add_bulk(cj.parent):
            print(f"bulk offset measured: {cj.parent}")
    for fp in clean(root):
        print(f"deleted {fp}")


def run_cases(args: argparse.Namespace, out_root: Path, scenes, variants, *,
              trial_steps: int, every: int) -> list[dict]:
    """Each case of ``scenes`` × ``variants`` in the pass's folder (``--long``: the
    confirmation pass): its Δt trial, one after another (their step costs are measured
    with nothing beside them), then the production runs of those without a case.json as
    one sweep in ``PASS/sweep`` (:func:`run_points`), each finished into its case folder
    as the sweep ends (:func:`finish_case`); prints each; returns their case.json (a run
    that failed: SystemExit with the reasons, after the others are written)."""
    from fem_ade.engine.jobs import status_of
    from fem_ade.model.params import ModelError
    from fem_ade.store.status import ENDED

    subdir = SETS[1][0] if args.long else SETS[0][0]
    root = out_root / subdir
    root.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    cases, pending = {}, []
    for name in scenes:
        for variant in variants:
            out = root / f"{name}-{variant}"
            if (out / "case.json").is_file() and status_of(out) in ENDED:  # not run again
                cases[out.name] = json.loads((out / "case.json").read_text())
                continue
            n = 16 if args.quick else SCENES[name][0]
            case, dt = trial_stage(name, variant, out, n, SCENES[name][1],
                                   trial_steps=trial_steps, every=every, tol=args.tol,
                                   allow=args.quick)
            out.mkdir(parents=True, exist_ok=True)
            if not math.isfinite(dt):
                cases[out.name] = case = {**case, "status": "no stable dt", "dt": math.nan}
                (out / "case.json").write_text(json.dumps(case, indent=1, default=str))
                continue
            (out / "trial.json").write_text(json.dumps({"case": case, "dt": dt}, default=str))
            pending.append((case, dt, out, *case_point(case, dt, quick=args.quick,
                                                       budget=args.budget)))
    if pending:
        run_points([spec for *_, spec, _ in pending], root / "sweep", args.workers)
    failed = []
    for case, dt, out, spec, run_kw in pending:
        try:
            cases[out.name] = finish_case(case, dt, out, root / "sweep" / "points" /
                                          spec["name"], run_kw)
        except ModelError as err:
            failed.append(str(err))
    order = [f"{name}-{variant}" for name in scenes for variant in variants]
    for key in (k for k in order if k in cases):
        c = cases[key]
        print(f"{key}: {c['status']} after {c.get('steps')} steps, "
              f"{c.get('wall_s', 0):.1f} s; elapsed {time.perf_counter() - t0:.0f} s",
              flush=True)
    if failed:
        raise SystemExit("constraints_study: " + "; ".join(failed))
    return [cases[k] for k in order if k in cases]


if __name__ == "__main__":
    main()
