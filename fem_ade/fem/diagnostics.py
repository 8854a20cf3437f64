"""E, W, G, V, A, ΔA of a FEM state (SPEC §2), with the definitions of the spectral reference.

Integrals of nonlinear expressions are exact integrals of their nodal interpolants,
∫ I(F) = Σᵢ wᵢ F(φᵢ) with w = M·1 (the trapezoid rule for uniform Q1, Simpson/Gauss–Lobatto for
tensor Q2), and the one gradient integral is exact: ∫|∇φ|² = φᵀKφ. With μ = M_L⁻¹Kφ standing
for −Δφ:

    f_c = −εμ − (1/ε)(φ² − 1)(φ + Cε),   W = (κ/2ε) ∫ f_c²
    V = ∫ (φ + 1)/2,   B = (ε/2) φᵀKφ + (1/4ε) ∫ (φ² − 1)²,   A = (3√2/4) B
    ΔA = −(3D/4) [ ∫ (1 − φ²)Δφ + (1/ε²) ∫ φ(1 − φ²)² ],   ∫ (1 − φ²)Δφ = (φ²)ᵀKφ
    G = (κ̄π / (2A₀D²)) (ΔA − ΔA₀)²,   E = W + G + M₁(V − α)² + M₂(A − β)²

Terms whose effect is off are not computed and report 0; V and A are always reported.
"""

from __future__ import annotations

import math

import numpy as np

from ..model import AREA_FACTOR, Params
from .solve import _dot


def volume(phi, weights) -> float:
    """V = ∫ (φ + 1)/2 (SPEC §2)."""
    return 0.5 * _dot(weights, phi + 1.0)


def area(phi, Kphi, weights, eps) -> float:
    """A = (3√2/4) ∫ (ε/2)|∇φ|² + (1/4ε)(φ² − 1)² (SPEC §2)."""
    grad2 = _dot(phi, Kphi)
    bulk = _dot(weights, (phi * phi - 1.0) ** 2)
    return AREA_FACTOR * (0.5 * eps * grad2 + bulk / (4.0 * eps))


def area_difference(phi, Kphi, weights, params: Params) -> float:
    """ΔA = −(3D/4) ∫ (1 − φ²)Δφ + (1/ε²) φ(1 − φ²)² (SPEC (2.6)); (1 − φ², Δφ) = (∇φ², ∇φ)."""
    phi2 = phi * phi
    lap_term = _dot(phi2, Kphi)
    bulk = _dot(weights, phi * (1.0 - phi2) ** 2) / params.eps**2
    return -0.75 * params.D * (lap_term + bulk)


def bending(phi, mu, weights, params: Params) -> float:
    """W = (κ/2ε) ∫ f_c², f_c = −εμ − (1/ε)(φ² − 1)(φ + Cε) (SPEC (2.1))."""
    eps, C = params.eps, params.C_eff
    fc = -eps * mu - (phi * phi - 1.0) * (phi + C * eps) / eps
    return params.kappa / (2.0 * eps) * _dot(weights, fc * fc)


def ade_energy(dA, params: Params) -> float:
    """G = (κ̄π / (2A₀D²)) (ΔA − ΔA₀)² (SPEC (2.7))."""
    coef = params.kappa_bar * math.pi / (2.0 * params.A0 * params.D**2)
    return coef * (dA - params.delta_A0) ** 2


def measure(phi, mu, Kphi, weights, params: Params) -> dict:
    """The history values E, W, G, V, A, dA of SPEC §6 (off terms report 0)."""
    V = volume(phi, weights)
    A = area(phi, Kphi, weights, params.eps)
    W = bending(phi, mu, weights, params)
    dA = area_difference(phi, Kphi, weights, params) if params.on("ade") else 0.0
    G = ade_energy(dA, params) if params.on("ade") else 0.0
    T1 = params.M1 * (V - params.alpha) ** 2 if params.on("volume") else 0.0
    T2 = params.M2 * (A - params.beta) ** 2 if params.on("area") else 0.0
    return {"E": W + G + T1 + T2, "W": W, "G": G, "V": V, "A": A, "dA": dA}


def sanity(values: dict) -> bool:
    """True when every value is finite."""
    return all(np.isfinite(v) for v in values.values())
