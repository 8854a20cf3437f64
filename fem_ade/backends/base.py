"""What the time loop asks of a backend, what every backend shares, and how one is found.

A backend knows how to build its state from a scene, take one step of a scheme, and measure
E, W, G, V, A, ΔA (model §6) on its state. It never writes files and never decides when to
stop: that is the loop's job (:mod:`fem_ade.engine.loop`), and the run folder is
:mod:`fem_ade.engine.execute`'s.
The backends are listed in :data:`fem_ade.registry.BACKENDS`.
"""

from __future__ import annotations

import importlib
import math
import os
from dataclasses import replace
from typing import Protocol, runtime_checkable

import numpy as np

from fem_ade.model.constraints import TargetRamp
from fem_ade.model.params import ModelError, check_resolution
from fem_ade.registry import BACKENDS, CONSTRAINTS, SCHEMES
from fem_ade.scenes.catalogue import Scene


@runtime_checkable
class Backend(Protocol):
    """The interface of a backend (the spectral reference and the FEM implement it).

    Construction: ``Backend(scene, n=..., ic=..., perturb=..., seed=..., scheme=...,
    constraints=..., dt=None, start_state=None, **options)``. The loop pushes Δt with
    :meth:`set_dt` before the first step.
    """

    #: short name used in the CLI and in summary.json
    name: str
    #: the scene the backend runs: its params are the effective ones (exact constraints:
    #: no penalty terms)
    scene: Scene
    #: extra history columns this backend appends after step,t,E,W,G,V,A,dA
    extra_columns: tuple[str, ...]
    #: False after a step on which E_M was allowed to rise (exact constraints' ramp)
    dissipative: bool

    @classmethod
    def check(cls, scene: Scene, *, n: int, dt: float, scheme: str, constraints: str,
              allow_underresolved: bool = False, **options) -> None:
        """Validate a run before anything is built or written; raise ModelError (one line)."""

    def set_dt(self, dt: float) -> None:
        """Set the time step (the loop's); rebuild only what depends on it."""

    def step(self) -> dict:
        """Advance one step in place; return the values of ``extra_columns`` for this step."""

    def diagnostics(self) -> dict:
        """E, W, G, V, A, dA (and T1, T2) of the current state (terms that are off report 0)."""

    def max_abs_phi(self) -> float:
        """max |φ| over the degrees of freedom (NaN if any is not finite)."""

    def state(self) -> dict[str, np.ndarray]:
        """The full state as arrays the backend will not mutate later (for guards, checkpoints)."""

    def extrapolate(self, anchor: dict[str, np.ndarray], beta: float) -> None:
        """Momentum: move the field φ to φ + β(φ − φ_anchor), ``anchor`` a :meth:`state`; the
        rest of the state (stabilization, ramp, warm starts) stays."""

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore a state returned by :meth:`state` (ModelError if it does not fit)."""

    def fields(self) -> dict[str, np.ndarray]:
        """Arrays for ``final.npz``: at least ``phi`` and the coordinates it lives on."""

    def grid_phi(self) -> np.ndarray:
        """φ on the uniform periodic grid x_j = jL/m, shape (m,)*dim (shape analysis, pictures,
        and the start of another run: :class:`fem_ade.scenes.initial.FieldIC`, kind "file")."""

    def output_mesh(self):
        """(points (P, 3), [(cell type, connectivity)]) for the XDMF series, periodic images
        closed."""

    def point_data(self) -> dict[str, np.ndarray]:
        """Fields at the points of :meth:`output_mesh` for one XDMF step."""

    def info(self) -> dict:
        """JSON-serialisable description (resolution, element, solver...) for summary.json."""


class BackendBase:
    """What every backend does the same way, and no physics: checking the scheme and
    constraints, the effective parameters (exact constraints switch the penalties off: a
    backend built directly is consistent), the initial field, and the resolution check."""

    name = "base"
    extra_columns: tuple[str, ...] = ()
    #: extra columns when the constraints are exact: the multipliers, and the fraction of the
    #: way the targets have ramped from the initial V₀, A₀ to α, β (fem_ade.model.constraints)
    exact_columns = ("lambda_V", "lambda_A", "ramp")

    def __init__(self, scene: Scene, *, n: int, scheme: str = "paper",
                 constraints: str = "penalty"):
        check_choice("scheme", scheme, SCHEMES)
        self.scheme = scheme
        self.constraints = constraints
        params = scene.params.for_constraints(constraints).validate()
        self.scene = scene if params is scene.params else replace(scene, params=params)
        self.params = params
        self.n = n
        self.exact = constraints == "exact"
        if self.exact:
            self.extra_columns = type(self).extra_columns + self.exact_columns
        self.dt = math.nan
        self.ramp: TargetRamp | None = None

    # -- exact constraints: the targets' ramp (no physics: numbers in, numbers out) ----------
    def start_ramp(self, V0: float, A0: float) -> None:
        """Targets from the initial state's own V₀, A₀ to α, β (:class:`TargetRamp`)."""
        self.ramp = TargetRamp.between((V0, A0), (self.params.alpha, self.params.beta))

    @property
    def dissipative(self) -> bool:
        """False while exact constraints move their targets: E_M may rise on such a step."""
        return not (self.ramp is not None and self.ramp.moving)

    def ramp_state(self) -> dict:
        return {"ramp": self.ramp.state()} if self.ramp is not None else {}

    def set_ramp_state(self, state: dict) -> None:
        """The ramp of a state; a state without one (e.g. of a penalty run) starts at α, β."""
        if not self.exact:
            return
        if "ramp" in state:
            self.ramp = TargetRamp.from_state(state["ramp"])
        else:
            end = (self.params.alpha, self.params.beta)
            self.ramp = TargetRamp(end, end, 1.0, 1.0, fraction=1.0)

    @classmethod
    def check(cls, scene: Scene, *, n: int, dt: float, scheme: str = "paper",
              constraints: str = "penalty", allow_underresolved: bool = False,
              **options) -> None:
        check_choice("scheme", scheme, SCHEMES)
        check_choice("constraints", constraints, CONSTRAINTS)
        unknown = set(options) - set(BACKENDS[cls.name].option_names)
        if unknown:
            raise ModelError(f"the {cls.name} backend takes no option(s) {sorted(unknown)}")
        params = scene.params.for_constraints(constraints).validate()
        scene.validate()
        cls.check_n(n, **options)
        least = cls.min_n(**options)
        spacing = cls.check_options(scene, n, **options)
        check_resolution(params, n, dt, allow_underresolved=allow_underresolved,
                         check_dt=scheme == "paper", spacing=spacing, min_n=least)
        need, have = cls.memory_bytes(scene, n, **options), physical_memory()
        if need > 0.8 * have:
            raise ModelError(f"n = {n} needs about {need / 2**30:.3g} GB of memory with the "
                             f"{cls.name} backend; this machine has {have / 2**30:.3g} GB")

    @classmethod
    def memory_bytes(cls, scene: Scene, n: int, **options) -> float:
        """About how much memory a run needs (bytes): ``bytes_per_dof`` per unknown."""
        return cls.bytes_per_dof * float(n) ** scene.dim

    #: memory per unknown (measured, with margin: the spectral step's dozen grid arrays)
    bytes_per_dof = 400.0

    @classmethod
    def default_n(cls, scene: Scene, **options) -> int:
        """The n of a run that gives none, in nodes per axis: the scene's grid."""
        return scene.n

    @classmethod
    def nodes_per_axis(cls, n: int, **options) -> int | None:
        """The cubic grid a run's scene records (its ``n``): ``n`` itself, or None where the
        run has no cubic grid (a mesh file, the (r, z) half-plane)."""
        return n

    @classmethod
    def run_options(cls, options: dict) -> dict:
        """The backend's options as a run records them: those given, and the defaults a run
        takes that its backend's constructor does not (the FEM's element order)."""
        return dict(options)

    @classmethod
    def min_n(cls, **options) -> int:
        """The smallest n (nodes per axis) a run takes: a grid of 8 points per axis."""
        return 8

    @classmethod
    def check_n(cls, n, **options) -> None:
        """A run's ``n`` — nodes per axis, at every layer (``--n``, ``simulate(n=...)``,
        the constructor, run.json) — for this backend and options; ModelError (one line)."""
        least = cls.min_n(**options)
        if not isinstance(n, int) or isinstance(n, bool) or n < least:
            raise ModelError(f"n must be an integer >= {least}, got {n!r}")

    @classmethod
    def check_options(cls, scene: Scene, n: int, **options) -> float:
        """Validate the backend's own options (ModelError); return the largest node spacing
        (the resolution check: it must not exceed ε)."""
        return scene.params.L / n

    def initial_field(self, points: np.ndarray, *, ic: str, perturb: float,
                      seed: int) -> np.ndarray:
        """φ₀ at ``points`` (shape (dim, ...)) from the scene's initial condition."""
        return self.scene.initial_phi(points, ic=ic, perturb=perturb, seed=seed)

    def max_abs_phi(self) -> float:
        m = float(np.max(np.abs(self.phi)))
        return m if math.isfinite(m) else math.nan

    def describe_final(self, final: dict, grid: np.ndarray | None = None):
        """(shape descriptors of the φ = 0 surface or None, (φ on the uniform grid, the
        surface, the full descriptors)): 3D runs with a finite field (:mod:`fem_ade.analysis.shape`;
        the axisymmetric FEM: :mod:`fem_ade.analysis.axishape`). ``final``: the diagnostics, whose
        diffuse V, A, ΔA the reduced values use; ``grid``: :meth:`grid_phi` if the caller
        has it."""
        from fem_ade.analysis.shape import SHAPE_KEYS, describe
        from fem_ade.analysis.surface import extract_surface

        p = self.scene.params
        grid = np.asarray(self.grid_phi() if grid is None else grid)
        if self.scene.dim != 3 or not np.all(np.isfinite(grid)):
            return None, (grid, None, None)
        surface = extract_surface(grid, p.L)
        d = describe(grid, p.L, V=final.get("V"), A=final.get("A"),
                     dA=final.get("dA") if p.on("ade") else None, D=p.D, surface=surface)
        shape = {k: d["sharp"][k] if k in d["sharp"] else d[k] for k in SHAPE_KEYS}
        shape["diffuse"] = {k: d[k] for k in ("reduced_volume", "reduced_area_difference")}
        shape["sharp"] = d["sharp"]
        return shape, (grid, surface, d)

    def resolution_per_length(self) -> float:
        """Grid points per L along an axis of the field the shape is measured on (the in-run
        sharp comparison needs at least one per ε): n."""
        return float(self.n)


