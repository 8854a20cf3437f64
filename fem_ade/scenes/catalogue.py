"""The scene catalogue: the paper's thirteen shapes (model §7) and the teaching scenes.

A scene is data plus a tiny constructor: parameters (:class:`fem_ade.model.params.Params`, whose
``effects`` say which energy terms run), the paper's time step, a default resolution, an
initial condition (:mod:`fem_ade.scenes.initial`), and the paper figure it reproduces. Initial
conditions are functions of position, so that every backend evaluates them on its own points
(grid or mesh nodes).

Initial conditions of the paper (model §7): u₀ = tanh((c − q(x)) / (√2 ε)),
q = (x−x₀)²/a + (y−y₀)²/b + (z−z₀)²/d. The consistent reading of c (the default) makes the
initial volume match α; the printed one (``ic="printed"``) is kept as a hard case.

Scene files (TOML) are read here, their ``[ic]`` table too (:func:`ic_from_mapping`, into one
of :mod:`fem_ade.scenes.initial`'s kinds), so that one module says what a scene file may hold.
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from fem_ade.model.params import EFFECTS, PARAM_FIELDS, ModelError, Params
from fem_ade.registry import IC_VARIANTS
from fem_ade.scenes.initial import KINDS, Ellipsoid, FieldIC, Shape, Sphere

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


@dataclass(frozen=True)
class Scene:
    """One simulation setup: parameters, effects, time step, resolution and initial condition."""

    name: str
    params: Params
    dt: float
    ic: Shape
    n: int = 64
    dim: int = 3
    figure: str = ""
    description: str = ""
    steps: int = 200  # default number of steps of the CLI (a short, visible run)
    #: the paper figure's shape as a label of :func:`fem_ade.analysis.shape.classify` ("" if none)
    shape: str = ""

    def initial_phi(
        self,
        points: np.ndarray,
        *,
        ic: str = "consistent",
        perturb: float = 0.0,
        seed: int = 0,
        periodic: bool = True,
        perturbation=None,
    ) -> np.ndarray:
        """φ₀ at ``points`` (shape (dim, ...)).

        ``periodic=False``: the shape is not repeated with the box's period (the axisymmetric
        geometry's half-plane, which may reach beyond the box); ``perturbation``: the field ψ
        of ``perturb`` as a function of the points (default :func:`smooth_perturbation` with
        ``seed``).

        ``perturb`` > 0 adds a smooth, seeded perturbation of the level set:
        s → s + perturb · scale · ψ(x), with ψ a random combination of the periodic Fourier
        modes of |k|∞ ≤ 2 normalised so that |ψ| ≤ 1. It breaks symmetries without adding
        grid-scale noise (which the paper's scheme does not survive, model §7). A field (kind
        "file") is perturbed the same way through its level set s = √2ε artanh φ.
        """
        if ic not in IC_VARIANTS:
            raise ModelError(f"unknown initial condition variant {ic!r}; use one of {IC_VARIANTS}")
        points = np.asarray(points, dtype=float)
        if points.shape[0] != self.dim:
            raise ValueError(
                f"scene {self.name} is {self.dim}D; got points of shape {points.shape}"
            )
        w = math.sqrt(2.0) * self.params.eps
        L = self.params.L if periodic else math.inf

        def psi(pts):
            if perturbation is not None:
                return perturbation(pts)
            return smooth_perturbation(pts, self.params.L, seed)

        if self.ic.is_field:
            phi = self.ic.field_values(points, self.params.L)
            if not perturb:
                return phi
            # its level set s = √2ε artanh φ, perturbed in units of the radius R_V of a sphere
            # of its volume (a kick that tells a stable steady state from a saddle)
            volume = float(np.mean(phi + 1.0) / 2.0) * self.params.L**self.dim
            scale = (3.0 * volume / (4.0 * math.pi)) ** (1.0 / 3.0) if self.dim == 3 else (
                math.sqrt(volume / math.pi))
            s = w * np.arctanh(np.clip(phi, -1.0 + 1e-12, 1.0 - 1e-12))
            return np.tanh((s + perturb * scale * psi(points)) / w)
        shape = self.ic
        if ic == "seeded":
            from fem_ade.scenes.seeds import seeded_shape

            shape = seeded_shape(self.name)
        s, scale = shape.level(points, L, ic)
        if perturb:
            s = s + perturb * scale * psi(points)
        return np.tanh(s / w)

    def validate(self) -> Scene:
        """See :meth:`_validate`; numbers too large or small to compute with are refused too."""
        try:
            return self._validate()
        except (OverflowError, ZeroDivisionError, ValueError) as err:
            if isinstance(err, ModelError):
                raise
            raise ModelError(f"the parameters of scene {self.name} are out of range "
                             f"({err})") from None

    def _validate(self) -> Scene:
        """ModelError (one line) unless the parameters are usable and fit the box: α below
        the box's volume, a membrane of area β that fits it (β·ε < |Ω|), α and β that a
        closed surface can have (reduced volume ≤ 1.5: a sphere has 1), ε well below L."""
        p = self.params.validate()
        if self.dim not in (2, 3):
            raise ModelError(f"dim must be 2 or 3, got {self.dim}")
        if not (isinstance(self.steps, int) and self.steps >= 0):
            raise ModelError(f"steps must be an integer >= 0, got {self.steps!r}")
        if not (isinstance(self.n, int) and self.n >= 8):
            raise ModelError(f"n must be an integer >= 8, got {self.n!r}")
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ModelError(f"dt must be a positive number, got {self.dt}")
        box = p.L**self.dim
        if not p.alpha < box:
            raise ModelError(f"alpha = {p.alpha:g} is not below the box's volume "
                             f"L^{self.dim} = {box:g}")
        if not p.beta * p.eps < box:
            raise ModelError(f"beta = {p.beta:g} is more membrane than the box holds "
                             f"(beta * eps must be below L^{self.dim} = {box:g})")
        if not p.eps <= p.L / 8:
            raise ModelError(f"eps = {p.eps:g} is too wide for the box (L = {p.L:g}; eps <= L/8)")
        # reduced volume in logarithms (no overflow or underflow for extreme α, β)
        if self.dim == 3:
            log_v0 = (math.log(p.alpha) - math.log(4.0 * math.pi / 3.0)
                      - 1.5 * (math.log(p.beta) - math.log(4.0 * math.pi)))
        else:
            log_v0 = math.log(4.0 * math.pi) + math.log(p.alpha) - 2.0 * math.log(p.beta)
        v0 = math.exp(min(log_v0, 700.0))
        if v0 > 1.5:
            raise ModelError(f"alpha = {p.alpha:g} is too much volume for the area beta = "
                             f"{p.beta:g}: reduced volume {v0:.3g} > 1 (a sphere has 1)")
        return self

    def with_(self, **changes) -> Scene:
        """A copy with scene fields or parameters changed (parameter names go to Params)."""
        pchanges = {k: changes.pop(k) for k in list(changes) if k in PARAM_FIELDS}
        params = self.params.with_(**pchanges) if pchanges else self.params
        return replace(self, params=params, **changes)


def smooth_perturbation(points: np.ndarray, L: float, seed: int, kmax: int = 2) -> np.ndarray:
    """A seeded, periodic, smooth field with |ψ| ≤ 1 built from Fourier modes |k|∞ ≤ kmax."""
    rng = np.random.default_rng(seed)
    dim = points.shape[0]
    ks = np.stack(np.meshgrid(*[np.arange(-kmax, kmax + 1)] * dim, indexing="ij"), -1)
    ks = ks.reshape(-1, dim)
    ks = ks[np.any(ks != 0, axis=1)]
    amps = rng.standard_normal(len(ks))
    phases = rng.uniform(0.0, 2.0 * math.pi, len(ks))
    amps /= np.sum(np.abs(amps))
    psi = np.zeros(points.shape[1:])
    for k, a, p in zip(ks, amps, phases, strict=True):
        arg = 2.0 * math.pi / L * np.tensordot(k, points, axes=1)
        psi += a * np.cos(arg + p)
    return psi


# ---------------------------------------------------------------------------------------
# The catalogue
# ---------------------------------------------------------------------------------------
PAPER_EFFECTS = frozenset({"bending", "ade", "volume", "area"})
_C = (0.5, 0.5, 0.5)


def _paper(name, figure, eps, dt, alpha, beta, dA0, axes, c_printed, c_consistent, desc, shape,
           **kw):
    n = kw.pop("n", 64)
    centre = kw.pop("centre", _C)
    params = Params(eps=eps, alpha=alpha, beta=beta, delta_A0=dA0, effects=PAPER_EFFECTS, **kw)
    ic = Ellipsoid(centre, axes, c_consistent=c_consistent, c_printed=c_printed)
    return Scene(name, params, dt, ic, n=n, figure=figure, description=desc, shape=shape)


_A3 = (0.2**2, 0.2**2, 0.35**2)
_S35 = (0.35**2,) * 3

_PAPER = [
    _paper("discocyte", "Fig. 1", 0.04, 5e-7, 0.0289, 0.4880, 0.1090, (0.5, 0.5, 0.1), 0.35,
           0.35**2, "experiment 1: flattened ellipsoid relaxing to a discocyte", "discocyte"),
    _paper("torus", "Fig. 2", 0.03, 2e-7, 0.0652, 0.9092, 0.2839, _S35, 0.6, 0.6,
           "experiment 2: sphere with excess area and area difference forming a torus", "torus"),
    _paper("biconcave", "Fig. 3a", 0.05, 5e-7, 0.0077, 0.1992, 0.1614, _A3, 0.5, 0.5**2,
           "experiment 3a: prolate ellipsoid to a biconcave shape", "discocyte"),
    _paper("gourd-early", "Fig. 3b", 0.05, 5e-7, 0.0077, 0.2068, 0.1676, _A3, 0.5, 0.5**2,
           "experiment 3b: early gourd", "gourd"),
    _paper("gourd-elongated", "Fig. 3c", 0.05, 5e-7, 0.0077, 0.2390, 0.1906, _A3, 0.5, 0.5**2,
           "experiment 3c: elongated gourd", "gourd"),
    _paper("gourd", "Fig. 3d", 0.05, 5e-7, 0.0077, 0.2390, 0.2253, _A3, 0.5, 0.5**2,
           "experiment 3d: gourd", "gourd"),
    _paper("cylinder", "Fig. 3e", 0.05, 5e-7, 0.0077, 0.2390, 0.2426, _A3, 0.5, 0.5**2,
           "experiment 3e: cylinder", "cylinder"),
    _paper("two-spheres", "Fig. 4", 0.02, 2e-7, 0.0074, 0.1969, 0.0711, _A3, 0.5, 0.5**2,
           "experiment 4: two connected spheres", "gourd"),
    _paper("chain", "Fig. 5", 0.02, 5e-7, 0.0074, 0.2328, 0.0958, _A3, 0.5, 0.5**2,
           "experiment 5: chain of beads", "chain"),
    _paper("three-arm", "Fig. 6", 0.02, 1e-7, 0.0226, 0.4489, 0.1520, _S35, 0.5, 0.5**2,
           "experiment 6: three-armed starfish", "starfish-3"),
    _paper("four-arm", "Fig. 7", 0.02, 2e-7, 0.0097, 0.2550, 0.1146, (0.35**2, 0.35**2, 0.15**2),
           0.5, 0.5**2, "experiment 7: four-armed starfish", "starfish-4"),
    _paper("six-arm", "Fig. 8", 0.02, 1e-7, 0.0529, 0.7911, 0.1766, _S35, 0.6, 0.6,
           "experiment 8: six-armed starfish", "starfish-6"),
    _paper("nested", "Fig. 9", 0.03, 5e-7, 0.2693, 2.8347, 0.3939, (0.16, 0.16, 0.16), 1.0, 1.0,
           "experiment 9: nested vesicle (L = 2)", "nested", n=100, centre=(1.0, 1.0, 1.0), L=2.0,
           M1=1e4, M2=1e4),
]


def sphere_values(R: float, eps: float, D: float) -> dict:
    """Diffuse volume, area and area difference of tanh((R − r)/(√2ε)) as h → 0 (model §8)."""
    return {
        "V": 4.0 * math.pi * R**3 / 3.0 + (2.0 * math.pi**3 / 3.0) * R * eps**2,
        "A": 4.0 * math.pi * (R**2 + (math.pi**2 - 6.0) * eps**2 / 6.0),
        "dA": 8.0 * math.pi * D * R,
        "W": 16.0 * math.sqrt(2.0) * math.pi / 3.0,
    }


def _sphere(name, effects, desc):
    R, eps = 0.25, 0.04
    sv = sphere_values(R, eps, 2.0 * eps / 3.0)
    params = Params(eps=eps, alpha=sv["V"], beta=sv["A"], delta_A0=sv["dA"], effects=effects)
    ic = Sphere(_C, radius=R)
    return Scene(name, params, 5e-7, ic, n=48, figure="model §8", description=desc,
                 shape="sphere")


_TEACHING = [
    _sphere("sphere", PAPER_EFFECTS,
            "teaching: equilibrium sphere R = 0.25, alpha, beta, dA0 at its diffuse values"),
    _sphere("sphere-bending", frozenset({"bending"}),
            "teaching: the same sphere under bending only (W = 16*sqrt(2)*pi/3)"),
]

_TEACHING.append(Scene(
    "ellipse-2d",
    Params(eps=0.05, alpha=0.2316, beta=0.95 * 1.7311, delta_A0=0.1, effects=PAPER_EFFECTS),
    2e-6, Ellipsoid((0.5, 0.5), (0.6, 0.4), c_consistent=0.15, c_printed=0.15),
    n=64, dim=2, figure="teaching (2D)",
    description="teaching: a 2D ellipse with 95 % of its perimeter as target (fast tests)"))

PAPER_SCENES: dict[str, Scene] = {s.name: s for s in _PAPER}
TEACHING_SCENES: dict[str, Scene] = {s.name: s for s in _TEACHING}
SCENES: dict[str, Scene] = {**PAPER_SCENES, **TEACHING_SCENES}


#: scene families: made from physical parameters (``get_scene(NAME)`` is the defaults)
FAMILIES = ("vesicle",)
#: the Params fields the vesicle family derives from its own parameters (a TOML scene with
#: base = "vesicle" sets them in [vesicle], not in [params])
VESICLE_PARAMS = frozenset({"eps", "alpha", "beta", "delta_A0", "kappa_bar", "C", "D", "L",
                            "effects", "volume_functional", "A0"})


def vesicle_scene(*, sharp_seed: bool = True, **kw) -> Scene:
    """The ``vesicle`` family (:mod:`fem_ade.scenes.vesicle`): a vesicle of reduced volume ``v``,
    relaxed area difference ``da0``, ``kbar`` = κ̄/κ, spontaneous curvature ``C``, width
    ``eps``, seeded on ``branch`` (prolate, oblate, stomatocyte, pear, torus, sphere);
    ``sharp_seed=False``: a scene to check options with, not to run
    (:func:`fem_ade.scenes.vesicle.vesicle_parts`)."""
    from fem_ade.scenes.vesicle import vesicle_parts

    return Scene(**vesicle_parts(sharp_seed=sharp_seed, **kw)).validate()


def get_scene(name: str) -> Scene:
    """A catalogue scene by name (a family's with its defaults), or a clear
    :class:`ModelError` listing the valid names."""
    if name in FAMILIES:
        return vesicle_scene()
    try:
        return SCENES[name]
    except KeyError:
        raise ModelError(
            f"unknown scene {name!r}; valid scenes: {', '.join([*SCENES, *FAMILIES])} "
            "(or a .toml file)") from None


# ---------------------------------------------------------------------------------------
# Scenes from TOML files
# ---------------------------------------------------------------------------------------
def _number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _parse(name: str, kind: str, value):
    bad = ModelError(f"ic.{name} must be {_WHAT[kind]}, got {value!r}")
    if kind == "vec":
        if not (isinstance(value, list) and value and all(_number(v) for v in value)):
            raise bad
        return tuple(float(v) for v in value)
    if kind == "vecs":
        if not (isinstance(value, list) and value and all(
                isinstance(v, list) and v and all(_number(x) for x in v) for v in value)):
            raise bad
        return tuple(tuple(float(x) for x in v) for v in value)
    if kind in ("floats+", "floats", "signs"):
        if not (isinstance(value, list) and value and all(_number(v) for v in value)):
            raise bad
        return tuple(int(v) if kind == "signs" else float(v) for v in value)
    if kind in ("float+", "float"):
        if not _number(value):
            raise bad
        return float(value)
    if kind == "int+":
        if not (isinstance(value, int) and not isinstance(value, bool)):
            raise bad
        return value
    if kind == "bool":
        if not isinstance(value, bool):
            raise bad
        return value
    if not isinstance(value, str):
        raise bad
    return value


_WHAT = {"vec": "a list of numbers", "vecs": "a list of lists of numbers",
         "floats+": "a list of positive numbers", "floats": "a list of numbers",
         "signs": "a list of +1 and -1",
         "float+": "a positive number", "float": "a number", "int+": "a positive integer",
         "bool": "true or false", "str": "a string"}


def ic_from_mapping(table: dict, dim: int, files: str = "") -> Shape:
    """An initial condition from the ``[ic]`` table of a scene file; ModelError (one line)
    for an unknown kind, an unknown, missing or ill-typed field, or a value that does not fit.
    ``files``: the folder a relative ``path`` of a field (kind "file") is read from (default:
    the working directory)."""
    table = dict(table)
    kind = table.pop("kind", None)
    if kind not in KINDS:
        raise ModelError(f"ic.kind must be one of {', '.join(KINDS)}, got {kind!r}")
    cls = KINDS[kind]
    if cls is Ellipsoid and "c" in table:
        c = table.pop("c")
        table.setdefault("c_consistent", c)
        table.setdefault("c_printed", c)
    spec = dict(cls.spec)
    unknown = set(table) - set(spec)
    if unknown:
        extra = ", c" if cls is Ellipsoid else ""
        raise ModelError(f"unknown field(s) ic.{', ic.'.join(sorted(unknown))} for kind "
                         f"{kind!r}; valid: {', '.join(spec)}{extra}")
    missing = [k for k in spec if k not in table and k not in cls.optional]
    if missing:
        raise ModelError(f"ic kind {kind!r} needs {', '.join('ic.' + k for k in missing)}")
    values = {k: _parse(k, spec[k], v) for k, v in table.items()}
    ic = cls(**values, base=files) if cls is FieldIC and files else cls(**values)
    ic.check(dim)
    return ic


_SCENE_KEYS = {"name": str, "figure": str, "description": str, "n": int, "dim": int,
               "dt": float, "steps": int, "shape": str}


def _typed(table: str, key: str, value, kind):
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if not isinstance(value, kind) or isinstance(value, bool):
        raise ModelError(f"{table}.{key} must be of type {kind.__name__}, got {value!r}")
    return value


def load_scene_file(path: str | Path) -> Scene:
    """Load a scene from a TOML file with the fields of :class:`Scene`.

    Layout (``base`` is optional and starts from a catalogue scene)::

        name = "my-disc"      # optional: base's name or the file's stem
        base = "discocyte"    # optional
        dt = 5e-7
        n = 48
        [params]              # any field of Params; effects is a list of names
        eps = 0.04
        alpha = 0.0289
        effects = ["bending", "ade", "volume", "area"]
        [ic]                  # kind = "ellipsoid" (centre, axes, c or c_consistent/c_printed)
        kind = "ellipsoid"    # or "sphere" (centre, radius)

    With ``base = "vesicle"``, a ``[vesicle]`` table gives the family's parameters (v, da0,
    kbar, C, eps, branch, R0, L: :func:`vesicle_scene`); the other keys then change that
    scene as they change a catalogue one.

    Unknown keys and ill-typed values raise :class:`ModelError`.
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ModelError(f"scene file not found: {path}") from None
    except IsADirectoryError:
        raise ModelError(f"scene file {path} is a folder") from None
    except OSError as err:
        raise ModelError(f"cannot read scene file {path}: {err.strerror or err}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise ModelError(f"malformed TOML in {path}: {err}") from None
    return scene_from_mapping(data, default_name=path.stem, where=str(path))


def scene_from_mapping(data: dict, *, default_name: str = "scene", where: str = "scene",
                       files: str = "") -> Scene:
    """Build a scene from the mapping of a TOML scene file (see :func:`load_scene_file`);
    ``files`` as :func:`ic_from_mapping`'s."""
    data = dict(data)
    path = where
    base = data.pop("base", None)
    if base is not None and not isinstance(base, str):
        raise ModelError(f"base must be a scene name, got {base!r}")
    params_t = data.pop("params", {})
    ic_t = data.pop("ic", None)
    vesicle_t = data.pop("vesicle", None)
    if vesicle_t is not None and (base != "vesicle" or not isinstance(vesicle_t, dict)):
        raise ModelError("a [vesicle] table needs base = \"vesicle\"")
    if not isinstance(params_t, dict) or (ic_t is not None and not isinstance(ic_t, dict)):
        raise ModelError("[params] and [ic] must be TOML tables")
    scene_kw = {}
    for key, value in data.items():
        if key not in _SCENE_KEYS:
            raise ModelError(f"unknown field {key!r} in {path}; valid: base, params, ic, "
                             f"{', '.join(_SCENE_KEYS)}")
        scene_kw[key] = _typed("scene", key, value, _SCENE_KEYS[key])

    param_kw = {}
    for key, value in params_t.items():
        if key not in PARAM_FIELDS:
            raise ModelError(
                f"unknown field params.{key!r}; valid: {', '.join(sorted(PARAM_FIELDS))}"
            )
        if key == "effects":
            if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
                raise ModelError(f"params.effects must be a list of names from {EFFECTS}")
            param_kw[key] = frozenset(value)
        elif key == "volume_functional":
            param_kw[key] = _typed("params", key, value, str)
        else:
            param_kw[key] = _typed("params", key, value, float)

    if "dim" in scene_kw and scene_kw["dim"] not in (2, 3):
        raise ModelError(f"dim must be 2 or 3, got {scene_kw['dim']}")
    if base == "vesicle":
        fixed = sorted(set(param_kw) & VESICLE_PARAMS)
        if fixed:
            raise ModelError(f"[params] {', '.join(fixed)}: the [vesicle] table sets "
                             "these (v, da0, kbar, C, eps, R0, L); give them there")
    base_scene = (vesicle_scene(**(vesicle_t or {})) if base == "vesicle" else
                  get_scene(base) if base is not None else None)
    dim = scene_kw.get("dim", base_scene.dim if base_scene else 3)
    ic = ic_from_mapping(ic_t, dim, files) if ic_t is not None else None

    if base_scene is not None:
        scene = base_scene
        try:
            params = scene.params.with_(**param_kw) if param_kw else scene.params
        except TypeError as err:
            raise ModelError(f"bad [params] in {path}: {err}") from None
        scene = replace(scene, params=params, ic=ic or scene.ic, **scene_kw)
        if "name" not in scene_kw:
            scene = replace(scene, name=default_name)
    else:
        missing = [k for k in ("dt",) if k not in scene_kw] + (["ic"] if ic is None else []) + [
            k for k in ("eps", "alpha", "beta") if k not in param_kw]
        if missing:
            raise ModelError(f"scene file {path} misses {', '.join(missing)} (or give base = NAME)")
        try:
            params = Params(**param_kw)
        except TypeError as err:
            raise ModelError(f"bad [params] in {path}: {err}") from None
        scene_kw.setdefault("name", default_name)
        scene = Scene(params=params, ic=ic, **scene_kw)

    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]*", scene.name):
        raise ModelError(f"name must be a plain file name (letters, digits, . _ -), got "
                         f"{scene.name!r}")
    scene.ic.check(scene.dim)
    return scene.validate()


def scene_to_mapping(scene: Scene) -> dict:
    """The inverse of :func:`scene_from_mapping` (used to store a run's scene for --resume)."""
    params = scene.params.as_dict()
    ic = scene.ic.to_mapping()
    return {"name": scene.name, "figure": scene.figure, "description": scene.description,
            "n": scene.n, "dim": scene.dim, "dt": scene.dt, "steps": scene.steps,
            "shape": scene.shape, "params": params, "ic": ic}


def resolve_scene(name_or_path: str) -> Scene:
    """A catalogue name or a path to a ``.toml`` scene file."""
    if name_or_path.endswith(".toml") or Path(name_or_path).is_file():
        return load_scene_file(name_or_path)
    return get_scene(name_or_path)
