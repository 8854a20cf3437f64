"""The model's parameters, the names of its effects, and their validation (model §1, §2, §4).

Everything here is backend-agnostic: both the finite-element backend and the spectral
reference read a :class:`Params` and switch terms on and off by :attr:`Params.effects`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from numbers import Integral, Real

from fem_ade.registry import CONSTRAINTS, VOLUMES

#: The energy terms a scene can switch on (model §2). ``bending`` is always on.
EFFECTS = ("bending", "spontaneous_curvature", "ade", "volume", "area")

SQRT2 = math.sqrt(2.0)
#: A = AREA_FACTOR * B  (model §2)
AREA_FACTOR = 3.0 * SQRT2 / 4.0


#: the version of the discrete physics (the model's functionals, schemes and their
#: discretizations): a sweep reuses a point's run only if it was made with the same
PHYSICS_VERSION = "2026.12-1"


class ModelError(ValueError):
    """Invalid model input: a parameter, a scene or a scene file. The message is one line."""


def is_int(value, low: int) -> bool:
    """An integer (numpy's too, not a bool) of at least ``low``: the one check of a count."""
    return isinstance(value, Integral) and not isinstance(value, bool) and value >= low


def is_real(value) -> bool:
    """A real, finite number (numpy's too, not a bool): the one check of a number."""
    return (isinstance(value, Real) and not isinstance(value, bool)
            and math.isfinite(float(value)))


@dataclass(frozen=True)
class Params:
    """Physical and numerical parameters of one simulation (model §1).

    ``D`` defaults to 2ε/3 and ``A0`` (the area scale of G) to β. A term is evaluated only
    when its effect is in ``effects``; ``C`` is used only with ``spontaneous_curvature``.
    ``volume_functional``: the V that the penalty or constraint holds at α
    (:data:`fem_ade.registry.VOLUMES`): "paper", V = ∫(φ + 1)/2, or "localized",
    V = ∫ s(φ) with s = (2 + 3φ − φ³)/4, whose gradient s′(φ) = (3/4)(1 − φ²) vanishes in
    the bulk phases.
    """

    eps: float
    alpha: float
    beta: float
    delta_A0: float = 0.0
    kappa: float = 1.0
    kappa_bar: float = 1.4
    C: float = 0.0
    D: float | None = None
    M1: float = 1e5
    M2: float = 1e4
    A0: float | None = None
    L: float = 1.0
    effects: frozenset[str] = field(
        default_factory=lambda: frozenset({"bending", "ade", "volume", "area"})
    )
    volume_functional: str = "paper"

    def __post_init__(self):
        object.__setattr__(self, "effects", frozenset(self.effects))
        if self.D is None:
            object.__setattr__(self, "D", 2.0 * self.eps / 3.0)
        if self.A0 is None:
            object.__setattr__(self, "A0", self.beta)

    # -- effects -----------------------------------------------------------------------
    def on(self, effect: str) -> bool:
        """True if ``effect`` (one of :data:`EFFECTS`) is switched on."""
        if effect not in EFFECTS:
            raise KeyError(f"unknown effect {effect!r}; valid: {', '.join(EFFECTS)}")
        return effect in self.effects

    @property
    def localized_volume(self) -> bool:
        """True when V = ∫ s(φ) (bulk-insensitive), False for the paper's ∫(φ + 1)/2."""
        return self.volume_functional == "localized"

    @property
    def C_eff(self) -> float:
        """C as the bending term sees it: 0 unless ``spontaneous_curvature`` is on."""
        return self.C if "spontaneous_curvature" in self.effects else 0.0

    # -- checks ------------------------------------------------------------------------
    def validate(self) -> Params:
        """Raise :class:`ModelError` with one clear line if a parameter is unusable."""
        unknown = set(self.effects) - set(EFFECTS)
        if unknown:
            raise ModelError(
                f"unknown effect(s) {sorted(unknown)}; valid effects: {', '.join(EFFECTS)}"
            )
        if "bending" not in self.effects:
            raise ModelError("the 'bending' effect is always on for a vesicle; add it to effects")
        if self.volume_functional not in VOLUMES:
            raise ModelError(f"unknown volume functional {self.volume_functional!r}; valid: "
                             f"{', '.join(VOLUMES)}")
        for name in ("eps", "kappa", "L"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ModelError(f"{name} must be a positive number, got {value}")
        if self.L > 1e3:
            raise ModelError(f"L = {self.L:g}: the box is measured in units of the vesicle's "
                             "size (the paper's L is 1 or 2); use L <= 1000")
        for name in ("alpha", "beta"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ModelError(
                    f"{name} must be positive (it is the target "
                    f"{'volume' if name == 'alpha' else 'area'}), got {value}"
                )
        if self.on("ade"):
            if not (math.isfinite(self.kappa_bar) and self.kappa_bar >= 0):
                raise ModelError(f"kappa_bar must be >= 0, got {self.kappa_bar}")
            for name in ("D", "A0"):
                value = getattr(self, name)
                if not (math.isfinite(value) and value > 0):
                    raise ModelError(f"{name} must be positive when 'ade' is on, got {value}")
        for name in ("M1", "M2"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ModelError(f"{name} must be a non-negative penalty, got {value}")
        for name in ("delta_A0", "C", "kappa_bar"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ModelError(f"{name} must be a finite number, got {value}")
        if self.C != 0.0 and not self.on("spontaneous_curvature"):
            raise ModelError(
                f"C = {self.C} is set but the 'spontaneous_curvature' effect is off; "
                "add it to effects"
            )
        return self

    def with_(self, **changes) -> Params:
        """A copy with some fields changed.

        D and A₀ follow ε and β when they were derived from them (D = 2ε/3, A₀ = β) and the
        change does not set them itself.
        """
        if "eps" in changes and "D" not in changes and self.D == 2.0 * self.eps / 3.0:
            changes["D"] = None
        if "beta" in changes and "A0" not in changes and self.A0 == self.beta:
            changes["A0"] = None
        return replace(self, **changes)

    def for_constraints(self, constraints: str) -> Params:
        """The parameters a run with ``constraints`` uses: exact constraints replace the
        volume and area penalties, they are not added to them (model §2, issue 6)."""
        if constraints not in CONSTRAINTS:
            raise ModelError(f"unknown constraints {constraints!r}; "
                             f"valid: {', '.join(CONSTRAINTS)}")
        if constraints == "exact":
            return self.with_(effects=self.effects - {"volume", "area"})
        return self

    # -- the scalar parts of E_M (model §2): one home for both backends -------------------
    # Each term below depends on φ only through one functional (V, A or ΔA), which each
    # backend computes on its own fields; its force is (slope) × (the functional's gradient).
    def volume_energy(self, V: float) -> float:
        """T₁ = M₁(V − α)²."""
        return self.M1 * (V - self.alpha) ** 2

    def volume_slope(self, V: float) -> float:
        """dT₁/dV = 2M₁(V − α)."""
        return 2.0 * self.M1 * (V - self.alpha)

    @property
    def volume_curvature(self) -> float:
        """d²T₁/dV² = 2M₁: the σ of T₁'s rank-one Hessian σ g_V g_Vᵀ (g_V = δV/δφ)."""
        return 2.0 * self.M1

    def area_energy(self, A: float) -> float:
        """T₂ = M₂(A − β)²."""
        return self.M2 * (A - self.beta) ** 2

    def area_slope(self, A: float) -> float:
        """dT₂/dA = 2M₂(A − β)."""
        return 2.0 * self.M2 * (A - self.beta)

    @property
    def area_curvature(self) -> float:
        """d²T₂/dA² = 2M₂: the σ of T₂'s rank-one Hessian σ g_A g_Aᵀ."""
        return 2.0 * self.M2

    def area_force_scale(self, A: float) -> float:
        """c_A = (3√2/2)M₂(A − β): the area penalty's force is δT₂/δφ = −c_A f (model §3)."""
        return 1.5 * SQRT2 * self.M2 * (A - self.beta)

    @property
    def ade_modulus(self) -> float:
        """κ̄π/(A₀D²): G = ½·ade_modulus·(ΔA − ΔA₀)², the second derivative of G in ΔA."""
        return self.kappa_bar * math.pi / (self.A0 * self.D**2)

    def ade_energy(self, dA: float) -> float:
        """G = (κ̄π / (2A₀D²)) (ΔA − ΔA₀)²   (paper 2.7)."""
        return self.kappa_bar * math.pi / (2.0 * self.A0 * self.D**2) * (dA - self.delta_A0) ** 2

    def ade_force_coefficient(self, dA: float) -> float:
        """γ = −(3κ̄π/(4A₀D))(ΔA − ΔA₀) = (dG/dΔA)·(−3D/4): the ADE force (model §3) is
        h = γ(−2φΔφ − Δ(φ²) + (1/ε²)(1 − 6φ² + 5φ⁴)), δΔA/δφ being −(3D/4) times the bracket."""
        return -0.75 * self.kappa_bar * math.pi / (self.A0 * self.D) * (dA - self.delta_A0)

    def energy(self, W: float, functionals: Mapping[str, float | None]) -> dict:
        """E_M and its parts from W and the functionals a backend measured, by name
        (:data:`TERMS`: ``{"V": …, "A": …, "dA": …}``). A term that is off reports 0, and so
        does its functional unless it is a penalty's (V and A are measured always).

        The parts come in the order of :data:`DIAGNOSTICS`: E, W, the shape terms' energies
        (G), the functionals (V, A, ΔA), the penalties' energies (T1, T2); E sums them in that
        order, E = W + G + T₁ + T₂."""
        energies = {t.energy: t.energy_of(self, functionals[t.functional])
                    if self.on(t.effect) else 0.0 for t in TERMS}
        reported = {t.functional: functionals[t.functional]
                    if t.penalty or self.on(t.effect) else 0.0 for t in TERMS}
        E = W
        for t in ENERGY_ORDER:
            E = E + energies[t.energy]
        parts = {"E": E, "W": W, **energies, **reported}
        return {name: parts[name] for name in DIAGNOSTICS}

    def reduced_targets(self) -> tuple[float, float]:
        """(v₀, Δa₀): the reduced volume and area difference the targets α, β, ΔA₀ describe."""
        return (reduced_volume(self.alpha, self.beta),
                reduced_area_difference(self.delta_A0, self.beta, self.D))

    def as_dict(self) -> dict:
        d = asdict(self)
        d["effects"] = sorted(self.effects, key=EFFECTS.index)
        return d


PARAM_FIELDS = {f.name for f in fields(Params)}


@dataclass(frozen=True)
class Term:
    """One global term of E_M (model §2), the part both backends share: a function of φ through
    one functional Q, whose value each backend measures on its own fields (the FEM's record:
    :mod:`fem_ade.backends.fem.terms`; the spectral reference writes its own).

    ``effect``: its effect in :data:`EFFECTS`; ``functional``: the name of Q, its key in the
    backends' measurements and its history column; ``energy``: the name of its energy in the
    diagnostics; ``penalty``: a penalty of a constraint (volume, area), whose energy is a
    diagnostic only and whose functional is measured even when the penalty is off (the exact
    constraints hold it; the reduced volume needs it) — a shape term's energy (G) is a history
    column and a part of the reduced energy e; ``energy_method``: the :class:`Params` method
    that gives its energy from Q (looked up when called, by name).
    """

    effect: str
    functional: str
    energy: str
    penalty: bool
    energy_method: str

    def energy_of(self, params: Params, value):
        """The term's energy at Q = ``value`` (a number, or an array of them)."""
        return getattr(params, self.energy_method)(value)


#: The global terms, in the model's order (the order of their functionals in the history and
#: of the stabilized scheme's rank-one terms)
TERMS = (Term("volume", "V", "T1", True, "volume_energy"),
         Term("area", "A", "T2", True, "area_energy"),
         Term("ade", "dA", "G", False, "ade_energy"))
#: the order in which E sums the terms' energies: the shape terms', then the penalties'
ENERGY_ORDER = (*(t for t in TERMS if not t.penalty), *(t for t in TERMS if t.penalty))
#: the energies a history records: E, W and the shape terms' (not the penalties': their
#: functionals are recorded)
ENERGY_COLUMNS = ("E", "W", *(t.energy for t in TERMS if not t.penalty))
#: the functionals' columns, in the terms' order
FUNCTIONAL_COLUMNS = tuple(t.functional for t in TERMS)
#: Columns every backend reports, in this order (model §6)
HISTORY_COLUMNS = ("step", "t", *ENERGY_COLUMNS, *FUNCTIONAL_COLUMNS)
#: the keys of :meth:`Params.energy`: the history's and the penalties' energies
DIAGNOSTICS = (*ENERGY_COLUMNS, *FUNCTIONAL_COLUMNS, *(t.energy for t in TERMS if t.penalty))


def reduced_volume(V: float, A: float) -> float:
    """v = V / (4π/3 (A/4π)^{3/2}): 1 for a sphere (NaN where it is undefined)."""
    den = 4.0 * math.pi / 3.0 * (A / (4.0 * math.pi)) ** 1.5 if A > 0 else 0.0
    return V / den if den > 0 else math.nan


def reduced_area_difference(dA: float, A: float, D: float) -> float:
    """Δa = ΔA / (8πD √(A/4π)): 1 for a sphere (ΔA = 8πDR; NaN where it is undefined)."""
    den = 8.0 * math.pi * D * math.sqrt(A / (4.0 * math.pi)) if A > 0 else 0.0
    return dA / den if den > 0 else math.nan


def max_stable_dt(params: Params) -> float:
    """ε³/κ: beyond it the step operator 1 + Δtκ(ε|k|⁴ − (2/ε)|k|²) is singular (model §4)."""
    return params.eps**3 / params.kappa


def check_resolution(params: Params, n: int, dt: float, *, allow_underresolved: bool = False,
                     check_dt: bool = True, spacing: float | None = None, min_n: int = 8):
    """Check the grid size n and the time step dt against the scene (model §4). Raises ModelError.

    ``check_dt=False`` skips the Δt < ε³/κ bound (the stabilized scheme has no such bound).
    ``spacing``: the largest node spacing of the discretization (default L/n), which must not
    exceed ε unless ``allow_underresolved``.
    """
    if not isinstance(n, int) or isinstance(n, bool) or n < min_n:
        raise ModelError(f"n must be an integer >= {min_n}, got {n!r}")
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise ModelError(f"the time step must be positive, got dt = {dt}")
    limit = max_stable_dt(params)
    if dt < 1e-12 * limit:
        raise ModelError(f"dt = {dt:g} is too small to move the field (below 1e-12 eps^3/kappa "
                         f"= {1e-12 * limit:g})")
    if check_dt and dt >= limit:
        raise ModelError(
            f"dt = {dt:g} >= eps^3/kappa = {limit:g}: the semi-implicit step operator is singular "
            "there (model §4); use a smaller dt or --scheme stabilized"
        )
    h = params.L / n if spacing is None else spacing
    if h > params.eps and not allow_underresolved:
        raise ModelError(
            f"grid too coarse for the interface: node spacing {h:.4g} > eps = {params.eps:g}; "
            f"use a finer grid (n >= {math.ceil(n * h / params.eps)}) or --allow-underresolved"
        )


def explicit_area_dt_bound(params: Params, A: float) -> tuple[float, float]:
    """The area penalty's explicit diffusion and the largest Δt the paper's scheme tolerates.

    The explicit term (3√2/2) M₂ (A − β) f contains the diffusion c Δφ with
    c = (3√2/2) M₂ (A − β) ε. Against the implicit operator κ(εΔ² + (2/ε)Δ), a Fourier mode
    of wavenumber k stays bounded while Δt((c + 2κ/ε)k² − κεk⁴) ≤ 2; the worst k gives
    Δt ≤ 8κε / (c + 2κ/ε)². Returns (c, bound); bound is inf when c ≤ 0.
    """
    c = params.area_force_scale(A) * params.eps
    if c <= 0 or not params.on("area"):
        return c, math.inf
    bound = 8.0 * params.kappa * params.eps / (c + 2.0 * params.kappa / params.eps) ** 2
    return c, bound


def stabilization_coefficients(params: Params, functionals: Mapping[str, float | None]):
    """(s₀, s₂) of the large-step scheme: it adds (s₀ − s₂Δ)(φⁿ⁺¹ − φⁿ) to the left side.

    Each explicit term contributes the Lipschitz bound of its linearisation for |φ| ≤ 1:

    * bending N(φ): diffusion (6/ε)φ² ≤ 6/ε; reaction (1/ε³)(15φ⁴ − 12φ² + 1) ≤ 4/ε³ plus
      the couplings to Δφ, (6/ε)|φΔφ| + (3/ε)|Δ(φ²)|, which are O(1/ε³) on an interface:
      s₀ = 8κ/ε³ (measured: 4κ/ε³ let E_M rise in ``discocyte`` at 100× Δt after 480 steps);
    * area penalty (3√2/2)M₂(A − β)f: reaction |c_A|·2/ε, diffusion |c_A|ε, c_A = (3√2/2)M₂(A − β);
    * ADE h = c_G(−2φΔφ − Δ(φ²) + (1 − 6φ² + 5φ⁴)/ε²): reaction 8|c_G|/ε², diffusion 4|c_G|,
      c_G = (3κ̄π/(4A₀D))(ΔA − ΔA₀);
    * the localized volume penalty 2M₁(V − α)s′(φ): reaction |2M₁(V − α)|·max|s″| =
      (3/2)|2M₁(V − α)| (the paper's V has s″ = 0).

    ``functionals``: the terms' functionals by name (:data:`TERMS`); A (ΔA, V) is absent or
    None when the area (ADE, volume) effect is off (V counts only if localized). The
    rank-one parts of the penalty Hessians (volume, area, ADE) are made implicit separately by
    each backend.
    """
    p = params
    A, dA, V = (functionals.get(name) for name in ("A", "dA", "V"))
    s0 = 8.0 * p.kappa / p.eps**3
    s2 = 6.0 * p.kappa / p.eps
    if A is not None:
        cA = abs(p.area_force_scale(A))
        s0 += 2.0 * cA / p.eps
        s2 += cA * p.eps
    if dA is not None:
        cG = abs(p.ade_force_coefficient(dA))
        s0 += 8.0 * cG / p.eps**2
        s2 += 4.0 * cG
    if V is not None and p.localized_volume:
        s0 += 1.5 * abs(p.volume_slope(V))
    return s0, s2


def ratchet_stabilization(current: tuple[float, float] | None, required: tuple[float, float]):
    """The (s₀, s₂) a step uses: keep ``current`` unless ``required`` exceeds it or falls
    below half of it (then take ``required``).

    Larger coefficients only damp more, so keeping them is safe; the hysteresis lets the FEM
    backend rebuild its matrix and AMG hierarchy a few times per run instead of every step.
    Both backends use this rule, so they run the same scheme.
    """
    if current is None:
        return required
    if any(r > c or r < 0.5 * c for r, c in zip(required, current, strict=True)):
        return required
    return current


def diagnose_blowup(params: Params, dt: float, last: dict | None) -> str:
    """Name the likely cause of a blow-up from the last finite diagnostics ``last``."""
    causes = []
    if last is not None and params.on("area") and math.isfinite(last.get("A", math.nan)):
        A = last["A"]
        c, bound = explicit_area_dt_bound(params, A)
        if dt > bound:
            causes.append(
                f"explicit area penalty: A - beta = {A - params.beta:.3g} gives an explicit "
                f"diffusion c = (3*sqrt(2)/2)*M2*(A-beta)*eps = {c:.3g}, which needs "
                f"dt <= 8*kappa*eps/(c+2*kappa/eps)^2 = {bound:.3g} (dt = {dt:.3g}); "
                "start closer to the target area (e.g. --ic consistent) or reduce --dt"
            )
    if not causes:
        causes.append(
            f"the explicit nonlinear terms at dt = {dt:.3g} "
            f"(eps^3/kappa = {max_stable_dt(params):.3g}); "
            "reduce --dt or start from a smoother initial condition"
        )
    return "; ".join(causes)
