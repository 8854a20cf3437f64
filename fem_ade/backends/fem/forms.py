"""The weak forms of the mixed scheme (model §2–§5): every functional and its gradient, once.

Implicit side (assembled once per run): ``mass`` (φ, v) and ``laplace`` (∇φ, ∇v).

Functionals (model §2) on nodal fields. Integrals of nonlinear expressions are exact integrals
of their nodal interpolants by the nodes' rule, ∫ I(F) = Σᵢ wᵢ F(φᵢ) with w = M·1 (the
Gauss–Lobatto–Legendre weights of the spectral elements: the trapezoid rule at order 1; the
lumped mass on a mesh file); the gradient integrals are exact,
∫|∇φ|² = φᵀKφ and ∫ (1 − φ²)Δφ = (φ²)ᵀKφ; μ = M_L⁻¹Kφ stands for −Δφ.

Gradients ⟨δQ/δφ, v⟩ as functionals with nodal products: each ``*_gradient`` returns
``(a, c)`` with ⟨·, v⟩ = K a + M_t c (M_t = M_L = diag(w) by default), so that a sum of terms
is one sparse product. A gradient times the slope of its term in E_M (``Params.*_slope``,
``Params.ade_force_coefficient``) is that term's force; the same gradient is the vector b of
the term's rank-one Hessian σbbᵀ in the stabilized scheme and the direction of the exact
constraints. The explicit part of the bending force, κN(φ) of model §4, is
:func:`bending_explicit`.

``*_linear``: each gradient's derivative along a direction (the exact Hessian-vector products
of Newton's method, docs/model.md §12).
"""

from __future__ import annotations

from skfem import BilinearForm
from skfem.helpers import dot, grad

from fem_ade.backends.fem.solve import global_dot
from fem_ade.model.params import AREA_FACTOR


# ---------------------------------------------------------------------------------------------
# implicit operator
# ---------------------------------------------------------------------------------------------
@BilinearForm
def mass(u, v, w):
    """(u, v): the mass matrix M of model §5."""
    return u * v


@BilinearForm
def laplace(u, v, w):
    """(∇u, ∇v): the stiffness matrix K of model §5 (−Δ in weak form)."""
    return dot(grad(u), grad(v))


# ---------------------------------------------------------------------------------------------
# the functionals of model §2
# ---------------------------------------------------------------------------------------------
def volume(phi, weights, localized=False) -> float:
    """V = ∫ (φ + 1)/2 (the paper's), or ∫ s(φ), s = (2 + 3φ − φ³)/4 (``localized``)."""
    if localized:
        return 0.25 * global_dot(weights, 2.0 + 3.0 * phi - phi * phi * phi)
    return 0.5 * global_dot(weights, phi + 1.0)


def area(phi, Kphi, weights, eps) -> float:
    """A = (3√2/4) ∫ (ε/2)|∇φ|² + (1/4ε)(φ² − 1)²."""
    grad2 = global_dot(phi, Kphi)
    bulk = global_dot(weights, (phi * phi - 1.0) ** 2)
    return AREA_FACTOR * (0.5 * eps * grad2 + bulk / (4.0 * eps))


def area_difference(phi, Kphi, weights, D, eps) -> float:
    """ΔA = −(3D/4) ∫ (1 − φ²)Δφ + (1/ε²) φ(1 − φ²)²  (paper 2.6); (1 − φ², Δφ) = (∇φ², ∇φ)."""
    phi2 = phi * phi
    lap_term = global_dot(phi2, Kphi)
    bulk = global_dot(weights, phi * (1.0 - phi2) ** 2) / eps**2
    return -0.75 * D * (lap_term + bulk)


def bending(phi, mu, weights, kappa, eps, C) -> float:
    """W = (κ/2ε) ∫ f_c², f_c = −εμ − (1/ε)(φ² − 1)(φ + Cε)  (paper 2.1)."""
    fc = -eps * mu - (phi * phi - 1.0) * (phi + C * eps) / eps
    return kappa / (2.0 * eps) * global_dot(weights, fc * fc)


