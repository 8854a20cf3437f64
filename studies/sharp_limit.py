"""How close to the sharp membrane: the axisymmetric sharp reference (``sharp_ref``) along its
branches, and where its lowest-energy branch changes.

Stage ``branches`` (the minimal model: bending only, fixed area and volume): the prolate,
oblate and stomatocyte branches and the axisymmetric torus at v = 0.50, 0.55, …, 0.95 (where
each exists), the sphere and the Willmore torus; the lowest-energy branch of genus 0 at each
v and the reduced volumes where it changes, each found as the root of the energy difference
of the two branches (a quadratic through three solves 0.01 apart around the sign change).
Classic values to compare with (Seifert, Berndl & Lipowsky, Phys. Rev. A 44, 1182 (1991)):
prolate ↔ oblate at v ≈ 0.652, oblate ↔ stomatocyte at v ≈ 0.592.

Stage ``eps`` (the limit ε → 0): for the sphere, the Clifford torus, and the prolate, oblate
and stomatocyte branches at v ∈ {0.95, 0.8, 0.65, 0.6, 0.55} where the branch exists, a
phase-field steady state seeded from the sharp meridian (initial condition ``meridian``: the
tanh profile of the signed distance to it), the minimal model (bending, volume, area; no
ADE), exact constraints with the localized volume (α and β those of the sharp shape of R₀
chosen to fit the box with a margin of ≥ 4.75 ε at the largest ε), the ``steady`` recipe
(stabilized scheme at 100× Δt = 0.75 ε³, momentum, until the relative change of E per step
is below 1e-9), at ε ∈ {0.04, 0.032, 0.02, 0.016} (and 0.0128, 0.01 for the cases that keep
their branch at 0.016, ``--fine``) with n = 1.28/ε points per axis (nodes per ε held fixed:
ε/h = 1.28), on the spectral backend, and for six cases that keep their branch on the FEM
too (order 4 on the same nodes, ε ≥ 0.016). e = W / (16√2π/3), the bending energy over that
of a sharp sphere in the model's units. The observed order p from the three smallest ε, then
Richardson over the two smallest: e₀ = e(ε₂) − (e(ε₁) − e(ε₂)) / ((ε₁/ε₂)^p − 1). A run
keeps its branch if its surface is one body of genus 0 (1 for the torus) with the branch's
label (prolate/cylinder/gourd/chain, oblate/discocyte; any genus-0 label for the sphere and
the stomatocyte) and reduced area difference within 0.12 of the sharp one (see ``LABELS``).
With two such ε only, p = 2 is assumed (marked).

Results: ``OUT/sharp_limit.md`` (tables), ``OUT/sharp_limit.json`` (``rows``: one per
(backend, branch, v) with e_sharp, e_extrapolated, rel_diff, eps, e_phase_field,
kept_branch; ``branches``, ``transitions``: the sharp stage), ``OUT/sharp-branches.png`` (w
along each branch; meridians), ``OUT/sharp-eps.png`` (e against ε², extrapolations) and
``OUT/sharp-sections.png`` (the phase field's φ = 0 at the smallest ε over the sharp
meridian). Every solve and run is cached in ``OUT/sharp/solves.json`` and
``OUT/sharp/runs.json`` (resumable: nothing cached is redone); the phase-field runs of a
stage are one sweep (:mod:`fem_ade.campaigns.sweep`: two Dask workers, each run in
``OUT/sharp/sweep/points/NAME``, resumed where it was killed).

    python studies/sharp_limit.py --out studies/results     # everything (~2 h on 2 cores)
    python studies/sharp_limit.py --out studies/results --stages eps --backends fem
    python studies/sharp_limit.py --out studies/results --report-only   # from the caches
    python studies/sharp_limit.py --quick          # a look in seconds (under runs/studies)
"""

from __future__ import annotations

import argparse
import json
import math
import re
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from fem_ade.analysis.sharp import (  # a sharp sphere's W (model units, per κ)
    SPHERE_W,
    reduced_energy,
)
from fem_ade.plots.render import save_figure
from fem_ade.store.output import write_json_atomic
from fem_ade.store.status import Status
from sharp_ref.branches import solve
from sharp_ref.membrane import BranchError

DEFAULT_OUT = Path("runs/studies")  # the committed results: --out studies/results
GRID = tuple(round(0.50 + 0.05 * i, 2) for i in range(10))  # 0.50 … 0.95
BRANCHES = ("prolate", "oblate", "stomatocyte")  # genus 0: the classic diagram's
COLUMNS = BRANCHES + ("torus",)  # the table's: genus 1 beside them
#: (lower branch above, lower branch below, first guess of the v where they swap)
TRANSITIONS = (("prolate", "oblate", 0.65), ("oblate", "stomatocyte", 0.59))


def _key(branch: str, v) -> str:
    return f"{branch}@{'free' if v is None else f'{v:.4f}'}"


class Cache:
    """{key: row} in a JSON file, written after each solve (atomically: a temporary file
    renamed over the old one)."""

    def __init__(self, path: Path):
        self.path = path
        self.rows = json.loads(path.read_text()) if path.is_file() else {}

    def get(self, branch: str, v, *, compute: bool = True) -> dict | None:
        key = _key(branch, v)
        if key not in self.rows and compute:
            t0 = time.perf_counter()
            try:
                solved = solve(branch, v).to_json()
                row = {k: solved[k] for k in ("branch", "v", "w", "e", "da", "converged",
                                              "residual")}
                row["r"], row["z"] = ([round(x, 7) for x in solved[k]] for k in ("r", "z"))
            except BranchError as err:
                row = {"branch": branch, "v": v, "missing": str(err)}
            row["seconds"] = round(time.perf_counter() - t0, 1)
            print(f"  {key}: " + (f"w = {row['w']:.10f}" if "w" in row else row["missing"])
                  + f"  ({row['seconds']} s)", flush=True)
            self.rows[key] = row
            self.path.parent.mkdir(parents=True, exist_ok=True)
            write_json_atomic(self.path, dict(sorted(self.rows.items())), indent=None)
        return self.rows.get(key)


