"""The weak forms of the mixed scheme (SPEC §5), one short function per term.

Implicit side (assembled once per run): ``mass`` (φ, v) and ``laplace`` (∇φ, ∇v).

Explicit side ⟨Rⁿ, v⟩ of SPEC §4–§5, Rⁿ = κN(φⁿ) + h(φⁿ) + M₁(Vⁿ − α) − (3√2/2)M₂(Aⁿ − β)f(φⁿ),
with every Δ moved onto v or replaced by −μⁿ. Each term exists twice, side by side:

- ``*_nodal(...) -> (a, c)``: nonlinear products interpolated at the nodes, so that the term is
  ``K @ a + M_L @ c`` (M_L = diag(M·1), the nodal quadrature; ``M @ c`` with the backend's
  ``mass="consistent"``): one sparse product for the whole right side. This is the default:
  the observed rates against the spectral reference are 2 (Q1) and 4 (Q2), the same as with
  quadrature, at a fraction of the cost.
- ``@LinearForm`` versions, integrated at quadrature points (scikit-fem), for verification and
  for meshes assembled with scikit-fem (``products="quadrature"``).

The ADE term is :func:`ade_nodal` / :func:`ade_explicit`.
"""

from __future__ import annotations

import math

from skfem import BilinearForm, LinearForm
from skfem.helpers import dot, grad

from ..model import SQRT2


# ---------------------------------------------------------------------------------------------
# implicit operator
# ---------------------------------------------------------------------------------------------
@BilinearForm
def mass(u, v, w):
    """(u, v): the mass matrix M of SPEC §5."""
    return u * v


@BilinearForm
def laplace(u, v, w):
    """(∇u, ∇v): the stiffness matrix K of SPEC §5 (−Δ in weak form)."""
    return dot(grad(u), grad(v))


# ---------------------------------------------------------------------------------------------
# explicit right side, nodal products: each returns (a, c) with ⟨term, v⟩ = K a + M_L c
# ---------------------------------------------------------------------------------------------
def bending_nodal(phi, mu, *, kappa, eps, C):
    """κ⟨N(φ), v⟩ (SPEC §4), N(φ) = −(1/ε)Δ(φ³) − CΔ(φ²) − (3/ε)φ²Δφ − 2CφΔφ + (1/ε³)P(φ).

    Weak form: (1/ε)(∇φ³, ∇v) + C(∇φ², ∇v) + ((3/ε)φ²μ + 2Cφμ + (1/ε³)P(φ), v),
    P(φ) = (3φ² + 2Cεφ − 1)(φ² − 1)(φ + Cε), μ = −Δφ.
    """
    phi2 = phi * phi
    a = (1.0 / eps) * phi2 * phi
    c = (3.0 / eps) * phi2 * mu
    c += (1.0 / eps**3) * (3.0 * phi2 + 2.0 * C * eps * phi - 1.0) * (phi2 - 1.0) * (phi + C * eps)
    if C != 0.0:
        a += C * phi2
        c += 2.0 * C * phi * mu
    return kappa * a, kappa * c


def ade_coefficient(dA, params) -> float:
    """γ = −(3κ̄π / (4A₀D))(ΔA − ΔA₀): h(φ) = γ(−2φΔφ − Δ(φ²) + (1/ε²)(1 − 6φ² + 5φ⁴)), SPEC §3."""
    return -3.0 * params.kappa_bar * math.pi / (4.0 * params.A0 * params.D) * (dA - params.delta_A0)


def ade_nodal(phi, mu, *, gamma, eps):
    """⟨h(φ), v⟩, the ADE term (SPEC §3, δG/δφ):

    γ[(2φμ, v) + (∇φ², ∇v) + (1/ε²)(1 − 6φ² + 5φ⁴, v)].
    """
    phi2 = phi * phi
    a = gamma * phi2
    c = gamma * (2.0 * phi * mu + (1.0 / eps**2) * (1.0 - 6.0 * phi2 + 5.0 * phi2 * phi2))
    return a, c


def area_penalty_nodal(phi, *, coef, eps):
    """−(3√2/2)M₂(A − β)⟨f, v⟩ with f = εΔφ − (1/ε)(φ² − 1)φ (SPEC §3), ``coef`` = (3√2/2)M₂(A − β).

    Weak form: coef·[ε(∇φ, ∇v) + (1/ε)((φ² − 1)φ, v)].
    """
    return coef * eps * phi, coef / eps * (phi * phi - 1.0) * phi


def area_penalty_coefficient(A, params) -> float:
    """(3√2/2) M₂ (A − β): δT₂/δφ = −(this)·f (SPEC §3)."""
    return 1.5 * SQRT2 * params.M2 * (A - params.beta)


def volume_penalty_coefficient(V, params) -> float:
    """M₁(V − α) = δT₁/δφ (SPEC §3); its weak form is this number times (1, v)."""
    return params.M1 * (V - params.alpha)


# ---------------------------------------------------------------------------------------------
# explicit right side, quadrature versions (w.phi, w.mu are interpolated fields)
# ---------------------------------------------------------------------------------------------
@LinearForm
def bending_explicit(v, w):
    """κ⟨N(φ), v⟩ at quadrature points (SPEC §4–§5); ∇(φ³) = 3φ²∇φ, ∇(φ²) = 2φ∇φ."""
    phi, mu, eps, C = w.phi, w.mu, w.eps, w.C
    flux = (3.0 / eps * phi**2 + 2.0 * C * phi) * dot(grad(phi), grad(v))
    P = (3.0 * phi**2 + 2.0 * C * eps * phi - 1.0) * (phi**2 - 1.0) * (phi + C * eps)
    src = (3.0 / eps * phi**2 + 2.0 * C * phi) * mu + P / eps**3
    return w.kappa * (flux + src * v)


@LinearForm
def ade_explicit(v, w):
    """⟨h(φ), v⟩, the ADE term at quadrature points (SPEC §3): γ[(2φμ, v) + (2φ∇φ, ∇v) + ...]."""
    phi = w.phi
    src = 2.0 * phi * w.mu + (1.0 - 6.0 * phi**2 + 5.0 * phi**4) / w.eps**2
    return w.gamma * (2.0 * phi * dot(grad(phi), grad(v)) + src * v)


@LinearForm
def area_penalty_explicit(v, w):
    """−(3√2/2)M₂(A − β)⟨f, v⟩ at quadrature points: coef·[ε(∇φ, ∇v) + (1/ε)((φ² − 1)φ, v)]."""
    phi = w.phi
    return w.coef * (w.eps * dot(grad(phi), grad(v)) + (phi**2 - 1.0) * phi * v / w.eps)


@LinearForm
def unit_load(v, w):
    """(1, v): the volume penalty's weak form is M₁(V − α) times this vector (SPEC §3)."""
    return v
