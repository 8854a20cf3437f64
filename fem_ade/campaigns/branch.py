"""Branches of steady states: pseudo-arclength continuation in one parameter, folds, and
stability (issue 32), on the FEM with Newton's method (:mod:`fem_ade.backends.fem.newton`).

    python -m fem_ade.branch vesicle --branch prolate --eps 0.01 --param v --from 0.95 \\
        --to 0.6 [--step 0.01] [--geometry axisymmetric] [--n N] [--order P] --out DIR

A branch starts at ``--from``: the scene's seed run to a steady state by the ``steady``
recipe's flow (to 1e-9 per step) and polished by Newton. Each further point is predicted
by the quadratic through the last three points in their chord lengths (from two: their
secant; at the first, along the solution of the Newton system's parameter derivative:
:meth:`Continuation.predict`) and corrected by Newton on the extended system

    F(φ, p) = (∇_φ L, V − α, A − β) = 0,
    θ ⟨t_φ, φ − φ_k⟩ + t_p (p − p_k) = Δs        (pseudo-arclength, Keller 1977),

by bordering: two solves of the symmetric bordered system of
:func:`fem_ade.backends.fem.newton.kkt_solve` (for −F and for −∂F/∂p, the latter a central
difference
in p), the arclength row eliminated. ⟨·,·⟩ is the mean over the domain (Σ wᵢ xᵢ yᵢ / Σ wᵢ),
and θ makes the first tangent's field and parameter parts equal. Δs halves where Newton does
not converge in ``MAX_NEWTON`` iterations and grows by 1.5 where it takes ≤ 4, between
``--step``/8 and 4·``--step``. A fold (turning point) is where the tangent's t_p changes
sign; its parameter is the extremum of the quadratic through the three points around it.
The branch ends at ``--to``, at a topology change (:func:`same_topology`: an oblate opening
into a torus, a neck closing into two vesicles; a genus-0 shape whose label changes — pear to
gourd, discocyte to stomatocyte — goes on) or where Δs falls below its least.

Stability: at each point the few lowest eigenvalues of the Hessian of the Lagrangian on the
constraints' tangent space, H_L v = λ P v with Cᵀv = 0 (ARPACK on the projected operator, P⁻¹
by the step's exact solve: :func:`stability`; P is Newton's bulk Hessian, so the count of
negative λ — the unstable directions — is that of the constrained Hessian by Sylvester's law
of inertia). In the axisymmetric geometry only
axisymmetric directions are seen.

Parameters (the ``vesicle`` family's, mapped to the model's with the seed's R₀ = √(β/4π)
kept): ``v`` (α = (4π/3)R₀³v), ``da0`` (ΔA₀ = 8πDR₀·Δa₀), ``kbar`` (κ̄/κ), ``C``.

The branch folder: ``points/NNNN/`` (``final.npz``: φ and its points; ``summary.json``: the
point's parameter, E and its parts, V, A, ΔA, e = (W + G)/W_sphere, the φ = 0 surface's v
and Δa, the label, the lowest eigenvalues and the unstable count, Newton's iterations),
``branch.json`` (what the branch is: a resumed one must be the same; its --to may differ, on
the same side of --from: the branch goes on to it), ``branch.csv`` (one
row per point: the parameter, e, E, W, G, unstable, label, fold, ...), ``branch.png`` (e
against the parameter: stable solid, unstable dashed, folds marked) and ``shapes.png``
(the meridians). Killed and started again with the same command, a branch goes on from its
last points — only from points it can vouch for (:func:`load_points`): each point's
summary.json carries its ``integrity`` (the checksum of the branch's identity, its index, the
checksums of its φ and its row), and a gap, a stranger, a copy, an edit or a folder without
branch.json stops the resume with one line.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from fem_ade.backends.threads import limit_threads
from fem_ade.model.params import HISTORY_COLUMNS, ModelError
from fem_ade.scenes.vesicle import PARAMETERS, get_parameter, set_parameter  # noqa: F401 (the branch's)

#: Newton iterations before a step is taken again at half the arclength; at most this many,
#: and the next step is half as long again. Measured with the quadratic predictor: 4-5 at
#: ε = 0.02 (the prolate, v 0.95 -> 0.85), 5-8 at ε = 0.01 (the pear at v = 0.8, Δa₀ 1.526
#: down through its fold at 1.5062 to 1.5068, where its lowest eigenvalue crosses 0 and
#: Newton stops converging; the secant predictor took 6-12 there and stopped converging at
#: 1.5065, before the fold). The first iterations contract the error by irregular factors
#: of 1.1-10, the last 2-3 quadratically: the exact Newton method outside its small
#: quadratic basin (:mod:`fem_ade.backends.fem.newton`), not an inexact solve
MAX_NEWTON, GROW_BELOW = 12, 4
#: the lowest eigenvalues of the m = 0 block computed at each point (stability; the
#: threshold below which a direction counts as unstable:
# :func:`fem_ade.campaigns.stability.threshold`)
EIGENVALUES = 4
#: the most azimuthal modes a branch computes at each point, and the command line's default
MAX_MODES, DEFAULT_MODES = 32, 8
#: a Newton correction is converged when its decrement |∇Lᵀδφ|/|E| (relative energy, as in
#: :func:`fem_ade.backends.fem.newton.solve_steady`) is below this and its |δp| below 1e-9·max(|p|,
# 1),
#: and
#: given up (a shorter step is tried) once its residual exceeds DIVERGED times its first: a
#: diverging correction's bordered solves take the most MINRES iterations (5000 at eps =
#: 0.005, where converging ones take 250-500); the converging ones measured there stay below
#: their first residual
NEWTON_TOL, DIVERGED = 1e-12, 2.0
#: the least arclength step, relative to the parameter's size: below it the parameter's
#: derivative (a central difference) and the predictor's chords are round-off
MIN_STEP = 1e-6
#: the table's columns: a point's energies and functionals are the history's columns
#: (:data:`fem_ade.model.params.HISTORY_COLUMNS` after step and t)
COLUMNS = ("point", "e", *HISTORY_COLUMNS[2:], "v_surface", "da_surface", "unstable",
           "lowest_eigenvalue", "label", "fold", "newton", "seconds", "newton_s", "stability_s")


# ---------------------------------------------------------------------------------------------
# the parameter
# ---------------------------------------------------------------------------------------------
def check_parameter(params, name: str) -> None:
    if name not in PARAMETERS:
        raise ModelError(f"--param must be one of {', '.join(PARAMETERS)}, got {name!r}")
    if name in ("da0", "kbar") and not params.on("ade"):
        raise ModelError(f"--param {name} moves the ADE term, which is off in this scene "
                         "(the vesicle family: give --kbar and --da0)")
    if name == "C" and not params.on("spontaneous_curvature"):
        raise ModelError("--param C moves the spontaneous curvature, which is off in this "
                         "scene (give --C, e.g. 0.0 is not on: use a small value)")


def check_branch(params, param: str, start, stop, step, folds=None) -> None:
    """A branch's settings (ModelError, one line): the parameter (:func:`check_parameter`),
    two different ends, a step in (0, |to − from|], folds a whole number ≥ 0 or None."""
    check_parameter(params, param)

    def number(x):
        return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

    if not (number(start) and number(stop)) or start == stop:
        raise ModelError(f"--from and --to must be two different numbers, got {start}, {stop}")
    if param == "v" and not (0 < start <= 1 and 0 < stop <= 1):
        raise ModelError(f"--from and --to of the reduced volume v must be in (0, 1] (v = 1 "
                         f"is the sphere), got {start}, {stop}")
    span = abs(stop - start)
    least = MIN_STEP * max(1.0, abs(start), abs(stop))
    if not (number(step) and least <= step <= span * (1.0 + 1e-9)):
        raise ModelError(f"--step must be in [{least:.3g}, |to - from| = {span:.6g}], got "
                         f"{step}")
    if folds is not None and (isinstance(folds, bool) or not isinstance(folds, int)
                              or folds < 0):
        raise ModelError(f"--folds must be a whole number >= 0, got {folds}")


def check_branch_name(branch) -> None:
    """The sharp branch a followed branch stands for (the vesicle family's, but the sphere:
    it is the point v = 1 of the prolate and the oblate)."""
    from fem_ade.registry import VESICLE_BRANCHES

    if branch == "sphere":
        raise ModelError("--branch sphere: the sphere is one point (v = 1) of the prolate and "
                         "oblate branches; follow --branch prolate or oblate from it")
    if branch not in VESICLE_BRANCHES:
        raise ModelError(f"--branch must be one of {', '.join(VESICLE_BRANCHES)}, got "
                         f"{branch!r}")


# ---------------------------------------------------------------------------------------------
# continuation
# ---------------------------------------------------------------------------------------------
class Continuation:
    """The extended Newton system of one backend along one parameter (module docstring)."""

    def __init__(self, be, name: str):
        from fem_ade.backends.fem.newton import NewtonSystem

        self.be, self.name = be, name
        self.sys = NewtonSystem(be)
        self.w = be.space.weights
        self.volume = float(np.sum(self.w))
        self.theta = 1.0

    # the parameter as the backend runs it
    @property
    def p(self) -> float:
        return get_parameter(self.be.stepper.params, self.name)

    def set_p(self, value: float) -> None:
        params = set_parameter(self.be.stepper.params, self.name, float(value))
        self.be.stepper.params = params
        self.be.params = params
        self.be.scene = replace(self.be.scene, params=params)

    def inner(self, a, b) -> float:
        from fem_ade.backends.fem.solve import global_dot

        return global_dot(self.w * a, b) / self.volume

    def residual(self, phi, lam):
        """F = (∇E + Cλ, V − α, A − β, 0) at φ and the current parameter, λ given."""
        sys_ = self.sys
        mu, Kphi = sys_.fields(phi)
        C = sys_.constraint_gradients(phi, Kphi)
        g = sys_.gradient(phi, mu, Kphi) + sum(lj * cj for lj, cj in zip(lam, C, strict=True))
        return np.concatenate([g, sys_.constraint_values(phi, Kphi)])

    def parameter_derivative(self, phi, lam, h: float | None = None) -> np.ndarray:
        """∂F/∂p by a central difference in p (the model is polynomial in α, ΔA₀, κ̄, C)."""
        p = self.p
        h = h or 1e-6 * max(abs(p), 1.0)
        self.set_p(p + h)
        plus = self.residual(phi, lam)
        self.set_p(p - h)
        minus = self.residual(phi, lam)
        self.set_p(p)
        return (plus - minus) / (2.0 * h)

    def tangent(self, phi) -> tuple[np.ndarray, float]:
        """(t_φ, t_p) at a solution: t_φ = dφ/dp from the bordered system, normalized so
        that θ⟨t_φ, t_φ⟩ + t_p² = 1 (θ set here, the first time, to make both parts equal)."""
        from fem_ade.backends.fem.newton import kkt_solve, linearize

        lin = linearize(self.sys, phi)
        Fp = self.parameter_derivative(phi, lin.lam)
        x, _ = kkt_solve(self.sys, lin, -Fp)
        t_phi = x[:phi.size]
        if self.theta == 1.0:
            self.theta = 1.0 / max(self.inner(t_phi, t_phi), 1e-300)
        norm = math.sqrt(self.theta * self.inner(t_phi, t_phi) + 1.0)
        return t_phi / norm, 1.0 / norm

    def chord(self, a, b) -> float:
        """The distance √(θ⟨Δφ, Δφ⟩ + Δp²) between two points (φ, p) of the branch."""
        dphi, dp = b[0] - a[0], b[1] - a[1]
        return math.sqrt(self.theta * self.inner(dphi, dphi) + dp * dp)

    def predict(self, points, ds):
        """The predicted point at an arclength ``ds`` past the last of ``points`` (the last
        two or three (φ, p) of the branch) and the tangent there: ((φ, p), (t_φ, t_p)). From
        three points, the quadratic through them in their chord lengths (its value at ds, its
        derivative at the last point); from two, the secant. Measured on the pear at ε = 0.01
        (v = 0.8, Δa₀ ≈ 1.52, Δs = 0.005): the quadratic's prediction is 2.3× nearer the
        corrected point (|Δφ|∞ 9e-3 against 2e-2), which Newton then needs one iteration
        fewer to correct (5 against 6, three points); along the branch 65 iterations for its
        first 11 points against the secant's 91, and the fold passed."""
        (phi_k, p_k), (phi_j, p_j) = points[-1], points[-2]
        if len(points) >= 3:
            phi_i, p_i = points[-3]
            h2 = self.chord(points[-2], points[-1])
            h1 = self.chord(points[-3], points[-2])
            s = (-h1 - h2, -h2, 0.0)  # the three points' arclengths, the last at 0

            def weights(x, derivative=False):  # Lagrange's basis (or its derivative) at x
                out = []
                for a in range(3):
                    b, c = (k for k in range(3) if k != a)
                    den = (s[a] - s[b]) * (s[a] - s[c])
                    out.append(((x - s[b]) + (x - s[c]) if derivative
                                else (x - s[b]) * (x - s[c])) / den)
                return out

            w = weights(ds)
            d = weights(0.0, derivative=True)
            predicted = (w[0] * phi_i + w[1] * phi_j + w[2] * phi_k,
                         w[0] * p_i + w[1] * p_j + w[2] * p_k)
            t_phi = d[0] * phi_i + d[1] * phi_j + d[2] * phi_k
            t_p = d[0] * p_i + d[1] * p_j + d[2] * p_k
        else:
            t_phi, t_p = phi_k - phi_j, p_k - p_j
            predicted = None
        norm = math.sqrt(self.theta * self.inner(t_phi, t_phi) + t_p * t_p)
        t_phi, t_p = t_phi / norm, t_p / norm
        if predicted is None:
            predicted = (phi_k + ds * t_phi, p_k + ds * t_p)
        return predicted, (t_phi, t_p)

    def advance(self, history, first, ds: float, ds_min: float):
        """The next point past the last of ``history`` (its last three (φ, p)): predicted
        by the secant of the last two, then by the quadratic through three, or along
        ``first`` (the tangent, at the branch's first step), corrected by Newton; the step
        halved until one converges. ((φ, p, its) or None below ``ds_min``, the step taken.)
        The secant first: on the pear at v = 0.75, ε = 0.01 the quadratic first (then the
        secant) ended the branch at Δa₀ = 1.5609 after 6 points, the secant alone at 1.5879
        after 14 — the points carry a mesh-pinned translation that the quadratic
        extrapolates — while on the pear at v = 0.8 the quadratic passed a fold the secant
        stopped at (measured)."""
        phi_k, p_k = history[-1]
        fits = (history[-2:], history) if len(history) >= 3 else (history[-2:],)
        while ds >= ds_min:
            for fit in fits:
                if first is None:
                    predicted, tangent = self.predict(fit, ds)
                else:
                    tangent = first
                    predicted = (phi_k + ds * first[0], p_k + ds * first[1])
                corrected = self.correct(*predicted, (phi_k, p_k), tangent, ds)
                if corrected is not None:
                    return corrected, ds
            ds *= 0.5
        return None, ds

    def correct(self, phi, p, anchor, tangent, ds):
        """Newton on the extended system from the predicted (φ, p); (φ, p, iterations) or
        None if it does not converge in :data:`MAX_NEWTON` iterations."""
        from fem_ade.backends.fem.newton import kkt_solve, linearize
        from fem_ade.backends.fem.solve import global_dot

        phi_k, p_k = anchor
        t_phi, t_p = tangent
        self.set_p(p)
        first = None
        for it in range(1, MAX_NEWTON + 1):
            lin = linearize(self.sys, phi)
            R = np.concatenate([lin.grad, lin.violation])
            size = float(np.linalg.norm(R))
            first = size if first is None else first
            if not size <= DIVERGED * first:  # diverging: a shorter step, before the solves
                return None
            Fp = self.parameter_derivative(phi, lin.lam)
            X, _ = kkt_solve(self.sys, lin, -np.column_stack([R, Fp]))
            x1, x2 = X[:, 0], X[:, 1]
            n = phi.size
            g = self.theta * self.inner(t_phi, phi - phi_k) + t_p * (p - p_k) - ds
            denom = self.theta * self.inner(t_phi, x2[:n]) + t_p
            if denom == 0.0 or not math.isfinite(denom):
                return None
            dp = (-g - self.theta * self.inner(t_phi, x1[:n])) / denom
            dphi = x1[:n] + dp * x2[:n]
            phi, p = phi + dphi, p + dp
            self.set_p(p)
            if not np.all(np.isfinite(phi)) or np.max(np.abs(phi)) > 2.0:
                return None
            decrement = abs(global_dot(lin.grad, dphi)) / max(abs(lin.E), 1e-300)
            if decrement < NEWTON_TOL and abs(dp) < 1e-9 * max(abs(p), 1.0):
                phi = self.sys.restore(phi)
                return (phi, p, it) if phi is not None else None
        return None


