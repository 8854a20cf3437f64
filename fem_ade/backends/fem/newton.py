"""Steady states by Newton's method: the discrete Euler–Lagrange equations of E_h with V = α
and A = β held exactly, solved by Newton–Krylov on a FEM backend with a tensor space.

A steady state of the gradient flow is a stationary point of the Lagrangian

    L(φ, λ) = E_h(φ) + λ_V (V_h(φ) − α) + λ_A (A_h(φ) − β) + λ_T T(φ),

and Newton's method goes to it directly: each iteration solves the bordered system

    [ H_L  C ] [δφ]     [ ∇_φ L ]
    [ Cᵀ   0 ] [δλ] = − [ c(φ)  ],     C = (∇V_h, ∇A_h, ∇T),

by a sparse LU of the Hessian in mixed form where the space is 2D with natural edges (the
axisymmetric geometry: :mod:`fem_ade.backends.fem.direct`), elsewhere by MINRES (:func:`minres`,
which takes an indefinite H_L: saddles too), preconditioned by diag(M, CᵀP⁻¹C) with P = (4κ/ε³)W +
(4κ/ε)K + κε KW⁻¹K — the Hessian of E_h in the bulk phases (φ = ±1, P′(φ) = 2), SPD, and inverted
exactly by the space's fast diagonalization — and M⁻¹ = P⁻¹ plus a coarse space's correction for the
membrane's shape modes (:mod:`fem_ade.backends.fem.coarse`; ``linear="minres"``: P⁻¹ alone). H_L·v
is exact: every term's linearization (:meth:`fem_ade.backends.fem.step.MixedStep.hessian_vector`,
checked against finite differences of the gradient to 1e-9). T = Σ wᵢ zᵢ φᵢ pins the translation
along z that the energy of an axisymmetric run does not see (it would make H_L singular; its
multiplier is 0 at a solution); in 3D the pins are P times the starting state's rigid motions (three
translations, the rotations that move it), so that a correction neither moves nor turns it.
The step is halved until E falls by 1e-4 of the Newton decrement, once V and A are
restored along P⁻¹∇V, P⁻¹∇A; it stops when the decrement |∇Lᵀδφ|/|E| — the energy the next
step would still gain — is below ``tol``: a steady state by a residual criterion, where the
gradient flow stops on its energy's change per step.

What it costs with P alone (the axisymmetric prolate at v = 0.8 from the flow's 1e-9 stop,
order 8, 2.5 nodes per ε): at ε = 0.01, 2–4 iterations of 95–225 MINRES iterations; at
ε = 0.005, 8 of 360–580 (the first step cut to ¼ by the line search; E to 3e-10 of the flow
run to a change of 1e-12 per step, in 3× its time). MINRES with P alone needs ~R/ε
iterations: P treats the membrane's shape modes, whose Hessian eigenvalues are the sharp
bending energy's, as bulk modes of eigenvalue 4κ/ε³. Hence the LU in 2D, and in 3D the
coarse space of interface displacements (figures: studies/newton3d_bench.py).

Why more iterations at small ε (measured, ε = 0.005 above): the error |φ − φ*|∞ fell
3.5e-2, 2.6e-2, 2.1e-2, 1.3e-2, 9.4e-3, 3.1e-3, 1.7e-3, then quadratically 9.3e-5 → 0.
Neither the inner solves (``inner_tol`` 1e-12 gives the same iterates to 4 digits, on the
pear at ε = 0.01 too) nor the Hessian (equal to central differences of ∇L to their h²
error there, the ADE term's rank-one part included) nor the line search (full steps after
the first) slow it: the error lies in the shape modes, whose curvature eᵀH_Le/eᵀPe ~ 1e-5
is so small that the Hessian's change over the error itself is larger — along the error
from iterate 0 it is 5.6e-5 there, −2.2e-5 midway and 5.5e-5 at φ*; from iterate 6 (1.7e-3
away) 3.1e-6 against 2.6e-6 at φ*. Newton's quadratic basin is |δφ|∞ ≲ 1e-3 at ε = 0.005
(~1e-2 at 0.01) and shrinks with the shape modes' eigenvalues (in units of P the lowest are ~1e-5 at
ε = 0.01, ~1.5e-6 at 0.005): a start
nearer φ* (a branch's predictor: :meth:`fem_ade.campaigns.continuation.Continuation.predict`) saves
iterations, a more exact step does not.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from fem_ade.backends.fem import forms
from fem_ade.backends.fem.solve import Eigenbasis, StepMatrix, global_dot
from fem_ade.model.params import ModelError


class NewtonError(ArithmeticError):
    """Newton's method did not converge from this state."""


