"""A non-axisymmetric branch born at an azimuthal bifurcation, followed on the Fourier–(r, z)
geometry (:mod:`fem_ade.backends.fem.fourier`) by its amplitude (docs/model.md §13).

At a bifurcation in mode m of an axisymmetric branch the new branch leaves along ψ_m cos mθ.
Its amplitude a = ⟨ψ cos mθ, φ⟩_W / ⟨ψ cos mθ, ψ cos mθ⟩_W is a good parameter near the
birth (the axisymmetric state has a = 0, the new branch a ≠ 0 on either side). For each a:
Newton with a pinned (:class:`fem_ade.backends.fem.fourier.FourierNewtonSystem`) gives the
state that is steady in every direction but the pin's, and ``lam`` — the pin's multiplier —
is zero on the branch only. The parameter p (Δa₀ or v) where it is zero is an unknown of
the Newton system (:meth:`AmplitudeBranch.solve_free`): the bordered system's multiplier of
the pin is replaced by p, so a Newton step is the bordered solve for two right sides — the
residual and ∂_p of it — combined so that the pin's multiplier vanishes (one factorization
of the modes' blocks, two GMRES solves). That Newton takes no line search (the system is
not a minimization once p moves), so each point first takes the pinned Newton at the
predicted p (:meth:`AmplitudeBranch.solve_at`, with its line search) and the bordered one
from there; where that fails the secant on the multiplier takes over, each of its solves a
pinned Newton. The first two amplitudes start from the (r, z) state plus a ψ cos mθ, the
third from the line through the last two points (φ and p), later ones from the parabola
through the last three, φ's taken in artanh φ (:func:`_extrapolate`).

n_θ is doubled (the field carried over by its cosines) while the highest cosine's largest
value exceeds :data:`TAIL` of the first's (up to :data:`MAX_N_THETA`): the angles resolve
the shape. Where the amplitude
stops serving as the parameter, the branch goes on with p held and the amplitude free
(:meth:`AmplitudeBranch.point_held`: the stable part of a branch, up to a fold in p).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from fem_ade.model.params import ModelError
from fem_ade.store.output import write_json_atomic

#: n_θ is doubled while max |a_{n_θ−1}| > TAIL · max |a₁|, up to MAX_N_THETA (a point
#: there keeps its tail in its row: measured, n_θ = 32 on the triaxial branch's 42,657 (r, z)
#: nodes outgrew 24 GB, n_θ = 16 peaked at 19 GB)
TAIL, MAX_N_THETA = 1e-3, 16
#: the secant stops when p moves less than this, or after SECANT_STEPS solves (the pin's
#: multiplier is steady to ~2e-5 on the window's branch, where it changes by ~20 per unit
#: of Δa₀: p to ~1e-6)
P_TOL, SECANT_STEPS = 1e-6, 10
#: the bordered Newton with the parameter as an unknown: its most steps (then the secant
#: takes over), and the relative step of the central difference ∂/∂p
NEWTON_STEPS, PARAMETER_STEP = 12, 1e-4
#: how a point's parameter is found: ``bordered`` (an unknown of Newton's system; the
#: secant where that fails) or ``secant`` (on the pin's multiplier alone)
METHODS = ("bordered", "secant")
#: the predictor's ψ = artanh φ is taken of φ clipped to |φ| ≤ CLIP
CLIP = 1.0 - 1e-9
#: the secant's second parameter at the first amplitude: this far from the first
FIRST_STEP = 1e-3


class AmplitudeBranch:
    """The branch of fold ``m0`` born from the axisymmetric backend ``be`` along ``psi`` (its
    block's eigenvector on the (r, z) nodes), in the parameter ``param``."""

    def __init__(self, be, psi: np.ndarray, *, m0: int, param: str = "da0",
                 n_theta: int = 4, p_birth: float | None = None, quiet: bool = True,
                 method: str = "bordered"):
        from fem_ade.backends.fem.fourier import FourierState
        from fem_ade.scenes.vesicle import get_parameter

        if method not in METHODS:
            raise ModelError(f"method is one of {', '.join(METHODS)}, got {method!r}")
        self.be, self.psi, self.m0, self.param, self.quiet = be, psi, m0, param, quiet
        self.method = method
        # where the branch is born (the first secant's start; default: be's parameter)
        self.p0 = get_parameter(be.stepper.params, param) if p_birth is None else p_birth
        self.birth_known = p_birth is not None
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
        res = solve_steady(self.state, system=self.system, quiet=self.quiet)
        if not res.converged:
            raise NewtonError(f"Newton at {self.param} = {p:.8g}: {res.message}")
        lam = float(linearize(self.system, self.state.phi).lam[3])
        if not self.quiet:  # a point takes minutes: each solve's progress
            print(f"    {self.param} = {p:.8f}: pin's multiplier {lam:.3e}, Newton "
                  f"{res.iterations}, GMRES {self.system.gmres_iterations[made:]}, "
                  f"{time.perf_counter() - t0:.0f} s", flush=True)
        return lam, res

    def solve_free(self, p: float, *, tol: float = 1e-12,
                   max_iterations: int = NEWTON_STEPS):
        """(p, the pin's multiplier, Newton's result): the steady state at the held amplitude
        with the parameter an unknown of Newton's system, from the current field and ``p``
        (module docstring).
        Raises :class:`fem_ade.backends.fem.newton.NewtonError` where it does not converge
        (the caller then takes the secant)."""
        from fem_ade.backends.fem.newton import NewtonError, NewtonResult, linearize
        from fem_ade.backends.fem.solve import global_dot

        sys_, st, t0 = self.system, self.state, time.perf_counter()
        made = len(sys_.gmres_iterations)
        st.set_parameter(self.param, p)
        phi = sys_.restore(st.phi.copy())
        if phi is None:
            raise NewtonError("the predictor is too far from V = alpha, A = beta")
        res = NewtonResult(False, 0, math.nan, math.nan, math.nan)
        for it in range(max_iterations + 1):
            lin = linearize(sys_, phi)
            solver = sys_.factor(lin)
            x1, y1 = solver.solve(-lin.grad, -lin.violation)
            x2, y2 = self._column_solve(solver, lin)
            dp = -(lin.lam[3] + y1[3]) / y2[3]  # the pin's multiplier to zero
            dphi = x1 + dp * x2
            decrement = abs(global_dot(lin.grad, dphi)) / max(abs(lin.E), 1e-300)
            res.decrement.append(decrement)
            res.E = lin.E
            lam = float(lin.lam[3])
            if decrement <= tol and abs(dp) <= tol ** 0.75:
                res.converged = True
                break
            if it == max_iterations or not math.isfinite(dp):
                break
            p += dp
            st.set_parameter(self.param, p)
            phi = sys_.restore(phi + dphi)
            if phi is None:
                raise NewtonError(f"V and A not restored after step {it} at {self.param} "
                                  f"= {p:.8g}")
            res.iterations = it + 1
        if not res.converged:
            raise NewtonError(f"the bordered Newton in {self.param} did not converge in "
                              f"{res.iterations} steps (decrements {res.decrement})")
        st._set(phi)
        res.krylov = sys_.gmres_iterations[made:]
        res.seconds = time.perf_counter() - t0
        if not self.quiet:
            print(f"    {self.param} = {p:.10f} (an unknown): Newton {res.iterations}, "
                  f"GMRES {res.krylov}, {res.seconds:.0f} s", flush=True)
        return p, lam, res

    def _column_solve(self, solver, lin) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) with the bordered system [x; y] = −∂_p(∇E + Cλ, the constraints' values).
        A part in the constraints' rows (v moves α) is first met by d₀ = P⁻¹C(CᵀP⁻¹C)⁻¹ ∂_p c,
        leaving GMRES a right side in the top rows: on the constraints' rows alone it
        stagnated (measured: 2.5e-3 after 660 iterations, the v column at ε = 0.04)."""
        from fem_ade.backends.fem.newton import lagrangian_hessian_vector

        gp, vp = self._parameter_column(lin)
        if not np.any(vp):
            return solver.solve(-gp, -vp)
        PC, G = self.system.constraint_block(lin.C)
        d0 = np.column_stack(PC) @ np.linalg.solve(G, vp)
        x, y = solver.solve(lagrangian_hessian_vector(self.system.step, lin, d0) - gp,
                            np.zeros_like(vp))
        return x - d0, y

    def _parameter_column(self, lin) -> tuple[np.ndarray, np.ndarray]:
        """∂/∂p of (∇E + Cλ, the constraints' values) at fixed φ and λ: a central difference,
        exact up to rounding (∇E is linear in Δa₀, the values in α, β)."""
        from fem_ade.scenes.vesicle import get_parameter

        sys_, st = self.system, self.state
        p = get_parameter(st.params, self.param)
        h = PARAMETER_STEP * max(1.0, abs(p))
        out = []
        for q in (p + h, p - h):
            st.set_parameter(self.param, q)
            out.append((sys_.gradient(lin.phi, lin.mu, lin.Kphi),
                        sys_.constraint_values(lin.phi, lin.Kphi)))
        st.set_parameter(self.param, p)
        return ((out[0][0] - out[1][0]) / (2 * h), (out[0][1] - out[1][1]) / (2 * h))

    def _predict(self, a: float, plain: bool = False) -> tuple[float, float]:
        """Set the field to the predictor of amplitude ``a``; the secant's two parameters.
        ``plain``: the line through the last two points, φ blended (the fallback)."""
        pts = self.points
        if len(pts) < 2:
            phi = self.state.space.from_modes({0: self.be.phi})
            self.state.phi = phi + a * self.P - self.amplitude(phi) * self.P
            if not pts:
                return self.p0, self.p0 + FIRST_STEP
            prev = pts[-1]  # p − p_b ∝ a² near the birth, where the birth is known
            guess = prev[self.param] if not self.birth_known else \
                self.p0 + (prev[self.param] - self.p0) * (a / prev["amplitude"]) ** 2
            return guess, guess + (0.1 * (guess - prev[self.param]) if self.birth_known
                                   else FIRST_STEP)
        k = 2 if plain else min(len(pts), 3)  # the line through two points, the parabola
        c = _lagrange([x["amplitude"] for x in pts[-k:]], a)
        self.state.phi = self._extrapolated(c, plain)
        self.state.phi += (a - self.amplitude(self.state.phi)) * self.P
        p = [x[self.param] for x in pts[-k:]]
        guess = float(np.dot(c, p))
        return guess, guess + 0.05 * (p[-1] - p[-2])

    def _extrapolated(self, c: np.ndarray, plain: bool = False) -> np.ndarray:
        """Σ cᵢ φᵢ over the last len(c) points' fields on the current n_θ, taken in artanh φ
        (:func:`_extrapolate`), or blended in φ with ``plain``."""
        space, n = self.state.space, self.state.space.n_theta
        fields = [space.from_modes(dict(enumerate(_pad(f, n))))
                  for f in self._fields[-len(c):]]
        return c @ np.array(fields) if plain else _extrapolate(fields, c)

    def _resolved(self) -> tuple[np.ndarray, float, bool]:
        """(the field's cosines, the top one's largest value over the first's, whether the
        angles resolve it: the tail within :data:`TAIL`, or n_θ at :data:`MAX_N_THETA`)."""
        modes = self.state.space.modes(self.state.phi)
        tail = float(np.abs(modes[-1]).max() / np.abs(modes[1]).max())
        return modes, tail, tail <= TAIL or self.state.space.n_theta >= MAX_N_THETA

    def point(self, a: float) -> dict:
        """The branch's point at amplitude ``a`` (n_θ doubled as :data:`TAIL` says)."""
        t0, c0 = time.perf_counter(), time.process_time()
        carried = None  # after n_θ is doubled: the parameters to start from
        while True:
            x0, x1 = self._predict(a) if carried is None else carried
            try:
                f0, _ = self.solve_at(x0)  # onto the pinned states, with the line search
            except ArithmeticError as err:  # seen once: GMRES stalled at the prolate's a = 0.4
                if len(self.points) < 2:
                    raise
                if not self.quiet:
                    print(f"    {err}: from the line through the last two points", flush=True)
                x0, x1 = self._predict(a, plain=True)
                f0, _ = self.solve_at(x0)
            pinned, used = self.state.phi.copy(), "secant"
            if self.method == "bordered":
                try:
                    x1, f1, res = self.solve_free(x0)
                    steps, used = 2, "bordered"
                except ArithmeticError as err:  # NewtonError, or GMRES short of its tolerance
                    if not self.quiet:
                        print(f"    {err}: the secant instead", flush=True)
                    self.state.phi = pinned
            if used == "secant":
                x1, f1, res, steps = self._secant(x0, x1, f0)
            modes, tail, resolved = self._resolved()
            if resolved:
                break
            n = 2 * self.state.space.n_theta
            # from the point found on n_θ angles, not the predictor again: at the triaxial
            # branch's a = 1.3 (n_θ 8 → 16) the predictor's E was 41.778, the point's 40.914
            self._resize(n, modes)
            spacing = x1 - x0
            carried = (x1, x1 + 0.05 * spacing if spacing else x1 + FIRST_STEP)
            if not self.quiet:
                print(f"  amplitude {a:g}: top cosine {tail:.1e} of the first, n_theta {n}",
                      flush=True)
        return self._record(a, x1, f1, res, modes, tail, (used, steps), t0, c0)

    def point_held(self, p: float) -> dict:
        """The branch's point at the parameter ``p`` held and the amplitude free (the point's
        amplitude is then its field's): natural continuation, for where the amplitude stops
        serving as the branch's parameter (the first cosine saturates as the interface
        reaches φ's range: 0.85, 1.01, 1.12, 1.20 on the triaxial branch at a = 1.0 … 1.9,
        while Δa₀ rose ever faster). The start: the polynomial in p through the last three
        points (their fields in artanh φ, :func:`_extrapolate`); then Newton with its line
        search on the system without the amplitude's pin, which finds the branch's state
        where that is a minimum in the sector (a stable part of the branch), n_θ doubled as
        in :meth:`point`. A fold in p ahead is not passed: Newton then ends elsewhere (the
        amplitude says where), or fails (:class:`fem_ade.backends.fem.newton.NewtonError`)."""
        from fem_ade.backends.fem.fourier import FourierNewtonSystem
        from fem_ade.backends.fem.newton import NewtonError, solve_steady

        t0, c0 = time.perf_counter(), time.process_time()
        pts = self.points
        if len(pts) < 3:
            raise ModelError(f"a point at {self.param} held needs three points before it, "
                             f"got {len(pts)}")
        self.state.phi = self._extrapolated(_lagrange([x[self.param] for x in pts[-3:]], p))
        self.system.galerkin = None  # the pinned system's coarse step: GBs at n_θ = 16
        while True:
            self.state.set_parameter(self.param, p)
            res = solve_steady(self.state, system=FourierNewtonSystem(self.state),
                               quiet=self.quiet)
            if not res.converged:
                raise NewtonError(f"Newton at {self.param} = {p:.8g} held: {res.message}")
            modes, tail, resolved = self._resolved()
            if resolved:
                break
            self._resize(2 * self.state.space.n_theta, modes)
            if not self.quiet:
                print(f"  {self.param} = {p:g}: top cosine {tail:.1e} of the first, n_theta "
                      f"{self.state.space.n_theta}", flush=True)
        return self._record(self.amplitude(self.state.phi), p, None, res, modes, tail,
                            ("held", res.iterations), t0, c0)

    def _secant(self, x0: float, x1: float, f0: float):
        """The secant on the pin's multiplier from parameters x0 (its multiplier f0, the
        state steady there) and x1: (p, multiplier, Newton's last result, solves)."""
        f1, res = self.solve_at(x1)
        steps = 2  # at least one secant step: the two starts may lie within P_TOL
        while (steps == 2 or abs(x1 - x0) > P_TOL) and steps < SECANT_STEPS and f1 != f0:
            x2 = x1 - f1 * (x1 - x0) / (f1 - f0)
            f2, res = self.solve_at(x2)
            x0, f0, x1, f1 = x1, f1, x2, f2
            steps += 1
        return x1, f1, res, steps

    def _record(self, a, x, lam, res, modes, tail, solves, t0, c0) -> dict:
        from fem_ade.analysis.sharp import reduced_energy

        st = self.state
        mu = st.space.laplacian(st.phi)
        d = st.stepper.diagnostics(st.phi, mu, st.space.weights * mu)
        row = {"amplitude": a, self.param: x, "e": reduced_energy(d, st.params.kappa),
               "E": d["E"], "W": d["W"], "G": d.get("G", 0.0), "V": d["V"], "A": d["A"],
               "lam_pin": lam, "n_theta": st.space.n_theta, "tail": tail,
               "cosines": [float(np.abs(x).max()) for x in modes[:6]],
               "method": solves[0], "solves": solves[1], "newton_last": res.iterations,
               "gmres_last": int(sum(res.krylov)),
               "seconds": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}
        self.points.append(row)
        self._fields.append(modes)
        if not self.quiet:
            print(f"  amplitude {a:g}: {self.param} = {x:.8f}, e = {row['e']:.8f}, "
                  f"n_theta {row['n_theta']}, {row['seconds']:.0f} s", flush=True)
        return row


def _extrapolate(fields: list[np.ndarray], weights: np.ndarray) -> np.ndarray:
    """Σ wᵢ φᵢ taken in ψ = artanh φ, where an interface that moves is a shift, not a blend
    of two profiles: tanh(Σ wᵢ ψᵢ) + Σ wᵢ (φᵢ − φᵢ clipped to |φ| < 1) (the last term keeps
    the fields exactly at their own points). Measured on the triaxial branch (ε = 0.01,
    n_θ = 8), a = 1.0 from 0.4, 0.7 (the line) and 0.2, 0.4, 0.7 (the parabola), after V and
    A are restored: E 40.968 and 40.9026 against the point's 40.9009; blended in φ, 52.70
    and 47.26 (Newton then took 10 iterations)."""
    inside = [np.clip(f, -CLIP, CLIP) for f in fields]
    psi = sum(w * np.arctanh(f) for w, f in zip(weights, inside, strict=True))
    rest = sum(w * (f - g) for w, f, g in zip(weights, fields, inside, strict=True))
    return np.tanh(psi) + rest


def _lagrange(nodes: list[float], x: float) -> np.ndarray:
    """The weights of the polynomial through ``nodes`` evaluated at ``x`` (Lagrange)."""
    w = np.ones(len(nodes))
    for i, xi in enumerate(nodes):
        for j, xj in enumerate(nodes):
            if i != j:
                w[i] *= (x - xj) / (xi - xj)
    return w


def _pad(modes: np.ndarray, n: int) -> np.ndarray:
    """The cosines to n rows (zeros added or the highest dropped)."""
    out = np.zeros((n, modes.shape[1]))
    k = min(n, modes.shape[0])
    out[:k] = modes[:k]
    return out


def follow(be, psi, amplitudes, out: Path, *, m0: int, param: str = "da0",
           n_theta: int = 4, p_birth: float | None = None, quiet: bool = True,
           method: str = "bordered", held=()) -> list[dict]:
    """The branch's points at ``amplitudes`` (increasing), then at the parameter values
    ``held`` (monotone, the amplitude free: :meth:`AmplitudeBranch.point_held`), each kept in
    ``out`` as ``NNNN.json`` with its cosines in ``NNNN.npz``; a point already there is read
    back (with its field, so the next predictor is the same), so a stopped run goes on."""
    amplitudes, held = [float(a) for a in amplitudes], [float(p) for p in held]
    if not amplitudes or any(not math.isfinite(a) or a <= 0 for a in amplitudes) or \
            any(b <= a for a, b in zip(amplitudes, amplitudes[1:], strict=False)):
        raise ModelError(f"amplitudes are positive and increasing, got {amplitudes}")
    steps = np.diff(held)
    if not all(math.isfinite(p) for p in held) or (
            steps.size and not (np.all(steps > 0) or np.all(steps < 0))):
        raise ModelError(f"the held {param} values are monotone, got {held}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    branch = AmplitudeBranch(be, psi, m0=m0, param=param, n_theta=n_theta, p_birth=p_birth,
                             quiet=quiet, method=method)
    for k, a in enumerate([*amplitudes, *held]):
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
        row = branch.point(a) if k < len(amplitudes) else branch.point_held(a)
        np.savez_compressed(field.with_suffix(".tmp.npz"), cosines=branch._fields[-1])
        field.with_suffix(".tmp.npz").replace(field)
        write_json_atomic(done, row, indent=1)
    return branch.points