def physical_memory() -> float:
    """The machine's memory in bytes."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # not POSIX: do not refuse anything
        return math.inf


def check_choice(what: str, value, valid) -> None:
    """ModelError "unknown WHAT 'value'; valid: ..." unless ``value`` is in ``valid``."""
    if value not in valid:
        raise ModelError(f"unknown {what} {value!r}; valid: {', '.join(map(str, valid))}")


def backend_class(name: str, **options) -> type:
    """The class of backend ``name`` that runs ``options`` (:data:`fem_ade.registry.BACKENDS`:
    its class, or a variant's, e.g. the PETSc FEM for ``linalg="petsc"``), imported on
    demand."""
    check_choice("backend", name, BACKENDS)
    module_name, cls_name = BACKENDS[name].target_for(**options).split(":")
    return getattr(importlib.import_module(module_name), cls_name)


def check_backend(name: str, scene: Scene, **kwargs) -> None:
    """Validate a run of backend ``name`` before anything is built (see :meth:`Backend.check`)."""
    backend_class(name, **kwargs).check(scene, **kwargs)


def make_backend(name: str, scene: Scene, **kwargs) -> Backend:
    """Build backend ``name`` for ``scene``. Unknown names raise :class:`ModelError`, so do
    an n that is not a positive integer and a scene that is not a Scene (TypeError)."""
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")
    n = kwargs.get("n")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ModelError(f"n must be a positive integer, got {n!r}")
    kwargs["n"] = int(n)
    return backend_class(name, **kwargs)(scene, **kwargs)