@dataclass
class NewtonResult:
    """What :func:`solve_steady` did: ``converged``, ``iterations``, ``krylov`` (MINRES
    iterations per Newton step; GMRES's on the Fourier–(r, z) geometry), ``decrement`` and
    ``violation`` per iteration (before its step), ``E``, the multipliers ``lambda_V``,
    ``lambda_A``, the seconds it took, the ``coarse`` spaces it made."""

    converged: bool
    iterations: int
    E: float
    lambda_V: float
    lambda_A: float
    krylov: list[int] = field(default_factory=list)
    decrement: list[float] = field(default_factory=list)
    violation: list[float] = field(default_factory=list)
    seconds: float = 0.0
    message: str = ""
    #: the coarse spaces made for MINRES (:meth:`fem_ade.backends.fem.coarse.CoarseSpace.
    #: describe`), in order
    coarse: list[dict] = field(default_factory=list)


#: the linear solvers of the bordered Newton system: ``direct`` (a sparse LU of the mixed
#: Hessian with its borders, :mod:`fem_ade.backends.fem.direct`: 2D tensor spaces with
#: natural edges), ``coarse`` (MINRES preconditioned by the bulk Hessian's fast
#: diagonalization and a coarse space of shape modes, :mod:`fem_ade.backends.fem.coarse`),
#: ``minres`` (the bulk Hessian alone: any tensor space), ``auto`` (direct where it
#: applies, elsewhere coarse from :data:`COARSE_FROM` nodes and minres below)
LINEAR_SOLVERS = ("auto", "direct", "coarse", "minres")
#: the nodes from which ``auto`` adds the coarse space. Measured on the tilted prolate of
#: studies/newton3d_bench.py (one thread, Newton from the flow's 1e-6 stop, coarse against P
#: alone): 32³, ε = 0.04: 1.64 s against 1.21 s; 48³, ε = 0.03: 4.85 s against 4.49 s (two
#: solves; the space's 3.5 s of set-up is most of it); 64³, ε = 0.02: 18.97 s against 42.95 s.
#: A continuation step at 32³ (tests/test_newton.py) takes the same time either way; the
#: D2 branch's --follow at 32³ nodes of order 8, 1.2× longer with the space
COARSE_FROM = 100_000


