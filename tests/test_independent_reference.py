"""An independent, naive implementation of model §2-§4, §6, §7, compared with the CLI.

Written straight from the formulas of docs/model.md, without reading or importing the
physics code of ``fem_ade`` or ``spectral_ref``: the package is used only as a black box through
``python -m fem_ade.run``. Deliberately naive: full complex FFTs (``numpy.fft.fftn/ifftn``), every
Laplacian computed by its own transform, no reuse of spectra between terms.
"""

from __future__ import annotations

import csv
import subprocess
import sys

import numpy as np

SQ2 = np.sqrt(2.0)


class NaiveADE:
    """model §2 energy, §3 variational derivatives, §4 semi-implicit step, §6 conventions."""

    def __init__(self, n, L, eps, dt, alpha, beta, dA0, kappa=1.0, kbar=1.4, M1=1e5, M2=1e4,
                 C=0.0, D=None, A0=None):
        self.n, self.L, self.eps, self.dt = n, L, eps, dt
        self.alpha, self.beta, self.dA0 = alpha, beta, dA0
        self.kappa, self.kbar, self.M1, self.M2, self.C = kappa, kbar, M1, M2, C
        self.D = 2.0 * eps / 3.0 if D is None else D
        self.A0 = beta if A0 is None else A0
        self.h = L / n
        k1 = 2.0 * np.pi * np.fft.fftfreq(n, d=L / n)  # Nyquist included (as -n/2)
        kx, ky, kz = np.meshgrid(k1, k1, k1, indexing="ij")
        self.k2 = kx**2 + ky**2 + kz**2  # Laplacian symbol is -|k|^2
        # implicit operator of §4: 1 + dt*kappa*(eps|k|^4 - (2/eps)|k|^2)
        self.op = 1.0 + dt * kappa * (eps * self.k2**2 - (2.0 / eps) * self.k2)
        assert self.op.min() > 0.0

    # --- discrete calculus (§6) -------------------------------------------------------------
    def lap(self, u):
        return np.real(np.fft.ifftn(-self.k2 * np.fft.fftn(u)))

    def integ(self, u):
        return self.h**3 * np.sum(u)

    # --- energy (§2) ------------------------------------------------------------------------
    def quantities(self, phi):
        eps, C, D = self.eps, self.C, self.D
        lphi = self.lap(phi)
        fc = eps * lphi - (1.0 / eps) * (phi**2 - 1.0) * (phi + C * eps)
        W = self.kappa / (2.0 * eps) * self.integ(fc**2)
        V = self.integ((phi + 1.0) / 2.0)
        # ∫|∇φ|² computed as −∫ φ Δφ: exact (summation by parts / Parseval) for a spectral
        # Laplacian, so it does not depend on how the Nyquist mode of a first derivative is
        # treated (which differs between conventions for the spectral gradient).
        grad2 = -self.integ(phi * lphi)
        B = (eps / 2.0) * grad2 + (1.0 / (4.0 * eps)) * self.integ((phi**2 - 1.0) ** 2)
        A = 3.0 * SQ2 / 4.0 * B
        dA = -(3.0 * D / 4.0) * self.integ(
            (1.0 - phi**2) * lphi + (1.0 / eps**2) * phi * (1.0 - phi**2) ** 2
        )
        G = self.kbar * np.pi / (2.0 * self.A0 * D**2) * (dA - self.dA0) ** 2
        T1 = self.M1 * (V - self.alpha) ** 2
        T2 = self.M2 * (A - self.beta) ** 2
        E = W + G + T1 + T2
        return dict(E=E, W=W, G=G, V=V, A=A, dA=dA)

    # --- one step of §4 ---------------------------------------------------------------------
    def step(self, phi):
        eps, C, D, kappa = self.eps, self.C, self.D, self.kappa
        q = self.quantities(phi)
        lphi = self.lap(phi)
        lphi2 = self.lap(phi**2)
        lphi3 = self.lap(phi**3)
        N = (
            -(1.0 / eps) * lphi3
            - C * lphi2
            - (3.0 / eps) * phi**2 * lphi
            - 2.0 * C * phi * lphi
            + (1.0 / eps**3) * (3.0 * phi**2 + 2.0 * C * eps * phi - 1.0)
            * (phi**2 - 1.0) * (phi + C * eps)
        )
        hterm = -(3.0 * self.kbar * np.pi / (4.0 * self.A0 * D)) * (q["dA"] - self.dA0) * (
            -2.0 * phi * lphi - lphi2 + (1.0 / eps**2) * (1.0 - 6.0 * phi**2 + 5.0 * phi**4)
        )
        f = eps * lphi - (1.0 / eps) * (phi**2 - 1.0) * phi
        rhs = (
            -kappa * N
            - hterm
            - self.M1 * (q["V"] - self.alpha)
            + (3.0 * SQ2 / 2.0) * self.M2 * (q["A"] - self.beta) * f
        )
        new_hat = np.fft.fftn(phi + self.dt * rhs) / self.op
        return np.real(np.fft.ifftn(new_hat))

    # --- initial condition (§7) -------------------------------------------------------------
    def ellipsoid(self, c, a, b, d, centre=(0.5, 0.5, 0.5)):
        x1 = np.arange(self.n) * self.L / self.n
        x, y, z = np.meshgrid(x1, x1, x1, indexing="ij")
        qf = (x - centre[0]) ** 2 / a + (y - centre[1]) ** 2 / b + (z - centre[2]) ** 2 / d
        return np.tanh((c - qf) / (SQ2 * self.eps))


