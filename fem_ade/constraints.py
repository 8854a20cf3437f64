"""Exact volume and area constraints (issue 6): Lagrange multipliers solved for each step.

With ``constraints="exact"`` the penalties M₁(V − α)² and M₂(A − β)² are off and each step
carries the multipliers of the constraints V(φ) = α, A(φ) = β in its implicit operator P
(the paper's 1/Δt + 𝓛, or the stabilized one):

    P (φⁿ⁺¹ − φⁿ) = −δE/δφ(φⁿ) − λ_V g_V − λ_A g_A,   g_V = δV/δφ = ½,  g_A = δA/δφ = −(3√2/4)f,

so φⁿ⁺¹ = φⁿ + δ₀ − λ_V P⁻¹g_V − λ_A P⁻¹g_A, with δ₀ the unconstrained step and (λ_V, λ_A)
from a 2×2 Newton iteration on V(φⁿ⁺¹) = α, A(φⁿ⁺¹) = β (:func:`solve_multipliers`). The
multipliers are the pressure and the tension; backends report them as the history columns
``lambda_V`` and ``lambda_A``. A steady state then satisfies δE/δφ + λ·g = 0, the
constrained equilibrium, at any Δt. (Correcting φ along g itself after the step, an L²
projection, does not: its fixed points satisfy δE/δφ ∈ P·span(g), which depends on Δt;
measured on ``discocyte``, its steady shape moved with Δt.)

The initial condition, which may be far from the constraints, is projected once by
:func:`project` (minimum-norm Newton steps along the current gradients).
"""

from __future__ import annotations

import math

import numpy as np

DEFAULT_TOL = 1e-10


class ConstraintError(ArithmeticError):
    """The projection did not converge (the state is too far from V = α, A = β)."""


def project(phi, measure, inner, alpha: float, beta: float, *, tol: float = DEFAULT_TOL,
            maxit: int = 60):
    """Return ``(phi_new, a, b, iterations)`` with V(phi_new) = α and A(phi_new) = β.

    ``measure(phi) -> (V, A, g_V, g_A)``: the constraint values and L² gradients at ``phi``;
    ``inner(u, v)``: the L² inner product. Each Newton step moves along the current gradients,
    φ ← φ + δa g_V(φ) + δb g_A(φ), with (δa, δb) from the 2×2 Gram system (the minimum-norm
    Newton step), halved while it does not reduce the residual; a, b are the sums of the
    steps. Converged when |V/α − 1| and |A/β − 1| < ``tol``.
    """
    V, A, gV, gA = measure(phi)
    a = b = 0.0
    res = _residual(V, A, alpha, beta)
    for it in range(maxit + 1):
        if res < tol:
            return phi, a, b, it
        J = np.array([[inner(gV, gV), inner(gV, gA)], [inner(gA, gV), inner(gA, gA)]])
        try:
            da, db = np.linalg.solve(J, [alpha - V, beta - A])
        except np.linalg.LinAlgError:
            break
        direction = da * gV + db * gA

        def trial(step, phi=phi, direction=direction):
            u = phi + step * direction
            V1, A1, gV1, gA1 = measure(u)
            return u, V1, A1, gV1, gA1, _residual(V1, A1, alpha, beta)

        found = _backtrack(trial, res)
        if found is None:
            break
        step, (phi, V, A, gV, gA, res) = found
        a, b = a + step * da, b + step * db
    raise ConstraintError(
        f"the exact-constraint projection did not converge: |V/alpha - 1| = "
        f"{abs(V / alpha - 1):.2g}, |A/beta - 1| = {abs(A / beta - 1):.2g} after {it} "
        "Newton steps; the state is far from V = alpha, A = beta (reduce dt or use penalties)")


def solve_multipliers(measure, alpha: float, beta: float, *, tol: float = DEFAULT_TOL,
                      maxit: int = 30) -> tuple[float, float, int]:
    """Find (a, b) with V = α and A = β at φ(a, b) = φ₀ + a z_V + b z_A (fixed directions).

    ``measure(a, b) -> (V, A, J)`` with J the 2×2 Jacobian ∂(V, A)/∂(a, b) = ⟨g_i(φ), z_j⟩.
    Newton steps are halved while they do not reduce the residual. Returns (a, b, its).
    """
    a = b = 0.0
    V, A, J = measure(a, b)
    res = _residual(V, A, alpha, beta)
    for it in range(maxit + 1):
        if res < tol:
            return a, b, it
        try:
            da, db = np.linalg.solve(J, [alpha - V, beta - A])
        except np.linalg.LinAlgError:
            break
        def trial(step, a=a, b=b, da=da, db=db):
            V1, A1, J1 = measure(a + step * da, b + step * db)
            return V1, A1, J1, _residual(V1, A1, alpha, beta)

        found = _backtrack(trial, res)
        if found is None:
            break
        step, (V, A, J, res) = found
        a, b = a + step * da, b + step * db
    raise ConstraintError(
        f"the constraint multipliers did not converge: |V/alpha - 1| = {abs(V / alpha - 1):.2g},"
        f" |A/beta - 1| = {abs(A / beta - 1):.2g} after {it} Newton steps (reduce dt)")


def _backtrack(trial, res: float):
    """Halve a Newton step until it reduces the residual.

    ``trial(step)`` returns a tuple whose last item is the residual there; returns
    ``(step, trial(step))`` for the first step that reduces ``res``, or None below 1e-4.
    """
    step = 1.0
    while step > 1e-4:
        out = trial(step)
        if math.isfinite(out[-1]) and out[-1] < res:
            return step, out
        step *= 0.5
    return None


def _residual(V, A, alpha, beta) -> float:
    return max(abs(V / alpha - 1.0), abs(A / beta - 1.0))
