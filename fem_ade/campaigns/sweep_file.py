"""A sweep's file (:mod:`fem_ade.campaigns.sweep` runs it): its TOML read into a
:class:`Sweep` and its :class:`Point` s, every mistake refused with one line before anything
runs (:func:`load_sweep`, :func:`check_sweep`); the studies build the same from their plans
(:func:`listed_sweep`).

A sweep file names a base scene, the fixed and the swept parameters, the seeds of each point
and the run's options::

    name = "tiny"
    base = "vesicle"                      # the vesicle family, a catalogue scene or a .toml
    seeds = ["prolate", "oblate"]         # vesicle: the branches each point starts from
    [scene]                               # fixed: the vesicle's v, da0, kbar, C, eps, R0, or
    eps = 0.08                            #   any scene or Params field of another base
    [axes]                                # swept: a list, or {start, stop, num}
    v = [0.7, 0.9]
    [run]                                 # fem_ade.engine.runs.simulate's options; recipe expands
    recipe = "steady"                     #   (geometry = "axisymmetric": the FEM's, §11)
    backend = "spectral"
    n = 16
    max_steps = 20
    constraints = "exact"

With a ``[branch]`` table each point is a branch followed by continuation
(:func:`fem_ade.campaigns.branch.follow`, axisymmetric) instead of a run: its parameter must be
neither
fixed nor swept, ``[run]`` may set only ``n`` and ``backend_options`` (e.g. the order)::

    [branch]
    param = "v"                           # v, da0, kbar or C
    from = 0.95                           # the first point (the seed's steady state)
    to = 0.8
    step = 0.01                           # the arclength step (default 0.01)
    folds = 0                             # optional: end past this many folds
    stability = false                     # optional: no stability at the points (faster)

Its row is the branch's last point (``steps``: its number of points; ``end``: the
parameter there; ``folds``: where it turned); one branch per Dask task. Its points may also
be listed (below), each with its own ends over [branch]'s: ``branch = {from = 0.7, to =
0.62}``; a branch starts from its seed, so there is no ``after``.

Points can also be listed one by one, beside the grid of ``[axes]`` or instead of it; a
listed point may start from another point's end (``after``: its final field, resampled to
this point's nodes), so that a chain of runs — ε halved from the last ε's steady state, a
steady end kicked to test its stability — is one sweep file::

    [[points]]
    name = "eps=0.02"                     # its folder's name (letters, digits, . _ - =)
    seed = "prolate"                      # vesicle: its branch (default: the first seed)
    base = "vesicle"                      # (default: the sweep's base; or a scene file's
                                          #  table: a scene made in code, scene_to_mapping)
    scene = {eps = 0.02}                  # over [scene]
    run = {n = 96}                        # over [run]
    [[points]]
    name = "eps=0.01"
    scene = {eps = 0.01}
    after = "eps=0.02"                    # starts from that point's final field
    when = ["steady"]                     # optional: only after such an end (else skipped)

Dask runs a point only after the one it starts from; if that one ended without a result
(failed, diverged) the point is recorded as failed, with the reason. A listed point's
``scene`` keys are columns of the table, as the axes are; ``after`` is one too.

Why a module of its own: what a sweep is — its points, their names and identities — is
read apart from running it (the studies build and check theirs; a point's row is
:mod:`fem_ade.campaigns.sweep_points`'s), and each of its checks is an error message, which
makes this the long part of a sweep.
"""

from __future__ import annotations

import itertools
import json
import re
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

from fem_ade.model.params import ModelError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

#: the run options a sweep's [run] table may set (fem_ade.engine.runs.simulate's keywords)
RUN_KEYS = {"recipe": str, "backend": str, "n": int, "dt": float, "steps": int,
            "until_steady": float, "max_steps": int, "every": int, "scheme": str,
            "constraints": str, "accelerate": bool, "perturb": float,
            "checkpoint_every": int, "render": bool, "backend_options": dict,
            "allow_underresolved": bool, "geometry": str, "ic": str, "shape_every": int,
            "sharp": bool}


