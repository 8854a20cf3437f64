"""The sizes of the seeded initial conditions (:mod:`fem_ade.scenes.seeds`): found by a 2D Newton
search so that the diffuse V and A of each paper shape, measured by the spectral reference
on the scene's grid, are the scene's α and β.

    python -m fem_ade.campaigns.seed_sizes [SCENE ...]     # print the sizes (the catalogue's SIZES)
"""

from __future__ import annotations

import sys

import numpy as np

from fem_ade.backends.base import make_backend
from fem_ade.scenes.catalogue import PAPER_SCENES
from fem_ade.scenes.seeds import FAMILIES


def diffuse_values(scene, shape, n: int | None = None) -> dict:
    """The diagnostics (V, A, ...) of φ₀ = tanh(s/(√2ε)) for ``shape`` on the scene's grid,
    measured by the spectral reference."""
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
    """Recompute the sizes of every seeded scene and print them (the catalogue's SIZES)."""
    out = {}
    names = argv or list(FAMILIES)
    for name in names:
        what, family, guess = FAMILIES[name]
        scene = PAPER_SCENES[name]
        try:
            sizes, shape = size(scene, family, guess)
        except RuntimeError as err:
            print(f"    # {err}", flush=True)
            continue
        d = diffuse_values(scene, shape)
        out[name] = sizes
        print(f"    {name!r}: ({sizes[0]:.6f}, {sizes[1]:.6f}),  # {what}: V/alpha "
              f"{d['V'] / scene.params.alpha:.5f}, A/beta {d['A'] / scene.params.beta:.5f}, "
              f"eps {scene.params.eps}", flush=True)
    return out


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]) and 0)
