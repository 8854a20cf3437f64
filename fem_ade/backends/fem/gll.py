"""Gauss–Lobatto–Legendre (GLL) nodes, weights and the 1D matrices of the spectral element.

A Lagrange element of order p on a hexahedron (quadrilateral) of a tensor mesh has its nodes
at the tensor grid of the p + 1 GLL points of each cell edge, and integrates with the GLL rule
on the same points (Patera 1984; Deville, Fischer & Mund, *High-Order Methods for
Incompressible Fluid Flow*, 2002, ch. 2 and 4). Then

* the mass matrix is diagonal: the GLL weights (a p + 1 point rule is exact to degree 2p − 1,
  so the mass (degree 2p) is under-integrated by a term of the order of the interpolation
  error, and the stiffness (degree 2p − 2) is exact on affine cells);
* on a tensor mesh the d-dimensional stiffness is a Kronecker sum of 1D stiffnesses, each
  scaled by the 1D weights of the other axes: K = K₁ ⊗ W ⊗ W + W ⊗ K₁ ⊗ W + W ⊗ W ⊗ K₁
  (:mod:`fem_ade.backends.fem.tensor`), which is what makes sum factorization and the fast
  diagonalization of the step exact.

Everything here is 1D and on the reference interval [−1, 1] unless it says otherwise.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.polynomial import legendre

#: the orders the package tests and documents (any p ≥ 1 works; beyond 16 the GLL points
#: are still accurate to 1e-14, but no study has used them)
MAX_ORDER = 16


@functools.cache
def points_weights(p: int) -> tuple[np.ndarray, np.ndarray]:
    """The p + 1 GLL points −1 = ξ₀ < … < ξ_p = 1 (the ends and the roots of P′_p) and their
    weights 2 / (p(p + 1) P_p(ξ)²), which sum to 2."""
    if not isinstance(p, (int, np.integer)) or p < 1:
        raise ValueError(f"the GLL order must be an integer >= 1, got {p}")
    Pp = legendre.Legendre.basis(p)
    inner = np.sort(Pp.deriv().roots().real) if p > 1 else np.zeros(0)
    # polish the interior roots by Newton on P′_p (numpy's companion roots lose ~1e-13 at p > 10)
    d1, d2 = Pp.deriv(), Pp.deriv(2)
    for _ in range(3):
        inner = inner - d1(inner) / d2(inner)
    xi = np.concatenate([[-1.0], inner, [1.0]])
    w = 2.0 / (p * (p + 1) * Pp(xi) ** 2)
    xi.setflags(write=False)
    w.setflags(write=False)
    return xi, w


def barycentric_weights(x: np.ndarray) -> np.ndarray:
    """λ_j = 1 / Π_{k≠j} (x_j − x_k), scaled to max |λ| = 1 (Berrut & Trefethen 2004)."""
    diff = x[:, None] - x[None, :]
    np.fill_diagonal(diff, 1.0)
    lam = 1.0 / np.prod(diff, axis=1)
    return lam / np.abs(lam).max()


def derivative_matrix_at(x: np.ndarray) -> np.ndarray:
    """D with D_ij = ℓ′_j(x_i) for the Lagrange basis of the nodes ``x`` (rows sum to zero:
    D·1 = 0 exactly)."""
    x = np.asarray(x, dtype=float)
    lam = barycentric_weights(x)
    diff = x[:, None] - x[None, :]
    np.fill_diagonal(diff, 1.0)
    D = (lam[None, :] / lam[:, None]) / diff
    np.fill_diagonal(D, 0.0)
    np.fill_diagonal(D, -D.sum(axis=1))
    return D


@functools.cache
def derivative_matrix(p: int) -> np.ndarray:
    """D with D_ij = ℓ′_j(ξ_i): the derivative at the GLL points of the interpolant of nodal
    values (rows sum to zero to round-off, which is enforced: D·1 = 0 exactly)."""
    xi, _ = points_weights(p)
    D = derivative_matrix_at(xi)
    D.setflags(write=False)
    return D


@functools.cache
def jacobi_points_weights(p: int) -> tuple[np.ndarray, np.ndarray]:
    """The p + 1 Gauss–Lobatto–Jacobi (0, 1) points −1 = ξ₀ < … < ξ_p = 1 and weights ρ of the
    rule ∫₋₁¹ f(ξ)(1 + ξ) dξ ≈ Σ ρ_j f(ξ_j), exact for polynomials f of degree ≤ 2p − 1.

    The axisymmetric cells that touch the axis r = 0 use it (Deville, Fischer & Mund §6.7;
    Nek5000's ``zwglj``): r = h(1 + ξ)/2 there, so ∫ f r dr = (h/2)² ∫ f (1 + ξ) dξ, and the
    weight of the node on the axis is positive, where the GLL rule applied to f·r gives it 0
    (a singular mass). The interior points are the roots of the Jacobi polynomial
    P⁽¹'²⁾_{p−1} (Gauss–Jacobi nodes of the weight (1 − ξ)(1 + ξ)²); the weights are those of
    the interpolatory rule on the points, integrated exactly by a Gauss–Legendre rule.
    """
    if not isinstance(p, (int, np.integer)) or p < 1:
        raise ValueError(f"the GLJ order must be an integer >= 1, got {p}")
    from scipy.special import roots_jacobi

    inner = np.sort(roots_jacobi(p - 1, 1.0, 2.0)[0]) if p > 1 else np.zeros(0)
    xi = np.concatenate([[-1.0], inner, [1.0]])
    g, gw = legendre.leggauss(p + 2)  # exact for the degree p + 1 of ℓ_j(ξ)(1 + ξ)
    rho = (interpolation_matrix_at(xi, g) * ((1.0 + g) * gw)[:, None]).sum(axis=0)
    xi.setflags(write=False)
    rho.setflags(write=False)
    return xi, rho


@functools.cache
def stiffness(p: int) -> np.ndarray:
    """The reference stiffness Dᵀ diag(w) D on [−1, 1] (exact: its integrand has degree 2p − 2);
    on a cell of length h it is (2/h) times this."""
    _, w = points_weights(p)
    D = derivative_matrix(p)
    K = D.T @ (w[:, None] * D)
    K = 0.5 * (K + K.T)
    K.setflags(write=False)
    return K


def interpolation_matrix_at(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(len(y), len(x)): the Lagrange basis of the nodes ``x`` evaluated at ``y``
    (barycentric formula of the second kind; exact at the nodes)."""
    lam = barycentric_weights(np.asarray(x, dtype=float))
    y = np.asarray(y, dtype=float).ravel()
    diff = y[:, None] - np.asarray(x)[None, :]
    exact = np.isclose(diff, 0.0, atol=1e-15, rtol=0.0)
    diff[exact] = 1.0
    terms = lam[None, :] / diff
    B = terms / terms.sum(axis=1, keepdims=True)
    rows = np.flatnonzero(exact.any(axis=1))
    B[rows] = exact[rows].astype(float)
    return B


def interpolation_matrix(p: int, y: np.ndarray) -> np.ndarray:
    """(len(y), p + 1): the Lagrange basis of the GLL points evaluated at y ∈ [−1, 1]."""
    return interpolation_matrix_at(points_weights(p)[0], y)