@dataclass(frozen=True)
class Point:
    """One run of a sweep: its name, the scene's parameters, its seed and run options."""

    name: str
    base: str | dict  # a scene's name (or the vesicle family), or a scene file's table
    values: dict  # the swept parameters' values
    fixed: dict
    seed: object
    run: dict = field(default_factory=dict)
    #: a branch point's continuation (param, from, to, step, folds), or None: a run
    branch: dict | None = None
    #: the point whose end it starts from (its name), and that point's identity; the
    #: statuses of that end it runs after (None: any end with a result)
    after: str | None = None
    start: dict | None = None
    when: tuple | None = None

    def scene(self, *, sharp_seed: bool = True):
        """The point's scene; ``sharp_seed=False``: a vesicle's without its sharp seed (to
        check options with, :func:`fem_ade.scenes.vesicle.vesicle_parts`)."""
        from fem_ade.scenes.catalogue import resolve_scene, vesicle_scene

        start = {self.branch["param"]: self.branch["from"]} if self.branch else {}
        if self.base == "vesicle" and self.branch and sharp_seed:  # R₀ to fit both ends
            from fem_ade.campaigns.branch import vesicle_for_branch

            return vesicle_for_branch({**self.fixed, **self.values, "branch": self.seed},
                                      self.branch["param"], self.branch["from"],
                                      self.branch["to"])
        if self.base == "vesicle":
            return vesicle_scene(**self.fixed, **self.values, **start, branch=self.seed,
                                 sharp_seed=sharp_seed)
        if isinstance(self.base, dict):  # a listed point's own scene (a scene file's table)
            from fem_ade.scenes.catalogue import scene_from_mapping

            made = scene_from_mapping(self.base, where=f"point {self.name}: base")
        else:
            made = resolve_scene(self.base)
        scene = made.with_(**self.fixed, **self.values)
        if self.branch:
            from fem_ade.campaigns.branch import set_parameter

            scene = replace(scene, params=set_parameter(scene.params, self.branch["param"],
                                                        self.branch["from"]))
        return scene

    def identity(self) -> dict:
        """What this point is: its base, fixed and swept parameters, seed, run options and
        the version of the model's discrete physics (a run folder is reused only for the
        same; the resolved scene and configuration follow from them)."""
        from fem_ade.model.params import PHYSICS_VERSION

        what = {"base": self.base, "fixed": self.fixed, "values": self.values,
                "seed": self.seed, "run": self.run, "physics": PHYSICS_VERSION}
        if self.branch:  # (absent for a run: the folders of before stay theirs)
            what["branch"] = self.branch
        if self.after:  # a point is also where it starts from
            what["after"] = {"point": self.after, "identity": self.start,
                             **({"when": list(self.when)} if self.when else {})}
        return json.loads(json.dumps(what, sort_keys=True, default=str))

    def options(self, scene) -> dict:
        from fem_ade.engine.runs import recipe

        run = dict(self.run)
        kw = recipe(run.pop("recipe"), scene) if "recipe" in run else {}
        if "geometry" in run:  # the FEM's geometry (docs/model.md §11): a backend option
            run["backend_options"] = {**run.get("backend_options", {}),
                                      "geometry": run.pop("geometry")}
        if "steps" in run:
            kw.pop("until_steady", None)
            kw.pop("max_steps", None)
        kw.update(run)
        kw.setdefault("checkpoint_every", 50)
        kw.setdefault("render", False)
        if self.base != "vesicle":
            kw["seed"] = int(self.seed)
        return kw


