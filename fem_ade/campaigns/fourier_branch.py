"""A non-axisymmetric branch born at an azimuthal bifurcation, followed on the Fourier–(r, z)
geometry (:mod:`fem_ade.backends.fem.fourier`) by its amplitude (docs/model.md §13).

At a bifurcation in mode m of an axisymmetric branch the new branch leaves along ψ_m cos mθ.
Its amplitude a = ⟨ψ cos mθ, φ⟩_W / ⟨ψ cos mθ, ψ cos mθ⟩_W is a good parameter near the
birth (the axisymmetric state has a = 0, the new branch a ≠ 0 on either side). For each a:
Newton with a pinned (:class:`fem_ade.backends.fem.fourier.FourierNewtonSystem`) gives the
state that is steady in every direction but the pin's, and ``lam`` — the pin's multiplier —
is zero on the branch only. The parameter p (Δa₀ or v) where it is zero is found by the
secant method, each solve warm-started; the first two amplitudes start from the (r, z) state
plus a ψ cos mθ, later ones from the line through the last two points (φ and p).

n_θ is doubled (the field carried over by its cosines) while the highest cosine's largest
value exceeds :data:`TAIL` of the first's: the angles resolve the shape.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from fem_ade.model.params import ModelError
from fem_ade.store.output import write_json_atomic

#: n_θ is doubled while max |a_{n_θ−1}| > TAIL · max |a₁|
TAIL = 1e-3
#: the secant stops when p moves less than this, or after SECANT_STEPS solves (the pin's
#: multiplier is steady to ~2e-5 on the window's branch, where it changes by ~20 per unit
#: of Δa₀: p to ~1e-6)
P_TOL, SECANT_STEPS = 1e-6, 10
#: the secant's second parameter at the first amplitude: this far from the first
FIRST_STEP = 1e-3


class AmplitudeBranch:
    """The branch of fold ``m0`` born from the axisymmetric backend ``be`` along ``psi`` (its
    block's eigenvector on the (r, z) nodes), in the parameter ``param``."""

    def __init__(self, be, psi: np.ndarray, *, m0: int, param: str = "da0",
                 n_theta: int = 4, p_birth: float | None = None, quiet: bool = True):
        from fem_ade.backends.fem.fourier import FourierState
        from fem_ade.scenes.vesicle import get_parameter

        self.be, self.psi, self.m0, self.param, self.quiet = be, psi, m0, param, quiet
        # where the branch is born (the first secant's start; default: be's parameter)
        self.p0 = get_parameter(be.stepper.params, param) if p_birth is None else p_birth
        self.state = FourierState.of(be, m0, n_theta)
        self.points: list[dict] = []
        self._fields: list[np.ndarray] = []  # the cosines of each point (n_θ, N_rz)
        self._pin()

    def _pin(self) -> None:
        from fem_ade.backends.fem.fourier import FourierNewtonSystem

        space = self.state.space
        self.P = space.from_modes({1: self.psi})
        self.pin = space.weights * self.P
        self.norm = float(self.pin @ self.P)
        self.system = FourierNewtonSystem(self.state, pins=[self.pin])

    def amplitude(self, phi: np.ndarray) -> float:
        return float(self.pin @ phi) / self.norm

    def _resize(self, n_theta: int, modes: np.ndarray) -> None:
        """The state on n_θ angles, its field from ``modes`` (the cosines, (k, N_rz))."""
        from fem_ade.backends.fem.fourier import FourierState

        st = FourierState.of(self.be, self.m0, n_theta)
        st.stepper.params = self.state.stepper.params
        k = min(n_theta, modes.shape[0])
        st.phi = st.space.from_modes({j: modes[j] for j in range(k)})
        self.state = st
        self._pin()

    def solve_at(self, p: float) -> tuple[float, object]:
        """(the pin's multiplier, Newton's result) of the steady state at parameter p with
        the amplitude held, from the current field."""
        from fem_ade.backends.fem.newton import NewtonError, linearize, solve_steady

        self.state.set_parameter(self.param, p)
        t0, made = time.perf_counter(), len(self.system.gmres_iterations)
        res = solve_steady(self.state, system=self.system)
        if not res.converged:
            raise NewtonError(f"Newton at {self.param} = {p:.8g}: {res.message}")
        lam = float(linearize(self.system, self.state.phi).lam[3])
        if not self.quiet:  # a point takes minutes: each solve's progress
            print(f"    {self.param} = {p:.8f}: pin's multiplier {lam:.3e}, Newton "
                  f"{res.iterations}, GMRES {self.system.gmres_iterations[made:]}, "
                  f"{time.perf_counter() - t0:.0f} s", flush=True)
        return lam, res

    def _predict(self, a: float) -> tuple[float, float]:
        """Set the field to the predictor of amplitude ``a``; the secant's two parameters."""
        pts = self.points
        if len(pts) < 2:
            phi = self.state.space.from_modes({0: self.be.phi})
            self.state.phi = phi + a * self.P - self.amplitude(phi) * self.P
            if not pts:
                return self.p0, self.p0 + FIRST_STEP
            prev = pts[-1]  # p − p_b ∝ a² near the birth
            guess = self.p0 + (prev[self.param] - self.p0) * (a / prev["amplitude"]) ** 2
            return guess, guess + 0.1 * (guess - prev[self.param])
        (a1, p1, f1), (a2, p2, f2) = [(x["amplitude"], x[self.param], f) for x, f in
                                      zip(pts[-2:], self._fields[-2:], strict=True)]
        s = (a - a2) / (a2 - a1)
        n = self.state.space.n_theta
        modes = _pad(f2, n) + s * (_pad(f2, n) - _pad(f1, n))
        self.state.phi = self.state.space.from_modes({j: modes[j] for j in range(n)})
        self.state.phi += (a - self.amplitude(self.state.phi)) * self.P
        guess = p2 + s * (p2 - p1)
        return guess, guess + 0.05 * (p2 - p1)

    def point(self, a: float) -> dict:
        """The branch's point at amplitude ``a`` (n_θ doubled as :data:`TAIL` says)."""
        t0, c0 = time.perf_counter(), time.process_time()
        while True:
            x0, x1 = self._predict(a)
            start = self.state.phi.copy()
            f0, _ = self.solve_at(x0)
            f1, res = self.solve_at(x1)
            steps = 2
            while abs(x1 - x0) > P_TOL and steps < SECANT_STEPS and f1 != f0:
                x2 = x1 - f1 * (x1 - x0) / (f1 - f0)
                f2, res = self.solve_at(x2)
                x0, f0, x1, f1 = x1, f1, x2, f2
                steps += 1
            modes = self.state.space.modes(self.state.phi)
            tail = float(np.abs(modes[-1]).max() / np.abs(modes[1]).max())
            if tail <= TAIL:
                break
            n = 2 * self.state.space.n_theta
            self._resize(n, self.state.space.modes(start))
            if not self.quiet:
                print(f"  amplitude {a:g}: top cosine {tail:.1e} of the first, n_theta {n}",
                      flush=True)
        return self._record(a, x1, f1, res, modes, tail, steps, t0, c0)

    def _record(self, a, x, lam, res, modes, tail, steps, t0, c0) -> dict:
        from fem_ade.analysis.sharp import reduced_energy

        st = self.state
        mu = st.space.laplacian(st.phi)
        d = st.stepper.diagnostics(st.phi, mu, st.space.weights * mu)
        row = {"amplitude": a, self.param: x, "e": reduced_energy(d, st.params.kappa),
               "E": d["E"], "W": d["W"], "G": d.get("G", 0.0), "V": d["V"], "A": d["A"],
               "lam_pin": lam, "n_theta": st.space.n_theta, "tail": tail,
               "cosines": [float(np.abs(x).max()) for x in modes[:6]],
               "solves": steps, "newton_last": res.iterations,
               "gmres_last": int(sum(self.system.gmres_iterations[-res.iterations - 1:])),
               "seconds": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}
        self.points.append(row)
        self._fields.append(modes)
        if not self.quiet:
            print(f"  amplitude {a:g}: {self.param} = {x:.8f}, e = {row['e']:.8f}, "
                  f"n_theta {row['n_theta']}, {row['seconds']:.0f} s", flush=True)
        return row


def _pad(modes: np.ndarray, n: int) -> np.ndarray:
    """The cosines to n rows (zeros added or the highest dropped)."""
    out = np.zeros((n, modes.shape[1]))
    k = min(n, modes.shape[0])
    out[:k] = modes[:k]
    return out


def follow(be, psi, amplitudes, out: Path, *, m0: int, param: str = "da0",
           n_theta: int = 4, p_birth: float | None = None, quiet: bool = True) -> list[dict]:
    """The branch's points at ``amplitudes`` (increasing), each kept in ``out`` as
    ``NNNN.json`` with its cosines in ``NNNN.npz``; a point already there is read back (with
    its field, so the next predictor is the same), so a stopped run goes on."""
    amplitudes = [float(a) for a in amplitudes]
    if not amplitudes or any(not math.isfinite(a) or a <= 0 for a in amplitudes) or \
            any(b <= a for a, b in zip(amplitudes, amplitudes[1:], strict=False)):
        raise ModelError(f"amplitudes are positive and increasing, got {amplitudes}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    branch = AmplitudeBranch(be, psi, m0=m0, param=param, n_theta=n_theta, p_birth=p_birth,
                             quiet=quiet)
    for k, a in enumerate(amplitudes):
        done, field = out / f"{k:04d}.json", out / f"{k:04d}.npz"
        if done.is_file() and field.is_file():
            row = json.loads(done.read_text())
            with np.load(field) as z:
                modes = np.array(z["cosines"])
            if modes.shape[0] != branch.state.space.n_theta:
                branch._resize(modes.shape[0], modes)
            branch.points.append(row)
            branch._fields.append(modes)
            continue
        row = branch.point(a)
        np.savez_compressed(field.with_suffix(".tmp.npz"), cosines=branch._fields[-1])
        field.with_suffix(".tmp.npz").replace(field)
        write_json_atomic(done, row, indent=1)
    return branch.points
