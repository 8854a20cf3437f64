"""Is it stable in 3D? The lowest eigenvalues of the constrained Hessian of a steady state.

    python -m fem_ade.stability RUN_FOLDER [--modes M] [--k K] [--json]

For a steady state φ with V and A exact, the eigenvalues of H_L v = λ P v on the
constraints' tangent space (H_L the Hessian of the Lagrangian, P the Hessian of E_h in the
bulk phases: docs/model.md §12) say whether it is stable: a negative one is a direction the
energy falls along. Rigid motions cost nothing in the continuous problem and are taken out
(P-orthogonally).

* **Axisymmetric states** (a run folder or a branch point of ``--geometry axisymmetric``):
  perturbations ψ(r, z) cos mθ decouple by m, so the 3D Hessian is a sum of 2D blocks, one
  per azimuthal mode m = 0, 1, 2, …; each block's k lowest eigenvalues and its count below
  the threshold come from a sparse LU of the bordered (H_m − σP_m) (shift-invert Lanczos and
  the LU's inertia: :mod:`fem_ade.backends.fem.modes`). A mode m ≥ 1 stands for two 3D directions
  (cos mθ and sin mθ): the 3D unstable count is n₀ + 2Σ_{m≥1} n_m.
* **3D states** (a run folder of the Cartesian FEM): the k lowest eigenvalues of the 3D
  constrained Hessian by ARPACK's Lanczos in regular mode, P⁻¹ by the fast
  diagonalization, the three translations and the rotations taken out (:func:`cartesian`).

A direction counts as unstable below a threshold (:func:`threshold`): in units of P the
shape modes' eigenvalues scale as (ε/R₀)⁴ (P is the bulk Hessian, 4κ/ε³ per unit volume;
measured: the prolate's lowest m = 0 one 4.8e-4 at ε = 0.02 and 3.1e-5 at 0.01, R₀ = 0.25),
so a fixed threshold would mean another thing at every ε — the −1e-6 of before counted the
oblate's m = 2 eigenvalue (−1.6e-6 … −5e-7 along it at ε = 0.01) as unstable at some points
and stable at their neighbours.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fem_ade.model.params import ModelError

#: the eigenvalue below which a direction counts as unstable, in units of P·(ε/R₀)⁴ (the
#: shape modes' scale, :func:`threshold`): −1e-6 at ε/R₀ = 0.08, the value used before at
#: every ε (the shape modes' eigenvalues there are 1e-5 … 1e-2)
UNSTABLE = -0.025


def shape_scale(eps: float, R0: float) -> float:
    """(ε/R₀)⁴: the scale of the shape modes' eigenvalues in units of P."""
    return (eps / R0) ** 4


def threshold(params) -> float:
    """The eigenvalue (in units of P) below which a direction of a state with ``params``
    counts as unstable: :data:`UNSTABLE`·(ε/R₀)⁴, R₀ = √(β/4π)."""
    return UNSTABLE * shape_scale(params.eps, math.sqrt(params.beta / (4.0 * math.pi)))


#: the modes and eigenvalues per mode the command line computes by default
MODES, EIGENVALUES = 8, 4
#: a 3D solve whose ``k`` eigenvalues are all unstable is made again with 2k, up to this many
#: (the starfish on the whole box had four below zero of four: the count was not all)
MAX_EIGENVALUES = 32
#: where the directions off the constraints' tangent space are put in the 3D operator
OFF_TANGENT = 10.0
#: Lanczos vectors ARPACK keeps in the 3D eigen-solve (scipy's default: max(2k + 1, 20)).
#: The lowest eigenvalues of a 3D state are shape modes clustered near 0 against a bulk
#: spectrum of O(1), and a longer basis restarts less. Measured on the steady tilted prolate
#: of studies/newton3d_bench.py at 64³, ε = 0.02 (k = 4, one thread; the eigenvalues equal to
#: 1e-11): 20, 60, 100, 140, 200 vectors take 1802, 1305, 906, 782, 767 Hessian products and
#: 127, 110, 83, 75, 80 s (beyond ~140 the orthogonalization costs more than it saves). At
#: 32³, ε = 0.04, where a solve takes seconds, it does not pay: 20, 40, 80, 140, 160 vectors
#: 1.9, 1.7, 2.9, 2.6, 1.6 s (ARPACK's restarts make it uneven)
ARNOLDI_VECTORS = 140


