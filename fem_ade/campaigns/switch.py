"""Branch switching into 3D: from a bifurcation of an axisymmetric branch, where a block
m ≥ 1 of its stability changes sign (``python -m fem_ade.branch --modes``), to the 3D state
that the instability leads to.

The start is φ(r, z) + δ ψ_m(r, z) cos m(θ − θ₀), revolved onto the 3D mesh: φ the branch
point on the bifurcation's unstable side (of the two points it lies between, the one whose
block m has a negative eigenvalue), ψ_m that block's lowest eigenvector
(:func:`fem_ade.backends.fem.modes.lowest_mode`, max |ψ| = 1) and δ = ``delta``. One sign
of δ is enough: for m ≥ 1, −cos mθ = cos m(θ + π/m) is the same start turned by π/m. The
phase θ₀ = π/(4m) puts the start halfway between cos mθ and sin mθ: the cubic mesh splits
that pair (one along its axes, one along its diagonals) and may make one stable where the
other is not — measured, the oblate at ε = 0.02, v = 0.863 on 64³ nodes of order 4: the 3D
pair −9.4e-5 and +1.5e-4 where the block's is −7.6e-5; a start along cos 2θ alone went back
to the saddle, its sin 2θ part never seeded.

The 3D run is an ordinary run folder (the steady recipe — the stabilized scheme, V and A
exact — until E changes by less than :data:`UNTIL_STEADY` per step) started from that
field, so ``python -m fem_ade.stability``, ``fem_ade.render`` and ``--resume`` read it; its
start field, with ψ_m and m, is kept in its initial.npz and what it was switched from in its
run.json's scene description.

``geometry="octant"`` (``--geometry octant``) runs the 3D state on one eighth of the box with
the mirrors x, y, z = L/2 (:mod:`fem_ade.backends.fem.octant`): for an even m and a state
with an equatorial mirror (not a pear), with θ₀ = 0 (cos mθ is even in x and y for even m,
and the mirrors pick that one of the pair), on :data:`OCTANT_ORDER` elements with
:data:`OCTANT_NODES_PER_EPS` nodes per ε — measured, the v = 0.65 prolate at ε = 0.01 (R₀ =
0.178): 1.28 nodes per ε of order 4 lose its waists (E 3.4 % below the (r, z) state's, a
cylinder), order 8 at 1.92 keeps them (E within 1e-4). The state's mirrors are checked on
the start's grid (:data:`MIRROR_TOL`).

Why the gradient flow and not Newton: Newton goes to the nearest stationary point, which
from a small δ is the axisymmetric saddle itself; the flow goes downhill from the saddle
along ψ_m cos mθ, to where the instability leads — a stable non-axisymmetric state if the
branch born there is one, or another state (axisymmetric too) if it is not. That is the
question a negative eigenvalue raises; following an unstable non-axisymmetric branch needs
3D continuation: :mod:`fem_ade.campaigns.switch_branch` (``--follow``).
"""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path

import numpy as np

from fem_ade.model.params import ModelError
from fem_ade.registry import RUN_ORDERS

#: max |δψ| of the start (ψ scaled to max 1): far enough from the saddle that the flow
#: leaves it in a few hundred steps, near enough that the start is the saddle's
DELTA = 0.1
#: the 3D mesh's nodes per unit length per 1/ε: 64 nodes at ε = 0.02 in the unit box
NODES_PER_EPS = 1.28
#: the run stops where E changes by less than this per step, relative — far below the steady
#: recipe's 1e-9, which a flow leaving a saddle meets before the unstable mode has grown
#: (measured, the oblate at ε = 0.04, v = 0.816, m = 2: "steady" at step 100 at 1e-9, from
#: where Newton does not converge; at 1e-14 the flow leaves the saddle at step ~300)
UNTIL_STEADY = 1e-13
#: the octant's element order and nodes per ε (module docstring)
OCTANT_ORDER = 8
OCTANT_NODES_PER_EPS = 1.92
#: the octant: the start may differ from its mirror images by at most this in max |φ|
MIRROR_TOL = 1e-2