class NewtonSystem:
    """The pieces of the bordered Newton system on an FEM backend (module docstring);
    ``linear`` one of :data:`LINEAR_SOLVERS`."""

    def __init__(self, be, linear: str = "auto"):
        if getattr(be, "exact", False) is not True:
            raise ModelError("Newton's method solves for steady states with exact constraints "
                             "(--constraints exact)")
        space = be.space
        if getattr(space, "axes", None) is None:
            raise ModelError("Newton's method needs a tensor mesh (its preconditioner is the "
                             "fast diagonalization)")
        self.be, self.space, self.step = be, space, be.stepper
        self.w = space.weights
        basis = be.stepper.eigenbasis or Eigenbasis(space, False)
        self.basis = basis
        self.P_inverse_symbol = basis.inverse(StepMatrix(*self.bulk()))
        self.translations = self._translations()
        if linear not in LINEAR_SOLVERS:
            raise ModelError(f"the Newton system's solver must be one of "
                             f"{', '.join(LINEAR_SOLVERS)}, got {linear!r}")
        planar = space.dim == 2 and not any(getattr(a, "periodic", False) for a in space.axes)
        if linear == "direct" and not planar:
            raise ModelError("the direct solver factors the Hessian of a 2D space with natural "
                             "edges (the axisymmetric geometry); use minres")
        self.direct = planar if linear == "auto" else linear == "direct"
        self.uses_coarse = (not planar and space.n_dofs >= COARSE_FROM if linear == "auto"
                            else linear == "coarse")
        self.coarse = None  # the coarse space in use (made by the first solve that needs one)
        self._K = None

    @property
    def K_assembled(self):
        """K as a sparse matrix (the direct solver's), once."""
        if self._K is None:
            self._K = self.space.assembled_stiffness()
        return self._K

    def bulk(self) -> tuple[float, float, float]:
        """(a, c, κε) of P = aW + cK + κε KW⁻¹K, the Hessian of E_h in the bulk phases."""
        p = self.params
        return 4.0 * p.kappa / p.eps**3, 4.0 * p.kappa / p.eps, p.kappa * p.eps

    def factor(self, lin: Linearization, sigma: float = 0.0, C=None):
        """The bordered Hessian of ``lin`` less σP, factored (:class:`fem_ade.backends.fem.direct.
        Bordered` over a :class:`~fem_ade.backends.fem.direct.HessianFactor`): its rank-one terms
        and
        the constraints ``C`` (default: ``lin.C``) as borders. Kept on ``lin`` for σ = 0
        and the default C (a Newton step's two right sides share it)."""
        from fem_ade.backends.fem.direct import Bordered, HessianFactor, node_order

        keep = sigma == 0.0 and C is None
        if keep and lin.bordered is not None:
            return lin.bordered
        a, c, ke = self.bulk()
        co = self.step.hessian_coefficients(lin.phi, lin.mu, lin.Kphi, lin.lam[0], lin.lam[1])
        F = HessianFactor(self.K_assembled, self.w, ke, co,
                          node_order(self.space.shape, self.space.order), sigma=sigma, P=(a, c))
        bordered = Bordered(F.solve, [b for _, b in co["rank_one"]],
                            [s for s, _ in co["rank_one"]], lin.C if C is None else C)
        bordered.factor = F
        if keep:
            lin.bordered = bordered
        return bordered

    @property
    def params(self):
        """The parameters the backend runs now (continuation changes them)."""
        return self.step.params

    # -- the functionals ---------------------------------------------------------------------
    def _translations(self) -> list[np.ndarray]:
        """Gradients of the linear functionals that pin the rigid motions (the pins):
        z in the axisymmetric and Fourier–(r, z) geometries; in 3D P·u for each rigid motion u
        of the starting state (the translations ∂ₐφ and the rotations about its centroid, made
        P-orthogonal and normalized, a rotation about an axis of symmetry left out:
        :func:`fem_ade.backends.fem.modes.rigid_motions`, :func:`~fem_ade.backends.fem.
        modes.p_orthogonal`), so that no Newton correction moves or turns the shape. The
        continuous problem has them as zero modes; the cubic mesh pins them with a small
        energy of either sign, which left Newton (and a continuation's tangent) to drift
        along them. None in 2D, and none in the octant (no rigid motion keeps its mirrors)."""
        if getattr(self.be, "geometry", "cartesian") in ("axisymmetric", "fourier"):
            z = self.space.doflocs[1]
            return [self.w * (z - float(np.sum(self.w * z) / np.sum(self.w)))]
        if self.space.dim != 3 or getattr(self.be, "geometry", "") == "octant":
            return []  # the octant's mirrors hold no rigid motion
        from fem_ade.backends.fem.modes import p_orthogonal, rigid_motions

        return p_orthogonal(self.P, rigid_motions(self.be, self.be.phi))

    def P(self, x: np.ndarray) -> np.ndarray:
        """P·x, the bulk Hessian (:meth:`bulk`) applied."""
        a, c, ke = self.bulk()
        x = np.ravel(x)
        Kx = self.space.K @ x
        return a * self.w * x + c * Kx + ke * (self.space.K @ (Kx / self.w))

    def fields(self, phi):
        mu = self.space.laplacian(phi)
        return mu, self.w * mu

    def gradient(self, phi, mu=None, Kphi=None) -> np.ndarray:
        """∇E_h(φ) (minus the step's descent direction)."""
        if mu is None:
            mu, Kphi = self.fields(phi)
        return self.step.gradient(phi, mu, Kphi)

    def constraint_gradients(self, phi, Kphi) -> list[np.ndarray]:
        return [self.step.volume_gradient(phi), self.step.area_gradient(phi, Kphi),
                *self.translations]

    def constraint_values(self, phi, Kphi) -> np.ndarray:
        """(V − α, A − β) at φ (the translations' rows: 0, they are kept where they are)."""
        p = self.params
        V = forms.volume(phi, self.w, p.localized_volume)
        A = forms.area(phi, Kphi, self.w, p.eps)
        return np.array([V - p.alpha, A - p.beta] + [0.0] * len(self.translations))

    def restore(self, phi, tol: float = 1e-13, steps: int = 8):
        """φ moved along P⁻¹∇V and P⁻¹∇A until V = α and A = β (Newton on the 2×2 system),
        or None if that does not converge."""
        p = self.params
        mu, Kphi = self.fields(phi)
        d = self.restore_directions(phi, Kphi)
        Kd = [self.w * self.space.laplacian(x) for x in d]
        ab = np.zeros(2)
        for _ in range(steps):
            u = phi + ab[0] * d[0] + ab[1] * d[1]
            Ku = Kphi + ab[0] * Kd[0] + ab[1] * Kd[1]
            V = forms.volume(u, self.w, p.localized_volume)
            A = forms.area(u, Ku, self.w, p.eps)
            r = np.array([V - p.alpha, A - p.beta])
            if abs(r[0]) <= tol * p.alpha and abs(r[1]) <= tol * p.beta:
                return u
            gV, gA = self.step.volume_gradient(u), self.step.area_gradient(u, Ku)
            J = np.array([[global_dot(g, x) for x in d[:2]] for g in (gV, gA)])
            try:
                ab -= np.linalg.solve(J, r)
            except np.linalg.LinAlgError:
                return None
        u = phi + ab[0] * d[0] + ab[1] * d[1]
        return u if np.all(np.isfinite(u)) else None

    def restore_directions(self, phi, Kphi) -> list[np.ndarray]:
        """The directions :meth:`restore` moves along: P⁻¹∇V, P⁻¹∇A."""
        return [self.P_inverse(c) for c in self.constraint_gradients(phi, Kphi)[:2]]

    # -- linear algebra ----------------------------------------------------------------------
    def P_inverse(self, x: np.ndarray) -> np.ndarray:
        """P⁻¹x, for a vector or a stack of them (k × N)."""
        x = np.asarray(x)
        if x.ndim == 2:
            return self.basis.apply(x, self.P_inverse_symbol)
        return self.basis.apply(x[None], self.P_inverse_symbol)[0]

    def constraint_block(self, C: list[np.ndarray]) -> tuple[list[np.ndarray], np.ndarray]:
        """(P⁻¹cᵢ for each constraint gradient cᵢ, S = CᵀP⁻¹C): the constraints' block of the
        bordered system's preconditioner, and the metric of :meth:`multipliers`."""
        PC = [self.P_inverse(c) for c in C]
        return PC, np.array([[global_dot(ci, pj) for pj in PC] for ci in C])

    def coarse_space(self, lin: Linearization):
        """The coarse space for MINRES at ``lin``: the one in use, or a new one made at ``lin``
        when there is none or it has gone stale (:attr:`fem_ade.backends.fem.coarse.
        CoarseSpace.stale`); None without ``uses_coarse``."""
        if not self.uses_coarse:
            return None
        if self.coarse is None or self.coarse.stale:
            from fem_ade.backends.fem.coarse import CoarseSpace

            self.coarse = CoarseSpace(self, lin)
        return self.coarse

    def multipliers(self, g: np.ndarray, C: list[np.ndarray]) -> np.ndarray:
        """The λ that minimise ‖∇E + Cλ‖ in the P⁻¹ norm."""
        PC, G = self.constraint_block(C)
        return np.linalg.solve(G, [-global_dot(g, pj) for pj in PC])