@dataclass
class Stability:
    """The result: ``modes`` {m: k lowest eigenvalues} and ``unstable`` {m: count} for an
    axisymmetric state (``geometry`` "axisymmetric"); ``eigenvalues`` for a 3D one (of the
    mirror-symmetric sector alone for ``geometry`` "octant": a lower bound on the 3D count);
    ``unstable_3d`` the count of unstable 3D directions (m ≥ 1 twice); ``seconds``."""

    geometry: str
    modes: dict = field(default_factory=dict)
    unstable: dict = field(default_factory=dict)
    eigenvalues: list = field(default_factory=list)
    unstable_3d: int = 0
    seconds: dict = field(default_factory=dict)
    #: a 3D state's eigenvectors (columns, at the FEM's nodes) when asked for
    vectors: np.ndarray | None = field(default=None, repr=False)
    #: False when every eigenvalue computed was unstable up to :data:`MAX_EIGENVALUES`: then
    #: ``unstable_3d`` is a lower bound (a 3D state; the blocks count by inertia, exactly)
    complete: bool = True

    def lowest(self, m: int) -> float | None:
        values = self.modes.get(m)
        return float(values[0]) if values is not None and len(values) else None

    def as_json(self) -> dict:
        if self.geometry == "axisymmetric":
            return {"modes": {str(m): [float(x) for x in v] for m, v in self.modes.items()},
                    "unstable": {str(m): int(n) for m, n in self.unstable.items()},
                    "unstable_3d": int(self.unstable_3d)}
        out = {"eigenvalues": [float(x) for x in self.eigenvalues],
               "unstable_3d": int(self.unstable_3d), "complete": bool(self.complete)}
        if self.geometry == "octant":  # the mirror-symmetric sector's: a lower bound
            out["sector"] = "mirror-symmetric (octant)"
        return out


def axisymmetric(be, modes=range(MODES + 1), k: int = EIGENVALUES,
                 below: float | None = None, near: dict | None = None) -> Stability:
    """The stability of an axisymmetric backend's state in the azimuthal ``modes``: per mode
    the ``k`` lowest eigenvalues and the count below ``below`` (default :func:`threshold`;
    module docstring). ``near`` {m: an eigenvalue near the block's lowest} — a neighbouring
    state's, e.g. the previous branch point's :meth:`Stability.lowest` — lets a block's
    Lanczos start from a shift nearer its lowest (:func:`fem_ade.backends.fem.modes.lowest`:
    fewer solves; the same eigenvalues and counts)."""
    import time

    from fem_ade.backends.fem.modes import lowest
    from fem_ade.backends.fem.newton import NewtonSystem, linearize

    sys_ = NewtonSystem(be)
    lin = linearize(sys_, be.phi.copy())
    out = Stability("axisymmetric")
    sigma = threshold(be.params) if below is None else below
    for m in modes:
        t0 = time.perf_counter()
        result = lowest(sys_, lin, int(m), k=k, sigma=sigma, near=(near or {}).get(int(m)))
        out.modes[int(m)] = result.eigenvalues
        out.unstable[int(m)] = result.unstable
        out.seconds[int(m)] = round(time.perf_counter() - t0, 3)
    out.unstable_3d = sum(n if m == 0 else 2 * n for m, n in out.unstable.items())
    return out


def cartesian(be, k: int = EIGENVALUES, below: float | None = None,
              tol: float = 1e-9, ncv: int = ARNOLDI_VECTORS,
              vectors: bool = False, most: int = MAX_EIGENVALUES) -> Stability:
    """The ``k`` lowest eigenvalues of H_L v = λ P v of a 3D FEM state on {Cᵀv = 0}, C the
    constraints' gradients and P times each rigid motion (a negligible one — a rotation
    about a state's axis of symmetry — left out): ARPACK (regular mode, P⁻¹ by the fast
    diagonalization) on ΠᵀH_LΠ + σ_c C(CᵀP⁻¹C)⁻¹Cᵀ, Π the P-orthogonal projector on the
    tangent space (the directions off it moved to σ_c = :data:`OFF_TANGENT`), with ``ncv``
    Lanczos vectors (:data:`ARNOLDI_VECTORS`); ``vectors``: keep the eigenvectors too
    (``Stability.vectors``, P-normalised, in the order of the eigenvalues). While all k are
    below ``below`` (default :func:`threshold`) the solve is made again with 2k, up to
    ``most``: the count of unstable directions is then all of them, or
    ``Stability.complete`` is False and it is a lower bound."""
    import time

    from scipy.sparse.linalg import eigsh

    t0 = time.perf_counter()
    H, P, P_inverse = _tangent_operators(be)
    N = be.phi.size
    sigma = threshold(be.params) if below is None else below
    while True:
        found = eigsh(H, k=k, M=P, Minv=P_inverse, which="SA", tol=tol,
                      ncv=min(N - 1, max(2 * k + 1, ncv)), return_eigenvectors=vectors,
                      v0=np.ones(N))
        vals, vecs = found if vectors else (found, None)
        order = np.argsort(vals)
        vals = vals[order]
        complete = bool(vals[-1] >= sigma)
        if complete or 2 * k > min(most, N - 2):
            break
        k *= 2
    out = Stability("octant" if getattr(be, "geometry", "") == "octant" else "cartesian",
                    eigenvalues=list(vals), vectors=None if vecs is None else vecs[:, order],
                    unstable_3d=int(np.sum(vals < sigma)), complete=complete)
    out.seconds["all"] = round(time.perf_counter() - t0, 3)
    return out