def bifurcation(branch: str | Path, index: int) -> dict:
    """Bifurcation ``index`` of a branch folder's bifurcations.json (``python -m
    fem_ade.branch --modes``); ModelError (one line) if there is none or it is m = 0."""
    path = Path(branch) / "bifurcations.json"
    try:
        found = json.loads(path.read_text())["bifurcations"]
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise ModelError(f"{path} is not a branch's bifurcations ({type(err).__name__}): "
                         "follow the branch with --modes first") from None
    if not found:
        raise ModelError(f"{path} lists no bifurcation")
    if not (isinstance(index, int) and 0 <= index < len(found)):
        raise ModelError(f"{branch} has bifurcations 0 … {len(found) - 1}, not {index!r}")
    bif = found[index]
    if int(bif["m"]) < 1:
        raise ModelError(f"bifurcation {index} is in mode m = 0: an axisymmetric branch is "
                         "born there (follow it with fem_ade.branch), not a 3D one")
    return bif


def unstable_point(branch: str | Path, bif: dict, point: int | None = None) -> Path:
    """The branch point of the two around ``bif`` whose block m is unstable (or point
    number ``point``): its folder (ModelError if the branch's points are not there)."""
    i, j = bif["between"]
    count_i, count_j = bif["unstable"]
    k = (i if count_i > count_j else j) if point is None else point
    folder = Path(branch) / "points" / f"{k:04d}"
    if not (folder / "final.npz").is_file():
        raise ModelError(f"{folder} is not there: the branch's points are needed (a committed "
                         "branch keeps only its table: follow it again with fem_ade.branch)")
    return folder


def start_fields(point: str | Path, m: int, delta: float = DELTA,
                 grid: int = 64, phase: float | None = None) -> tuple[object, dict, float]:
    """(the point's parameters, the 3D start's fields, the block's lowest eigenvalue): the
    point's (r, z) field and axis, ψ_m·δ at its nodes, m, the phase θ₀ (default π/(4m),
    module docstring), and the start on a uniform grid of ``grid``³ nodes (``phi_grid``:
    what a field file holds for any backend)."""
    from fem_ade.backends.fem.modes import lowest_mode
    from fem_ade.backends.fem.newton import NewtonSystem, linearize
    from fem_ade.campaigns.stability import load_state, read_fields
    from fem_ade.scenes.fields import meridian_values

    if not (math.isfinite(delta) and 0 <= delta <= 1):
        raise ModelError(f"delta is the start's max |δψ|, in [0, 1] (0: the revolved state "
                         f"alone, a control), got {delta!r}")
    be, _ = load_state(point)
    sys_ = NewtonSystem(be)
    lam, psi = lowest_mode(sys_, linearize(sys_, be.phi), m)
    saved = read_fields(Path(point) / "final.npz")
    fields = {"axis": np.asarray(saved["axis"], dtype=float),
              "points": np.asarray(saved["points"], dtype=float),
              "phi": np.asarray(saved["phi"], dtype=float),
              "azimuthal_m": np.array(float(m)), "azimuthal_psi": delta * psi,
              "azimuthal_phase": np.array(math.pi / (4 * m) if phase is None else phase)}
    L = be.params.L
    x = np.arange(grid) * (L / grid)
    fields["phi_grid"] = meridian_values(fields, np.stack(np.meshgrid(x, x, x,
                                                                      indexing="ij")))
    return be.params, fields, lam


def mirror_error(phi_grid: np.ndarray) -> float:
    """max |φ − φ∘σ| over the mirrors σ about the box's centre planes, on a uniform periodic
    grid x_j = jL/m (the image of node j about L/2 is node m − j, mod m)."""
    worst = 0.0
    for axis in range(phi_grid.ndim):
        image = np.roll(np.flip(phi_grid, axis=axis), 1, axis=axis)
        worst = max(worst, float(np.max(np.abs(phi_grid - image))))
    return worst