def _run_cli(scene, n, steps, every, out):
    cmd = [sys.executable, "-m", "fem_ade.run", scene, "--backend", "spectral", "--n", str(n),
           "--steps", str(steps), "--every", str(every), "--out", str(out), "--quiet",
           "--no-render"]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, f"CLI failed:\n{res.stdout}\n{res.stderr}"
    with open(out / "history.csv", newline="") as fh:
        header = fh.readline()
        assert header.startswith("step,t,E,W,G,V,A,dA"), header
        fh.seek(0)
        rows = list(csv.DictReader(fh))
    return {int(r["step"]): {k: float(v) for k, v in r.items() if k != "step"} for r in rows}


def _compare(model, phi, steps, every, cli, tol=1e-8):
    mine = {0: model.quantities(phi)}
    for s in range(1, steps + 1):
        phi = model.step(phi)
        if s % every == 0:
            mine[s] = model.quantities(phi)
    assert sorted(cli) == sorted(mine), (sorted(cli), sorted(mine))
    worst = {}
    for s in sorted(mine):
        for key in ("E", "W", "G", "V", "A", "dA"):
            rel = abs(cli[s][key] - mine[s][key]) / abs(mine[s][key])
            print(f"step {s:4d} {key:>2}: cli {cli[s][key]: .15e} mine {mine[s][key]: .15e} "
                  f"rel {rel:.2e}")
            if key in ("E", "V", "A", "dA"):
                worst[key] = max(worst.get(key, 0.0), rel)
        assert abs(cli[s]["t"] - s * model.dt) <= 1e-12 * max(1.0, s * model.dt)
    print("max relative differences:", {k: f"{v:.2e}" for k, v in worst.items()})
    for key, rel in worst.items():
        assert rel < tol, f"{key}: max relative difference {rel:.3e} >= {tol}"


def test_discocyte_matches_independent_reference(tmp_path):
    n, steps, every = 32, 100, 50
    cli = _run_cli("discocyte", n, steps, every, tmp_path / "D")
    model = NaiveADE(n=n, L=1.0, eps=0.04, dt=5e-7, alpha=0.0289, beta=0.4880, dA0=0.1090)
    phi0 = model.ellipsoid(c=0.35**2, a=0.5, b=0.5, d=0.1)
    _compare(model, phi0, steps, every, cli)


def test_torus_matches_independent_reference(tmp_path):
    n, steps, every = 40, 60, 30
    cli = _run_cli("torus", n, steps, every, tmp_path / "T")
    model = NaiveADE(n=n, L=1.0, eps=0.03, dt=2e-7, alpha=0.0652, beta=0.9092, dA0=0.2839)
    phi0 = model.ellipsoid(c=0.6, a=0.35**2, b=0.35**2, d=0.35**2)
    _compare(model, phi0, steps, every, cli)