def stability(be, k: int = EIGENVALUES) -> np.ndarray:
    """The ``k`` lowest eigenvalues of H_L v = λ P v on {Cᵀv = 0} at the backend's state,
    ascending: in the axisymmetric geometry the azimuthal block m = 0
    (:func:`fem_ade.backends.fem.modes.lowest`: shift-invert Lanczos on a sparse LU of the bordered
    H − σP; the z-translation taken out), elsewhere :func:`fem_ade.campaigns.stability.cartesian`
    (ARPACK in regular mode, the rigid motions taken out). Both equal a dense solve of the
    same problem; the two agree to 3e-12 on the prolate at ε = 0.02 (m = 0).

    C = (∇V, ∇A, P t) with t = ∂φ/∂z in the axisymmetric geometry: a shape's translation
    along the axis is a zero mode of the continuous problem, which the mesh pins with a
    small energy of either sign. Counted (with Newton's pin ∇T in its place, which a slight
    tilt of the bulk φ satisfies), it made isolated points of the prolate at ε = 0.01,
    v 0.95 → 0.6 "unstable" (v = 0.668, 0.624, 0.609: lowest −1.9e-6 … −2.7e-4 between
    neighbours at +1.6e-5 … +1.4e-4; its eigenvector 0.83 along the translation); without it
    the lowest is the next shape mode, smooth along the branch (1.05e-4 … 1.76e-4 there,
    measured)."""
    if getattr(be, "geometry", "cartesian") == "axisymmetric":
        from fem_ade.campaigns.stability import axisymmetric

        return np.asarray(axisymmetric(be, (0,), k).modes[0])
    from fem_ade.campaigns.stability import cartesian

    return np.asarray(cartesian(be, k).eigenvalues)


