"""The global terms of E_M on the FEM space, one record each (model §2–§5, §9, §12).

A global term T(Q(φ)) depends on φ through one functional Q — the volume penalty
T₁ = M₁(V − α)², the area penalty T₂ = M₂(A − β)², the ADE term G = (κ̄π/(2A₀D²))(ΔA − ΔA₀)².
Its record holds all that the mixed scheme (:class:`fem_ade.backends.fem.step.MixedStep`)
needs of it, from the weak forms of :mod:`fem_ade.backends.fem.forms` and the scalar parts of
:class:`fem_ade.model.params.Params`:

* :meth:`GlobalTerm.measure`: Q on nodal fields;
* :meth:`GlobalTerm.force`: T′(Q)⟨δQ/δφ, v⟩ = K a + W c as the nodal products (a, c) (None
  for a part the term has not), the term's share of ⟨Rⁿ, v⟩;
* :meth:`GlobalTerm.force_linear`: that force's derivative along (v, μ_v) at fixed Q (Newton's
  Hessian-vector products; the part through Q is the rank-one term);
* :meth:`GlobalTerm.gradient` and :meth:`GlobalTerm.curvature`: b = ⟨δQ/δφ, v⟩ as a DOF vector
  and σ = T″(Q), the rank-one Hessian σbbᵀ of the stabilized scheme and of Newton's method;
* :meth:`GlobalTerm.energy` and the names (:attr:`GlobalTerm.model`: a
  :class:`fem_ade.model.params.Term`, its effect, its functional's history column, its
  energy's name).

The spectral reference has its own records (``spectral_ref/solver.py``), written apart.
"""

from __future__ import annotations

from fem_ade.backends.fem import forms
from fem_ade.model.params import TERMS, Params, Term

_MODEL = {t.effect: t for t in TERMS}


class GlobalTerm:
    """A global term on the FEM space; subclasses fill in the forms. ``p``: the parameters,
    ``w``: the nodal weights W, ``K``: the stiffness (``K @ x``), ``value``: Q at φ
    (:meth:`measure`)."""

    effect: str

    @property
    def model(self) -> Term:
        """The scalar side: names and energy (:data:`fem_ade.model.params.TERMS`)."""
        return _MODEL[self.effect]

    @property
    def functional(self) -> str:
        """Q's name: its key in :meth:`MixedStep.values` and its history column."""
        return self.model.functional

    def energy(self, p: Params, value: float) -> float:
        """T(Q) (``Params.*_energy``)."""
        return self.model.energy_of(p, value)

    def measure(self, p: Params, w, phi, Kphi) -> float:
        """Q at φ (``Kphi``: Kφ)."""
        raise NotImplementedError

    def force(self, p: Params, phi, mu, value):
        """(a, c), ⟨·, v⟩ = K a + W c: T′(Q)⟨δQ/δφ, v⟩ at φ, Q = ``value``; None for a part
        the term has not."""
        raise NotImplementedError

    def force_linear(self, p: Params, phi, mu, v, mu_v, value):
        """(a′, c′): :meth:`force`'s derivative along (v, μ_v) at fixed ``value``."""
        raise NotImplementedError

    def gradient(self, p: Params, K, w, phi, mu, Kphi):
        """b = ⟨δQ/δφ, v⟩ as a DOF vector (the rank-one term's, the constraints')."""
        raise NotImplementedError

    def curvature(self, p: Params) -> float:
        """σ = T″(Q) (a constant: each term is quadratic in its functional)."""
        raise NotImplementedError


class VolumePenalty(GlobalTerm):
    """T₁ = M₁(V − α)², V = ∫(φ + 1)/2 or the localized ∫ s(φ): its force is c only."""

    effect = "volume"

    def measure(self, p, w, phi, Kphi):
        return forms.volume(phi, w, p.localized_volume)

    def force(self, p, phi, mu, value):
        # slope × ⟨δV/δφ, v⟩ = slope × W(½ or s′(φ))
        return None, p.volume_slope(value) * forms.volume_gradient(phi, p.localized_volume)

    def force_linear(self, p, phi, mu, v, mu_v, value):
        return None, p.volume_slope(value) * forms.volume_gradient_linear(phi, v,
                                                                        p.localized_volume)

    def gradient(self, p, K, w, phi, mu, Kphi):
        """⟨δV/δφ, v⟩: ½W·1, or W s′(φ) for the localized V."""
        return w * forms.volume_gradient(phi, p.localized_volume)

    def curvature(self, p):
        return p.volume_curvature


class AreaPenalty(GlobalTerm):
    """T₂ = M₂(A − β)²: its force's K part is a multiple of φ (of v, linearized)."""

    effect = "area"

    def measure(self, p, w, phi, Kphi):
        return forms.area(phi, Kphi, w, p.eps)

    def force(self, p, phi, mu, value):
        s, c = forms.area_gradient(phi, p.eps, p.area_force_scale(value))
        return s * phi, c

    def force_linear(self, p, phi, mu, v, mu_v, value):
        s, c = forms.area_gradient_linear(phi, v, p.eps, p.area_force_scale(value))
        return s * v, c

    def gradient(self, p, K, w, phi, mu, Kphi):
        """⟨δA/δφ, v⟩ (the exact gradient of the discrete A)."""
        s, c = forms.area_gradient(phi, p.eps)
        return s * Kphi + w * c

    def curvature(self, p):
        return p.area_curvature


class AreaDifference(GlobalTerm):
    """G = (κ̄π/(2A₀D²))(ΔA − ΔA₀)² (paper 2.7), the ADE term."""

    effect = "ade"

    def measure(self, p, w, phi, Kphi):
        return forms.area_difference(phi, Kphi, w, p.D, p.eps)

    def force(self, p, phi, mu, value):
        return forms.area_difference_gradient(phi, mu, p.eps, p.ade_force_coefficient(value))

    def force_linear(self, p, phi, mu, v, mu_v, value):
        return forms.area_difference_gradient_linear(phi, mu, v, mu_v, p.eps,
                                                     p.ade_force_coefficient(value))

    def gradient(self, p, K, w, phi, mu, Kphi):
        """⟨δΔA/δφ, v⟩ (coef −3D/4 of :func:`forms.area_difference_gradient`)."""
        a, c = forms.area_difference_gradient(phi, mu, p.eps, -0.75 * p.D)
        return K @ a + w * c

    def curvature(self, p):
        return p.ade_modulus


VOLUME, AREA, ADE = VolumePenalty(), AreaPenalty(), AreaDifference()
#: every global term, in the model's order (:data:`fem_ade.model.params.TERMS`)
GLOBAL_TERMS = (VOLUME, AREA, ADE)  # (tests/test_architecture.py checks the two agree)


def active_terms(params: Params) -> tuple[GlobalTerm, ...]:
    """The terms whose effect is on, in the model's order."""
    return tuple(t for t in GLOBAL_TERMS if params.on(t.effect))
