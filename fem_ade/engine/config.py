"""One run configuration: :class:`RunConfig`, every choice of a run, checked once.

The command line, the Python API (:func:`fem_ade.engine.runs.simulate`), a resume (from
``run.json``), the studies and a sweep all build the same frozen, validated object; a run
folder's ``run.json`` is its :meth:`RunConfig.to_mapping` — what was actually run, with the
scene as run (its resolution and, for ``--ic seeded``, the seeded shape) — and
:meth:`RunConfig.from_mapping` reads it back with the same checks as a new run's. A value such
as ``dt`` goes CLI → :class:`RunConfig` → :func:`fem_ade.engine.runs.simulate` → the loop → the
backend's ``set_dt``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np

from fem_ade.backends.base import backend_class, check_backend
from fem_ade.engine.loop import AdaptiveDt, check_loop_options, option
from fem_ade.model.params import ModelError, is_int, is_real, max_stable_dt
from fem_ade.scenes.catalogue import Scene


@dataclass(frozen=True)
class RunConfig:
    """Every choice of a run but its scene and output folder (``fem_ade.engine.runs.simulate``'s
    keyword arguments, with the scene's defaults filled in by :meth:`build`).

    ``steps`` or ``until_steady`` (with ``max_steps``) says how long; ``every`` how often a
    history row is recorded; ``adaptive``: the fields of :class:`fem_ade.engine.loop.AdaptiveDt` or
    None; ``backend_options``: the backend's own (``fem_ade.registry.BACKENDS``).
    """

    backend: str
    n: int
    dt: float
    steps: int | None = None
    until_steady: float | None = None
    max_steps: int = 100_000
    every: int = 10
    ic: str = "consistent"
    perturb: float = 0.0
    seed: int = 0
    scheme: str = "paper"
    constraints: str = "penalty"
    adaptive: dict | None = None
    accelerate: bool = False
    checkpoint_every: int | None = None
    save_every: int | None = None
    shape_every: int | None = None
    render: bool = True
    #: compare the end shape with its sharp membrane (a sharp_ref solve of 0.3–10 s)
    sharp: bool = True
    backend_options: dict = field(default_factory=dict)

    # -- building ---------------------------------------------------------------------------
    @classmethod
    def build(cls, scene, *, backend: str = "fem", n: int | None = None,
              dt: float | None = None, steps: int | None = None,
              until_steady: float | None = None, adaptive: bool | dict = False,
              backend_options: dict | None = None, **kwargs) -> RunConfig:
        """A run of ``scene``: its defaults filled in (the backend's n for the scene, the
        scene's Δt and steps), ``adaptive=True`` made concrete (Δt in [Δt/1000, 1000Δt],
        below ε³/κ with the paper's scheme), and every value checked (ModelError, one
        line; TypeError for a value of the wrong kind)."""
        if not isinstance(scene, Scene):
            raise TypeError(f"scene must be a Scene, got {type(scene).__name__}")
        n, steps = (int(x) if isinstance(x, np.integer) else x for x in (n, steps))
        for name in ("max_steps", "every", "seed", "checkpoint_every", "save_every",
                     "shape_every"):
            if isinstance(kwargs.get(name), np.integer):  # numpy's integers are integers
                kwargs[name] = int(kwargs[name])
        if backend_options is not None and not isinstance(backend_options, dict):
            raise TypeError(f"backend_options must be a dict, got "
                            f"{type(backend_options).__name__}")
        for name, value in (("dt", dt), ("until_steady", until_steady)):
            if value is not None and (isinstance(value, bool) or not isinstance(
                    value, (int, float, np.integer, np.floating))):
                raise ModelError(f"{name} must be a number, got {value!r}")
        options = dict(backend_options or {})
        counts = backend_class(backend, **options)
        options = counts.run_options(options)
        n = counts.default_n(scene, **options) if n is None else n  # nodes per axis
        dt = scene.dt if dt is None else dt
        if steps is None and until_steady is None:
            steps = scene.steps
        scheme = kwargs.get("scheme", "paper")
        if adaptive is True:
            if not (is_real(dt) and dt > 0):
                raise ModelError(f"--dt must be a positive number, got {dt}")
            dt_max = 1000 * dt if scheme == "stabilized" else min(
                1000 * dt, 0.9 * max_stable_dt(scene.params))
            adaptive = {"dt_min": dt / 1000, "dt_max": max(dt, dt_max)}
        adaptive = asdict(AdaptiveDt(**adaptive)) if adaptive else None
        return cls(backend=backend, n=n, dt=dt, steps=steps, until_steady=until_steady,
                   adaptive=adaptive, backend_options=options, **kwargs)

    def with_(self, **changes) -> RunConfig:
        return replace(self, **changes)

    # -- checks -----------------------------------------------------------------------------
    def check(self, scene, *, allow_underresolved: bool = False) -> None:
        """Everything a run needs of its configuration, before anything is built or
        written: the backend and its options against the scene (resolution, Δt, memory), the
        loop's numbers, the perturbation, momentum without adaptive Δt."""
        if not isinstance(self.backend_options, dict):
            raise ModelError(f"backend_options must be a table, got {self.backend_options!r}")
        if not is_real(self.perturb) or self.perturb < 0:
            raise ModelError(f"{option('perturb')} must be a number >= 0, got {self.perturb!r}")
        if not is_int(self.seed, 0):
            raise ModelError(f"{option('seed')} must be an integer >= 0, got {self.seed!r}")
        check_loop_options(steps=self.steps, until_steady=self.until_steady,
                           max_steps=self.max_steps, every=self.every,
                           checkpoint_every=self.checkpoint_every,
                           save_every=self.save_every, shape_every=self.shape_every,
                           accelerate=self.accelerate, adaptive=self.adaptive)
        check_backend(self.backend, scene, n=self.n, dt=self.dt, scheme=self.scheme,
                      constraints=self.constraints, allow_underresolved=allow_underresolved,
                      **self.backend_options)
        if self.adaptive is not None:
            if not isinstance(self.adaptive, dict):
                raise ModelError(f"adaptive must be a table, got {self.adaptive!r}")
            try:
                AdaptiveDt(**self.adaptive)
            except TypeError as err:
                raise ModelError(f"adaptive: {err}") from None
        for name in ("accelerate", "render", "sharp"):
            if not isinstance(getattr(self, name), bool):
                raise ModelError(f"{name} must be true or false, got {getattr(self, name)!r}")

    @property
    def total_steps(self) -> int:
        """The step the run ends at the latest (``steps``, or ``max_steps`` to a steady state)."""
        return self.steps if self.until_steady is None else self.max_steps

    def continued_to(self, steps: int) -> RunConfig:
        """The same run, to step ``steps`` (a resume's --steps)."""
        check_loop_options(steps=steps, until_steady=None, max_steps=1, every=1)
        key = "steps" if self.until_steady is None else "max_steps"
        return replace(self, **{key: steps})

    # -- run.json ---------------------------------------------------------------------------
    def to_mapping(self) -> dict:
        """The configuration as run.json records it (and a checkpoint's identity): its fields
        and the :data:`RUN_FORMAT` they are written in."""
        return {**asdict(self), "format": RUN_FORMAT}

    @classmethod
    def from_mapping(cls, data) -> RunConfig:
        """The configuration of a run.json of any :data:`RUN_FORMAT` (ModelError if a key is
        missing; the values are checked by :meth:`check`)."""
        if not isinstance(data, dict):
            raise ModelError(f"a run configuration must be a table, got {type(data).__name__}")
        data = upgraded(data)
        names = {f.name for f in fields(cls)}
        missing = sorted(names - set(data))
        if missing:
            raise ModelError(f"run.json lacks {', '.join(missing)}")
        return cls(**{k: data[k] for k in names})


#: the format a run.json is written in: 2, ``n`` in nodes per axis (as ``--n`` and
#: ``simulate(n=...)`` give it) for every backend; a run.json without ``format`` (1, before
#: 2026-12) counted the FEM's ``n`` in cells of order p, and :func:`upgraded` reads it
RUN_FORMAT = 2


def upgraded(data: dict) -> dict:
    """A run configuration's mapping (run.json's, or a checkpoint's identity's) in the
    current :data:`RUN_FORMAT`: a format-1 FEM run on a tensor mesh has ``n`` cells of order
    p, n·p nodes per axis; a mesh file's n was the grid already. Anything else is returned
    as it is, for :meth:`RunConfig.check` to judge."""
    if data.get("format", 1) != 1:
        return data
    data = {**data, "format": RUN_FORMAT}
    options = data.get("backend_options")
    if data.get("backend") == "fem" and isinstance(options, dict) and is_int(data.get("n"), 1):
        order = options.get("order", 1)
        try:
            tensor = backend_class("fem", **options).is_tensor(options.get("mesh"))
        except ModelError:  # options no run takes: left to the checks
            return data
        if tensor and is_int(order, 1):
            data["n"] = data["n"] * order
    return data
