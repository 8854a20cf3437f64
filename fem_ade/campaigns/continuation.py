"""The numerics of a branch (:mod:`fem_ade.campaigns.branch`): the extended Newton system
along one parameter, its predictor and corrector, the stability of a point and its row.

Each further point is predicted
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
``--step``/8 and 4·``--step``.

Stability: at each point the few lowest eigenvalues of the Hessian of the Lagrangian on the
constraints' tangent space, H_L v = λ P v with Cᵀv = 0 (ARPACK on the projected operator, P⁻¹
by the step's exact solve: :func:`stability`; P is Newton's bulk Hessian, so the count of
negative λ — the unstable directions — is that of the constrained Hessian by Sylvester's law
of inertia). In the axisymmetric geometry only
axisymmetric directions are seen.

Why a module of its own: this is the solver's side of a branch — the backend's state, one
step along the branch and what a converged point is (:func:`describe_point`, its row) —
with no file and no command line; the branch's folder is
:mod:`fem_ade.campaigns.branch_folder`, what its rows show (folds, bifurcations, crossings,
pictures) :mod:`fem_ade.campaigns.branch_analysis`, and when the branch goes on or ends
the driver's, :func:`fem_ade.campaigns.branch.follow`.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from fem_ade.model.params import HISTORY_COLUMNS
from fem_ade.scenes.vesicle import get_parameter, set_parameter

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
#: a Newton correction is converged when its decrement |∇Lᵀδφ|/|E| (relative energy, as in
#: :func:`fem_ade.backends.fem.newton.solve_steady`) is below NEWTON_TOL and its |δp| below
#: PARAMETER_TOL·max(|p|, 1) — the error left after a step of the quadratic phase is of the
#: order of the step's square: measured on the prolate at v = 0.75, ε = 0.005 (Δa₀ from 0.8),
#: |δp| 1.5e-4, 3.8e-6, 2.1e-9, 2.0e-13 in the last four iterations, so a bound of 1e-9 (as
#: before) took a sixth Newton iteration, a factorization, to move p by 2e-13 — and
#: given up (a shorter step is tried) once its residual exceeds DIVERGED times its first: a
#: diverging correction's bordered solves take the most MINRES iterations (5000 at eps =
#: 0.005, where converging ones take 250-500); the converging ones measured there stay below
#: their first residual
NEWTON_TOL, PARAMETER_TOL, DIVERGED = 1e-12, 1e-7, 2.0
#: the least arclength step, relative to the parameter's size: below it the parameter's
#: derivative (a central difference) and the predictor's chords are round-off
MIN_STEP = 1e-6


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
            if decrement < NEWTON_TOL and abs(dp) < PARAMETER_TOL * max(abs(p), 1.0):
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
# a point's row
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
