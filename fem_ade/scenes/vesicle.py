"""The ``vesicle`` scene family: a vesicle given by its physical parameters.

A membrane physicist thinks of a vesicle by its reduced volume v, its relaxed reduced area
difference Δa₀, the ADE modulus κ̄/κ, a spontaneous curvature C, and the branch of shapes it
starts on. :func:`vesicle_scene` maps those to the model's α, β, ΔA₀ and D, in a unit box:

* R₀ (the vesicle's √(A/4π) in the box) is ``R0`` or, by default, the largest up to 0.25 with
  which the seed keeps 0.1 L + 2ε from the box's faces (0.2 L + 4ε from its periodic
  images: nearer, a slender prolate merges with its images into a tube through the box);
* β = 4πR₀², α = (4π/3)R₀³·v — with the **localized** volume functional, whose V is that of
  the φ = 0 surface, so that v is the sharp reduced volume of the seed (run it with exact
  constraints: ``--constraints exact``, as the ``steady`` recipe's sweeps do);
* D = 2ε/3 and ΔA₀ = 8πDR₀·Δa₀ (a sphere of radius R₀ has ΔA = 8πDR₀: Δa₀ = 1); the ADE term
  runs when κ̄/κ > 0, the spontaneous curvature term when C ≠ 0;
* the seed: the sharp membrane of ``branch`` at (v, Δa₀, κ̄, C) from :mod:`sharp_ref` (its
  meridian as the ``meridian`` initial condition: the tanh profile of the signed distance);
  where that branch does not exist there, the branch's sharp shape of the minimal model at
  v, then (prolate, oblate) a spheroid of reduced volume v, a sphere for ``sphere``;
  ``scene.description`` says which;
* n = 1.28 L/ε grid points per axis (ε/h = 1.28, where the sharp-limit study's energies
  extrapolate), Δt = 0.0075 ε³ (the ``steady`` recipe runs at 100× that).

From the command line: ``python -m fem_ade.run vesicle --v 0.8 --branch oblate --recipe
steady --constraints exact``; from a TOML scene file: ``base = "vesicle"`` and a ``[vesicle]``
table with these keys; from Python: :func:`fem_ade.scenes.catalogue.vesicle_scene`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from fem_ade.model.params import ModelError, Params
from fem_ade.registry import VESICLE_BRANCHES
from fem_ade.scenes.initial import Meridian

#: the branches a vesicle can start on
BRANCHES = VESICLE_BRANCHES
#: the smallest reduced volume of the family (its sharp branches end above it; a spheroid
#: of v = 0.2 is 12 times as long as it is wide)
V_MIN = 0.2
#: a vesicle must be at least this many ε across its thinnest part (else the phase field
#: has no membrane to speak of: at v = 0.3 the default box gave R₀ = 1.3ε)
THICKNESS_PER_EPS = 2.0
#: ε/h of the default grid, and Δt / ε³
NODES_PER_EPS = 1.28
DT_PER_EPS3 = 0.0075


@dataclass(frozen=True)
class Vesicle:
    """The physical parameters of a ``vesicle`` scene (see the module docstring)."""

    v: float = 0.9
    da0: float | None = None  # None: the seed's own Δa (no ADE unless kbar > 0)
    kbar: float = 0.0
    C: float = 0.0
    eps: float = 0.04
    branch: str = "prolate"
    R0: float | None = None
    L: float = 1.0

    def check(self) -> Vesicle:
        def real(name, value, low=None, high=None, strict=False):
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and \
                math.isfinite(value)
            if ok and low is not None:
                ok = value > low if strict else value >= low
            if ok and high is not None:
                ok = value <= high
            if not ok:
                bounds = "" if low is None else (f" > {low}" if strict else f" >= {low}")
                bounds += "" if high is None else f" and <= {high}"
                raise ModelError(f"vesicle {name} must be a number{bounds}, got {value!r}")

        real("v", self.v, 0.0, 1.0, strict=True)
        if self.da0 is not None:
            real("da0", self.da0, 0.0, strict=True)
        real("kbar", self.kbar, 0.0)
        real("C", self.C)
        real("eps", self.eps, 0.0, self.L / 8.0, strict=True)
        real("L", self.L, 0.0, strict=True)
        if self.R0 is not None:
            real("R0", self.R0, 0.0, 0.5 * self.L, strict=True)
        if self.branch not in BRANCHES:
            raise ModelError(f"vesicle branch must be one of {', '.join(BRANCHES)}, got "
                             f"{self.branch!r}")
        if (self.kbar > 0) != (self.da0 is not None):
            raise ModelError("vesicle kbar and da0 go together: area-difference elasticity "
                             "needs kbar > 0 (kappa_bar/kappa) and da0 (the relaxed reduced "
                             "area difference)" + (f"; got kbar = {self.kbar:g} without da0"
                                                   if self.kbar > 0 else
                                                   f"; got da0 = {self.da0:g} without kbar"))
        if self.v < V_MIN:
            raise ModelError(f"vesicle v = {self.v:g}: below {V_MIN} no seed of this family "
                             "fits (no sharp shape of its branches, a spheroid too slender to "
                             "resolve)")
        return self

    @property
    def ade(self) -> tuple[float, float]:
        """(m₀, κ̄/κ) of the sharp model: ADE only with both ``kbar`` and ``da0`` given."""
        on = self.kbar > 0 and self.da0 is not None
        return (self.da0 if self.da0 is not None else 0.0), (self.kbar if on else 0.0)


def sharp_shape(branch: str, v: float, m0: float, kbar: float, c: float):
    """The sharp membrane of ``branch`` (a :class:`sharp_ref.membrane.Result`), or None
    where it does not exist (:func:`fem_ade.analysis.sharp.solve_cached`: a sweep asks for the same
    seed many times)."""
    from fem_ade.analysis.sharp import solve_cached
    from sharp_ref.membrane import BranchError

    try:
        return solve_cached(branch, round(v, 6), round(m0, 6), round(kbar, 6), round(c, 6))
    except (BranchError, ArithmeticError, ValueError, np.linalg.LinAlgError):
        return None  # no such shape here, or the solver cannot find one


def sharp_of(branch: str, **kw):
    """The sharp membrane of ``branch`` (any sharp_ref branch, the torus too) with a
    vesicle's parameters ``kw`` — the one its seed is (for the seed's branch) — or None
    where it does not exist, or with C ≠ 0 (its c = √2·C·R₀ depends on the fitted R₀)."""
    ves = Vesicle(**kw).check()
    if ves.C:
        return None
    m0, kbar = ves.ade
    return sharp_shape(branch, ves.v, m0, kbar, 0.0)


def spheroid_meridian(v: float, prolate: bool, points: int = 201) -> tuple[np.ndarray, ...]:
    """(r, z) of the spheroid of reduced volume ``v`` with area 4π (R₀ = 1)."""
    from scipy.optimize import brentq

    def shape(q):  # semi-axes: a around the axis, c along it, q = c / a
        th = np.linspace(0.0, math.pi, 4001)
        r, z = np.sin(th), q * np.cos(th)
        ds = np.hypot(np.gradient(r, th), np.gradient(z, th))
        area = 2.0 * math.pi * np.trapezoid(r * ds, th)
        volume = 4.0 * math.pi / 3.0 * q
        return area, volume

    def reduced(q):
        area, volume = shape(q)
        return volume / (4.0 * math.pi / 3.0 * (area / (4.0 * math.pi)) ** 1.5) - v

    try:
        q = 1.0 if v >= 1.0 else (brentq(reduced, 1.0 + 1e-9, 200.0) if prolate else
                                  brentq(reduced, 1e-3, 1.0 - 1e-9))
    except ValueError:
        raise ModelError(f"no {'prolate' if prolate else 'oblate'} spheroid has reduced volume "
                         f"{v:g}") from None
    area, _ = shape(q)
    a = math.sqrt(4.0 * math.pi / area)  # scaled to area 4π
    th = np.linspace(0.0, math.pi, points)
    return a * np.sin(th), a * q * np.cos(th)


def seed_meridian(ves: Vesicle, c: float) -> tuple[np.ndarray, np.ndarray, str]:
    """(r, z, where it came from) of the seed, R₀ = 1."""
    m0, kbar = ves.ade
    if ves.branch == "sphere":
        if ves.v < 1.0:
            R = ves.v ** (1.0 / 3.0)  # a sphere of the target volume: its area relaxes up
            th = np.linspace(0.0, math.pi, 201)
            return R * np.sin(th), R * np.cos(th), "a sphere of the target volume"
    attempts = [(m0, kbar, c, "the sharp shape")] + ([(0.0, 0.0, 0.0, "the sharp shape of the "
                                                     "minimal model")] if kbar or c else [])
    for mm, kb, cc, what in attempts:
        res = sharp_shape(ves.branch, ves.v, mm, kb, cc)
        if res is not None:
            j = res.to_json(points=201)
            r = np.maximum(np.asarray(j["r"]), 0.0)  # the poles' round-off: r = -1e-17
            return r, np.asarray(j["z"]), f"{what} ({ves.branch})"
    if ves.branch in ("prolate", "oblate"):
        r, z = spheroid_meridian(ves.v, ves.branch == "prolate")
        return r, z, f"a {ves.branch} spheroid (no sharp {ves.branch} here)"
    raise ModelError(f"no sharp {ves.branch} at v = {ves.v} (with these da0, kbar, C) to start "
                     f"from; choose another branch")


def vesicle_parts(*, sharp_seed: bool = True, **kw) -> dict:
    """The fields of the ``vesicle`` scene (:func:`fem_ade.scenes.catalogue.vesicle_scene` makes the
    Scene) of :class:`Vesicle`'s parameters (``v``, ``da0``, ``kbar``, ``C``, ``eps``,
    ``branch``, ``R0``, ``L``); ModelError (one line) for bad values.

    ``sharp_seed=False``: a spheroid of the vesicle's v stands in for its sharp seed, and
    what only the seed can tell (does it fit the box, is it thick enough) is not checked —
    a scene to check a run's options with (a sweep's check before anything runs), in
    milliseconds where a sharp solve takes 0.3–10 s; never one to run."""
    unknown = set(kw) - set(Vesicle.__dataclass_fields__)
    if unknown:
        raise ModelError(f"unknown vesicle parameter(s) {', '.join(sorted(unknown))}; valid: "
                         f"{', '.join(Vesicle.__dataclass_fields__)}")
    ves = Vesicle(**kw).check()
    # the seed's distance from the box's faces: its periodic images 0.2 L + 4ε apart (at 6ε
    # a prolate's poles merged with their images' into a tube through the box, ε = 0.02)
    margin = 0.1 * ves.L + 2.0 * ves.eps
    R0 = ves.R0 if ves.R0 is not None else 0.25 * ves.L
    c = math.sqrt(2.0) * ves.C * R0
    if not sharp_seed:
        r, z = spheroid_meridian(ves.v, ves.branch != "oblate")
        return _parts(ves, r, z, R0, "a spheroid standing in for the sharp seed (a check)")
    r, z, origin = seed_meridian(ves, c)
    extent = max(float(np.ptp(z)), 2.0 * float(np.max(r)))
    if ves.R0 is None and extent * R0 > ves.L - 2.0 * margin:
        R0 = (ves.L - 2.0 * margin) / extent
        if ves.C:  # c = √2·C·R₀ changed with R₀: the seed again
            c = math.sqrt(2.0) * ves.C * R0
            r, z, origin = seed_meridian(ves, c)
    elif extent * R0 > ves.L - 2.0 * margin:
        raise ModelError(f"the {ves.branch} at v = {ves.v} with R0 = {R0:g} does not fit the "
                         f"box with 0.1 L + 2 eps to spare (extent {extent * R0:.3g} L); "
                         "give a smaller R0 or leave it out")
    thin = min(float(np.ptp(z)), 2.0 * float(np.max(r)))  # the body's thickness, R₀ = 1
    if thin * R0 < THICKNESS_PER_EPS * ves.eps:
        raise ModelError(f"the {ves.branch} at v = {ves.v:g} is {thin * R0 / ves.eps:.2g} eps "
                         f"thick (R0 = {R0:.3g} in the box): below {THICKNESS_PER_EPS:g} eps "
                         "the phase field has no membrane to speak of; give a smaller eps")
    return _parts(ves, r, z, R0, origin)


def _parts(ves: Vesicle, r, z, R0: float, origin: str) -> dict:
    """The scene's fields of a vesicle seeded on the meridian (r, z) (R₀ = 1) scaled to R0."""
    D = 2.0 * ves.eps / 3.0
    effects = {"bending", "volume", "area"}
    if ves.ade[1]:
        effects.add("ade")
    if ves.C:
        effects.add("spontaneous_curvature")
    params = Params(eps=ves.eps, L=ves.L, alpha=4.0 / 3.0 * math.pi * R0**3 * ves.v,
                    beta=4.0 * math.pi * R0**2, kappa_bar=ves.kbar, C=ves.C,
                    delta_A0=(ves.da0 if ves.da0 is not None else 0.0) * 8.0 * math.pi * D * R0,
                    effects=frozenset(effects), volume_functional="localized")
    centre = (0.5 * ves.L,) * 3
    ic = Meridian(centre=centre, r=tuple(float(x) for x in r), z=tuple(float(x) for x in z),
                  scale=R0)
    n = max(16, round(NODES_PER_EPS * ves.L / ves.eps))
    text = ", ".join(f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}"
                     for k, v in asdict(ves).items() if v is not None and k != "L")
    ic.check(3)
    return {"name": "vesicle", "params": params, "dt": DT_PER_EPS3 * ves.eps**3, "ic": ic,
            "n": n, "figure": "vesicle family", "shape": ves.branch,
            "description": f"vesicle: {text}; R0 = {R0:.4g}; seeded from {origin}"}


# ---------------------------------------------------------------------------------------------
# the parameters a branch follows (fem_ade.campaigns.branch, fem_ade.campaigns.stability)
# ---------------------------------------------------------------------------------------------
#: the reduced parameters of the family a branch can follow
PARAMETERS = ("v", "da0", "kbar", "C")


def get_parameter(params, name: str) -> float:
    R0 = math.sqrt(params.beta / (4.0 * math.pi))
    if name == "v":
        return params.alpha / (4.0 / 3.0 * math.pi * R0**3)
    if name == "da0":
        return params.delta_A0 / (8.0 * math.pi * params.D * R0)
    if name == "kbar":
        return params.kappa_bar / params.kappa
    return params.C


def set_parameter(params, name: str, value: float):
    """The parameters with ``name`` at ``value`` (R₀ = √(β/4π) kept)."""
    R0 = math.sqrt(params.beta / (4.0 * math.pi))
    if name == "v":
        return params.with_(alpha=4.0 / 3.0 * math.pi * R0**3 * value)
    if name == "da0":
        return params.with_(delta_A0=8.0 * math.pi * params.D * R0 * value)
    if name == "kbar":
        return params.with_(kappa_bar=value * params.kappa)
    return params.with_(C=value)