# ---------------------------------------------------------------------------------------------
# the branch folder
# ---------------------------------------------------------------------------------------------
def describe_point(be, name: str, cont: Continuation, newton: int, seconds: float,
                   stab) -> dict:
    """A point's row; ``stab`` its :class:`fem_ade.campaigns.stability.Stability` (None: not
    computed:
    ``unstable`` and ``lowest_eigenvalue`` None): the m = 0 block's ``eigenvalues``, its
    unstable count, and with azimuthal modes the lowest eigenvalue of each
    (``lowest_mM``) and the count of unstable 3D directions (``unstable_3d``)."""
    from fem_ade.analysis.sharp import reduced_energy

    final = be.diagnostics()
    shape, _ = be.describe_final(final)
    sharp = (shape or {}).get("sharp") or {}
    eigenvalues = np.zeros(0) if stab is None else np.asarray(stab.modes[0])
    row = {name: cont.p, "e": reduced_energy(final, be.params.kappa),
           **{k: final[k] for k in HISTORY_COLUMNS[2:]},
           "v_surface": sharp.get("reduced_volume"),
           "da_surface": sharp.get("reduced_area_difference"),
           "label": (shape or {}).get("label"),
           "unstable": None if stab is None else int(stab.unstable[0]),
           "eigenvalues": [float(x) for x in eigenvalues],
           "lowest_eigenvalue": float(eigenvalues[0]) if len(eigenvalues) else None,
           "newton": newton, "seconds": round(seconds, 2), "theta": cont.theta}
    if stab is not None and len(stab.modes) > 1:
        row.update({f"lowest_m{m}": stab.lowest(m) for m in stab.modes})
        row["unstable_3d"] = int(stab.unstable_3d)
        row["unstable_modes"] = {str(m): int(n) for m, n in stab.unstable.items()}
    return row


def _digest(text: bytes) -> str:
    import hashlib

    return hashlib.sha256(text).hexdigest()


def identity_digest(identity: dict) -> str:
    """The branch's identity (branch.json) as a checksum: what ties each point to it."""
    return _digest(json.dumps(identity, sort_keys=True).encode())


def field_digest(phi: np.ndarray) -> str:
    """A point's φ as a checksum (its float64 values, little-endian)."""
    return _digest(np.ascontiguousarray(phi, dtype="<f8").tobytes())


