"""A compact Fourier-spectral reference for the ADE phase-field model (model §2–§4, §6).

Written straight from the formulas, independently of the finite-element physics, so that
the two backends cross-check each other. It shares with the FEM only the scene catalogue and
its parameters (the scalar parts of E_M in :class:`fem_ade.model.params.Params`), and generic code
that holds no physics (the backend base with the constraints' target ramp, output meshes):
its energy terms, forces, stabilization and constraint multipliers are its own.

Conventions (model §6): grid x_j = jL/n in each direction; derivatives by FFT (``rfftn``);
integrals by the rectangle rule h^d Σ; no dealiasing.

One step of the semi-implicit scheme (model §4)::

    φ̂ⁿ⁺¹ = (φ̂ⁿ/Δt − R̂ⁿ) / (1/Δt + κ(ε|k|⁴ − (2/ε)|k|²))
    Rⁿ   = κN(φⁿ) + h(φⁿ) + M₁(Vⁿ − α) − (3√2/2) M₂ (Aⁿ − β) f(φⁿ)

Every term of Rⁿ is either a pointwise function P of (φ, Δφ) or a Laplacian Δ Q of a
pointwise function Q. Gathering them, R̂ = FFT(P) − |k|² FFT(Q), so that a step costs four
transforms: φ and Δφ back to the grid (φ̂ is kept between steps), P and Q forward.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import fft

from fem_ade.backends.base import BackendBase
from fem_ade.backends.threads import fft_workers
from fem_ade.model.constraints import ConstraintError
from fem_ade.model.params import ModelError
from fem_ade.store.xdmf import closed_grid_values, grid_mesh

SQRT2 = math.sqrt(2.0)


def wavenumbers_squared(n: int, L: float, dim: int) -> np.ndarray:
    """|k|² on the rfftn half-spectrum of an n^dim grid of period L."""
    k_full = 2.0 * np.pi * fft.fftfreq(n, d=L / n)
    k_half = 2.0 * np.pi * fft.rfftfreq(n, d=L / n)
    axes = [k_full] * (dim - 1) + [k_half]
    grids = np.meshgrid(*axes, indexing="ij", sparse=True)
    return sum(g * g for g in grids)


# --- the energy terms, one function each (the names are what tests count) ----------------
def bending_energy(phi, lap, p, dV):
    """W = (κ/2ε) ∫ f_c², f_c = εΔφ − (1/ε)(φ² − 1)(φ + Cε)   (model §2)."""
    fc = p.eps * lap - (phi * phi - 1.0) * (phi + p.C_eff * p.eps) / p.eps
    return p.kappa / (2.0 * p.eps) * dV * np.sum(fc * fc)


def bending_force_explicit(phi, lap, p):
    """κN(φ) of model §4 as (P, Q), κN = P + ΔQ:

    N = −(1/ε)Δ(φ³) − CΔ(φ²) − (3/ε)φ²Δφ − 2CφΔφ + (1/ε³)(3φ² + 2Cεφ − 1)(φ² − 1)(φ + Cε).
    """
    eps, C, kappa = p.eps, p.C_eff, p.kappa
    phi2 = phi * phi
    P = (-(3.0 / eps) * phi2 * lap - 2.0 * C * phi * lap
         + (3.0 * phi2 + 2.0 * C * eps * phi - 1.0) * (phi2 - 1.0) * (phi + C * eps) / eps**3)
    Q = -phi2 * phi / eps - C * phi2
    return kappa * P, kappa * Q


def volume(phi, dV, p):
    """V = ∫ (φ + 1)/2 (the paper's), or ∫ s(φ), s = (2 + 3φ − φ³)/4 (``localized``)."""
    if p.localized_volume:
        return dV * np.sum(2.0 + 3.0 * phi - phi * phi * phi) / 4.0
    return dV * np.sum(phi + 1.0) / 2.0


def volume_gradient(phi, p):
    """δV/δφ: ½ (a constant, the k = 0 mode), or s′(φ) = (3/4)(1 − φ²) (``localized``)."""
    if p.localized_volume:
        return 0.75 * (1.0 - phi * phi)
    return 0.5


def area(phi, lap, p, dV):
    """A = (3√2/4) ∫ (ε/2)|∇φ|² + (1/4ε)(φ² − 1)².

    ∫|∇φ|² = −∫φΔφ, exact for the FFT Laplacian (Parseval) and free: Δφ is on the grid anyway.
    """
    grad2 = -np.sum(phi * lap)
    well = np.sum((phi * phi - 1.0) ** 2)
    return 0.75 * SQRT2 * dV * (0.5 * p.eps * grad2 + well / (4.0 * p.eps))


def area_gradient(phi, lap, p):
    """δA/δφ = −(3√2/4) f, f = εΔφ − (1/ε)(φ² − 1)φ (pointwise)."""
    return -0.75 * SQRT2 * (p.eps * lap - (phi * phi - 1.0) * phi / p.eps)


def area_difference(phi, lap, p, dV):
    """ΔA = −(3D/4) ∫ (1 − φ²)Δφ + (1/ε²) φ(1 − φ²)²   (model §2, paper 2.6)."""
    one_m = 1.0 - phi * phi
    return -0.75 * p.D * dV * np.sum(one_m * lap + phi * one_m * one_m / p.eps**2)


def area_difference_gradient(phi, lap, eps, coef):
    """coef·(−2φΔφ − Δ(φ²) + (1/ε²)(1 − 6φ² + 5φ⁴)) as (P, Q), the sum being P + ΔQ.

    coef = −3D/4 gives δΔA/δφ; coef = γ (``Params.ade_force_coefficient``) the ADE force
    h = δG/δφ of model §3.
    """
    phi2 = phi * phi
    P = coef * (-2.0 * phi * lap + (1.0 - 6.0 * phi2 + 5.0 * phi2 * phi2) / eps**2)
    Q = -coef * phi2
    return P, Q


# --- the global terms, one record each ------------------------------------------------------
class GlobalTerm:
    """A term of E_M that depends on φ through one functional (V, A or ΔA: the volume and area
    penalties, the ADE term), as this reference computes it: ``key`` names the functional (the
    name ``Params.energy`` reads), ``effect`` switches the term on; ``penalty``: its
    functional is measured even when the term is off (the constraints' V and A).

    ``measure`` gives the functional's value; ``force`` the term's share of Rⁿ at that value
    as (P, Q, m): P + ΔQ on the grid plus the constant m (the k = 0 mode), None where a part
    is absent; ``rank_one`` the Hessian's σ g⟨g, ·⟩ for the large-step scheme as (σ, P, Q),
    g = P + ΔQ, or None where this reference makes the term implicit otherwise (the paper's V:
    :func:`stabilization_symbol`).
    """

    key = effect = ""
    penalty = False

    def measure(self, phi, lap, p, dV):
        raise NotImplementedError

    def force(self, phi, lap, p, value):
        raise NotImplementedError

    def rank_one(self, phi, lap, p):
        raise NotImplementedError


class VolumeTerm(GlobalTerm):
    """M₁(V − α)²: force 2M₁(V − α)·δV/δφ, a constant (the k = 0 mode) for the paper's V."""

    key, effect, penalty = "V", "volume", True

    def measure(self, phi, lap, p, dV):
        return volume(phi, dV, p)

    def force(self, phi, lap, p, value):
        if p.localized_volume:
            return p.volume_slope(value) * volume_gradient(phi, p), None, None
        return None, None, 0.5 * p.volume_slope(value)  # slope × ½

    def rank_one(self, phi, lap, p):
        if not p.localized_volume:
            return None
        return p.volume_curvature, volume_gradient(phi, p), None


class AreaTerm(GlobalTerm):
    """M₂(A − β)²: force 2M₂(A − β)·δA/δφ, pointwise."""

    key, effect, penalty = "A", "area", True

    def measure(self, phi, lap, p, dV):
        return area(phi, lap, p, dV)

    def force(self, phi, lap, p, value):
        return p.area_slope(value) * area_gradient(phi, lap, p), None, None

    def rank_one(self, phi, lap, p):
        return p.area_curvature, area_gradient(phi, lap, p), None


class AreaDifferenceTerm(GlobalTerm):
    """G = (κ̄π/(2A₀D²))(ΔA − ΔA₀)²: force γ(…) with γ = ``Params.ade_force_coefficient``."""

    key, effect = "dA", "ade"

    def measure(self, phi, lap, p, dV):
        return area_difference(phi, lap, p, dV)

    def force(self, phi, lap, p, value):
        return (*area_difference_gradient(phi, lap, p.eps, p.ade_force_coefficient(value)),
                None)

    def rank_one(self, phi, lap, p):
        return (p.ade_modulus, *area_difference_gradient(phi, lap, p.eps, -0.75 * p.D))


#: the global terms (volume, area, ADE); the rank-one terms come in this order, the forces
#: are summed in the reverse one
TERMS = (VolumeTerm(), AreaTerm(), AreaDifferenceTerm())


def stabilization(p, values):
    """(s₀, s₂) of the large-step scheme (model §9): the Lipschitz bounds of the explicit
    terms' linearisations for |φ| ≤ 1 — bending 8κ/ε³ and 6κ/ε; the area penalty's force
    c_A f, c_A = (3√2/2)M₂(A − β): 2|c_A|/ε and |c_A|ε; the ADE force, c_G =
    (3κ̄π/(4A₀D))(ΔA − ΔA₀): 8|c_G|/ε² and 4|c_G|; the localized volume penalty:
    (3/2)|2M₁(V − α)|. ``values``: the functionals by key (absent: the term is off).
    (Written here from the formulas, apart from the FEM's copy, so that the two backends check
    each other's scheme.)"""
    A, dA, V = values.get("A"), values.get("dA"), values.get("V")
    s0 = 8.0 * p.kappa / p.eps**3
    s2 = 6.0 * p.kappa / p.eps
    if A is not None:
        cA = abs(1.5 * SQRT2 * p.M2 * (A - p.beta))
        s0 += 2.0 * cA / p.eps
        s2 += cA * p.eps
    if dA is not None:
        cG = abs(0.75 * p.kappa_bar * math.pi / (p.A0 * p.D) * (dA - p.delta_A0))
        s0 += 8.0 * cG / p.eps**2
        s2 += 4.0 * cG
    if V is not None and p.localized_volume:
        s0 += 1.5 * abs(2.0 * p.M1 * (V - p.alpha))
    return s0, s2


def ratchet(current, required):
    """Keep the (s₀, s₂) in use unless the required ones exceed them or fall below half of
    them: larger coefficients only damp more, and the FEM rebuilds its solver less often."""
    if current is None or any(r > c or r < 0.5 * c
                              for r, c in zip(required, current, strict=True)):
        return required
    return current


def newton_multipliers(measure, alpha, beta, tol=1e-10, maxit=30):
    """(a, b) with V = α and A = β at φ₀ + a z_V + b z_A: Newton on the 2×2 system
    ``measure(a, b) -> (V, A, J)``, steps halved while they do not reduce
    max(|V/α − 1|, |A/β − 1|); ConstraintError when it does not converge."""
    def residual(V, A):
        return max(abs(V / alpha - 1.0), abs(A / beta - 1.0))

    a = b = 0.0
    V, A, J = measure(a, b)
    res = residual(V, A)
    for it in range(maxit + 1):
        if res < tol:
            return a, b, it
        try:
            da, db = np.linalg.solve(J, [alpha - V, beta - A])
        except np.linalg.LinAlgError:
            break
        step = 1.0
        while step > 1e-4:
            V1, A1, J1 = measure(a + step * da, b + step * db)
            r1 = residual(V1, A1)
            if math.isfinite(r1) and r1 < res:
                break
            step *= 0.5
        else:
            break
        a, b, V, A, J, res = a + step * da, b + step * db, V1, A1, J1, r1
    raise ConstraintError(f"the constraint multipliers did not converge: |V/alpha - 1| = "
                          f"{abs(V / alpha - 1):.2g}, |A/beta - 1| = {abs(A / beta - 1):.2g} "
                          "(reduce dt)")


def stabilization_symbol(k2, p, s0, s2, dim):
    """The diagonal part S of the large-step scheme, added as S(φⁿ⁺¹ − φⁿ) (model §9).

    S = s₀ + s₂|k|² (:func:`stabilization`) + σ_V δ_k0, where
    σ_V = 2M₁·(½)²|Ω| = M₁|Ω|/2 is the paper's volume penalty's rank-one Hessian (g_V = ½),
    which acts on the mean only (the localized one's is a rank-one term of the step solver).
    """
    S = s0 + s2 * k2
    if p.on("volume") and not p.localized_volume:
        S[(0,) * dim] += 0.25 * p.volume_curvature * p.L**dim  # σ_V ⟨½, ½⟩ |Ω|
    return S


class SpectralBackend(BackendBase):
    """The spectral reference as a backend of :mod:`fem_ade.engine.loop` (see
    fem_ade.backends.base)."""

    name = "spectral"

    def __init__(self, scene, *, n: int, dt: float | None = None, ic: str = "consistent",
                 perturb: float = 0.0, seed: int = 0, scheme: str = "paper",
                 constraints: str = "penalty", workers: int | None = None,
                 start_state: dict | None = None):
        super().__init__(scene, n=n, scheme=scheme, constraints=constraints)
        self.dim = dim = self.scene.dim
        L = self.params.L
        self.dV = (L / n) ** dim
        self.workers = workers if workers is not None else fft_workers()
        self.axes = tuple(range(dim))
        x = np.arange(n) * (L / n)
        self.points = np.stack(np.meshgrid(*[x] * dim, indexing="ij"))
        self.k2 = wavenumbers_squared(n, L, dim)
        self.stab = None  # (s₀, s₂) in use by the stabilized scheme
        if start_state is not None:
            self.set_state(start_state)
        else:
            phi0 = self.initial_field(self.points, ic=ic, perturb=perturb, seed=seed)
            self._set_hat(self._fwd(phi0))
            if self.exact:
                d = self.diagnostics()
                self.start_ramp(d["V"], d["A"])
        if dt is not None:
            self.set_dt(dt)

    def set_dt(self, dt: float) -> None:
        """Set Δt; the implicit symbol of model §4 is 1/Δt + κ(ε|k|⁴ − (2/ε)|k|²)."""
        if dt == self.dt:
            return
        p = self.params
        self.dt = dt
        self.symbol = 1.0 / dt + p.kappa * (p.eps * self.k2**2 - (2.0 / p.eps) * self.k2)

    # -- transforms -------------------------------------------------------------------
    def _fwd(self, u):
        return fft.rfftn(u, axes=self.axes, workers=self.workers)

    def _hermitian(self, u_hat):
        """Remove (in place) the part of a half-spectrum that ``irfftn`` cannot see.

        In the planes k_last = 0 and k_last = n/2 a real field's coefficients satisfy
        û(−k) = conj(û(k)). Round-off breaks this slightly, ``irfftn`` ignores the broken
        part, and the implicit operator amplifies it by 1/(1 − Δtκ/ε³) per step wherever
        κ(ε|k|⁴ − (2/ε)|k|²) < 0: invisible at first, it reaches the field through round-off
        after a few thousand steps. Projecting those two planes keeps φ̂ the transform of φ.
        """
        axes = tuple(range(self.dim - 1))
        for iz in (0, self.n // 2) if self.n % 2 == 0 else (0,):
            plane = u_hat[..., iz]
            mirror = np.conj(np.roll(np.flip(plane, axis=axes), 1, axis=axes))
            u_hat[..., iz] = 0.5 * (plane + mirror)
        return u_hat

    def _inv(self, u_hat):
        return fft.irfftn(u_hat, s=(self.n,) * self.dim, axes=self.axes, workers=self.workers)

    def _set_hat(self, phi_hat):
        self.phi_hat = self._hermitian(phi_hat)
        self.phi = self._inv(phi_hat)
        self.lap = self._inv(-self.k2 * phi_hat)

    # -- the scheme -------------------------------------------------------------------
    def step(self) -> dict:
        p, phi, lap, dV = self.params, self.phi, self.lap, self.dV
        P, Q = bending_force_explicit(phi, lap, p)
        terms = [t for t in TERMS if p.on(t.effect)]
        values = {t.key: t.measure(phi, lap, p, dV) for t in terms}
        mode0 = None
        for t in reversed(terms):  # ADE, area, volume: the order of the sum (bit for bit)
            Pt, Qt, mode0_t = t.force(phi, lap, p, values[t.key])
            if Pt is not None:
                P = P + Pt
            if Qt is not None:
                Q = Q + Qt
            if mode0_t is not None:
                mode0 = mode0_t if mode0 is None else mode0 + mode0_t
        R_hat = self._fwd(P) - self.k2 * self._fwd(Q)
        if mode0 is not None:  # a constant force: the k = 0 mode
            R_hat[(0,) * self.dim] += mode0 * self.n**self.dim
        if self.scheme == "paper" and not self.exact:
            self._set_hat((self.phi_hat / self.dt - R_hat) / self.symbol)
            return {}
        solve = self._step_solver(values)
        delta = solve(-R_hat - (self.symbol - 1.0 / self.dt) * self.phi_hat)
        if not self.exact:
            self._set_hat(self.phi_hat + delta)
            return {}
        lam_V, lam_A = self._constrained_update(self.phi_hat + delta, solve)
        return {"lambda_V": lam_V, "lambda_A": lam_A, "ramp": self.ramp.fraction}

    def _constrained_update(self, base_hat, solve):
        """φⁿ⁺¹ = base − λ_V P⁻¹g_V − λ_A P⁻¹g_A with V, A at this step's targets (α, β once
        the ramp is done; fem_ade.model.constraints)."""
        p, dV, phi, lap = self.params, self.dV, self.phi, self.lap
        if p.localized_volume:
            gV_hat = self._fwd(volume_gradient(phi, p))
        else:
            gV_hat = np.zeros_like(base_hat)
            gV_hat[(0,) * self.dim] = 0.5 * self.n**self.dim  # the transform of the constant ½
        gA_hat = self._fwd(area_gradient(phi, lap, p))
        zs_hat = [solve(gV_hat), solve(gA_hat)]
        base, lap_base = self._inv(base_hat), self._inv(-self.k2 * base_hat)
        zs = [(self._inv(z), self._inv(-self.k2 * z)) for z in zs_hat]
        JV = [0.5 * dV * float(np.sum(z)) for z, _ in zs]  # ⟨½, z⟩ (the paper's V)

        def fields(a, b):
            return (base + a * zs[0][0] + b * zs[1][0], lap_base + a * zs[0][1] + b * zs[1][1])

        def measure(a, b):
            u, lu = fields(a, b)
            gA = area_gradient(u, lu, p)
            rows = [[dV * float(np.sum(volume_gradient(u, p) * z)) for z, _ in zs]
                    if p.localized_volume else JV, [dV * float(np.sum(gA * z)) for z, _ in zs]]
            return volume(u, dV, p), area(u, lu, p, dV), np.array(rows)

        a, b, _ = self.ramp.solve(lambda targets: newton_multipliers(measure, *targets))
        # φ from φ̂ (not the sums the Newton solve used): the state is φ̂ alone, so that a
        # resumed run is bit for bit the uninterrupted one
        self._set_hat(base_hat + a * zs_hat[0] + b * zs_hat[1])
        return -a, -b

    def _inner(self, a_hat, b_hat) -> float:
        """∫ a b over the box from half-spectra (Parseval with the rfft weights)."""
        w = np.full(a_hat.shape[-1], 2.0)
        w[0] = 1.0
        if self.n % 2 == 0:
            w[-1] = 1.0
        return self.dV / self.n**self.dim * float(np.sum(w * (np.conj(a_hat) * b_hat).real))

    def _step_solver(self, values):
        """P⁻¹ of this step: δ = φⁿ⁺¹ − φⁿ solves P δ = −Rⁿ − 𝓛φⁿ, 𝓛 = κ(εΔ² + (2/ε)Δ).

        The paper's scheme: P = 1/Δt + 𝓛 (diagonal). The large-step scheme (model §9 recipe,
        made concrete): P = 1/Δt + 𝓛 + S + Σᵢ σᵢ gᵢ⟨gᵢ, ·⟩, S the diagonal of
        :func:`stabilization_symbol`, the rank-one terms the Hessians of the penalties: area
        σ = 2M₂ with g = δA/δφ, ADE σ = κ̄π/(A₀D²) with g = δΔA/δφ, the localized volume
        σ = 2M₁ with g = s′(φ), applied by Woodbury. ``values``: the active terms' functionals
        by key.
        """
        if self.scheme == "paper":
            return lambda rhs: rhs / self.symbol
        p, phi, lap = self.params, self.phi, self.lap
        self.stab = ratchet(self.stab, stabilization(p, values))
        d = self.symbol + stabilization_symbol(self.k2, p, *self.stab, self.dim)
        low_rank = []
        for t in TERMS:
            term = t.rank_one(phi, lap, p) if t.key in values else None
            if term is not None and term[0] > 0:
                sigma, Pg, Qg = term
                g = self._fwd(Pg) if Qg is None else self._fwd(Pg) - self.k2 * self._fwd(Qg)
                low_rank.append((sigma, g))
        if not low_rank:
            return lambda rhs: rhs / d
        z = [g / d for _, g in low_rank]
        m = len(low_rank)
        G = np.array([[self._inner(low_rank[i][1], z[j]) for j in range(m)] for i in range(m)])
        G += np.diag([1.0 / sig for sig, _ in low_rank])

        def solve(rhs):
            y = rhs / d
            c = np.linalg.solve(G, [self._inner(g, y) for _, g in low_rank])
            return y - sum(ci * zi for ci, zi in zip(c, z, strict=True))

        return solve

    # -- measurements -----------------------------------------------------------------
    def diagnostics(self) -> dict:
        p, phi, lap, dV = self.params, self.phi, self.lap, self.dV
        values = {t.key: t.measure(phi, lap, p, dV) for t in TERMS if t.penalty or p.on(t.effect)}
        return p.energy(bending_energy(phi, lap, p, dV), values)

    def state(self) -> dict:
        state = {"phi_hat": self.phi_hat, **self.ramp_state()}  # replaced, never mutated
        if self.stab is not None:
            state["stab"] = np.array(self.stab)
        return state

    def extrapolate(self, anchor: dict, beta: float) -> None:
        self._set_hat(self.phi_hat + beta * (self.phi_hat - anchor["phi_hat"]))

    def set_state(self, state: dict) -> None:
        phi_hat = np.asarray(state.get("phi_hat", np.zeros(0)))
        shape = self.k2.shape
        if phi_hat.shape != shape or not np.iscomplexobj(phi_hat):
            raise ModelError(f"the state holds a spectrum of shape {phi_hat.shape}; this "
                             f"grid (n = {self.n}, {self.dim}D) needs {shape}")
        self._set_hat(np.array(phi_hat))
        self.stab = tuple(float(v) for v in state["stab"]) if "stab" in state else None
        self.set_ramp_state(state)

    def fields(self) -> dict:
        x = np.arange(self.n) * (self.params.L / self.n)
        return {"phi": self.phi, "x": x}

    def grid_phi(self) -> np.ndarray:
        return self.phi

    def output_mesh(self):
        return grid_mesh(self.n, self.params.L, self.dim)

    def point_data(self) -> dict:
        return {"phi": closed_grid_values(self.phi)}

    def info(self) -> dict:
        return {"n": self.n, "dim": self.dim, "grid": "uniform periodic",
                "dofs": self.n**self.dim, "scheme": self.scheme,
                "constraints": "exact" if self.exact else "penalty",
                "transforms_per_step": 4 if self.scheme == "paper" else 7}