def check_octant_mode(m: int) -> None:
    """ModelError (one line) for a mode the octant cannot hold: an odd m (cos mθ is even
    about the mirrors x and y for even m only)."""
    if m % 2:
        raise ModelError(f"the octant holds cos m theta for even m only (its mirrors x and y); "
                         f"this is m = {m}")


def check_octant_mirrors(point, phi_grid: np.ndarray) -> None:
    """ModelError (one line) for a start that differs from its mirror images about the box's
    centre planes by more than :data:`MIRROR_TOL` (a pear, a body off centre)."""
    if (err := mirror_error(phi_grid)) > MIRROR_TOL:
        raise ModelError(f"{point}: the state is not symmetric about the box's centre "
                         f"planes (max |phi - mirror image| = {err:.2g} > {MIRROR_TOL:g}): "
                         "the octant holds no such shape (a pear, or a body off centre)")


def octant_nodes(params, order: int) -> int:
    """The octant's default nodes per L: :data:`OCTANT_NODES_PER_EPS` per ε, whole cells of
    order p on each half axis."""
    return default_nodes(params.eps, params.L, 2 * order, OCTANT_NODES_PER_EPS)


def default_nodes(eps: float, L: float, order: int, per_eps: float = NODES_PER_EPS) -> int:
    """Nodes per axis of the 3D mesh: ``per_eps``·L/ε (default :data:`NODES_PER_EPS`), up
    to a multiple of the order (a product that rounding lifts a hair above a multiple, as
    2.56/0.04 can, stays on it)."""
    return order * math.ceil(per_eps * L / eps / order - 1e-9)


def chosen(branch: str | Path, index: int | None, point: int | None,
           mode: int | None) -> tuple[dict, Path]:
    """(the bifurcation, the branch point's folder) a switch starts from: bifurcation
    ``index`` (default 0) and the point on its unstable side (or ``point``); or, with
    ``mode`` and ``point`` and no ``index``, that block at that point, a bifurcation or not
    (a branch unstable in it all along). ModelError (one line) for any other combination."""
    if mode is None:
        bif = bifurcation(branch, 0 if index is None else index)
    elif point is None or index is not None or not (isinstance(mode, int) and mode >= 1):
        raise ModelError("a mode m >= 1 is taken at a point (--mode M --point I, without "
                         "--bifurcation)")
    else:  # a point unstable in block `mode`, a bifurcation or not
        bif = {"m": mode, "between": [point, point], "unstable": [1, 0]}
    return bif, unstable_point(branch, bif, point)


