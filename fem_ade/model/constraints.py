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

The initial condition may be far from the constraints: the paper's initial fields have a
phase-field area up to several times β. So a run starts with the targets at the initial
state's own V₀, A₀ and moves them in a straight line to α, β over as many steps as keep the
relative change per step below :data:`RAMP_RATE` (:class:`TargetRamp`; the history's ``ramp``
column is the fraction of the way done). While the targets move, E_M may rise: it is the
constrained energy only once they stand still.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DEFAULT_TOL = 1e-10
class ConstraintError(ArithmeticError):
    """The multipliers did not converge (the step is too far from V = α, A = β)."""


#: the largest relative change of a target per step while the targets ramp from the initial
#: state's V₀, A₀ to α, β (measured: every paper scene's ramp converges at 1e-2 per step)
RAMP_RATE = 1e-2


@dataclass
class TargetRamp:
    """Targets (V, A) moving in a straight line from ``start`` to ``end``.

    Each step asks for ``fraction + increment`` of the way (:meth:`propose`). If the step's
    multipliers cannot reach that (:meth:`slow_down`: the step is tried again with a quarter
    of the increment) the ramp slows; after each step that reaches it (:meth:`accept`) the
    increment grows by half again, up to ``max_increment`` (the :data:`RAMP_RATE` relative
    change per step). So a small Δt, where one step cannot move V or A far, ramps slowly
    instead of failing. Part of a backend's state: a resumed run ramps the same.
    """

    start: tuple[float, float]
    end: tuple[float, float]
    max_increment: float
    increment: float
    fraction: float = 0.0
    moved: bool = False  # the last accepted step moved the targets

    @classmethod
    def between(cls, start, end, rate: float = RAMP_RATE) -> TargetRamp:
        gap = max(abs(e / s - 1.0) for s, e in zip(start, end, strict=True))
        inc = 1.0 if gap <= rate else float(rate / gap)
        return cls(tuple(map(float, start)), tuple(map(float, end)), inc, inc)

    def _at(self, f: float) -> tuple[float, float]:
        if f >= 1.0:
            return self.end
        return tuple(s + f * (e - s) for s, e in zip(self.start, self.end, strict=True))

    def propose(self) -> tuple[float, float]:
        """The targets of the next step."""
        return self._at(min(1.0, self.fraction + self.increment))

    def accept(self) -> None:
        """The step reached the proposed targets: move on, and speed up again."""
        new = min(1.0, self.fraction + self.increment)
        self.moved = new > self.fraction
        self.fraction = new
        self.increment = min(self.max_increment, 1.5 * self.increment)

    def slow_down(self) -> bool:
        """The step could not reach the proposed targets: a quarter of the increment (False
        when the targets stand still already or the increment is negligible)."""
        if self.fraction >= 1.0 or self.increment < 1e-6:
            return False
        self.increment *= 0.25
        return True

    @property
    def moving(self) -> bool:
        """True if the last step moved the targets (E_M may have risen on it)."""
        return self.moved

    @property
    def done(self) -> bool:
        return self.fraction >= 1.0

    def state(self) -> np.ndarray:
        return np.array([*self.start, *self.end, self.max_increment, self.increment,
                         self.fraction, float(self.moved)], dtype=float)

    @classmethod
    def from_state(cls, a) -> TargetRamp:
        a = np.asarray(a, dtype=float).ravel()
        return cls((a[0], a[1]), (a[2], a[3]), a[4], a[5], a[6], bool(a[7]))

    def solve(self, multipliers):
        """Run ``multipliers(targets) -> result`` at this step's targets, slowing the ramp and
        trying again while it fails; return its result (ConstraintError if it never works)."""
        while True:
            try:
                result = multipliers(self.propose())
            except ConstraintError:
                if not self.slow_down():
                    raise
                continue
            self.accept()
            return result


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