def _ade_solve(branch: str, v: float, m0: float, kbar: float):
    """sharp_ref's membrane with ADE; where its anchor does not reach it (the pear below
    m₀ ≈ 1.68 at v = 0.85), by continuation down in m₀ from 1.8 in steps of at most 0.04
    (as studies/ade_plane.py follows it)."""
    try:
        return solve(branch, v, m0=m0, kbar=kbar)
    except BranchError:
        if branch != "pear" or m0 >= 1.8:
            raise
    steps = max(1, math.ceil((1.8 - m0) / 0.04))
    result = None
    for k in range(steps + 1):
        result = solve(branch, v, m0=1.8 - (1.8 - m0) * k / steps, kbar=kbar, start=result)
    return result


def ade_sharp(cache: Cache, branch: str, v: float, m0: float, kbar: float,
              compute: bool = True) -> dict | None:
    """The sharp membrane with area-difference elasticity (κ̄/κ = ``kbar``, m₀), cached in
    the same file as the minimal model's under "ade:BRANCH@V/m0=M0/kbar=K"."""
    key = f"ade:{_key(branch, v)}/m0={m0:g}/kbar={kbar:g}"
    if key not in cache.rows and compute:
        t0 = time.perf_counter()
        try:
            solved = _ade_solve(branch, v, m0, kbar).to_json()
            row = {k: solved[k] for k in ("branch", "v", "w", "e", "da", "converged",
                                          "residual")}
            row["r"], row["z"] = ([round(x, 7) for x in solved[k]] for k in ("r", "z"))
        except BranchError as err:
            row = {"branch": branch, "v": v, "missing": str(err)}
        row.update(m0=m0, kbar=kbar, seconds=round(time.perf_counter() - t0, 1))
        print(f"  {key}: " + (f"e = {row['e']:.10f}" if "e" in row else row["missing"]),
              flush=True)
        cache.rows[key] = row
        cache.path.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(cache.path, dict(sorted(cache.rows.items())), indent=None)
    return cache.rows.get(key)


def crossing(cache: Cache, upper: str, lower: str, guess: float, compute: bool = True) -> dict:
    """The v where ``upper`` (lowest above it) and ``lower`` (lowest below) have equal w:
    the root of a quadratic through their differences at three v, 0.01 apart, that bracket
    it (moved along until they do)."""
    vs = [round(guess - 0.01, 2), round(guess, 2), round(guess + 0.01, 2)]
    for _ in range(8):
        rows = [(cache.get(upper, v, compute=compute), cache.get(lower, v, compute=compute))
                for v in vs]
        if any(a is None or b is None or "w" not in a or "w" not in b for a, b in rows):
            return {"between": [upper, lower], "v": None, "note": "a branch is missing near "
                    f"v = {guess}"}
        d = [a["w"] - b["w"] for a, b in rows]  # > 0 where ``lower`` is the lower one
        if d[0] > 0 > d[-1] or d[0] < 0 < d[-1]:
            c = np.polyfit(vs, d, 2)
            roots = [x.real for x in np.roots(c) if abs(x.imag) < 1e-12 and vs[0] <= x.real
                     <= vs[-1]]
            v = float(roots[0])
            w = float(np.polyval(np.polyfit(vs, [a["w"] for a, _ in rows], 2), v))
            return {"between": [upper, lower], "v": v, "w": w, "samples": vs,
                    "differences": d}
        step = -0.01 if d[0] > 0 else 0.01  # lower already lower everywhere: move up
        vs = [round(x + step, 2) for x in vs]
    return {"between": [upper, lower], "v": None, "note": "no sign change found"}


# ---------------------------------------------------------------------------------------
# stage eps: phase-field steady states seeded from the sharp shapes, ε → 0
# ---------------------------------------------------------------------------------------
EPS = (0.04, 0.032, 0.02, 0.016, 0.0128, 0.01)
NODES_PER_EPS = 1.28  # ε/h: n = 1.28/ε points per axis (32, 40, 64, 80, 100, 128)
EPS_V = (0.95, 0.8, 0.65, 0.6, 0.55)
#: (branch, v) of the ε stage: the sphere and the Clifford torus first
EPS_CASES = (("sphere", 1.0), ("torus", None)) + tuple(
    (b, v) for b in BRANCHES for v in EPS_V)
#: the labels a run of each branch may end with (a sphere at R₀/h = 8 reads as slightly
#: oblate or prolate; the prolate below v ≈ 0.85 has a waist, "gourd", whose long flat middle
#: can read as two necks, "chain"); with ``DA_TOL`` on the reduced area difference, which
#: tells a budding chain (da 0.18–0.25 above the sharp prolate's) from the prolate (≤ 0.12
#: measured, 0.10 for the torus at ε = 0.04) and the stomatocyte (da 0.4–0.6) from the
#: oblate (≈ 1)
GENUS0 = ("sphere", "oblate", "discocyte", "prolate")
LABELS = {"sphere": GENUS0, "torus": ("torus",),
          "prolate": ("prolate", "cylinder", "gourd", "chain"),
          "oblate": ("oblate", "discocyte"),
          # the axisymmetric descriptors tell the stomatocyte (one pole invaginated) apart
          "stomatocyte": GENUS0 + ("stomatocyte",)}