@dataclass
class Linearization:
    """The Newton system at φ: its fields, E, the constraints' gradients C and values, the
    least-squares multipliers λ, the Lagrangian's gradient ∇L = ∇E + Cλ."""

    phi: np.ndarray
    mu: np.ndarray
    Kphi: np.ndarray
    E: float
    C: list
    lam: np.ndarray
    grad: np.ndarray
    violation: np.ndarray
    #: the factored bordered Hessian (the direct solver's), made on first use
    bordered: object = None


def linearize(sys_: NewtonSystem, phi: np.ndarray) -> Linearization:
    mu, Kphi = sys_.fields(phi)
    E = sys_.step.diagnostics(phi, mu, Kphi)["E"]
    C = sys_.constraint_gradients(phi, Kphi)
    g = sys_.gradient(phi, mu, Kphi)
    lam = sys_.multipliers(g, C)
    grad = g + sum(lj * cj for lj, cj in zip(lam, C, strict=True))
    return Linearization(phi, mu, Kphi, E, C, lam, grad, sys_.constraint_values(phi, Kphi))


def lagrangian_hessian_vector(step, lin, v: np.ndarray) -> np.ndarray:
    """H_L v = ∇²E_h v + (λ_V∇²V_h + λ_A∇²A_h) v at a linearization ``lin`` (its φ, μ, Kφ
    and multipliers λ), exactly."""
    return (step.hessian_vector(lin.phi, lin.mu, lin.Kphi, v)
            + step.constraint_hessian_vector(lin.phi, lin.Kphi, v, lin.lam[0], lin.lam[1]))