def switch(branch: str | Path, index: int | None, out: str | Path, *, delta: float = DELTA,
           n: int | None = None, order: int | None = None, backend: str = "fem",
           max_steps: int | None = None, point: int | None = None,
           checkpoint_every: int = 200, mode: int | None = None, quiet: bool = False,
           geometry: str = "cartesian"):
    """The 3D run from bifurcation ``index`` of a branch folder (module docstring), into the
    run folder ``out``: its :class:`fem_ade.engine.loop.RunResult`, and a dict of what it
    was switched from. ``point``: switch from this point of the branch instead (its block m
    unstable: one farther from the bifurcation, where the flow leaves the saddle faster).
    ``mode`` with ``point`` (and no ``index``): switch along that block at that point, a
    point unstable in it with no bifurcation on the branch (unstable all along).
    ``geometry="octant"``: on the mirror-symmetric eighth of the box (module docstring;
    ``order`` None: :data:`OCTANT_ORDER`). A folder that holds this very switch already
    is continued, not refused: an ended run is returned as it is, an interrupted one
    resumed (so a study or a second call after a kill goes on where it stopped)."""
    from fem_ade.engine.runs import recipe, simulate
    from fem_ade.scenes.catalogue import Scene
    from fem_ade.scenes.initial import FieldIC
    from fem_ade.scenes.vesicle import DT_PER_EPS3

    if geometry not in ("cartesian", "octant"):
        raise ModelError(f"a switch runs in the cartesian or octant geometry, not {geometry!r}")
    octant = geometry == "octant"
    if octant and backend != "fem":
        raise ModelError("the octant geometry is the FEM's (--backend fem)")
    order = (OCTANT_ORDER if octant else RUN_ORDERS["tensor"]) if order is None else order
    bif, point = chosen(branch, index, point, mode)
    m = int(bif["m"])
    if octant:
        check_octant_mode(m)
    options = {"order": order} if backend == "fem" else {}
    if octant:
        options["geometry"] = "octant"
    with tempfile.TemporaryDirectory() as tmp:
        params, fields, lam = start_fields(point, m, delta, phase=0.0 if octant else None)
        if lam >= 0:
            raise ModelError(f"{point}: its block m = {m} has no negative eigenvalue "
                             f"(lowest {lam:.3e}): nothing to switch along")
        if octant:
            check_octant_mirrors(point, fields["phi_grid"])
        start = Path(tmp) / "switch.npz"
        np.savez(start, **fields)
        if octant:
            n = n or octant_nodes(params, order)
        n = n or default_nodes(params.eps, params.L, order)
        origin = {"branch": str(Path(branch).resolve()),
                  "bifurcation": None if mode is not None else (index or 0), "m": m,
                  "v": bif.get("v"), "point": point.name, "eigenvalue": lam, "delta": delta,
                  "geometry": geometry}
        scene = Scene(name=f"switch-m{m}", params=params, dt=DT_PER_EPS3 * params.eps**3,
                      ic=FieldIC(path=str(start)), n=n, dim=3,
                      description="switched into 3D: " + json.dumps(origin))
        kw = {**recipe("steady", scene), "until_steady": UNTIL_STEADY, "backend": backend,
              "n": n, "phi0": str(start),
              "sharp": False, "quiet": quiet, "checkpoint_every": checkpoint_every,
              "backend_options": options}
        if max_steps is not None:
            kw["max_steps"] = max_steps
        result = _continued(Path(out), scene, kw, max_steps, quiet)
        if result is None:
            result = simulate(scene, out=out, **kw)
    return result, origin


def _continued(out: Path, scene, kw: dict, max_steps: int | None, quiet: bool):
    """The result of this very switch in ``out`` if it holds one: an ended run as it ended
    (nothing runs); an interrupted one, or one stopped at a cap below ``max_steps``,
    resumed from its checkpoint (to ``max_steps`` if given); None for a folder with no run
    in it. ModelError if it holds another run (the scene, the description — the branch,
    point, m, δ — and every choice a resume must match,
    :func:`fem_ade.engine.jobs.holds_another`)."""
    from fem_ade.engine.jobs import holds_another, read_summary
    from fem_ade.engine.loop import RunResult
    from fem_ade.engine.runs import resume
    from fem_ade.store.status import ENDED, Status

    if not (out / "run.json").is_file():
        return None
    other = holds_another(out, scene, kw)
    if other:
        raise ModelError(f"{out}: {other}")
    s = read_summary(out)
    more = (s is not None and s.get("status") == Status.MAX_STEPS and max_steps is not None
            and max_steps > s.get("steps", max_steps))  # capped below what is asked now
    if s is not None and s.get("status") in ENDED and not more:
        return RunResult(status=s["status"], steps=s["steps"], t=s["t"], final=s["final"],
                         message=s.get("message", ""), wall_s=s.get("wall_s", 0.0),
                         shape=s.get("shape"), cpu_s=s.get("cpu_s", 0.0))
    if not (out / "checkpoint.npz").is_file():
        raise ModelError(f"{out} holds this switch's run, interrupted before its first "
                         "checkpoint: remove the folder to run it anew")
    return resume(out, steps=max_steps, quiet=quiet)
