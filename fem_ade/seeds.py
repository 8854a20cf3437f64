"""Seeded initial conditions: each paper scene started from the shape its figure shows.

``--ic seeded`` starts a catalogue scene from its paper shape (:data:`FAMILIES`: a torus for
``torus``, beads for the gourds and the chain, a starfish for the armed scenes, ...), built
from the kinds of :mod:`fem_ade.initial` with two free sizes. The sizes are chosen so that the
*diffuse* V and A of φ₀ = tanh(s/(√2ε)), measured on the scene's grid by the spectral
reference, equal α and β (:func:`size`): a shape sized by its sharp formulas has the wrong
diffuse values at these interface widths, e.g. a torus by 2π²Rr² = α, 4π²Rr = β has a hole of
half an ε and closes at once. The sizes found are stored in the catalogue
(:data:`fem_ade.scenes.SEEDS`); ``python -m fem_ade.seeds`` recomputes them and
``tests/test_seeds.py`` checks them.
"""

from __future__ import annotations

import sys

import numpy as np

from .initial import Capsule, Discocyte, Spheres, Starfish, Torus

C3 = (0.5, 0.5, 0.5)


def _beads(k: int):
    """k equal beads of radius R along z, centres s apart: (R, s) -> Spheres."""
    def make(R, s):
        zs = [(i - (k - 1) / 2) * s for i in range(k)]
        return Spheres(tuple((0.5, 0.5, 0.5 + z) for z in zs), (R,) * k)
    return make


def _star(k: int, plane: bool = True):
    """k arms of radius r reaching out to ℓ around a core of radius 1.6 r: (ℓ, r)."""
    return lambda ell, r: Starfish(C3, k, ell, r, 1.6 * r, plane)


#: scene -> (what the paper shows, the family (two sizes -> shape), a first guess of the sizes)
FAMILIES = {
    "discocyte": ("a red-cell discocyte", lambda d, t: Discocyte(
        C3, d, c0=0.0518 * t, c2=2.0026 * t, c4=-4.491 * t), (0.5, 1.0)),
    "torus": ("a torus", lambda R, r: Torus(C3, R, r), (0.2, 0.12)),
    "biconcave": ("a biconcave disc", lambda d, t: Discocyte(
        C3, d, c0=0.0518 * t, c2=2.0026 * t, c4=-4.491 * t), (0.3, 1.0)),
    "gourd-early": ("a gourd (two lobes, a wide neck)", _beads(2), (0.1, 0.12)),
    "gourd-elongated": ("an elongated gourd", _beads(2), (0.1, 0.15)),
    "gourd": ("a gourd", _beads(2), (0.1, 0.15)),
    "cylinder": ("a cylinder with round ends",
                 lambda ell, r: Capsule(C3, (0.0, 0.0, 1.0), ell, r), (0.3, 0.07)),
    "two-spheres": ("two connected spheres", _beads(2), (0.1, 0.17)),
    "chain": ("a chain of three beads", _beads(3), (0.08, 0.13)),
    "three-arm": ("a three-armed starfish", _star(3), (0.3, 0.08)),
    "four-arm": ("a four-armed starfish", _star(4), (0.25, 0.05)),
    "six-arm": ("a six-armed starfish", _star(6), (0.3, 0.07)),
    "nested": ("a vesicle inside a vesicle",
               lambda R1, R2: Spheres(((1.0, 1.0, 1.0),) * 2, (R1, R2), (1, -1)), (0.6, 0.4)),
}


def diffuse_values(scene, shape, n: int | None = None) -> dict:
    """The diagnostics (V, A, ...) of φ₀ = tanh(s/(√2ε)) for ``shape`` on the scene's grid,
    measured by the spectral reference."""
    from .backend import make_backend

    return make_backend("spectral", scene.with_(ic=shape), n=n or scene.n).diagnostics()


def size(scene, family, guess, n: int | None = None, tol: float = 2e-4):
    """(sizes, shape) with diffuse V = α and A = β (relative ``tol``): a 2D Newton search
    on the logarithms of the sizes, from ``guess``."""
    from scipy.optimize import root

    p = scene.params

    def residual(x):
        d = diffuse_values(scene, family(*np.exp(x)), n)
        return [d["V"] / p.alpha - 1.0, d["A"] / p.beta - 1.0]

    sol = root(residual, np.log(guess), method="hybr", options={"xtol": 1e-10})
    res = residual(sol.x)
    if max(abs(r) for r in res) > tol:
        raise RuntimeError(f"{scene.name}: no sizes with diffuse V = alpha, A = beta near "
                           f"{guess} (residual {res})")
    sizes = tuple(float(v) for v in np.exp(sol.x))
    return sizes, family(*sizes)


def main(argv=None) -> dict:
    """Recompute the sizes of every seeded scene and print them (the catalogue's SEEDS)."""
    from .scenes import PAPER_SCENES

    out = {}
    for name, (what, family, guess) in FAMILIES.items():
        scene = PAPER_SCENES[name]
        sizes, shape = size(scene, family, guess)
        d = diffuse_values(scene, shape)
        out[name] = sizes
        print(f"    {name!r}: ({sizes[0]:.6f}, {sizes[1]:.6f}),  # {what}: V/alpha "
              f"{d['V'] / scene.params.alpha:.5f}, A/beta {d['A'] / scene.params.beta:.5f}, "
              f"eps {scene.params.eps}", flush=True)
    return out


if __name__ == "__main__":
    sys.exit(main() and 0)