def count_text(unstable: int | None, eigenvalues=()) -> str:
    """A 3D count of unstable directions as a table shows it: ``n``, or ``≥ n`` when every
    eigenvalue computed (``eigenvalues``) was unstable, so that the count is a lower bound
    (:attr:`Stability.complete` False; counts written before :func:`cartesian` asked for
    more when all k were unstable); ``—`` for none computed."""
    if unstable is None:
        return "—"
    return f"≥ {unstable}" if eigenvalues and unstable >= len(eigenvalues) else f"{unstable}"


def _tangent_operators(be):
    """(H, P, P⁻¹) of :func:`cartesian` as LinearOperators: the constrained Hessian projected
    on the tangent space (the rest moved to :data:`OFF_TANGENT`), the preconditioner's P and
    its fast-diagonalization inverse."""
    from scipy.sparse.linalg import LinearOperator

    from fem_ade.backends.fem.modes import p_orthogonal, zero_modes
    from fem_ade.backends.fem.newton import NewtonSystem, lagrangian_hessian_vector, linearize

    sys_ = NewtonSystem(be)
    lin = linearize(sys_, be.phi.copy())
    step, N, P = sys_.step, be.phi.size, sys_.P
    if getattr(be, "geometry", "cartesian") == "axisymmetric":
        Cs = list(lin.C[:2]) + p_orthogonal(P, zero_modes(be.space, lin.phi, 0))
    else:  # in 3D Newton's pins are P times this state's rigid motions, made P-orthogonal
        Cs = list(lin.C)
    C = np.column_stack(Cs)
    Y = np.column_stack([sys_.P_inverse(cj) for cj in Cs])
    G = np.linalg.inv(C.T @ Y)

    def H(x):
        x = np.ravel(x)
        y = x - Y @ (G @ (C.T @ x))
        h = lagrangian_hessian_vector(step, lin, y)
        return h - C @ (G @ (Y.T @ h)) + OFF_TANGENT * (C @ (G @ (C.T @ x)))

    return tuple(LinearOperator((N, N), matvec=f, dtype=float)
                 for f in (H, P, lambda x: sys_.P_inverse(np.ravel(x))))


# ---------------------------------------------------------------------------------------------
# a run folder or a branch point
# ---------------------------------------------------------------------------------------------
#: a saved state is steady when Newton from it takes at most this many iterations and moves
#: E by at most this much (relative); the CLI then reports the polished state's stability
POLISH_ITERATIONS, POLISH_DE = 6, 1e-7