@dataclass
class Sweep:
    name: str
    base: str
    axes: dict
    fixed: dict
    seeds: list
    run: dict
    branch: dict | None = None
    #: the points listed one by one ([[points]]: name, seed, scene, run, after)
    listed: list = field(default_factory=list)

    def columns(self) -> list[str]:
        """The table's parameter columns: the axes, then the listed points' scene keys."""
        extra = [k for p in self.listed for k in p["scene"]]
        return list(dict.fromkeys([*self.axes, *extra]))

    def points(self) -> list[Point]:
        """The grid's points (one per value of each axis and seed; none when points are
        listed and there are no axes), then the listed ones."""
        out = self._grid() if self.axes or not self.listed else []
        made = {p.name: p for p in out}
        for spec in self.listed:
            start = made[spec["after"]].identity() if spec["after"] else None
            made[spec["name"]] = point = Point(
                spec["name"], spec.get("base", self.base), dict(spec["scene"]),
                {k: v for k, v in self.fixed.items() if k not in spec["scene"]},
                spec["seed"], {**self.run, **spec["run"]}, spec.get("branch"),
                after=spec["after"], start=start,
                when=tuple(spec["when"]) if spec.get("when") else None)
            out.append(point)
        return out

    def _grid(self) -> list[Point]:
        names = list(self.axes)
        out = []
        for combo in itertools.product(*(self.axes[k] for k in names)):
            values = dict(zip(names, combo, strict=True))
            for seed in self.seeds:
                label = "_".join([f"{k}={_fmt(v)}" for k, v in values.items()]
                                 + [f"seed={seed}"])
                out.append(Point(label, self.base, values, dict(self.fixed), seed,
                                 dict(self.run), dict(self.branch) if self.branch else None))
        return out


def _fmt(value) -> str:
    """A value in a point's name: a float's shortest round-trip form (0.9 and 0.9000001 are
    two names), anything else as text."""
    if isinstance(value, float):
        return repr(value) if not value.is_integer() else f"{value:g}"
    return str(value)


