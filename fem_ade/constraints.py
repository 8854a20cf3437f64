"""Exact volume and area constraints (issue 6): a two-scalar Newton projection after each step.

With ``constraints="exact"`` the penalties M₁(V − α)² and M₂(A − β)² are off and, after every
step, φ is corrected along the constraint gradients,

    φ ← φ + a g_V + b g_A,   g_V = δV/δφ = ½,   g_A = δA/δφ = −(3√2/4) f(φ),

with (a, b) from a 2×2 Newton iteration on V(φ) = α, A(φ) = β (see :func:`project`). The
Lagrange multipliers of the continuous constrained flow φ_t = −δE/δφ − λ_V g_V − λ_A g_A are
then λ_V = −a/Δt (a pressure) and λ_A = −b/Δt (a tension); backends report them as the
history columns ``lambda_V`` and ``lambda_A``.

The routine is backend-agnostic: it sees φ only through ``measure`` and ``inner``.
"""

from __future__ import annotations

import math

import numpy as np

from .model import ModelError

CONSTRAINTS = ("penalty", "exact")
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
        step = 1.0
        while step > 1e-4:
            trial = phi + step * (da * gV + db * gA)
            V1, A1, gV1, gA1 = measure(trial)
            res1 = _residual(V1, A1, alpha, beta)
            if math.isfinite(res1) and res1 < res:
                break
            step *= 0.5
        else:
            break
        phi, a, b = trial, a + step * da, b + step * db
        V, A, gV, gA, res = V1, A1, gV1, gA1, res1
    raise ConstraintError(
        f"the exact-constraint projection did not converge: |V/alpha - 1| = "
        f"{abs(V / alpha - 1):.2g}, |A/beta - 1| = {abs(A / beta - 1):.2g} after {it} "
        "Newton steps; the state is far from V = alpha, A = beta (reduce dt or use penalties)")


def _residual(V, A, alpha, beta) -> float:
    return max(abs(V / alpha - 1.0), abs(A / beta - 1.0))


def check(constraints: str) -> str:
    if constraints not in CONSTRAINTS:
        raise ModelError(f"unknown constraints {constraints!r}; valid: {', '.join(CONSTRAINTS)}")
    return constraints