def kkt_apply(step, lin, C: list, x: np.ndarray, shift=None) -> np.ndarray:
    """[[H_L − S, C], [Cᵀ, 0]] x at ``lin``: x = (v, ν), ``shift`` v ↦ S v (none: S = 0)."""
    N = lin.phi.size
    v, nu = x[:N], x[N:]
    top = lagrangian_hessian_vector(step, lin, v)
    if shift is not None:
        top = top - shift(v)
    for nj, cj in zip(nu, C, strict=True):
        top = top + nj * cj
    return np.concatenate([top, [global_dot(c, v) for c in C]])


def kkt_solve(sys_: NewtonSystem, lin: Linearization, rhs: np.ndarray,
              inner_tol: float = 1e-8) -> tuple[np.ndarray, int]:
    """x with [[H_L, C], [Cᵀ, 0]] x = rhs (length N + len(C); or a stack of right sides,
    (N + len(C), k)): by the factored Hessian (``sys_.direct``: the same factorization for
    every right side), or by MINRES, preconditioned by diag(P, CᵀP⁻¹C) (module docstring),
    P⁻¹ with the coarse space's correction added where ``sys_.uses_coarse``
    (:meth:`NewtonSystem.coarse_space`); (x, Krylov iterations: MINRES's, or those a
    factor that iterates records (the Fourier–(r, z) system's GMRES), 0 for a direct solve)."""
    rhs = np.asarray(rhs, dtype=float)
    N = lin.phi.size
    if sys_.direct:
        solver = sys_.factor(lin)
        before = len(getattr(solver, "iterations", ()))
        x, y = solver.solve(rhs[:N], rhs[N:])
        return np.concatenate([x, y], axis=0), sum(getattr(solver, "iterations", ())[before:])
    if rhs.ndim == 2:
        out = [kkt_solve(sys_, lin, rhs[:, j], inner_tol) for j in range(rhs.shape[1])]
        return np.column_stack([x for x, _ in out]), sum(its for _, its in out)
    step, C = sys_.step, lin.C
    N = lin.phi.size
    S_inv = np.linalg.inv(sys_.constraint_block(C)[1])

    def kkt(x):
        return kkt_apply(step, lin, C, x)

    coarse = sys_.coarse_space(lin)

    def prec(x):
        y = sys_.P_inverse(x[:N])
        if coarse is not None:
            y += coarse.apply(x[:N])
        return np.concatenate([y, S_inv @ x[N:]])

    x, its = minres(kkt, rhs, prec, rtol=inner_tol, maxiter=5000)
    if coarse is not None:
        coarse.record(its)
    return x, its


def minres(A, b: np.ndarray, M, *, rtol: float, maxiter: int) -> tuple[np.ndarray, int]:
    """x with A x = b, A symmetric (indefinite), M symmetric positive definite, by MINRES
    (Paige & Saunders 1975, the recurrences of :func:`scipy.sparse.linalg.minres`), stopped
    when the residual in the M-norm has fallen by ``rtol``: ‖b − Ax‖_M ≤ rtol ‖b‖_M (or at
    ``maxiter``); (x, iterations).

    Why not scipy's: its stop is the backward error ‖r‖_M / (‖M½AM½‖ ‖x‖₂), which mixes the
    preconditioned residual with the plain 2-norm of x. On the bordered system the multipliers'
    part of x is ~1/(CᵀP⁻¹C) ~ 1e8 times the right side (∇V, ∇A are small), so that test
    passes while the residual is not small at all: the tangent of a branch at ε = 0.01 (the
    right side only in the constraint rows) stopped after 2 iterations with ‖r‖₂ 4e5 times
    ‖b‖₂ (measured). This test is invariant to the scaling of the rows."""
    x = np.zeros_like(b)
    r1 = b.copy()
    y = M(r1)
    beta1 = float(np.dot(r1, y))
    if beta1 < 0:
        raise ValueError("MINRES: the preconditioner is not positive definite")
    if beta1 == 0.0:
        return x, 0
    beta1 = math.sqrt(beta1)
    beta, oldb, dbar, epsln, phibar = beta1, 0.0, 0.0, 0.0, beta1
    cs, sn = -1.0, 0.0
    w, w2, r2 = np.zeros_like(b), np.zeros_like(b), r1
    tiny = np.finfo(float).eps
    for itn in range(1, maxiter + 1):
        v = y / beta
        y = A(v)
        if itn >= 2:
            y = y - (beta / oldb) * r1
        alfa = float(np.dot(v, y))
        y = y - (alfa / beta) * r2
        r1, r2 = r2, y
        y = M(r2)
        oldb, beta = beta, float(np.dot(r2, y))
        if beta < 0:
            raise ValueError("MINRES: the preconditioner is not positive definite")
        beta = math.sqrt(beta)
        oldeps = epsln
        delta = cs * dbar + sn * alfa
        gbar = sn * dbar - cs * alfa
        epsln, dbar = sn * beta, -cs * beta
        gamma = max(math.hypot(gbar, beta), tiny)
        cs, sn = gbar / gamma, beta / gamma
        phi, phibar = cs * phibar, sn * phibar
        w1, w2 = w2, w
        w = (v - oldeps * w1 - delta * w2) / gamma
        x = x + phi * w
        if phibar <= rtol * beta1 or beta <= tiny * beta1:
            return x, itn
    return x, maxiter