#: a row's keys that are not the point's own: the checksum's record, and the fold, which
#: its neighbours decide (:func:`mark_folds`)
DERIVED = ("integrity", "fold")


def row_digest(row: dict) -> str:
    """A point's row as a checksum: its values as summary.json stores them, without
    :data:`DERIVED`."""
    from fem_ade.store.output import jsonable

    plain = {k: v for k, v in row.items() if k not in DERIVED}
    return _digest(json.dumps(jsonable(plain), sort_keys=True).encode())


def save_point(out: Path, k: int, be, row: dict, branch: str) -> dict:
    """Point ``k`` in ``points/NNNN/``: final.npz (φ), then summary.json (its row and its
    ``integrity``: the branch's :func:`identity_digest`, the index, φ's and the row's
    checksums — the summary is written last, so a point cut short has none); the row as
    saved."""
    from fem_ade.store.output import jsonable, write_fields, write_json_atomic

    folder = out / "points" / f"{k:04d}"
    folder.mkdir(parents=True, exist_ok=True)
    fields = be.fields()
    write_fields(folder / "final.npz", fields)
    row = json.loads(json.dumps(jsonable({k_: v for k_, v in row.items()
                                          if k_ not in DERIVED})))
    row["integrity"] = {"branch": branch, "index": k, "phi": field_digest(fields["phi"]),
                        "row": row_digest(row)}
    write_json_atomic(folder / "summary.json", row)
    return row


def load_points(out: Path, branch: str | None = None, size: int | None = None,
                param: str | None = None) -> list[tuple[dict, np.ndarray]]:
    """The saved points of a branch folder, in order: (row, φ). Each is checked against the
    branch (``branch``: its :func:`identity_digest`) — its index, its φ's and its row's
    checksums, its φ's length (``size``); the folders must be 0000, 0001, … without a gap
    or a stranger. Only the last may be cut short (final.npz without summary.json: a kill
    between the two), and is left out. ModelError (one line) for anything else: a resume
    never continues from points it cannot vouch for. Points written before the checksums
    (no ``integrity``) are taken as they are, in their order."""
    points = out / "points"
    if not points.exists():
        return []
    if not points.is_dir():
        raise ModelError(f"{points} is not a folder: {out} is not a branch folder this "
                         "command can continue")
    names = sorted(p.name for p in points.iterdir())
    strangers = [n for n in names if not (len(n) == 4 and n.isdigit()
                                          and (points / n).is_dir())]
    if strangers:
        raise ModelError(f"{points} holds {strangers[0]!r}, which is no point of a branch: "
                         "remove it, or give another --out")
    found = []
    for k, name in enumerate(names):
        where = points / name
        if name != f"{k:04d}":
            raise ModelError(f"{points}: point {k:04d} is missing (next is {name}): the "
                             f"branch's points have a gap; remove the points from {name} "
                             "on to go on from the last whole one, or give another --out")
        summary = where / "summary.json"
        if not summary.exists() and k == len(names) - 1:
            break  # cut short by a kill: made again
        try:
            row = json.loads(summary.read_text())
            with np.load(where / "final.npz") as z:
                phi = np.array(z["phi"], dtype=float)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as err:
            raise ModelError(f"{where} is not a whole point ({type(err).__name__}: "
                             f"{str(err)[:80]}): remove it and the points after it, or give "
                             "another --out") from None
        _check_point(where, k, row, phi, branch, size, param)
        found.append((row, phi))
    return found


def _check_point(where: Path, k: int, row, phi: np.ndarray, branch, size, param) -> None:
    """ModelError (one line) where a saved point is not point ``k`` of this branch."""
    def refuse(why):
        raise ModelError(f"{where}: {why}; a resume continues only from its own branch's "
                         "points: remove this point and those after it, or give another --out")

    if not isinstance(row, dict):
        refuse("its summary.json is not a table")
    for key in (param, "e", "s", "theta") if param else ():
        value = row.get(key, 0.0 if key in ("s", "theta") else None)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not \
                math.isfinite(value):
            refuse(f"its {key} is {value!r}, not a number")
    if phi.ndim != 1 or (size is not None and phi.size != size) or not np.all(
            np.isfinite(phi)):
        refuse(f"its final.npz holds no finite field of this branch's {size} nodes")
    record = row.get("integrity")
    if record is None:  # written before the checksums
        return
    if not isinstance(record, dict):
        refuse("its integrity record is not a table")
    if branch is not None and record.get("branch") != branch:
        refuse("it belongs to another branch (its integrity record names another)")
    if record.get("index") != k:
        refuse(f"it is point {record.get('index')!r} of its branch, not {k}")
    if record.get("phi") != field_digest(phi):
        refuse("its final.npz is not the field the point was saved with (changed or "
               "replaced)")
    if record.get("row") != row_digest(row):
        refuse("its summary.json was changed after the point was saved")


def mode_columns(rows: list[dict]) -> list[str]:
    """The azimuthal modes' columns of a branch's rows: lowest_m0 … lowest_mM, unstable_3d
    (none for a branch without modes)."""
    modes = sorted({int(k[len("lowest_m"):]) for r in rows for k in r
                    if k.startswith("lowest_m")})
    return [f"lowest_m{m}" for m in modes] + (["unstable_3d"] if modes else [])


def write_branch_table(out: Path, name: str, rows: list[dict]) -> None:
    """A branch's rows as its branch.csv (:func:`fem_ade.store.tables.write_table`): the
    point's number, the parameter ``name``, :data:`COLUMNS` and the modes' columns."""
    from fem_ade.store.tables import write_table

    cols = ["point", name, *COLUMNS[1:], *mode_columns(rows)]
    write_table(out / "branch.csv", cols, [{**r, "point": k} for k, r in enumerate(rows)])


def read_branch_table(out: Path) -> list[dict]:
    """A branch folder's branch.csv (:func:`write_branch_table`) as rows, numbers as the
    ints and floats they were written from ('' where a cell is empty: no fold, no
    stability)."""
    from fem_ade.store.tables import read_table

    return read_table(out / "branch.csv", empty="")


def mark_folds(rows: list[dict], name: str) -> list[dict]:
    """``fold``: at a point where the parameter turns (its neighbours on the same side), the
    extremum of the quadratic through the three (arclength, parameter) points."""
    for r in rows:
        r["fold"] = ""
    for i in range(1, len(rows) - 1):
        a, b, c = (rows[j][name] for j in (i - 1, i, i + 1))
        if (b - a) * (c - b) < 0:
            s = np.array([rows[j].get("s", j) for j in (i - 1, i, i + 1)], dtype=float)
            q = np.polyfit(s, [a, b, c], 2)
            rows[i]["fold"] = (f"{np.polyval(q, -q[1] / (2 * q[0])):.6g}"
                               if q[0] != 0 else f"{b:.6g}")
    return rows