def load_state(folder: str | Path):
    """(backend at the saved state, what it is) of a run folder or a branch point, with V
    and A held exactly (a run with penalties: at its own V and A); ModelError (one line) if
    it is neither, or unreadable."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ModelError(f"{folder} is not a folder (a run folder or a branch point)")
    branch = folder.parent.parent / "branch.json"
    if folder.parent.name == "points" and branch.is_file():
        return _branch_point(folder, branch), "branch point"
    if (folder / "run.json").is_file():
        return _run_folder(folder), "run folder"
    raise ModelError(f"{folder} is neither a run folder (run.json) nor a branch point "
                     "(points/NNNN of a branch folder)")


def read_fields(path: Path) -> dict:
    """The arrays of a saved field file (final.npz) as a dict; ModelError (one line) for a
    file that is not readable."""
    import zipfile

    try:
        with np.load(path) as z:
            return {k: np.array(z[k]) for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise ModelError(f"{path} is not readable ({type(err).__name__})") from None


def _branch_point(folder: Path, branch: Path):
    from fem_ade.backends.fem.axisym import SavedMeshBackend
    from fem_ade.campaigns.branch_folder import read_identity
    from fem_ade.model.params import Params
    from fem_ade.scenes.vesicle import set_parameter

    try:
        identity = read_identity(branch.parent)
        row = json.loads((folder / "summary.json").read_text())
        params = Params(**identity["params"])
        params = set_parameter(params, identity["param"], float(row[identity["param"]]))
        n = int(identity["n"])
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise ModelError(f"{folder} is not a readable branch point ({type(err).__name__}: "
                         f"{err})") from None
    fields = read_fields(folder / "final.npz")
    try:
        return SavedMeshBackend(params, fields, n=n)
    except KeyError as err:
        raise ModelError(f"{folder}/final.npz lacks {err}: not an axisymmetric point") from None


def _run_folder(folder: Path):
    from fem_ade.engine.runs import build_backend, read_run

    scene, config = read_run(folder)
    if config.backend != "fem":
        raise ModelError(f"{folder} is a run of the {config.backend} backend: the stability "
                         "needs the FEM's Hessian (run it with --backend fem)")
    fields = read_fields(folder / "final.npz")
    if config.backend_options.get("geometry") == "axisymmetric" and "r_vertices" in fields:
        from fem_ade.backends.fem.axisym import SavedMeshBackend

        be = SavedMeshBackend(scene.params, fields, n=config.n)
    else:
        exact = config.with_(constraints="exact", scheme="stabilized")
        be = build_backend(scene, exact)
        phi = np.asarray(fields.get("phi", []), dtype=float).ravel()
        if phi.size != be.phi.size:
            raise ModelError(f"{folder}/final.npz holds no field of its run's mesh")
        be._set(phi, None)
    if config.constraints != "exact":  # the shape at its own V and A
        d = be.diagnostics()
        be.stepper.params = be.params = be.params.with_(alpha=d["V"], beta=d["A"])
    return be


def polish(be) -> dict:
    """Newton from the saved state (:func:`fem_ade.backends.fem.newton.solve_steady`): the state's
    steadiness; ModelError (one line) if it is not a steady state (Newton does not converge
    within :data:`POLISH_ITERATIONS`, or moves E by more than :data:`POLISH_DE`)."""
    from fem_ade.backends.fem.newton import NewtonError, solve_steady

    E0 = be.diagnostics()["E"]
    try:
        result = solve_steady(be, max_iterations=POLISH_ITERATIONS)
    except NewtonError as err:
        raise ModelError(f"not a steady state: {err}") from None
    change = abs(result.E - E0) / max(abs(E0), 1e-300)
    if not result.converged or change > POLISH_DE:
        how = f"moves E by {change:.1e}" if result.converged else "does not converge"
        raise ModelError(f"not a steady state: Newton from it {how} in {result.iterations} "
                         "iterations (run it to a steady state first: --recipe steady, or "
                         "python -m fem_ade.branch)")
    return {"newton_iterations": result.iterations, "E": result.E, "relative_change": change}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m fem_ade.stability",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", help="a run folder (FEM) or a branch point (BRANCH/points/NNNN)")
    ap.add_argument("--modes", type=int, default=MODES,
                    help=f"azimuthal modes 0 … M of an axisymmetric state (default {MODES})")
    ap.add_argument("--k", type=int, default=EIGENVALUES,
                    help=f"the lowest eigenvalues per mode (default {EIGENVALUES})")
    ap.add_argument("--json", action="store_true", help="print one JSON object")

    def error(message):
        ap.exit(2, f"fem_ade.stability: error: {message}\n")

    ap.error = error
    args = ap.parse_args(argv)
    from fem_ade.backends.threads import limited
    from fem_ade.store.interrupt import install

    install()
    try:
        if args.modes < 0 or args.k < 1:
            raise ModelError(f"--modes must be >= 0 and --k >= 1, got {args.modes}, {args.k}")
        be, kind = load_state(Path(args.folder))
        steady = polish(be)
        with limited():
            if getattr(be, "geometry", "cartesian") == "axisymmetric":
                result = axisymmetric(be, range(args.modes + 1), args.k)
            else:
                result = cartesian(be, args.k)
    except ModelError as err:
        print(f"fem_ade.stability: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fem_ade.stability: interrupted", file=sys.stderr)
        return 130
    if args.json:
        print(json.dumps(result.as_json()))
        return 0
    print(f"{args.folder}: a {kind}, steady (Newton {steady['newton_iterations']} "
          f"iterations, E = {steady['E']:.10g})")
    if result.geometry == "axisymmetric":
        for m, values in result.modes.items():
            print(f"  m = {m}: " + ", ".join(f"{x:.4g}" for x in values)
                  + f"   unstable {result.unstable[m]}" + ("" if m == 0 else " (x2 in 3D)"))
    else:
        print("  " + ", ".join(f"{x:.4g}" for x in result.eigenvalues))
    count = (f"{result.unstable_3d}" if result.complete else
             f"at least {result.unstable_3d} (every one of the {len(result.eigenvalues)} "
             "computed)")
    if result.geometry == "octant":
        print(f"unstable directions even in x, y and z (the octant's; in 3D at least as "
              f"many): {count}")
    else:
        print(f"unstable directions in 3D: {count}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