def load_sweep(path: str | Path) -> Sweep:
    """A sweep from its TOML file (see the module docstring); ModelError (one line)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ModelError(f"sweep file not found: {path}") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ModelError(f"cannot read sweep file {path}: {err}") from None
    except tomllib.TOMLDecodeError as err:
        raise ModelError(f"malformed TOML in {path}: {err}") from None
    known = {"name", "base", "seeds", "scene", "axes", "run", "branch", "points"}
    unknown = set(data) - known
    if unknown:
        raise ModelError(f"unknown key(s) {', '.join(sorted(unknown))} in {path}; valid: "
                         f"{', '.join(sorted(known))}")
    base = data.get("base", "vesicle")
    if not isinstance(base, str):
        raise ModelError(f"base must be a scene name, got {base!r}")
    axes = {}
    for key, spec in data.get("axes", {}).items():
        if isinstance(spec, dict):
            try:
                start, stop, num = float(spec["start"]), float(spec["stop"]), spec["num"]
            except (KeyError, TypeError, ValueError):
                raise ModelError(f"axes.{key} as a table needs start, stop and num") from None
            if isinstance(num, bool) or not isinstance(num, int) or num < 1:
                raise ModelError(f"axes.{key}.num must be an integer >= 1, got {num!r}")
            axes[key] = [round(start + (stop - start) * i / max(num - 1, 1), 10)
                         for i in range(num)]
        elif isinstance(spec, list) and spec:
            axes[key] = spec
        else:
            raise ModelError(f"axes.{key} must be a non-empty list or {{start, stop, num}}")
    for key, values in axes.items():
        for value in values:
            if isinstance(value, bool) or not isinstance(value, (int, float, str)):
                raise ModelError(f"axes.{key}: {value!r} is not a number or a name")
        if len(set(map(_fmt, values))) != len(values):
            raise ModelError(f"axes.{key} lists a value twice: {values}")
    seeds = data.get("seeds", ["prolate"] if base == "vesicle" else [0])
    if not isinstance(seeds, list) or not seeds:
        raise ModelError("seeds must be a non-empty list")
    if len(set(map(str, seeds))) != len(seeds):
        raise ModelError(f"seeds lists a seed twice: {seeds}")
    for seed in seeds:
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]*", str(seed)):
            raise ModelError(f"a seed must be a plain name (letters, digits, . _ -), got "
                             f"{seed!r}")
    fixed = data.get("scene", {})
    if not isinstance(fixed, dict):
        raise ModelError("[scene] must be a table")
    both = sorted(set(fixed) & set(axes))
    if both:
        raise ModelError(f"{', '.join(both)} is both fixed ([scene]) and swept ([axes])")
    for table, keys in (("scene", fixed), ("axes", axes)):
        _scene_keys(base, keys, f"[{table}]")
    run = _run_table(data.get("run", {}), "[run]")
    branch = _branch_table(data.get("branch"), fixed, axes, run)
    listed = _listed(data.get("points", []), base, seeds, axes, branch)
    sweep = Sweep(str(data.get("name", path.stem)), base, axes, dict(fixed), seeds, run, branch,
                  listed)
    check_sweep(sweep)
    return sweep


def listed_sweep(name: str, specs: list[dict], *, base: str = "vesicle") -> Sweep:
    """A sweep of points listed in code — each a ``[[points]]`` table as a sweep file gives
    it (name, base, seed, scene, run; optionally after, when, and a branch point's whole
    ``branch``) — checked as a sweep file's is (:func:`check_sweep`; ModelError, one line).
    Its seeds are its points'; with branch points, [branch] is the first one's."""
    full = [{"seed": 0, "scene": {}, "run": {}, "after": None, "when": None, **spec}
            for spec in specs]
    branch = next((spec["branch"] for spec in full if spec.get("branch")), None)
    sweep = Sweep(name, base, {}, {}, list(dict.fromkeys(spec["seed"] for spec in full)), {},
                  branch, listed=full)
    check_sweep(sweep)
    return sweep


def _scene_keys(base: str, keys, where: str) -> None:
    """A vesicle sweep's scene keys must be the family's parameters (ModelError)."""
    if base != "vesicle":
        return
    from fem_ade.scenes.vesicle import Vesicle

    allowed = set(Vesicle.__dataclass_fields__) - {"branch"}
    bad = sorted(set(keys) - allowed)
    if bad:
        raise ModelError(f"{where} {', '.join(bad)}: not a parameter of the vesicle family "
                         f"(its branch is the seed); valid: {', '.join(sorted(allowed))}")


def _run_table(run, where: str) -> dict:
    """A [run] table (or a listed point's ``run``), its values checked and floats made float."""
    if not isinstance(run, dict):
        raise ModelError(f"{where} must be a table")
    run = dict(run)
    for key, value in run.items():
        kind = RUN_KEYS.get(key)
        if kind is None:
            raise ModelError(f"unknown run option {key!r} in {where}; valid: "
                             f"{', '.join(RUN_KEYS)}")
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            run[key] = float(value)
        elif not isinstance(value, kind) or (kind is not bool and isinstance(value, bool)):
            raise ModelError(f"run.{key} must be of type {kind.__name__}, got {value!r}"
                             + ("" if where == "[run]" else f" in {where}"))
    return run


#: a listed point's keys (a branch sweep's: ``branch`` for ``after`` and ``when``)
POINT_KEYS = ("name", "base", "seed", "scene", "run", "after", "when")
BRANCH_POINT_KEYS = ("name", "base", "seed", "scene", "run", "branch")


def _listed(points, base: str, seeds: list, axes: dict, branch: dict | None = None
            ) -> list[dict]:
    """The [[points]] tables, checked for their form: a new plain name each, a seed of the
    sweep's, scene keys (over [scene]; an axis's too: the point is off the grid), run options,
    and ``after`` naming a point made before it (a grid point or one listed above: no cycle
    can be written). In a branch sweep a point follows its own branch from its seed: its
    ``branch`` (from, to, step, folds over [branch]) instead of ``after``."""
    if not isinstance(points, list) or not all(isinstance(p, dict) for p in points):
        raise ModelError("points must be a list of tables ([[points]])")
    grid = set()
    if axes or not points:
        grid = {p.name for p in Sweep("", base, axes, {}, seeds, {})._grid()}
    out, names = [], set(grid)
    for i, table in enumerate(points, 1):
        where = f"[[points]] #{i}"
        keys = BRANCH_POINT_KEYS if branch else POINT_KEYS
        unknown = sorted(set(table) - set(keys))
        if unknown:
            raise ModelError(f"unknown key(s) {', '.join(unknown)} in {where}; valid: "
                             f"{', '.join(keys)}"
                             + (" (a branch starts from its seed)" if branch and {
                                 "after", "when"} & set(unknown) else ""))
        name = table.get("name")
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._=-]*", name):
            raise ModelError(f"{where} needs a name of letters, digits and . _ - = (its "
                             f"folder's), got {name!r}")
        where = f"[[points]] {name}"
        if name in names:
            raise ModelError(f"{where}: a point of that name is already in the sweep")
        own = table.get("base", base)
        if isinstance(own, dict):  # a scene of its own: what a scene file holds
            from fem_ade.scenes.catalogue import scene_from_mapping

            scene_from_mapping(own, where=f"{where}: base")
        elif not isinstance(own, str):
            raise ModelError(f"{where}: base must be a scene name or a scene's table, got "
                             f"{own!r}")
        seed = table.get("seed", seeds[0])
        if str(seed) not in map(str, seeds):
            raise ModelError(f"{where}: seed {seed!r} is not one of the sweep's seeds "
                             f"({', '.join(map(str, seeds))})")
        scene = table.get("scene", {})
        if not isinstance(scene, dict):
            raise ModelError(f"{where}: scene must be a table")
        _scene_keys(own, scene, f"{where}: scene")
        after = table.get("after")
        if after is not None and after not in names:
            raise ModelError(f"{where}: after = {after!r} names no point before it (a grid "
                             "point or one listed above)")
        run = _run_table(table.get("run", {}), where)
        spec = {"name": name, "base": own, "seed": seed, "scene": dict(scene), "run": run,
                "after": after, "when": _when(table.get("when"), after, where)}
        if branch:
            spec["branch"] = _point_branch(table.get("branch", {}), branch, scene, run, where)
        out.append(spec)
        names.add(name)
    return out


