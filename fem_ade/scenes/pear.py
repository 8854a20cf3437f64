"""The pear's seed at any Δa₀ where a sharp pear exists, found by continuation where
``sharp_ref`` does not find it from scratch.

The pear (up-down asymmetric: a bud on a prolate body) exists only at large relaxed area
difference. ``sharp_ref``'s anchor reaches it at m₀ = 1.64 (κ̄/κ = 1.4, v = 0.8 and 0.85) but
not lower: at 1.54 it does not, though the branch is there. :func:`pear_scene` is the
``vesicle`` family's pear where that finds one, else the sharp pear continued down in m₀
from 1.64 in steps of 0.04, each solve starting from the one before. A module of its own
because it builds on :func:`fem_ade.scenes.catalogue.vesicle_scene`, which the ``vesicle``
family's module stands below.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fem_ade.model.params import ModelError
from fem_ade.scenes.catalogue import Scene, vesicle_scene
from fem_ade.scenes.initial import Meridian

#: where ``sharp_ref`` finds the pear from scratch (κ̄/κ = 1.4): the continuation's anchor
ANCHOR = 1.64


def pear_scene(v: float, m0: float, eps: float, R0: float, kbar: float = 1.4) -> Scene:
    """The ``vesicle`` scene on the pear branch at reduced volume ``v``, Δa₀ = ``m0``, ε and
    R₀, κ̄/κ = ``kbar``: the family's own seed, or where ``sharp_ref`` finds no pear there
    from scratch, :func:`continued_pear`'s."""
    try:
        return vesicle_scene(v=v, da0=m0, kbar=kbar, eps=eps, branch="pear", R0=R0)
    except ModelError:
        return continued_pear(v, m0, eps, R0, kbar)


def continued_pear(v: float, m0: float, eps: float, R0: float, kbar: float = 1.4) -> Scene:
    """The vesicle scene seeded with the sharp pear at ``m0`` found by continuation down from
    m₀ = :data:`ANCHOR` (ModelError where the pear is lost on the way)."""
    r, z = _pear_meridian(v, m0, kbar)
    scene = vesicle_scene(v=v, da0=m0, kbar=kbar, eps=eps, branch="prolate", R0=R0)
    ic = Meridian(centre=scene.ic.centre, r=tuple(max(float(x), 0.0) for x in r),
                  z=tuple(float(x) for x in z), scale=R0)
    ic.check(3)
    return replace(scene, ic=ic, shape="pear", description=scene.description.replace(
        "branch = prolate", "branch = pear").split("; seeded from")[0]
        + "; seeded from the sharp pear (by continuation from m0 = 1.64)")


def _pear_meridian(v: float, m0: float, kbar: float) -> tuple[list[float], list[float]]:
    """The sharp pear's meridian at ``m0`` (101 points, to 7 digits): solved at the grid
    point nearest :data:`ANCHOR`, then at each point below it from the one before
    (tolerance 1e-7, ``sharp_ref``'s three coarsest levels)."""
    from sharp_ref.branches import LEVELS, solve
    from sharp_ref.membrane import BranchError

    grid = [m0, *np.round(np.arange(m0 + 0.04, ANCHOR, 0.04), 4), ANCHOR]
    start = min(range(len(grid)), key=lambda i: abs(grid[i] - ANCHOR))
    result = None
    try:
        for i in range(start, -1, -1):
            result = solve("pear", v, m0=grid[i], kbar=kbar, tol=1e-7, levels=LEVELS[:3],
                           start=result)
    except BranchError as err:
        raise ModelError(f"no sharp pear at v = {v}, m0 = {m0}, even by continuation") from err
    j = result.to_json(points=101)
    return [round(x, 7) for x in j["r"]], [round(x, 7) for x in j["z"]]