# ---------------------------------------------------------------------------------------------
# gradients: (a, c) with ⟨δQ/δφ, v⟩ = K a + M_t c
# ---------------------------------------------------------------------------------------------
def volume_gradient(phi, localized=False):
    """c with ⟨δV/δφ, v⟩ = M_t c: the constant ½, or s′(φ) = (3/4)(1 − φ²) (``localized``)."""
    if localized:
        return 0.75 * (1.0 - phi * phi)
    return 0.5


def area_gradient(phi, eps, coef=AREA_FACTOR):
    """coef·[ε(∇φ, ∇v) + (1/ε)((φ² − 1)φ, v)]: ⟨δA/δφ, v⟩ for coef = 3√2/4, and the area
    penalty's force −(3√2/2)M₂(A − β)⟨f, v⟩ for coef = ``Params.area_force_scale(A)``
    (f = εΔφ − (1/ε)(φ² − 1)φ, model §3).

    Returns (s, c): the K part is s·φ (a multiple of φ, so callers reuse Kφ).
    """
    return coef * eps, coef / eps * (phi * phi - 1.0) * phi


def area_difference_gradient(phi, mu, eps, coef):
    """coef·⟨−2φΔφ − Δ(φ²) + (1/ε²)(1 − 6φ² + 5φ⁴), v⟩
    = coef·[(2φμ, v) + (∇φ², ∇v) + (1/ε²)(1 − 6φ² + 5φ⁴, v)].

    coef = −3D/4 gives ⟨δΔA/δφ, v⟩; coef = γ (``Params.ade_force_coefficient``) the ADE
    force ⟨h(φ), v⟩ of model §3.
    """
    phi2 = phi * phi
    a = coef * phi2
    c = coef * (2.0 * phi * mu + (1.0 / eps**2) * (1.0 - 6.0 * phi2 + 5.0 * phi2 * phi2))
    return a, c


def bending_explicit(phi, mu, *, kappa, eps, C):
    """κ⟨N(φ), v⟩ (model §4), N(φ) = −(1/ε)Δ(φ³) − CΔ(φ²) − (3/ε)φ²Δφ − 2CφΔφ + (1/ε³)P(φ).

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


# ---------------------------------------------------------------------------------------------
# linearizations: the directional derivative of each (a, c) above along v (μ_v = W⁻¹Kv), for
# the exact Hessian-vector products of Newton's method (fem_ade.backends.fem.newton)
# ---------------------------------------------------------------------------------------------
def bending_explicit_linear(phi, mu, v, mu_v, *, kappa, eps, C):
    """d/dt of :func:`bending_explicit` at φ + tv (μ + tμ_v): (a′, c′)."""
    phi2 = phi * phi
    a = (3.0 / eps) * phi2 * v
    c = (3.0 / eps) * (2.0 * phi * v * mu + phi2 * mu_v)
    # P(φ) = (3φ² + 2Cεφ − 1)(φ² − 1)(φ + Cε): P′ by the product rule
    p1, p2, p3 = 3.0 * phi2 + 2.0 * C * eps * phi - 1.0, phi2 - 1.0, phi + C * eps
    dP = (6.0 * phi + 2.0 * C * eps) * p2 * p3 + p1 * 2.0 * phi * p3 + p1 * p2
    c += dP * v / eps**3
    if C != 0.0:
        a += 2.0 * C * phi * v
        c += 2.0 * C * (v * mu + phi * mu_v)
    return kappa * a, kappa * c


def area_difference_gradient_linear(phi, mu, v, mu_v, eps, coef):
    """d/dt of :func:`area_difference_gradient` at fixed ``coef``: (a′, c′)."""
    phi2 = phi * phi
    a = coef * 2.0 * phi * v
    c = coef * (2.0 * (v * mu + phi * mu_v) + (1.0 / eps**2) * (-12.0 * phi
                                                                 + 20.0 * phi2 * phi) * v)
    return a, c


def area_gradient_linear(phi, v, eps, coef=AREA_FACTOR):
    """d/dt of :func:`area_gradient`: (s, c′) with the K part s·v."""
    return coef * eps, coef / eps * (3.0 * phi * phi - 1.0) * v


def volume_gradient_linear(phi, v, localized=False):
    """d/dt of :func:`volume_gradient`: c′ (0 for the paper's V)."""
    return -1.5 * phi * v if localized else 0.0 * v