def solve_steady(be, *, tol: float = 1e-12, max_iterations: int = 30,
                 max_halvings: int = 10, inner_tol: float = 1e-8,
                 quiet: bool = True, linear: str = "auto", system=None) -> NewtonResult:
    """Newton's method from the backend's current state to a steady state with V = α and
    A = β exactly (module docstring). Each iteration: the bordered system by MINRES (its
    preconditioned residual below ``inner_tol``), then the step (reversed where it climbs,
    i.e. along negative curvature: a saddle the flow crept to), halved until E falls by at
    least 1e-4 of the Newton decrement once the constraints are restored along P⁻¹∇V,
    P⁻¹∇A (Armijo; a full step where the quadratic model holds). Stops when the decrement
    is below ``tol``·|E|. The backend is left at the last state reached (its field, with
    φⁿ⁻¹ cleared); :class:`NewtonResult` says whether it converged. ``system``: the Newton
    system to use (default ``NewtonSystem(be, linear)``; e.g. one with extra pins, or
    :class:`fem_ade.backends.fem.fourier.FourierNewtonSystem`)."""
    t0 = time.perf_counter()
    sys_ = NewtonSystem(be, linear) if system is None else system
    step = sys_.step
    phi = sys_.restore(be.phi.copy())
    if phi is None:
        raise NewtonError("the state is too far from V = alpha, A = beta to restore them")
    N = phi.size
    result = NewtonResult(False, 0, math.nan, math.nan, math.nan)
    for it in range(max_iterations + 1):
        lin = linearize(sys_, phi)
        E = lin.E
        made = sys_.coarse
        x, its = kkt_solve(sys_, lin, -np.concatenate([lin.grad, lin.violation]), inner_tol)
        if sys_.coarse is not made:
            result.coarse.append(sys_.coarse.describe())
        gL, viol, lam = lin.grad, lin.violation, lin.lam
        dphi = x[:N]
        if global_dot(gL, dphi) > 0.0:  # negative curvature along the step: downhill instead
            dphi = -dphi
        decrement = abs(global_dot(gL, dphi)) / max(abs(E), 1e-300)
        result.krylov.append(its)
        result.decrement.append(decrement)
        result.violation.append(float(np.max(np.abs(viol[:2]) / np.array(
            [sys_.params.alpha, sys_.params.beta]))))
        result.E, result.lambda_V, result.lambda_A = E, float(lam[0]), float(lam[1])
        if not quiet:
            print(f"  newton {it}: E = {E:.13g}, decrement {decrement:.2e}, Krylov {its}",
                  flush=True)
        if decrement <= tol:
            result.converged = True
            break
        if it == max_iterations:
            break
        s = 1.0
        for _ in range(max_halvings + 1):
            trial = sys_.restore(phi + s * dphi)
            if trial is not None:
                E_t = step.diagnostics(trial, *sys_.fields(trial))["E"]
                if math.isfinite(E_t) and E_t <= E - 1e-4 * s * decrement * abs(E):
                    break
            s *= 0.5
        else:
            result.message = (f"Newton step {it} does not lower the energy even at "
                              f"2^-{max_halvings} of its length")
            break
        phi = trial
        result.iterations = it + 1
    be._set(phi, None)
    result.seconds = time.perf_counter() - t0
    if not result.converged and not result.message:
        result.message = f"not converged in {max_iterations} Newton iterations"
    return result
