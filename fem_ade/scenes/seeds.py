"""Seeded initial conditions: each paper scene started from the shape its figure shows.

``--ic seeded`` starts a catalogue scene from its paper shape (:data:`FAMILIES`: a torus for
``torus``, beads for the gourds and the chain, a starfish for the armed scenes, ...), built
from the kinds of :mod:`fem_ade.scenes.initial` with two free sizes. The sizes are chosen so that
the
*diffuse* V and A of φ₀ = tanh(s/(√2ε)), measured on the scene's grid by the spectral
reference, equal α and β (:func:`size`): a shape sized by its sharp formulas has the wrong
diffuse values at these interface widths, e.g. a torus by 2π²Rr² = α, 4π²Rr = β has a hole of
half an ε and closes at once. The sizes found are stored here (:data:`SIZES`);
``python -m fem_ade.campaigns.seed_sizes`` recomputes them (:mod:`fem_ade.campaigns.seed_sizes`,
which runs the
spectral backend: this module, a catalogue the scenes read, imports no backend) and
``tests/test_seeds.py`` checks them.

Five scenes have no seed: at ε = 0.05 (``biconcave``, the gourds, ``cylinder``) no disc, pair
of beads or capsule with equilibrium profiles has both: with diffuse V = α its diffuse area is
at most 0.55–0.64 β (scanned on their families at n = 48), because the interface, 0.4 of the
radius, carries most of the diffuse volume (model §7).
"""

from __future__ import annotations

from fem_ade.scenes.initial import Capsule, Discocyte, Spheres, Starfish, Torus

C3 = (0.5, 0.5, 0.5)


def _beads(k: int, neck: float = 0.0):
    """k equal beads of radius R along z, centres s apart (joined by tubes of radius
    neck·R): (R, s) -> Spheres."""
    def make(R, s):
        zs = [(i - (k - 1) / 2) * s for i in range(k)]
        return Spheres(tuple((0.5, 0.5, 0.5 + z) for z in zs), (R,) * k, neck=neck)
    return make


def _star(k: int, plane: bool = True):
    """k arms of radius r reaching out to ℓ around a core of radius 1.6 r: (ℓ, r)."""
    return lambda ell, r: Starfish(C3, k, ell, r, 1.6 * r, plane)


#: scene -> (what the paper shows, the family (two sizes -> shape), a first guess of the sizes)
FAMILIES = {
    "discocyte": ("a biconcave disc", lambda d, c0: Discocyte(C3, d, c0=c0, c2=2 * c0, c4=0.0),
                  (0.42, 0.33)),
    "torus": ("a torus", lambda R, r: Torus(C3, R, r), (0.2, 0.12)),
    "biconcave": ("a biconcave disc", lambda d, c0: Discocyte(C3, d, c0=c0, c2=2 * c0, c4=0.0),
                  (0.28, 0.33)),
    "gourd-early": ("a gourd (two lobes, a wide neck)", _beads(2), (0.1, 0.12)),
    "gourd-elongated": ("an elongated gourd", _beads(2), (0.1, 0.15)),
    "gourd": ("a gourd", _beads(2), (0.1, 0.15)),
    "cylinder": ("a cylinder with round ends",
                 lambda ell, r: Capsule(C3, (0.0, 0.0, 1.0), ell, r), (0.3, 0.07)),
    "two-spheres": ("two connected spheres", _beads(2), (0.1, 0.17)),
    "chain": ("a chain of three beads", _beads(3, neck=0.4), (0.077, 0.23)),
    "three-arm": ("a three-armed starfish", _star(3), (0.3, 0.08)),
    "four-arm": ("a four-armed starfish", _star(4), (0.25, 0.05)),
    "six-arm": ("a six-armed starfish (arms along ±x, ±y, ±z: its initial sphere grows "
                "along the grid's axes)", _star(6, plane=False), (0.2, 0.1)),
    "nested": ("a vesicle inside a vesicle",
               lambda R1, R2: Spheres(((1.0, 1.0, 1.0),) * 2, (R1, R2), (1, -1)), (0.6, 0.4)),
}


#: the sizes of :data:`FAMILIES` with diffuse V = α and A = β on the scene's grid (computed by
#: :func:`main` on 2026-11-30; checked by tests/test_seeds.py)
SIZES = {
    "discocyte": (0.465980, 0.229780),
    "torus": (0.174161, 0.132166),
    "two-spheres": (0.091477, 0.154102),
    "chain": (0.074641, 0.221810),
    "three-arm": (0.189281, 0.088296),
    "four-arm": (0.132389, 0.062219),
    "six-arm": (0.170286, 0.119554),
    "nested": (0.419674, 0.219877),
}

#: scenes without a seed, and why
NO_SEED = {name: "at eps = 0.05 no such shape with equilibrium profiles has diffuse V = alpha "
                 "and A = beta (with V = alpha its area is at most 0.55-0.64 beta)"
           for name in ("biconcave", "gourd-early", "gourd-elongated", "gourd", "cylinder")}


def seeded_shape(name: str):
    """The seeded initial condition of catalogue scene ``name`` (ModelError if it has none)."""
    from fem_ade.model.params import ModelError

    if name not in SIZES:
        why = NO_SEED.get(name, "it is not one of the paper's scenes")
        raise ModelError(f"scene {name!r} has no seeded initial condition: {why}")
    return FAMILIES[name][1](*SIZES[name])