def bifurcations(rows: list[dict], name: str) -> list[dict]:
    """Where a mode's count of unstable directions changes between two neighbouring points
    (``unstable_modes``, the LU's inertia): a branch point of mode m — m ≥ 1 a
    non-axisymmetric branch is born (in 3D a circle of them, cos mθ and sin mθ), m = 0
    without a fold between the two points an axisymmetric symmetry-breaking one (at a fold
    the m = 0 count changes too: that is the fold, in ``fold``). Located like the folds: the
    zero of the mode's lowest eigenvalue, linear in the arclength, where the count changed
    from 0 or to 0 (else the midpoint, ``located`` False), and the parameter there. The
    count is taken below a threshold (:func:`fem_ade.campaigns.stability.threshold`), so a point
    whose eigenvalue lies between it and 0 moves the change one interval away from the
    zero: the zero is then looked for in the neighbouring interval too (``between``: the
    interval where it is)."""
    out = []
    for i in range(len(rows) - 1):
        a, b = rows[i], rows[i + 1]
        ca, cb = a.get("unstable_modes"), b.get("unstable_modes")
        if not (isinstance(ca, dict) and isinstance(cb, dict)):
            continue
        for key in sorted(set(ca) & set(cb), key=int):
            if ca[key] == cb[key]:
                continue
            m = int(key)
            if m == 0 and (a.get("fold") or b.get("fold")):
                continue
            j, t = i, None
            if min(ca[key], cb[key]) == 0:
                j, t = _zero_near(rows, i, f"lowest_m{m}", rising=ca[key] > cb[key])
            located = t is not None
            t = 0.5 if t is None else t
            ra, rb = rows[j], rows[j + 1]
            sa, sb = float(ra.get("s", j)), float(rb.get("s", j + 1))
            out.append({"m": m, name: float(ra[name] + t * (rb[name] - ra[name])),
                        "s": sa + t * (sb - sa), "between": [j, j + 1],
                        "unstable": [ca[key], cb[key]], "located": bool(located),
                        "kind": f"non-axisymmetric (m = {m})" if m else
                        "axisymmetric symmetry breaking (m = 0, no fold)"})
    return out


def _zero_near(rows: list[dict], i: int, column: str, rising: bool) -> tuple[int, float | None]:
    """(j, t): the zero of ``column`` at the fraction t of rows j … j+1, looked for between
    rows i, i+1 and then in the intervals beside them, crossing upwards (``rising``: the
    count fell) or downwards; (i, None) where none of them holds it."""
    for j in (i, i - 1, i + 1):
        if not 0 <= j < len(rows) - 1:
            continue
        la, lb = rows[j].get(column), rows[j + 1].get(column)
        if la is None or lb is None or la == "" or lb == "":
            continue
        la, lb = float(la), float(lb)
        if (la < 0.0 <= lb) if rising else (lb < 0.0 <= la):
            return j, la / (la - lb)
    return i, None