DA_TOL = 0.12
#: a phase-field run writes a checkpoint every this many steps (a killed one resumes there)
CHECKPOINT_EVERY = 500
MARGIN = 4.75 * max(EPS)
#: the finest two only for the cases given with --fine (the cost grows like ε⁻⁴): by default
#: those that keep their branch at ε = 0.016; ``FINE_STOP``: where a case stops (the sphere's
#: steady state is slow to settle: 2350 steps at ε = 0.0128)
FINE = (0.0128, 0.01)
#: the axisymmetric FEM's column (docs/model.md §11): every case at ε = 0.04 … 0.0025, order
#: 8 at ``AXI_NODES_PER_EPS`` nodes per ε, and at the two smallest ε again at
#: ``AXI_CHECK_NODES_PER_EPS`` (the difference bounds the discretization error of the first;
#: it is largest against the ε effect, which falls like ε², where ε is smallest)
AXI_EPS = (0.04, 0.02, 0.01, 0.005, 0.0025)
AXI_ORDER, AXI_NODES_PER_EPS, AXI_CHECK_NODES_PER_EPS = 8, 3.5, 2.5
#: where an axisymmetric case stops: the sphere, whose exact constraints at v = 1 leave only
#: a nearly free deformation (a prolate or oblate of vanishing excess), settles slowly: 2750
#: steps at ε = 0.01, and its e is 1 + O(ε²) on any near-sphere
AXI_STOP = {"sphere@1.0000": 0.01}
#: stage ``ade`` (the ADE term as ε → 0, axisymmetric): (branch, v, m₀) at κ̄/κ = ADE_KBAR —
#: a torus, a prolate and a pear with the area difference away from its relaxed value (the
#: pear near the prolate → pear transition, 1.531: at m₀ = 1.7 its neck pinches off in the
#: phase field down to ε = 0.005)
ADE_KBAR = 1.4
ADE_CASES = (("torus", 0.65, 1.3), ("prolate", 0.85, 1.4), ("pear", 0.85, 1.58))
#: stage ``transitions`` (axisymmetric): where the phase field's lowest branch changes at each
#: ε, from seeded steady states on three points around the sharp transition — the minimal
#: model's (upper branch, lower branch, v) and the ADE plane's prolate → pear at v = 0.85,
#: κ̄/κ = ADE_KBAR, along m₀ (from 1.53: at 1.48 the sharp pear relaxes to the prolate)
TRANSITION_EPS = (0.02, 0.01, 0.005, 0.0025)
MINIMAL_TRANSITIONS = (("prolate", "oblate", (0.62, 0.65, 0.68)),
                       ("oblate", "stomatocyte", (0.56, 0.59, 0.62)))
PEAR_TRANSITION = (0.85, ("prolate", "pear"), (1.53, 1.58, 1.63))
FINE_CASES = ("sphere@1.0000", "torus@free", "prolate@0.9500", "prolate@0.8000", "prolate@0.6500",
              "prolate@0.6000", "prolate@0.5500", "oblate@0.9500", "oblate@0.8000",
              "oblate@0.5500")
FINE_STOP = {"sphere@1.0000": 0.0128}


#: what a run of the study covers (the full one, or ``--quick``'s): the grid of v and the
#: branches of the sharp stage, its transitions, the ε, the cases, those also at the finest
#: ε, and the FEM's column (order 4 on the same nodes, ε down to 0.016: the cases that keep
#: their branch)
Plan = SimpleNamespace
FULL = Plan(grid=GRID, columns=COLUMNS, transitions=TRANSITIONS, eps=EPS, cases=EPS_CASES,
            fine=FINE_CASES, fem_cases=("sphere@1.0000", "torus@free", "prolate@0.9500",
                                        "prolate@0.8000", "oblate@0.9500", "oblate@0.8000"),
            axi_eps=AXI_EPS, ade_cases=ADE_CASES, transition_eps=TRANSITION_EPS,
            minimal_transitions=MINIMAL_TRANSITIONS, pear_transition=PEAR_TRANSITION)
#: a look in seconds: the prolate and oblate at v = 0.8, three coarse ε, no transitions
QUICK = Plan(grid=(0.8,), columns=("prolate", "oblate"), transitions=(),
             eps=(0.08, 0.064, 0.05), cases=(("prolate", 0.8),), fine=(), fem_cases=(),
             axi_eps=(0.08, 0.064, 0.05), ade_cases=(), transition_eps=(),
             minimal_transitions=(), pear_transition=None)


def eps_of(plan, backend: str) -> tuple[float, ...]:
    """The ε of a backend's column (the axisymmetric check: the two smallest)."""
    if backend == "axisymmetric-check":
        return tuple(sorted(plan.axi_eps)[:2])
    return plan.axi_eps if backend.startswith("axisymmetric") else plan.eps


def _case_key(backend: str, branch: str, v, eps: float) -> str:
    return f"{backend}/{_key(branch, v)}/{eps:.4f}"


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


def radius(sharp: dict) -> float:
    """R₀ in the unit box: 0.25 or less, so that the shape keeps ``MARGIN`` from its
    periodic images."""
    extent = max(np.ptp(sharp["z"]), 2.0 * max(sharp["r"]))
    return min(0.25, (1.0 - 2.0 * MARGIN) / extent)


