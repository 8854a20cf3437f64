"""The sharp membrane a run's final shape stands for, and how far the run is from it.

Where a run ends as one body whose label names an axisymmetric branch of :mod:`sharp_ref`
(prolate, cylinder or gourd → ``prolate``; oblate or discocyte → ``oblate``; torus →
``torus``), :func:`compare` solves that branch at the reduced volume of the run's φ = 0
surface with the run's model — bending, spontaneous curvature c = √2·C·R₀, and with ADE
κ̄/κ and m₀ = ΔA₀/(8πDR₀), R₀ = √(A/4π) of that surface — and sets the run's energy
e = (W + G)/(16√2πκ/3) beside the sharp one (both in units of a sphere's bending energy; they
agree as ε → 0, docs/model.md §8). A branch that does not exist there is said so.
"""

from __future__ import annotations

import math
from functools import lru_cache

from fem_ade.model.params import ENERGY_COLUMNS, Params

#: shape label (fem_ade.analysis.shape.classify) → sharp_ref branch
BRANCH_OF_LABEL = {"prolate": "prolate", "cylinder": "prolate", "gourd": "prolate",
                   "oblate": "oblate", "discocyte": "oblate", "torus": "torus",
                   # told apart by the axisymmetric descriptors only (fem_ade.analysis.axishape)
                   "stomatocyte": "stomatocyte", "pear": "pear"}
#: a sphere's bending energy in the model's units, per κ
SPHERE_W = 16.0 * math.sqrt(2.0) * math.pi / 3.0


@lru_cache(maxsize=256)
def solve_cached(branch: str, v: float, m0: float, kbar: float, c: float):
    """sharp_ref's membrane of ``branch`` to 1e-7 in e, cached per process (a run's
    comparison and a sweep's seeds ask for the same ones); BranchError where there is none."""
    from sharp_ref.branches import LEVELS, solve

    return solve(branch, v, m0=m0, kbar=kbar, c=c, tol=1e-7, levels=LEVELS[:2])


def reduced_energy(final: dict, kappa: float = 1.0) -> float:
    """e = (W + G) / (16√2πκ/3): a run's bending and ADE energy over a sharp sphere's
    bending energy in the model's units (the sharp reference's e). W + G: W and the shape
    terms' energies (:data:`fem_ade.model.params.ENERGY_COLUMNS` after E; not the
    penalties'), 0 where a record lacks one."""
    shape = final["W"]
    for name in ENERGY_COLUMNS[2:]:
        shape = shape + (final.get(name) or 0.0)
    return shape / (SPHERE_W * kappa)


#: fewer grid points per ε than this and the run's energy is not worth a comparison (its
#: interface is not resolved; the test suite's small runs are such)
MIN_POINTS_PER_EPS = 1.0


def compare(params: Params, shape: dict | None, final: dict,
            points: int | None = None) -> dict | None:
    """The sharp reference of the run's final shape (None where there is none to compare
    with, or where the run does not resolve its interface: fewer than
    ``MIN_POINTS_PER_EPS`` of its ``points`` per axis per ε): ``branch``, ``v``,
    ``e_sharp``, ``e_run``, ``rel_diff``, ``eps`` and ``line``; or ``branch``, ``v`` and
    ``missing`` (why there is no sharp shape there)."""
    if not shape or shape.get("components") != 1:
        return None
    if points is not None and points * params.eps / params.L < MIN_POINTS_PER_EPS:
        return None
    branch = BRANCH_OF_LABEL.get(shape.get("label", ""))
    sharp = shape.get("sharp") or {}
    area, v = sharp.get("A"), sharp.get("reduced_volume")
    if branch is None or not area or not v or not math.isfinite(v):
        return None
    R0 = math.sqrt(area / (4.0 * math.pi))
    kbar = params.kappa_bar / params.kappa if params.on("ade") else 0.0
    m0 = params.delta_A0 / (8.0 * math.pi * params.D * R0) if kbar else 0.0
    c = math.sqrt(2.0) * params.C * R0 if params.on("spontaneous_curvature") else 0.0
    v = round(float(v), 4)
    out = {"branch": branch, "v": v, "eps": params.eps, "eps_over_R0": params.eps / R0}
    from sharp_ref.membrane import BranchError

    try:
        result = solve_cached(branch, v, round(m0, 4), round(kbar, 6), round(c, 4))
    except (BranchError, ValueError) as err:
        out["missing"] = str(err)
        out["line"] = f"no sharp {branch} at v = {v:.3f} to compare with ({err})"
        return out
    e_run = reduced_energy(final, params.kappa)
    out.update(e_sharp=result.e, e_run=e_run, rel_diff=e_run / result.e - 1.0,
               da_sharp=result.da)
    out["line"] = (f"sharp {branch} at v = {v:.3f}: e = {result.e:.4g}; this run "
                   f"{e_run:.4g} ({out['rel_diff']:+.1%} at ε = {params.eps:g}, "
                   f"ε/R₀ = {out['eps_over_R0']:.2f})")
    return out