def draw(out: Path, name: str, rows: list[dict], meridians: list) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fem_ade.plots.render import save_figure

    paths = []
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    x = np.array([r[name] for r in rows])
    e = np.array([r["e"] for r in rows])
    count = "unstable_3d" if any(r.get("unstable_3d") not in (None, "") for r in rows) \
        else "unstable"  # stable in 3D where the azimuthal modes were computed
    stable = np.array([r.get(count) in (0, None, "") for r in rows])  # None: not computed
    for i in range(len(rows) - 1):
        both = stable[i] and stable[i + 1]
        ax.plot(x[i:i + 2], e[i:i + 2], "-" if both else "--", color="tab:blue" if both
                else "tab:red", lw=1.8)
    known = any(r["unstable"] not in (None, "") for r in rows)
    ax.plot(x[stable], e[stable], "o", ms=3, color="tab:blue",
            label=("stable in 3D" if count == "unstable_3d" else "stable (axisymmetric "
                   "perturbations)") if known else "stability not computed")
    ax.plot(x[~stable], e[~stable], "o", ms=3, color="tab:red", label="unstable")
    for r in rows:
        if r.get("fold"):
            ax.plot([float(r["fold"])], [r["e"]], "k*", ms=11)
    for b in bifurcations(rows, name):
        i, j = b["between"]
        t = (b[name] - x[i]) / (x[j] - x[i]) if x[j] != x[i] else 0.5
        eb = e[i] + t * (e[j] - e[i])
        ax.plot([b[name]], [eb], "D", ms=7, mfc="none", mec="tab:green")
        ax.annotate(f"m={b['m']}", (b[name], eb), textcoords="offset points",
                    xytext=(4, 6), fontsize=8, color="tab:green")
    ax.set(xlabel=name, ylabel="e = (W + G) / W_sphere",
           title=f"branch ({rows[0].get('label')} at {name} = {rows[0][name]:.4g}); ★ fold, "
                 "◇ bifurcation (its mode m)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, out / "branch.png", dpi=110, colours=64)
    plt.close(fig)
    paths.append(out / "branch.png")
    if meridians:
        step = max(1, len(meridians) // 10)
        chosen = meridians[::step][:10]
        fig, axes = plt.subplots(1, len(chosen), figsize=(1.6 * len(chosen), 3.0))
        for axis, (value, curves) in zip(np.atleast_1d(axes), chosen, strict=False):
            for pts in curves:
                axis.plot(pts[:, 0], pts[:, 1], "k", lw=1)
                axis.plot(-pts[:, 0], pts[:, 1], "k", lw=1)
            axis.set_aspect("equal")
            axis.set_axis_off()
            axis.set_title(f"{name} = {value:.3g}", fontsize=8)
        fig.tight_layout()
        save_figure(fig, out / "shapes.png", dpi=100, colours=32)
        plt.close(fig)
        paths.append(out / "shapes.png")
    return paths


def crossing(a: list[dict], b: list[dict], name: str) -> float | None:
    """Where two branches' energies cross: the parameter at which e_a = e_b, or None if they
    do not cross where both were followed. Each branch is taken up to its first fold (one e
    per parameter value) and its e interpolated linearly between its points (with points
    Δp ≈ 0.002 apart and e'' ~ 5: ~2e-6 in e); the crossing nearest the branches' start."""
    def up_to_fold(rows):
        out = rows[:2]
        for r in rows[2:]:
            if (r[name] - out[-1][name]) * (out[1][name] - out[0][name]) <= 0:
                break
            out.append(r)
        out = sorted(out, key=lambda r: r[name])
        return np.array([r[name] for r in out]), np.array([r["e"] for r in out])

    if len(a) < 2 or len(b) < 2:
        return None
    (pa, ea), (pb, eb) = up_to_fold(a), up_to_fold(b)
    grid = np.unique(np.concatenate([pa, pb]))
    grid = grid[(grid >= max(pa[0], pb[0])) & (grid <= min(pa[-1], pb[-1]))]
    if a[0][name] > a[1][name]:
        grid = grid[::-1]  # from the start
    d = np.interp(grid, pa, ea) - np.interp(grid, pb, eb)
    for i in range(len(grid) - 1):
        if d[i] == 0.0 or d[i] * d[i + 1] < 0:
            return float(grid[i] - d[i] * (grid[i + 1] - grid[i]) / (d[i + 1] - d[i]))
    return None


# ---------------------------------------------------------------------------------------------
# the driver
# ---------------------------------------------------------------------------------------------
@limit_threads
def follow(scene, *, param: str, start: float, stop: float, step: float, out: Path,
           backend_options: dict | None = None, n: int | None = None, quiet: bool = False,
           max_points: int = 400, folds: int | None = None,
           stable: bool = True, branch: str | None = None, modes: int = 0) -> list[dict]:
    """Follow the branch of ``scene``'s seed in ``param`` from ``start`` to ``stop`` (module
    docstring); the rows of branch.csv. ``folds``: end the branch at the point after its
    ``folds + 1``-th fold (0: the stable part from a stable start; None: go on past folds).
    ``stable=False``: no stability at the points (their ``unstable`` blank): at small ε the
    stability is most of a point's time. ``branch``: the sharp branch the seed stands for
    (the vesicle family's ``branch``); its first point must be one (ModelError otherwise: a
    torus seed that relaxes into an oblate is not followed as a torus). ``modes``: the
    azimuthal modes m = 1 … modes too (docs/model.md §13): each point's lowest eigenvalue
    per mode, its 3D unstable count, and the bifurcations where a mode's lowest eigenvalue
    crosses zero (bifurcations.json, branch.png)."""
    from fem_ade.backends.base import make_backend
    from fem_ade.store.lock import FolderLock

    say = (lambda text: None) if quiet else (lambda text: print(text, flush=True))
    check_follow(scene, param=param, start=start, stop=stop, step=step,
                 backend_options=backend_options, n=n, folds=folds, branch=branch,
                 modes=modes)
    options = {"geometry": "axisymmetric", **(backend_options or {})}
    out = _check_out(out)
    scene, config, identity = _branch_setup(scene, param, start, stop, step, n, options)
    if not stable:  # (absent when on: the folders of before stay theirs)
        identity["stability"] = False
    if stable and modes:  # (absent for modes = 0: the folders of before stay theirs)
        identity["modes"] = modes
    check = _checker(stable, modes)
    try:
        out.mkdir(parents=True, exist_ok=True)
        lock = FolderLock(out).acquire()
    except OSError as err:
        raise ModelError(f"--out {out}: cannot make or lock it ({err.strerror or err})") from None
    try:
        identity = _open_folder(out, identity)
        tag = identity_digest(identity)
        be = make_backend("fem", scene, n=config.n, dt=config.dt, scheme="stabilized",
                          constraints="exact", **options)
        cont = Continuation(be, param)
        done = load_points(out, tag, be.phi.size, param)
        if not done:
            done = [_first_point(be, param, cont, out, config.dt, say, check, tag, branch)]
        rows = [r for r, _ in done]
        for r, _ in done:
            cont.theta = r.get("theta", cont.theta)
        meridians = []
        for r, phi in done[-10:]:
            be._set(phi, None)
            meridians.append((r[param], _curves(be)))
        direction = 1.0 if stop > start else -1.0
        ds = rows[-1].get("ds_next", step)  # a resumed branch takes the step it would have
        while (why := _end_of_branch(rows, param, stop, direction, max_points, folds)) is None:
            point = _next_point(be, cont, param, done, direction, ds, step, check)
            if isinstance(point, str):
                why = point
                break
            row, phi = point
            row = save_point(out, len(rows), be, row, tag)
            rows.append(row)
            done.append((row, phi.copy()))
            meridians.append((row[param], _curves(be)))
            say(_line(param, row))
            write_branch_table(out, param, mark_folds(rows, param))
            ds = row["ds_next"]
        if why:
            say(why)
        why = why or f"max_points = {max_points} reached"
        rows = _finish(out, param, rows, meridians, with_modes=bool(modes and stable))
        _write_ended(out, param, rows, why)
    finally:
        lock.release()
    return rows


def _write_ended(out: Path, param: str, rows: list[dict], why: str) -> None:
    """``ended.json``: why the branch ended where it did (what the command printed last), its
    points and its last parameter, rewritten by each run that ends (a resume that goes on
    past an end says the new one)."""
    from fem_ade.store.output import write_json_atomic

    write_json_atomic(out / "ended.json", {"why": why, "points": len(rows),
                                           "param": param, "last": rows[-1][param]})


def _finish(out: Path, param: str, rows: list[dict], meridians: list,
            with_modes: bool) -> list[dict]:
    """The branch's table with its folds, its bifurcations (with the azimuthal modes) and
    its pictures; its rows."""
    from fem_ade.store.output import write_json_atomic

    rows = mark_folds(rows, param)
    write_branch_table(out, param, rows)
    if with_modes:
        write_json_atomic(out / "bifurcations.json",
                          {"param": param, "bifurcations": bifurcations(rows, param)})
    draw(out, param, rows, meridians)
    return rows


def _checker(stable: bool, modes: int):
    """A point's stability: the m = 0 block's :data:`EIGENVALUES` lowest, and with ``modes``
    the lowest of each block m = 1 … modes (:func:`fem_ade.campaigns.stability.axisymmetric`)."""
    if not stable:
        return lambda be: None
    from fem_ade.campaigns.stability import axisymmetric

    def check(be):
        out = axisymmetric(be, (0,), EIGENVALUES)
        if modes:
            more = axisymmetric(be, range(1, modes + 1), 1)
            out.modes.update(more.modes)
            out.unstable.update(more.unstable)
            out.unstable_3d += more.unstable_3d
        return out
    return check


def check_follow(scene, *, param: str, start: float, stop: float, step: float,
                 backend_options: dict | None = None, n: int | None = None,
                 folds: int | None = None, branch: str | None = None,
                 modes: int = 0) -> None:
    """What :func:`follow` checks before it makes anything, for a sweep to check its branch
    points before they run (ModelError, one line): the parameter and the ends, the branch's
    name, the geometry, and the run's configuration (n, order, the backend's options, the
    scene a surface of revolution)."""
    if backend_options is not None and not isinstance(backend_options, dict):
        raise ModelError(f"backend_options must be a table, got {backend_options!r}")
    options = {"geometry": "axisymmetric", **(backend_options or {})}
    if options["geometry"] != "axisymmetric":
        raise ModelError(f"a branch is followed in the axisymmetric geometry (its Newton "
                         f"solves and stability are the (r, z) ones), not "
                         f"geometry = {options['geometry']!r}")
    check_branch(scene.params, param, start, stop, step, folds)
    if branch is not None:
        check_branch_name(branch)
    if isinstance(modes, bool) or not isinstance(modes, int) or not 0 <= modes <= MAX_MODES:
        raise ModelError(f"--modes must be a whole number from 0 to {MAX_MODES}, got {modes!r}")
    _branch_setup(scene, param, start, stop, step, n, options)


def _check_out(out) -> Path:
    """``--out`` as a path a branch folder can be made in (ModelError, one line)."""
    from fem_ade.store.output import check_creatable, check_path_name

    if not isinstance(out, (str, Path)) or str(out).strip() in ("", "."):
        raise ModelError("--out needs a folder name (a new folder, or the branch's own)")
    out = Path(out)
    check_path_name(out)
    if out.exists() and not out.is_dir():
        raise ModelError(f"--out {out} exists and is not a folder")
    if out.exists():
        if not os.access(out, os.W_OK | os.X_OK):
            raise ModelError(f"--out {out} is not writable")
    else:
        check_creatable(out)
    return out


def _open_folder(out: Path, identity: dict) -> dict:
    """The branch folder ``out`` (locked) made this branch's: a new or empty one gets its
    branch.json, one with this branch's is gone on with; ModelError (one line) for a folder
    of another branch, one whose branch.json is not a branch's, or one that holds files but
    no branch.json (a run folder; a branch whose record was removed, whose points could be
    of any model). Returns the identity as branch.json holds it."""
    from fem_ade.campaigns.identity import same_identity
    from fem_ade.store.output import contents, write_json_atomic

    recorded = out / "branch.json"
    if recorded.exists() or recorded.is_symlink():
        try:
            stored = json.loads(recorded.read_text())
        except (OSError, ValueError) as err:
            raise ModelError(f"{recorded} is not a branch's record ({type(err).__name__}): "
                             "give another --out") from None
        if not same_identity(stored, identity):
            from fem_ade.engine.folder import identity_difference

            why = identity_difference(stored, identity) if isinstance(stored, dict) else None
            why = "" if why is None else " (" + why.replace("in the checkpoint", "there").replace(
                "in run.json", "now") + ")"
            raise ModelError(f"{out} holds another branch{why}: give another --out")
        return stored
    if contents(out):
        raise ModelError(f"{out} holds files but no branch.json: it is no branch folder (a "
                         "run's, or a branch whose record was removed, so its points could "
                         "be of any model); give a new or empty --out")
    write_json_atomic(recorded, identity)
    return identity


def _branch_setup(scene, param: str, start: float, stop: float, step: float, n, options):
    """The scene at the branch's start, its run configuration (the ``steady`` recipe's Δt,
    exact constraints, the axisymmetric FEM) and the branch's identity: what its points are
    (not where they stop: a branch run again with another --to on the same side goes on
    from its points, or stops where it had)."""
    from fem_ade.engine.config import RUN_FORMAT, RunConfig
    from fem_ade.engine.runs import recipe

    scene = replace(scene, params=set_parameter(scene.params, param, start))
    steady = recipe("steady", scene)
    config = RunConfig.build(scene, backend="fem", n=n, dt=steady["dt"],
                             until_steady=1e-9, max_steps=20000, scheme="stabilized",
                             constraints="exact", accelerate=True, backend_options=options)
    config.check(scene)
    identity = {"scene": scene.name, "params": scene.params.as_dict(), "param": param,
                "from": start, "direction": "up" if stop > start else "down", "step": step,
                "n": config.n, "options": options, "format": RUN_FORMAT}
    return scene, config, json.loads(json.dumps(identity, default=str))


def _first_point(be, param: str, cont, out: Path, dt: float, say, check, tag: str,
                 branch: str | None = None) -> tuple[dict, np.ndarray]:
    """The branch's first point: the seed relaxed to its steady state, then Newton's; saved
    as point 0 (ModelError where Newton does not converge, or where it is not of
    ``branch``); ``check``: its stability."""
    from fem_ade.backends.fem.newton import solve_steady
    from fem_ade.engine.loop import run_loop

    t0 = time.perf_counter()
    run_loop(be, dt=dt, until_steady=1e-9, max_steps=20000, every=10, accelerate=True)
    newton = solve_steady(be, max_iterations=60)
    if not newton.converged:
        raise ModelError(f"the branch's first point did not converge: {newton.message}")
    row = _timed_row(be, param, cont, newton.iterations, t0, check)
    if branch is not None and not same_branch(branch, row["label"]):
        label = row["label"]
        article = "an" if str(label)[:1] in "aeiou" else "a"
        raise ModelError(f"the {branch} seed at {param} = {cont.p:.6g} relaxed into {article} "
                         f"{label}: the phase field has no steady {branch} there to "
                         f"follow (try another --from, or --branch "
                         f"{branch_of_label(row['label']) or row['label']})")
    row["s"] = 0.0
    row = save_point(out, 0, be, row, tag)
    say(_line(param, row))
    return row, be.phi.copy()


def _timed_row(be, param: str, cont, newton: int, t0: float, check) -> dict:
    """The point's row once Newton (started at ``t0``) has converged: its stability
    (``check``), its description, and its time — ``seconds`` all of it, ``newton_s`` and
    ``stability_s`` its parts (the latter None without stability)."""
    t1 = time.perf_counter()
    stab = check(be)
    t2 = time.perf_counter()
    row = describe_point(be, param, cont, newton, 0.0, stab)
    row["seconds"] = round(time.perf_counter() - t0, 2)
    row["newton_s"] = round(t1 - t0, 2)
    row["stability_s"] = None if stab is None else round(t2 - t1, 2)
    return row


def _end_of_branch(rows: list[dict], param: str, stop: float, direction: float,
                   max_points: int, folds: int | None) -> str | None:
    """Why the branch ends at its last point ('' without a word: ``max_points``), or None
    where it goes on."""
    last = rows[-1]
    p_k = last[param]
    if not same_topology(rows[0]["label"], last["label"]):  # a resumed one's too
        return (f"the branch ends at {param} = {p_k:.6g}: its shape became a "
                f"{last['label']} (a topology change)")
    if (p_k - stop) * direction >= 0:
        return f"reached {param} = {stop}"
    if len(rows) >= max_points:
        return ""
    turned = [r["fold"] for r in mark_folds(rows, param) if r["fold"]]
    if folds is not None and len(turned) > folds:
        return f"the branch ends after its fold at {param} = {turned[-1]} (--folds {folds})"
    return None


def _next_point(be, cont, param: str, done: list, direction: float, ds: float,
                step: float, check) -> tuple[dict, np.ndarray] | str:
    """The point one arclength step ``ds`` on from the last of ``done`` (along the tangent
    for the first step, then by secant prediction and Newton's correction, the step cut down
    to step/8 where Newton does not converge): its row and φ, or why the branch ends."""
    last_row, phi_k = done[-1]
    p_k = last_row[param]
    be._set(phi_k, None)
    cont.set_p(p_k)
    history = [(ph, r[param]) for r, ph in done[-3:]]
    first = None
    if len(done) < 2:  # the first step: along the tangent from the Newton system
        first = cont.tangent(phi_k)
        if first[1] * direction < 0:
            first = (-first[0], -first[1])
    ds_min, ds_max = step / 8.0, 4.0 * step
    t0 = time.perf_counter()
    corrected, ds = cont.advance(history, first, ds, ds_min)
    if corrected is None:
        return (f"the branch ends at {param} = {p_k:.6g}: Newton does not converge at an "
                f"arclength step of {ds_min:.3g}")
    phi, p, its = corrected
    be._set(phi, None)
    cont.set_p(p)
    row = _timed_row(be, param, cont, its, t0, check)
    row["s"] = last_row.get("s", 0.0) + ds
    row["ds_next"] = min(ds * 1.5, ds_max) if its <= GROW_BELOW else ds
    return row, phi


def _curves(be):
    from fem_ade.analysis.axishape import meridians

    try:
        return [c.copy() for c in meridians(be).curves]
    except Exception:  # noqa: BLE001 (a picture's curves, never the branch's numbers)
        return []


def vesicle_for_branch(chosen: dict, param: str, start: float, stop: float):
    """The ``vesicle`` scene whose seed is the branch's first point (``param`` at ``start``)
    and, without a given R₀, the R₀ with which the family's seed fits the box at both ends
    of the branch: the smaller of the two defaults (a prolate followed from v = 0.95 at that
    v's R₀ = 0.239 reached the box's ends near v = 0.72 and stopped there, ε = 0.01)."""
    from fem_ade.scenes.catalogue import vesicle_scene

    if "R0" not in chosen:
        sizes = []
        for value in (start, stop):
            try:
                s = vesicle_scene(**{**chosen, param: value})
            except ModelError:  # no seed at that end (outside the family): the start decides
                continue
            sizes.append(math.sqrt(s.params.beta / (4.0 * math.pi)))
        if sizes:
            chosen = {**chosen, "R0": round(min(sizes), 6)}
    return vesicle_scene(**{**chosen, param: start})


def branch_of_label(label):
    """The sharp branch a point's shape label stands for
    (:data:`fem_ade.analysis.sharp.BRANCH_OF_LABEL`,
    where a prolate whose waists multiply, gourd → chain, is still the prolate: one body of
    genus 0, two necks, seen at eps/R0 = 0.06-0.12 from v = 0.67 down), or None."""
    from fem_ade.analysis.sharp import BRANCH_OF_LABEL

    return {**BRANCH_OF_LABEL, "chain": "prolate"}.get(label)


def same_topology(first, label) -> bool:
    """Whether a point's shape has its branch's topology: one body of genus 0 (whatever its
    label: a prolate that grows a second waist, a pear whose label flips to gourd, an oblate
    whose dimples deepen into a stomatocyte are each still one branch), a torus, or the same
    label otherwise (two vesicles, nested)."""
    def kind(text):
        if text == "torus":
            return "torus"
        genus0 = branch_of_label(text) in ("prolate", "oblate", "stomatocyte", "pear")
        return "one body of genus 0" if genus0 or text == "sphere" else text

    return kind(first) == kind(label)


def same_branch(first, label) -> bool:
    """Whether a point's label is its branch's: the same sharp branch
    (:func:`branch_of_label`; a label of no branch only equals itself)."""
    return (branch_of_label(first) or first) == (branch_of_label(label) or label)


def _line(param, row) -> str:
    stable = ("stability not computed" if row["unstable"] is None else
              f"unstable {row['unstable']} (lowest eigenvalue {row['lowest_eigenvalue']:.3g})")
    if row.get("unstable_3d") is not None:
        stable += f", in 3D {row['unstable_3d']}"
    return (f"  {param} = {row[param]:.6g}: e = {row['e']:.8g}, {row['label']}, {stable}, "
            f"Newton {row['newton']}, {row['seconds']} s")


def _parser() -> argparse.ArgumentParser:
    """The command line's parser (its errors one line, exit 2)."""
    from fem_ade.registry import VESICLE_BRANCHES

    ap = argparse.ArgumentParser(prog="python -m fem_ade.branch",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", help="vesicle (the family), a scene name or a .toml file")
    ap.add_argument("--param", required=True, choices=PARAMETERS)
    ap.add_argument("--from", dest="start", type=float, required=True)
    ap.add_argument("--to", dest="stop", type=float, required=True)
    ap.add_argument("--step", type=float, default=0.01,
                    help="the arclength step, in units of the parameter (default 0.01)")
    ap.add_argument("--out", required=True, help="the branch folder")
    ap.add_argument("--geometry", default="axisymmetric", choices=("axisymmetric",),
                    help="axisymmetric (the default and, for now, the only one)")
    ap.add_argument("--n", type=int, help="nodes per L at the finest spacing, as for "
                    "python -m fem_ade.run (default: 2.5 per eps)")
    ap.add_argument("--order", type=int, help="element order (default 8)")
    ap.add_argument("--folds", type=int, help="end the branch past this many folds (0: at "
                    "the first; default: go on past folds)")
    ap.add_argument("--modes", type=int, default=DEFAULT_MODES,
                    help="azimuthal modes m = 0 ... M at each point: the lowest eigenvalue "
                    f"of each, the 3D unstable count, the bifurcations (default "
                    f"{DEFAULT_MODES}; 0: axisymmetric perturbations only)")
    ap.add_argument("--no-stability", dest="stable", action="store_false",
                    help="no stability at the points (their unstable count blank): at small "
                    "eps most of a point's time")
    ap.add_argument("--quiet", action="store_true")
    ves = ap.add_argument_group("the vesicle family")
    for name in ("v", "da0", "kbar", "C", "eps", "R0"):
        ves.add_argument(f"--{name}", type=float)
    ves.add_argument("--branch", choices=VESICLE_BRANCHES)

    def error(message):
        ap.exit(2, f"fem_ade.branch: error: {message}\n")

    ap.error = error
    return ap


def main(argv=None) -> int:
    ap = _parser()
    args = ap.parse_args(argv)
    from fem_ade.store.interrupt import install

    install()  # SIGTERM as SIGINT: the points saved so far stay, the command goes on later
    try:
        from fem_ade.scenes.catalogue import resolve_scene

        chosen = {k: getattr(args, k) for k in ("v", "da0", "kbar", "C", "eps", "R0",
                                                 "branch") if getattr(args, k) is not None}
        if args.param in chosen:
            raise ModelError(f"--{args.param} is the branch's parameter: it goes from --from "
                             f"to --to (leave --{args.param} out)")
        branch = None
        if args.scene == "vesicle":
            branch = chosen.get("branch", "prolate")
            check_branch_name(branch)
            scene = vesicle_for_branch(chosen, args.param, args.start, args.stop)
        elif chosen:
            raise ModelError("--v, --da0, ... describe the vesicle scene; give them with "
                             "the scene vesicle")
        else:
            scene = resolve_scene(args.scene)
        options = {} if args.order is None else {"order": args.order}
        follow(scene, param=args.param, start=args.start, stop=args.stop, step=args.step,
               out=args.out, backend_options=options, n=args.n, quiet=args.quiet,
               folds=args.folds, stable=args.stable, branch=branch, modes=args.modes)
    except ModelError as err:
        print(f"fem_ade.branch: error: {err}", file=sys.stderr)
        return 2
    except np.linalg.LinAlgError as err:
        print(f"fem_ade.branch: error: a linear solve failed ({err}): the branch cannot go on "
              "from here (a smaller --step, or another --from)", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fem_ade.branch: interrupted; the same command goes on from the last point",
              file=sys.stderr)
        return 130
    print(f"wrote {Path(args.out) / 'branch.csv'} and branch.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