def seeded(sharp: dict, branch: str, eps: float, backend: str, *, kbar: float = 0.0,
           m0: float = 0.0) -> SimpleNamespace:
    """One seeded steady state: its ``scene`` (the sharp meridian, R₀ fitted in the box), its
    ``run`` options beside the ``steady`` recipe (fem_ade.engine.runs.simulate's keywords), its
    ``n`` (the row's) and ``R0``; with ``kbar`` (κ̄/κ), area-difference elasticity toward
    the reduced ``m0`` (ΔA₀ = 8πDR₀·m₀, R₀ the seed's in the box)."""
    from fem_ade.model.params import Params
    from fem_ade.scenes.catalogue import Scene
    from fem_ade.scenes.initial import Meridian

    R0, v = radius(sharp), sharp["v"]
    ic = Meridian(centre=(0.5, 0.5, 0.5), r=tuple(sharp["r"]), z=tuple(sharp["z"]), scale=R0)
    ade = {"effects": {"bending", "volume", "area", "ade"}, "kappa_bar": kbar,
           "delta_A0": m0 * 8.0 * math.pi * (2.0 * eps / 3.0) * R0} if kbar else {
        "effects": {"bending", "volume", "area"}}
    params = Params(eps=eps, alpha=4.0 / 3.0 * math.pi * R0**3 * v, beta=4.0 * math.pi * R0**2,
                    volume_functional="localized", **ade)
    n = round(NODES_PER_EPS / eps)
    scene = Scene(name=f"sharp-{branch}", params=params, dt=0.0075 * eps**3, ic=ic,
                  n=n).validate()
    if backend.startswith("axisymmetric"):
        npe = AXI_CHECK_NODES_PER_EPS if backend.endswith("check") else AXI_NODES_PER_EPS
        n = math.ceil(npe / (eps * AXI_ORDER) - 1e-9)  # cells per L (the row's n)
        options = {"backend": "fem", "n": n * AXI_ORDER,  # nodes per L
                   "backend_options": {"geometry": "axisymmetric", "order": AXI_ORDER}}
    else:
        options = {"backend": "spectral", "n": n} if backend == "spectral" else {
            "backend": "fem", "n": n // 4 * 4, "backend_options": {"order": 4}}
    run = dict(options, every=50, render=False, sharp=False,  # its own sharp shape: above
               checkpoint_every=CHECKPOINT_EVERY)
    return SimpleNamespace(scene=scene, run=run, n=n, R0=R0, kbar=kbar)


def phase_field_row(summary: dict, folder: Path, sharp: dict, branch: str, eps: float,
                    backend: str, made: SimpleNamespace) -> dict:
    """A seeded steady state's row, from its run folder (``made``: :func:`seeded`'s): its
    energy, shape and cost, and its section y = ½ (``section``, for the picture); e is
    (W + G) over a sharp sphere's bending energy."""
    res, params = summary, made.scene.params
    d = res["shape"]  # the run's own descriptors of its final φ = 0 surface (sharp values)
    final = res["final"]
    row = {"branch": branch, "v": sharp["v"], "eps": eps, "n": made.n, "R0": made.R0,
           "backend": backend, "status": res["status"], "steps": res["steps"],
           "cpu_s": round(res["cpu_s"] + (res["setup_cpu_s"] or 0.0), 2),
           "e": reduced_energy(final),  # G is 0 with ADE off
           "w": final["W"] / SPHERE_W,
           # the area difference the model's ADE term sees (the diffuse ΔA), reduced
           "da_diffuse": (final["dA"] / (8.0 * math.pi * params.D * made.R0)
                          if made.kbar else None),
           "G": final["G"], "W": final["W"],
           "label": d["label"], "components": d["components"], "genus": d["genus"],
           "da": d["reduced_area_difference"], "v_surface": d["reduced_volume"],
           "seconds": round(res["wall_s"], 1)}  # the loop's wall time
    row["kept_branch"] = kept(row, sharp)
    with np.load(folder / "final.npz") as z:
        grid = np.array(z["phi_grid"] if "phi_grid" in z.files else z["phi"])
    row["section"] = grid[:, grid.shape[1] // 2, :].astype(np.float32)  # y = ½, the picture's
    return row


def point_name(key: str) -> str:
    """A runs.json key as a sweep point's name (its folder's): ``/`` and ``@`` → ``_``."""
    return re.sub(r"[^A-Za-z0-9._=-]", "_", key)


def make_runs(root: Path, jobs: list[SimpleNamespace], workers: int = 2) -> list[tuple]:
    """The seeded steady states ``jobs`` (each: ``key``, ``sharp``, ``branch``, ``eps``,
    ``backend`` and ``ade``, the keywords kbar and m0 or none) as one sweep of listed points
    (:mod:`fem_ade.campaigns.sweep`) on ``workers`` Dask processes: each in
    ``root/sweep/points/NAME`` (:func:`point_name`), resumable, a failure recorded with its
    reason (and printed here). Returns (job, row) (:func:`phase_field_row`) of those that
    ended with a result, in the jobs' order."""
    from fem_ade.campaigns.sweep import listed_sweep, run_sweep
    from fem_ade.engine.jobs import read_failure, read_summary
    from fem_ade.scenes.catalogue import scene_to_mapping

    if not jobs:
        return []
    made, specs = {}, []
    for job in jobs:
        made[job.key] = seeded(job.sharp, job.branch, job.eps, job.backend, **job.ade)
        specs.append({"name": point_name(job.key), "seed": 1,
                      "base": scene_to_mapping(made[job.key].scene),
                      "run": {"recipe": "steady", **made[job.key].run}})
    run_sweep(listed_sweep(root.name, specs), root / "sweep", workers=workers, quiet=True)
    rows = []
    for job in jobs:
        folder = root / "sweep" / "points" / point_name(job.key)
        summary = read_summary(folder)
        if summary is None or summary.get("status") in (Status.FAILED, Status.DIVERGED):
            failed = read_failure(folder)
            print(f"  {job.key}: no result ({failed['reason'] if failed else 'not run'})",
                  flush=True)
            continue
        rows.append((job, phase_field_row(summary, folder, job.sharp, job.branch, job.eps,
                                          job.backend, made[job.key])))
    return rows


def kept(run: dict, sharp: dict) -> bool:
    """Whether a run ended on its sharp shape's branch (see the module docstring; a branch
    without ``LABELS``, the pear, by its area difference alone)."""
    labels = LABELS.get(run["branch"])
    return bool(run["components"] == 1 and (labels is None or run["label"] in labels)
                and abs(run["da"] - sharp["da"]) < DA_TOL)


def extrapolate(eps: list[float], e: list[float]) -> tuple[float, float, bool]:
    """(e₀, p, observed): the observed order from the three smallest ε (p = 2, not observed,
    if there are two or they do not give one in [0.5, 6]) and Richardson over the two
    smallest."""
    from scipy.optimize import brentq

    order = np.argsort(eps)
    x = [eps[i] for i in order]
    y = [e[i] for i in order]
    p, observed = 2.0, False
    if len(x) >= 3:
        ratio = (y[2] - y[1]) / (y[1] - y[0]) if y[1] != y[0] else math.nan

        def f(q):
            return (x[2] ** q - x[1] ** q) / (x[1] ** q - x[0] ** q) - ratio

        try:
            if math.isfinite(ratio) and f(0.5) * f(6.0) < 0:
                p, observed = brentq(f, 0.5, 6.0), True
        except ValueError:
            pass
    e0 = y[0] - (y[1] - y[0]) / ((x[1] / x[0]) ** p - 1.0)
    return e0, p, observed


def eps_rows(runs: dict, cache: Cache, backend: str, plan) -> list[dict]:
    rows = []
    for branch, v in plan.cases:
        sharp = cache.get(branch, v, compute=False)
        if sharp is None or "w" not in sharp:
            continue
        found = [runs[k] for k in (_case_key(backend, branch, v, e)
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
                check = runs.get(_case_key("axisymmetric-check", branch, v, r["eps"]))
                if check is not None and r["kept_branch"] and abs(r["e"] - sharp["w"]) > 0:
                    ratios.append(abs(r["e"] - check["e"]) / abs(r["e"] - sharp["w"]))
            row["disc_over_eps_effect"] = max(ratios) if ratios else None
        rows.append(row)
    return rows


def report(cache: Cache, out: Path, plan=FULL) -> dict:
    """sharp_limit.md, sharp_limit.json and the pictures from the caches (nothing is run)."""
    lines, rows, extra, table = branches_section(cache, plan)
    crossings = [crossing(cache, *t, compute=False) for t in plan.transitions]
    lines += crossings_section(crossings)
    runs_path = out / "sharp" / "runs.json"
    runs = json.loads(runs_path.read_text()) if runs_path.is_file() else {}
    eps_table = []
    for backend in ("spectral", "fem", "axisymmetric"):
        rows_b = eps_rows(runs, cache, backend, plan)
        if rows_b:
            eps_table += rows_b
            lines += eps_section(backend, rows_b, eps_of(plan, backend), runs)
    if eps_table:
        lines += ["", "![e over e_sharp against ε²](sharp-eps.png)", "",
                  "![the phase field's φ = 0 over the sharp meridian](sharp-sections.png)", ""]
    ade = ade_rows(cache, runs, plan)
    lines += ade_report(ade)
    trans = transition_rows(cache, runs, plan)
    lines += transitions_report(trans, plan)
    notes = out / "sharp" / "notes.md"
    if notes.is_file():
        lines += [notes.read_text().strip(), ""]
    (out / "sharp_limit.md").write_text("\n".join(lines))
    payload = {"rows": eps_table, "ade": ade, "phase_field_transitions": trans,
               "branches": [{k: r[k] for k in r if k not in ("r", "z")} for r in rows],
               "exact": [{k: r[k] for k in r if k not in ("r", "z")} for r in extra if r],
               "lowest": table, "transitions": crossings}
    (out / "sharp_limit.json").write_text(json.dumps(payload, indent=1) + "\n")
    figure(cache, out / "sharp-branches.png", crossings, plan)
    if eps_table:
        eps_figures(eps_table, runs, cache, out)
    return payload


def branches_section(cache: Cache, plan) -> tuple[list[str], list, list, list]:
    """The report's head, exact values and branch table: (lines, the branches' rows, the
    sphere's and Clifford torus's, the lowest branch per v)."""
    rows, table = [], []
    for branch in plan.columns:
        for v in plan.grid:
            r = cache.get(branch, v, compute=False)
            if r is not None:
                rows.append(r)
    extra = [cache.get("sphere", 1.0, compute=False), cache.get("torus", None, compute=False)]
    lines = ["# How close to the sharp membrane", "",
             "Written by `studies/sharp_limit.py` from `sharp_ref` (axisymmetric sharp "
             "membranes, the minimal model: bending only, fixed area and volume). Energies "
             "in units of a sphere's bending energy (w), reduced volume v and reduced area "
             "difference da (1 for a sphere).", "",
             "## Exact values", "",
             "| shape | v | w | exact | misfit |", "|---|---|---|---|---|"]
    for r, exact in zip(extra, (1.0, math.pi / 2), strict=True):
        if r is not None and "w" in r:
            lines.append(f"| {r['branch']} | {r['v']:.6f} | {r['w']:.12f} | {exact:.12f} | "
                         f"{abs(r['w'] - exact):.1e} |")
    lines += ["", "## Branches", "",
              "The lowest of genus 0 (the classic phase diagram's) and, beside it, the torus "
              "(axisymmetric, up-down symmetric).", "",
              "| v | " + " | ".join(f"w {b}" for b in plan.columns) + " | lowest of genus 0 |",
              "|---|" + "---|" * (len(plan.columns) + 1)]
    for v in plan.grid:
        ws = {b: cache.get(b, v, compute=False) for b in plan.columns}
        cells = [f"{r['w']:.8f}" if r and "w" in r else "—" for r in ws.values()]
        have = {b: r["w"] for b, r in ws.items() if r and "w" in r}
        genus0 = {b: w for b, w in have.items() if b in BRANCHES}
        lowest = min(genus0, key=genus0.get) if genus0 else "—"
        lines.append(f"| {v:.2f} | " + " | ".join(cells) + f" | {lowest} |")
        table.append({"v": v, "lowest_genus0": lowest,
                      **{b: have.get(b) for b in plan.columns}})
    lines += ["", "![w along the branches; meridians](sharp-branches.png)", "",
              "— : the branch is not found there; why:", ""]
    lines += [f"- {r['branch']} at v = {r['v']:.2f}: {r['missing']}" for r in rows
              if "missing" in r]
    return lines, rows, extra, table


def crossings_section(crossings) -> list[str]:
    lines = ["", "## Where the lowest branch changes", "",
             "| from (above) | to (below) | v | w there | literature |", "|---|---|---|---|---|"]
    for c, lit in zip(crossings, ("0.652", "0.592")[:len(crossings)], strict=True):
        v = "—" if c["v"] is None else f"{c['v']:.4f}"
        w = f"{c['w']:.6f}" if c.get("w") else c.get("note", "")
        lines.append(f"| {c['between'][0]} | {c['between'][1]} | {v} | {w} | {lit} |")
    return lines + ["", "Literature: Seifert, Berndl & Lipowsky, Phys. Rev. A 44, 1182 (1991).",
                    ""]


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


def figure(cache: Cache, path: Path, crossings, plan) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.4))
    colours = {"prolate": "tab:blue", "oblate": "tab:orange", "stomatocyte": "tab:green",
               "torus": "tab:purple"}
    for b in plan.columns:
        pts = sorted((r["v"], r["w"]) for r in cache.rows.values()
                     if r["branch"] == b and "w" in r)
        if pts:
            ax.plot(*zip(*pts, strict=True), "o-", ms=3, color=colours[b], label=b)
    for c in crossings:
        if c["v"] is not None:
            ax.axvline(c["v"], color="0.6", lw=0.8, ls="--")
            ax.annotate(f"{c['v']:.3f}", (c["v"], ax.get_ylim()[1]), fontsize=8,
                        ha="center", va="bottom")
    ax.set(xlabel="reduced volume v", ylabel="w = bending / sphere's",
           title="minimal model: the axisymmetric branches")
    ax.legend()
    for k, (b, v) in enumerate((("prolate", 0.8), ("oblate", 0.65), ("stomatocyte", 0.55))):
        r = cache.get(b, v, compute=False)
        if r and "r" in r:
            r_, z_ = np.array(r["r"]), np.array(r["z"])
            off = 3.0 * k
            bx.plot(off + r_, z_, color=colours[b])
            bx.plot(off - r_, z_, color=colours[b])
            bx.text(off, -1.9, f"{b}\nv = {v}", ha="center", va="top", fontsize=8)
    bx.set_aspect("equal")
    bx.set_ylim(-2.6, 2.0)
    bx.set_axis_off()
    bx.set_title("meridians (R₀ = 1)")
    fig.tight_layout()
    save_figure(fig, path, dpi=110, colours=64)
    plt.close(fig)


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
        if only and branch not in only and _key(branch, v) not in only:
            continue
        sharp = cache.get(branch, v)
        if "w" not in sharp:
            continue
        for eps in eps_of(plan, backend):
            key = _case_key(backend, branch, v, eps)
            axi = backend.startswith("axisymmetric")
            stop = (AXI_STOP if axi else FINE_STOP).get(_key(branch, v), 0.0)
            if key in runs or (not axi and eps in FINE and _key(branch, v) not in fine) or (
                    eps < stop):
                continue
            jobs.append(SimpleNamespace(key=key, sharp=sharp, branch=branch, eps=eps,
                                        backend=backend, ade={}))
    return jobs


def _ade_key(branch, v, m0, eps) -> str:
    return f"axisymmetric-ade/{_key(branch, v)}/m0={m0:g}/{eps:.4f}"


def run_ade(cache: Cache, out: Path, plan) -> None:
    """Stage ``ade``: each ADE case at every ε of the axisymmetric column."""
    path = out / "sharp" / "runs.json"
    runs = json.loads(path.read_text()) if path.is_file() else {}
    jobs = []
    for branch, v, m0 in plan.ade_cases:
        sharp = ade_sharp(cache, branch, v, m0, ADE_KBAR)
        if sharp is None or "e" not in sharp:
            continue
        jobs += [SimpleNamespace(key=_ade_key(branch, v, m0, eps), sharp=sharp, branch=branch,
                                 eps=eps, backend="axisymmetric",
                                 ade={"kbar": ADE_KBAR, "m0": m0})
                 for eps in plan.axi_eps if _ade_key(branch, v, m0, eps) not in runs]
    for job, row in make_runs(out / "sharp", jobs):
        key = job.key
        row.pop("section")
        row["m0"] = job.ade["m0"]
        print(f"  {key}: e = {row['e']:.6f} (sharp {job.sharp['e']:.6f}), da diffuse "
              f"{row['da_diffuse']:.5f}, surface {row['da']:.5f} "
              f"(sharp {job.sharp['da']:.5f}), {row['label']}, {row['steps']} steps, "
              f"{row['seconds']} s", flush=True)
        runs[key] = row
        write_json_atomic(path, runs, indent=None)


def slope(eps: list[float], err: list[float]) -> float | None:
    """The observed order: the least-squares slope of log|err| against log ε over the three
    smallest ε (None with fewer, or where an error is 0)."""
    pts = sorted(zip(eps, err, strict=True))[:3]
    if len(pts) < 3 or any(e == 0 for _, e in pts):
        return None
    x = np.log([p[0] for p in pts])
    y = np.log([abs(p[1]) for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def ade_rows(cache: Cache, runs: dict, plan) -> list[dict]:
    """Per ADE case: along ε, the model's (diffuse) and the φ = 0 surface's reduced area
    difference, G and W against the sharp membrane's, and their observed orders."""
    c = 3.0 * math.pi * ADE_KBAR / (2.0 * math.sqrt(2.0))  # G / W_sphere = c (m − m₀)²
    out = []
    for branch, v, m0 in plan.ade_cases:
        sharp = ade_sharp(cache, branch, v, m0, ADE_KBAR, compute=False)
        if sharp is None or "e" not in sharp:
            continue
        found = [runs[k] for k in (_ade_key(branch, v, m0, e) for e in plan.axi_eps)
                 if k in runs]
        found = [r for r in found if r["kept_branch"]]
        if not found:
            continue
        g_sharp = sharp["e"] - sharp["w"]
        row = {"branch": branch, "v": v, "m0": m0, "kbar": ADE_KBAR, "da_sharp": sharp["da"],
               "g_sharp": g_sharp, "w_sharp": sharp["w"], "e_sharp": sharp["e"],
               "eps": [r["eps"] for r in found],
               "da_diffuse": [r["da_diffuse"] for r in found],
               "da_surface": [r["da"] for r in found],
               "g": [r["G"] / SPHERE_W for r in found], "w": [r["W"] / SPHERE_W for r in found],
               "e": [r["e"] for r in found], "labels": [r["label"] for r in found]}
        for name, values, ref in (("da_diffuse", row["da_diffuse"], sharp["da"]),
                                  ("da_surface", row["da_surface"], sharp["da"]),
                                  ("g", row["g"], g_sharp), ("w", row["w"], sharp["w"]),
                                  ("e", row["e"], sharp["e"])):
            row[f"order_{name}"] = slope(row["eps"], [x - ref for x in values])
        row["g_check"] = [c * (m - m0) ** 2 for m in row["da_diffuse"]]
        out.append(row)
    return out


def ade_report(rows: list[dict]) -> list[str]:
    if not rows:
        return []
    lines = ["", "## The ADE term as ε → 0 (axisymmetric FEM)", "",
             f"At κ̄/κ = {ADE_KBAR}: each case seeded from its sharp membrane with ADE, run to a "
             "steady state at every ε. Δa: the reduced area difference — the model's, from its "
             "diffuse ΔA (what its ADE term G sees), and the φ = 0 surface's, ∮H dA/(4πR₀) — "
             "against the sharp membrane's; g = G / W_sphere and w = W / W_sphere against the "
             "sharp ones; p: the observed order (slope of log|error| over the three smallest "
             "ε).", ""]
    for r in rows:
        lines += [f"**{r['branch']}** at v = {r['v']}, m₀ = {r['m0']}: sharp Δa = "
                  f"{r['da_sharp']:.5f}, g = {r['g_sharp']:.5f}, w = {r['w_sharp']:.5f}", "",
                  "| ε | Δa diffuse − sharp | Δa surface − sharp | g − g_sharp | "
                  "w − w_sharp | label |", "|---|---|---|---|---|---|"]
        for i, eps in enumerate(r["eps"]):
            lines.append(f"| {eps:g} | {r['da_diffuse'][i] - r['da_sharp']:+.2e} | "
                         f"{r['da_surface'][i] - r['da_sharp']:+.2e} | "
                         f"{r['g'][i] - r['g_sharp']:+.2e} | {r['w'][i] - r['w_sharp']:+.2e} "
                         f"| {r['labels'][i]} |")

        def fmt(p):
            return "—" if p is None else f"{p:.2f}"

        lines += [f"| p | {fmt(r['order_da_diffuse'])} | {fmt(r['order_da_surface'])} | "
                  f"{fmt(r['order_g'])} | {fmt(r['order_w'])} | |", ""]
    return lines


def run_transitions(cache: Cache, out: Path, plan) -> None:
    """Stage ``transitions``: the seeded steady states around each transition."""
    path = out / "sharp" / "runs.json"
    runs = json.loads(path.read_text()) if path.is_file() else {}
    jobs = []

    def one(key, sharp, branch, eps, **ade):
        if key not in runs and sharp is not None and "w" in sharp:
            jobs.append(SimpleNamespace(key=key, sharp=sharp, branch=branch, eps=eps,
                                        backend="axisymmetric", ade=ade))

    for eps in plan.transition_eps:
        for upper, lower, vs in plan.minimal_transitions:
            for v in vs:
                for b in (upper, lower):
                    one(_case_key("axisymmetric", b, v, eps), cache.get(b, v), b, eps)
        if plan.pear_transition:
            v, branches, m0s = plan.pear_transition
            for m0 in m0s:
                for b in branches:
                    one(_ade_key(b, v, m0, eps), ade_sharp(cache, b, v, m0, ADE_KBAR), b, eps,
                        kbar=ADE_KBAR, m0=m0)
    for job, row in make_runs(out / "sharp", jobs):
        key = job.key
        row.pop("section")
        row.update({k: v for k, v in job.ade.items() if k == "m0"})
        print(f"  {key}: e = {row['e']:.6f}, {row['label']}"
              f"{'' if row['kept_branch'] else ' LEFT the branch'}, {row['steps']} steps, "
              f"{row['seconds']} s", flush=True)
        runs[key] = row
        write_json_atomic(path, runs, indent=None)


def _root(xs: list[float], ds: list[float]) -> float | None:
    """The x where d changes sign between the points (quadratic through three, linear
    through two), or None."""
    pts = sorted(zip(xs, ds, strict=True))
    if len(pts) < 2 or not any(a[1] * b[1] <= 0 for a, b in zip(pts, pts[1:], strict=False)):
        return None
    x, d = [p[0] for p in pts], [p[1] for p in pts]
    if len(pts) >= 3:
        roots = [r.real for r in np.roots(np.polyfit(x, d, 2)) if abs(r.imag) < 1e-12
                 and x[0] <= r.real <= x[-1]]
        if roots:
            return float(min(roots, key=lambda r: abs(r - np.mean(x))))
    for (x0, d0), (x1, d1) in zip(pts, pts[1:], strict=False):
        if d0 * d1 <= 0:
            return x0 - d0 * (x1 - x0) / (d1 - d0)
    return None


def transition_rows(cache: Cache, runs: dict, plan) -> list[dict]:
    """Per transition: its location at each ε (where both branches were kept at ≥ 2 of the
    points), the observed order and the extrapolation to ε → 0, beside the sharp one."""
    out = []
    def minimal_key(b, v):
        return lambda eps: _case_key("axisymmetric", b, v, eps)

    def ade_key(b, v, m):
        return lambda eps: _ade_key(b, v, m, eps)

    cases = [(f"{u} → {lo}", "v", [(v, minimal_key(u, v), minimal_key(lo, v)) for v in vs],
              crossing(cache, u, lo, float(np.mean(vs)), compute=False).get("v"))
             for u, lo, vs in plan.minimal_transitions]
    if plan.pear_transition:
        v, (u, lo), m0s = plan.pear_transition
        es = {b: [(ade_sharp(cache, b, v, m, ADE_KBAR, compute=False) or {}).get("e")
                  for m in m0s] for b in (u, lo)}
        sharp_x = None
        if all(e is not None for b in es for e in es[b]):
            sharp_x = _root(list(m0s), [a - b for a, b in zip(es[u], es[lo], strict=True)])
        cases.append((f"{u} → {lo} (v = {v}, κ̄/κ = {ADE_KBAR})", "m0",
                      [(m, ade_key(u, v, m), ade_key(lo, v, m)) for m in m0s],
                      sharp_x))
    for name, along, points, sharp_x in cases:
        at = {}
        for eps in plan.transition_eps:
            xs, ds = [], []
            for x, ku, kl in points:
                ru, rl = runs.get(ku(eps)), runs.get(kl(eps))
                if ru and rl and all(r["kept_branch"] and r.get("status") == Status.STEADY
                                     for r in (ru, rl)):  # a run cut at max_steps: no point
                    xs.append(x)
                    ds.append(ru["e"] - rl["e"])
            at[eps] = _root(xs, ds)
        have = [(e, x) for e, x in at.items() if x is not None]
        row = {"transition": name, "along": along, "sharp": sharp_x,
               "at": {f"{e:g}": x for e, x in at.items()}, "extrapolated": None,
               "order": None}
        if len(have) >= 2:
            x0, p, observed = extrapolate([e for e, _ in have], [x for _, x in have])
            row.update(extrapolated=x0, order=p, order_observed=observed)
        out.append(row)
    return out


def transitions_report(rows: list[dict], plan) -> list[str]:
    if not rows:
        return []
    lines = ["", "## Where the lowest branch changes, from the phase field (axisymmetric FEM)",
             "", "Seeded steady states at three points around each sharp transition; at each "
             "ε the root of the difference of the two branches' e (a quadratic through the "
             "points where both reached a steady state on their branch), then the observed "
             "order and Richardson over the smallest ε. — : a branch left (opened, pinched "
             "or budded) at too many of the points.", "",
             "| transition | along | " + " | ".join(f"ε = {e:g}" for e in plan.transition_eps)
             + " | p | ε → 0 | sharp |", "|---|---|" + "---|" * (len(plan.transition_eps) + 3)]
    for r in rows:
        cells = ["—" if r["at"][f"{e:g}"] is None else f"{r['at'][f'{e:g}']:.4f}"
                 for e in plan.transition_eps]
        ex = "—" if r["extrapolated"] is None else f"{r['extrapolated']:.4f}"
        p = "—" if r["order"] is None else (f"{r['order']:.2f}"
                                            + ("" if r.get("order_observed") else " (assumed)"))
        sh = "—" if r["sharp"] is None else f"{r['sharp']:.4f}"
        lines.append(f"| {r['transition']} | {r['along']} | " + " | ".join(cells)
                     + f" | {p} | {ex} | {sh} |")
    return lines + [""]


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT,
                    help="results folder (default runs/studies; the committed: studies/results)")
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--quick", action="store_true",
                    help="prolate and oblate at v = 0.8, ε = 0.08 … 0.05 (seconds)")
    ap.add_argument("--stages", nargs="+", choices=("branches", "eps", "ade", "transitions"),
                    default=["branches", "eps", "ade", "transitions"])
    ap.add_argument("--backends", nargs="+", choices=("spectral", "fem", "axisymmetric"),
                    default=["spectral", "fem", "axisymmetric"],
                    help="the FEM runs the plan's fem_cases only, without the finest ε; the "
                    "axisymmetric FEM every case at ε = 0.04 … 0.0025, twice (its check)")
    ap.add_argument("--cases", nargs="+", default=None, metavar="BRANCH[@V]",
                    help="only these branches or cases, e.g. torus prolate@0.8000 (stage eps)")
    ap.add_argument("--fine", nargs="*", default=None, metavar="BRANCH@V",
                    help="the cases run at ε = 0.0128 and 0.01 too (default: those that keep "
                    "their branch at 0.016)")
    args = ap.parse_args(argv)
    plan = QUICK if args.quick else FULL
    fine = set(plan.fine if args.fine is None else args.fine)
    lock = None
    if not args.report_only:  # one process at a time: the caches are read, then rewritten
        from fem_ade.store.lock import FolderLock

        (args.out / "sharp").mkdir(parents=True, exist_ok=True)
        lock = FolderLock(args.out / "sharp").acquire()
    try:
        return _main(args, plan, fine)
    finally:
        if lock is not None:
            lock.release()


def _main(args, plan, fine) -> dict:
    cache = Cache(args.out / "sharp" / "solves.json")
    if not args.report_only and "branches" in args.stages:
        if not args.quick:
            cache.get("sphere", 1.0)
            cache.get("torus", None)
        for v in plan.grid:
            for b in plan.columns:
                if b == "stomatocyte" and v > 0.70:
                    continue  # left by the continuation (see the report's notes)
                cache.get(b, v)
        for t in plan.transitions:
            crossing(cache, *t)
    if not args.report_only and "eps" in args.stages:
        columns = []
        for backend in args.backends:
            if backend == "spectral":
                columns.append((backend, args.cases, fine))
            elif backend == "axisymmetric":
                columns += [(b, args.cases, ()) for b in ("axisymmetric", "axisymmetric-check")]
            else:
                only = set(plan.fem_cases) & set(args.cases or plan.fem_cases)
                if only:
                    columns.append((backend, only, ()))
        run_eps(cache, args.out, plan, columns)
    if not args.report_only and "ade" in args.stages:
        run_ade(cache, args.out, plan)
    if not args.report_only and "transitions" in args.stages:
        if plan.pear_transition:  # the sharp ones first (the report reads them)
            v, branches, m0s = plan.pear_transition
            for m0 in m0s:
                for b in branches:
                    ade_sharp(cache, b, v, m0, ADE_KBAR)
        run_transitions(cache, args.out, plan)
    payload = report(cache, args.out, plan)
    print(f"wrote {args.out / 'sharp_limit.md'}")
    return payload


if __name__ == "__main__":
    main()