#: a [branch] table's keys (their types) and the [run] options a branch sweep takes
BRANCH_KEYS = {"param": str, "from": float, "to": float, "step": float, "folds": int,
               "stability": bool, "modes": int}
BRANCH_RUN_KEYS = ("n", "backend_options")


def _branch_table(table, fixed: dict, axes: dict, run: dict) -> dict | None:
    """The [branch] table, checked for its form (its values by :func:`check_sweep`)."""
    if table is None:
        return None
    if not isinstance(table, dict):
        raise ModelError("[branch] must be a table")
    unknown = sorted(set(table) - set(BRANCH_KEYS))
    if unknown:
        raise ModelError(f"unknown key(s) {', '.join(unknown)} in [branch]; valid: "
                         f"{', '.join(BRANCH_KEYS)}")
    missing = [k for k in ("param", "from", "to") if k not in table]
    if missing:
        raise ModelError(f"[branch] needs {', '.join(missing)}")
    out = _branch_types({"step": 0.01, "folds": None, **table}, "branch")
    from fem_ade.campaigns.branch import PARAMETERS

    if out["param"] not in PARAMETERS:
        raise ModelError(f"branch.param (--param) must be one of {', '.join(PARAMETERS)}, "
                         f"got {out['param']!r}")
    where = "[scene]" if out["param"] in fixed else "[axes]" if out["param"] in axes else None
    if where:
        raise ModelError(f"{out['param']} is the branch's parameter ([branch] from, to); it "
                         f"cannot be in {where} too")
    _branch_run(run, "[run]")
    return out


def _branch_types(table: dict, where: str) -> dict:
    """A branch table's values of their types (ints as floats where a float is asked)."""
    out = dict(table)
    for key, value in table.items():
        kind = BRANCH_KEYS[key]
        if key == "folds" and value is None:
            continue
        if kind is bool:
            if not isinstance(value, bool):
                raise ModelError(f"{where}.{key} must be true or false, got {value!r}")
            continue
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            out[key] = value = float(value)
        if not isinstance(value, kind) or isinstance(value, bool):
            raise ModelError(f"{where}.{key} must be of type {kind.__name__}, got {value!r}")
    return out


def _branch_run(run: dict, where: str) -> None:
    other = sorted(set(run) - set(BRANCH_RUN_KEYS))
    if other:
        raise ModelError(f"run option(s) {', '.join(other)}: a branch sweep's {where} takes "
                         f"only {', '.join(BRANCH_RUN_KEYS)} (each point is Newton's "
                         "continuation, not a run)")


