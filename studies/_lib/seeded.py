"""Phase-field steady states seeded from a sharp meridian, and the rule that says whether one
kept its sharp shape's branch: the sharp-limit study's method (``studies/sharp_limit.py``),
which the ADE plane (``studies/ade_plane.py``) uses for its own seeds.

A seed is the tanh profile of the signed distance to the sharp meridian (initial condition
``meridian``), R₀ fitted in the unit box with a margin of ≥ 4.75 ε at the sharp-limit
study's largest ε, run by the ``steady`` recipe with exact constraints and the localized
volume; :func:`make_runs` runs a list of them as one sweep and returns their rows.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from fem_ade.analysis.sharp import (  # a sharp sphere's W (model units, per κ)
    SPHERE_W,
    reduced_energy,
)
from fem_ade.store.status import Status

NODES_PER_EPS = 1.28  # ε/h: n = 1.28/ε points per axis (32, 40, 64, 80, 100, 128)
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
#: the margin between the seed and its periodic images: 4.75 ε at the largest ε of the
#: sharp-limit study's 3D columns (0.04)
MARGIN = 4.75 * 0.04
#: the axisymmetric FEM's runs: order ``AXI_ORDER`` at ``AXI_NODES_PER_EPS`` nodes per ε, and
#: at ``AXI_CHECK_NODES_PER_EPS`` for the check of the discretization error (backend
#: ``axisymmetric-check``)
AXI_ORDER, AXI_NODES_PER_EPS, AXI_CHECK_NODES_PER_EPS = 8, 3.5, 2.5


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
    from fem_ade.campaigns.sweep import run_sweep
    from fem_ade.campaigns.sweep_file import listed_sweep
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
    """Whether a run ended on its sharp shape's branch: one body, a label of ``LABELS`` and
    da within ``DA_TOL`` of the sharp one's (a branch without ``LABELS``, the pear, by its
    area difference alone)."""
    labels = LABELS.get(run["branch"])
    return bool(run["components"] == 1 and (labels is None or run["label"] in labels)
                and abs(run["da"] - sharp["da"]) < DA_TOL)