def _point_branch(table, branch: dict, scene: dict, run: dict, where: str) -> dict:
    """A listed point's branch in a branch sweep: [branch] with the point's own from, to,
    step or folds (its parameter is the sweep's)."""
    if not isinstance(table, dict):
        raise ModelError(f"{where}: branch must be a table")
    own = sorted(set(table) - (set(BRANCH_KEYS) - {"param"}))
    if own:
        raise ModelError(f"unknown key(s) {', '.join(own)} in {where}: branch; valid: "
                         f"{', '.join(k for k in BRANCH_KEYS if k != 'param')} (the "
                         "parameter is [branch]'s)")
    if branch["param"] in scene:
        raise ModelError(f"{where}: {branch['param']} is the branch's parameter; give it as "
                         "branch = {from, to}, not in scene")
    _branch_run(run, f"{where}: run")
    return {**branch, **_branch_types(table, f"{where}: branch")}


def _when(when, after, where: str) -> list | None:
    """A listed point's ``when``: the end statuses of its start it runs after."""
    if when is None:
        return None
    from fem_ade.store.status import HAS_RESULT

    valid = sorted(str(s) for s in HAS_RESULT)
    if after is None:
        raise ModelError(f"{where}: when needs after (the point whose end it starts from)")
    if not isinstance(when, list) or not when or any(w not in valid for w in when):
        raise ModelError(f"{where}: when must be a list of the statuses {', '.join(valid)}, "
                         f"got {when!r}")
    return when


def check_sweep(sweep: Sweep) -> None:
    """Every point's parameters and the run options, before anything runs (ModelError, one
    line): each point's vesicle (or scene) without its sharp seed, and the first point's
    run and each listed point's — its scene built (a vesicle's without its sharp seed),
    its configuration checked as a run's."""
    from fem_ade.registry import RECIPES

    for run in (sweep.run, *(spec["run"] for spec in sweep.listed)):
        if "recipe" in run and run["recipe"] not in RECIPES:
            raise ModelError(f"unknown recipe {run['recipe']!r}; valid: {', '.join(RECIPES)}")
    points = sweep.points()
    for point in points:
        try:
            if point.base == "vesicle":
                from fem_ade.scenes.vesicle import Vesicle

                start = {point.branch["param"]: point.branch["from"]} if point.branch else {}
                Vesicle(**point.fixed, **point.values, **start, branch=point.seed).check()
            elif point is points[0]:
                pass  # built below
        except TypeError as err:
            raise ModelError(f"point {point.name}: {err}") from None
        except ModelError as err:
            raise ModelError(f"point {point.name}: {err}") from None
    first = points[0]
    if sweep.branch:  # each point's scene, ends and run, as follow checks them
        from fem_ade.campaigns.branch import check_follow

        for point in points:
            b = point.branch
            try:
                run = point.run  # (n, backend_options: _branch_run)
                options = run.get("backend_options")
                check_follow(point.scene(sharp_seed=False), param=b["param"],
                             start=b["from"], stop=b["to"], step=b["step"], folds=b["folds"],
                             n=run.get("n"), backend_options=options,
                             modes=b.get("modes", 0),
                             branch=point.seed if point.base == "vesicle" else None)
            except (ModelError, TypeError, KeyError) as err:
                raise ModelError(f"point {point.name}: {err}") from None
        return
    listed = {spec["name"] for spec in sweep.listed}
    for point in points:  # the first point's run, and each listed point's (its own options)
        if point is first or point.name in listed:
            _check_run(point)


def _check_run(point: Point) -> None:
    """The point's scene built and its run's configuration checked (ModelError, one line).
    A vesicle's scene without its sharp seed: what only the seed tells (it fits the box, it
    is thick enough) is the point's own failure when it runs, recorded with the reason."""
    from fem_ade.engine.config import RunConfig

    try:
        scene = point.scene(sharp_seed=False)
        kw = point.options(scene)
        allow = kw.pop("allow_underresolved", False)
        kw.pop("checkpoint_every", None)
        config = RunConfig.build(scene, **{k: v for k, v in kw.items() if k in (
            "backend", "n", "dt", "steps", "until_steady", "backend_options")},
            **{k: v for k, v in kw.items() if k in (
                "max_steps", "every", "scheme", "constraints", "accelerate", "perturb",
                "render", "sharp", "seed")})
        config.check(scene, allow_underresolved=allow)
    except TypeError as err:
        raise ModelError(f"point {point.name}: {err}") from None
    except ModelError as err:
        raise ModelError(f"point {point.name}: {err}") from None
