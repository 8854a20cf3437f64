"""Parameter sweeps on Dask: many runs to a steady state, resumable, and their table and
phase diagram.

    python -m fem_ade.sweep SWEEP.toml [--out DIR] [--workers N | --scheduler ADDRESS]
                            [--report-only] [--quiet]

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

Each point (one value per axis and one seed) is one run folder ``OUT/points/NAME`` (NAME from
its parameters, e.g. ``v=0.7_seed=prolate``), run by :func:`run_point` on a Dask worker: a
``LocalCluster`` of ``--workers`` processes (one thread each) by default, or the scheduler at
``--scheduler ADDRESS`` (or the scheduler's JSON file: one started by ``dask scheduler`` /
``dask worker``, ``dask-mpi`` or dask-jobqueue on Slurm/PBS; docs/cluster.md).
Killed at any moment and started again, a sweep skips the finished points, resumes those with
a checkpoint and never runs a point twice at once (the run folder's lock: a point whose
folder another process holds is waited for). A point that fails (bad parameters, an error)
is recorded with its reason in ``OUT/points/NAME.failed.json`` and the sweep goes on
(started again, it skips that point unless ``--retry-failed``).

Written: ``OUT/sweep.csv`` (one row per point, rebuilt from the run folders after each point:
an interrupted and resumed sweep ends with the table of an uninterrupted one),
``OUT/phase-diagram.png`` (each point coloured by its end state; the lowest-energy state per
point ringed; where seeds end in different states, marked; with the sharp reference's lowest
branch behind) and ``OUT/montage.png`` (the end shapes, when the runs render).
"""

from __future__ import annotations

import argparse
import itertools
import json
import logging
import os
import re
import signal
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from fem_ade.engine.jobs import failure_record, read_failure, record_failure
from fem_ade.model.params import ENERGY_COLUMNS, ModelError
from fem_ade.store.output import write_json_atomic
from fem_ade.store.status import ENDED, Status

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
#: the table's columns (the axes' names come first, after ``point``; no timings: a resumed
#: sweep's table is the uninterrupted one's, and each run's times are in its summary.json);
#: the energies are the history's (:data:`fem_ade.model.params.ENERGY_COLUMNS`: E, W, G)
COLUMNS = ("seed", "status", "steps", *ENERGY_COLUMNS, "e", "label", "components", "genus",
           "v_surface", "da_surface", "e_sharp_seed", "sharp_end", "reason")


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


# ---------------------------------------------------------------------------------------
# one point, on a worker
# ---------------------------------------------------------------------------------------
def run_point(point: Point, root: str, *started) -> dict:
    """Run (or resume, or skip) one point in ``root/points/NAME`` through
    :func:`fem_ade.engine.jobs.ensure`; its table row. A folder held by another process gives
    status ``busy`` (the driver tries again later). ``started``: the row of the point it
    starts from (Dask passes it once that one has run; the folder is what is read)."""
    from fem_ade.engine.jobs import ensure

    folder = Path(root) / "points" / point.name
    start = _start(point, Path(root))
    if start is not None and not isinstance(start, Path):  # its start is not there (yet)
        return start
    _record_point(point, folder)
    if point.branch:
        done = ensure(folder, make=lambda f: _follow(point, f))
    else:
        def scene():  # made only when the run starts: its errors are the point's failure
            made = point.scene()
            write_json_atomic(folder.with_name(point.name + ".seed.json"),
                        {"point": point.name, "seed": made.description,
                         "e_sharp": _seed_sharp_e(point)}, make_folder=True)
            return made

        done = ensure(folder, scene, options=point.options, after=start)
    if done.status == Status.BUSY:
        return {"point": point.name, "status": Status.BUSY, "reason": done.reason}
    return {**row(point, Path(root)), "task_s": done.seconds}


def _record_point(point: Point, folder: Path) -> None:
    """``NAME.point.json`` beside the point's folder: what the point is (its identity)."""
    write_json_atomic(folder.with_name(point.name + ".point.json"), point.identity(),
                      make_folder=True)


def _start(point: Point, root: Path) -> Path | dict | None:
    """The run folder a point starts from (``after``), None without one, or the point's row
    when it cannot start: ``busy`` while its start has not ended (the driver asks again),
    ``failed`` with the reason when its start ended without a result, ``skipped`` when it
    ended otherwise than ``when`` asks (looked at again on the next run of the sweep)."""
    if point.after is None:
        return None
    from fem_ade.engine.jobs import status_of
    from fem_ade.store.status import HAS_RESULT

    folder = root / "points" / point.name
    if (folder / "summary.json").is_file():  # it ran: a finished point is not looked at again
        return root / "points" / point.after
    start = root / "points" / point.after
    out = _head(point)
    status = (read_failure(start) or {}).get("status") or status_of(start)
    if status in HAS_RESULT and point.when and status not in point.when:
        reason = (f"not run: its start {point.after} ended {status}; it runs after "
                  f"{' or '.join(point.when)}")
        _record_point(point, folder)
        record_failure(folder, reason, status=Status.SKIPPED)
        return {**out, "status": Status.SKIPPED, "reason": reason}
    if status in HAS_RESULT:
        return start
    if status in ENDED | {Status.FAILED, Status.SKIPPED}:
        how = "was skipped" if status == Status.SKIPPED else f"ended {status}"
        reason = f"its start {point.after} {how}: there is no field to start from"
        _record_point(point, folder)
        record_failure(folder, reason)
        return {**out, "status": Status.FAILED, "reason": reason}
    return {**out, "status": Status.BUSY, "reason": f"waits for {point.after} to end"}


def _follow(point: Point, folder: Path) -> None:
    """A branch point: the branch followed (or gone on with, after a kill) in ``folder``,
    then its summary.json (status ``completed``: it is not followed again; ``seconds``: this
    call's wall time, its seed included)."""
    from fem_ade.campaigns.branch import follow

    t0 = time.perf_counter()
    b = point.branch
    rows = follow(point.scene(), param=b["param"], start=b["from"], stop=b["to"],
                  step=b["step"], out=folder, n=point.run.get("n"),
                  backend_options=point.run.get("backend_options"), quiet=True,
                  folds=b["folds"], stable=b.get("stability", True),
                  modes=b.get("modes", 0))
    # (no branch= check of the first point's shape: a sweep follows what its seed relaxes
    # to, and its table's label says what that is — studies/branches.py sets aside a seed
    # that is not on its branch, with the reason, in its report)
    last = rows[-1]
    forks = folder / "bifurcations.json"
    forks = json.loads(forks.read_text())["bifurcations"] if forks.is_file() else []
    write_json_atomic(folder / "summary.json", {
        "status": Status.COMPLETED, "branch": b, "points": len(rows), "end": last[b["param"]],
        "folds": [r["fold"] for r in rows if r.get("fold")], "last": last,
        **({"bifurcations": forks} if b.get("modes") else {}),
        "seconds": round(time.perf_counter() - t0, 1)}, make_folder=True)


def changed(point: Point, root: Path) -> str | None:
    """Why the point's folder (or failure record) is not this point's — its parameters,
    seed, run options or the physics' version differ from the recorded ones — or None (also
    when nothing was run yet)."""
    folder = root / "points" / point.name
    record = folder.with_name(point.name + ".point.json")
    made = [p for p in (folder, failure_record(folder),
                        folder.with_name(point.name + ".seed.json")) if p.exists()]
    if not made:
        return None
    try:
        recorded = json.loads(record.read_text())
    except (OSError, ValueError):
        return "its folder records no parameters (an older fem_ade made it)"
    from fem_ade.engine.runs import identity_difference

    difference = identity_difference(recorded, point.identity())
    return None if difference is None else difference.replace(" in run.json", " now").replace(
        "in the checkpoint", "when it ran")


def forget(point: Point, root: Path) -> None:
    """Remove what an earlier run of the point left (its run's files, its records)."""
    import shutil

    folder = root / "points" / point.name
    if folder.is_dir():
        shutil.rmtree(folder)
    failure_record(folder).unlink(missing_ok=True)
    for suffix in (".seed.json", ".point.json"):
        folder.with_name(point.name + suffix).unlink(missing_ok=True)


def check_out(out: Path) -> None:
    """``--out``: a sweep's folder (it holds sweep.json) or a new or empty folder that can be
    made there; ModelError (one line) otherwise — nothing is made here."""
    if str(out) in ("", "."):
        raise ModelError("--out needs a folder name")
    if out.exists() or out.is_symlink():
        if not out.is_dir():
            raise ModelError(f"--out {out} is not a folder")
        if any(out.iterdir()) and not (out / "sweep.json").is_file():
            raise ModelError(f"--out {out} holds other files and no sweep: give a new or empty "
                             "folder, or the folder of this sweep")
        if not os.access(out, os.W_OK | os.X_OK):
            raise ModelError(f"--out {out} is not writable")
        return
    parent = out.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise ModelError(f"cannot make --out {out}: {parent} is not a writable folder")


#: Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in each worker it starts. An explicit trim
#: threshold turns off glibc's dynamic mmap threshold, so that every array above 128 KiB is
#: mapped and unmapped anew, page faults and all: a point of the axisymmetric ε ladder (105 x
#: 257 nodes, 230 steps) took 6.0 s of CPU in a worker against 1.56 s without it (1.4-1.7 s
#: in the driver's own process); the same in one process with the variable set, 5.9-6.4 s.
#: The workers of a LocalCluster are started without it (docs/cluster.md: external workers)
NANNY_ENVIRON = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
#: the -W option of multiprocessing's resource tracker (:func:`connect`)
QUIET_TRACKER = "ignore:resource_tracker:UserWarning"


def connect(scheduler: str | None, workers: int):
    """(client, cluster or None): a LocalCluster of ``workers`` processes, or a client of the
    scheduler at ``scheduler`` (an address, or a scheduler file) within 10 s; ModelError
    (one line) for an address that does not answer, resolve or parse, or a file that is no
    scheduler's."""
    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler is None:
        # Workers stopped mid-point (Ctrl-C, SIGTERM) leave their semaphores to
        # multiprocessing's resource tracker, which frees them and then warns, on stderr after
        # the sweep's one line: "There appear to be 2 leaked semaphore objects". The tracker
        # is a process of its own started with this interpreter's -W options: ignore it there.
        if QUIET_TRACKER not in sys.warnoptions:
            sys.warnoptions.append(QUIET_TRACKER)
        if os.environ.get("MALLOC_TRIM_THRESHOLD_") == "65536":  # a Dask nanny's, left in this
            del os.environ["MALLOC_TRIM_THRESHOLD_"]              # process: workers inherit it
        # Logs at CRITICAL only: a worker that heartbeats while an interrupted sweep closes
        # the scheduler logs an ERROR with its traceback (31 lines on stderr after the sweep's
        # one; seen once in the suite). A point's failure reaches the sweep as its task's
        # exception and is written in the point's folder, not in the workers' logs.
        with dask.config.set(NANNY_ENVIRON):
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=logging.CRITICAL)
        return Client(cluster), cluster
    if not scheduler.strip():
        raise ModelError("--scheduler needs an address (tcp://HOST:PORT) or a scheduler file")
    path = Path(scheduler)
    try:
        if path.is_file():
            try:
                info = json.loads(path.read_text())
            except (OSError, ValueError) as err:
                raise ModelError(f"--scheduler {scheduler} is not a scheduler file ({err})") \
                    from None
            if not isinstance(info, dict) or "address" not in info:
                raise ModelError(f"--scheduler {scheduler} is not a scheduler file (no "
                                 "address in it)")
            return Client(scheduler_file=str(path), timeout="10s"), None
        return Client(scheduler, timeout="10s"), None
    except ModelError:
        raise
    except Exception as err:  # noqa: BLE001 (dask raises OSError, TimeoutError, ValueError...)
        text = " ".join(str(err).split())[:200] or type(err).__name__
        raise ModelError(f"cannot reach the Dask scheduler at {scheduler}: {text}") from None


def check_points(sweep: Sweep, root: Path, rerun_changed: bool) -> None:
    """Before anything runs or is reported: the folder of every point must be that point's
    (:func:`changed`); with ``rerun_changed`` a changed one is removed, to run anew, else
    the sweep is refused with one line naming the first difference."""
    for point in sweep.points():
        why = changed(point, root)
        if why is None:
            continue
        if not rerun_changed:
            raise ModelError(f"point {point.name} in {root} was run with other settings "
                             f"({why}); give another --out, or --rerun-changed to run it "
                             "anew")
        forget(point, root)


def _head(point: Point) -> dict:
    """A row's first columns: the point, its parameters, its seed and its start."""
    return {"point": point.name, **point.values, "seed": point.seed,
            **({"after": point.after} if point.after else {})}


def row(point: Point, root: Path) -> dict:
    """The table row of a point, from its run folder (or its failure record)."""

    folder = root / "points" / point.name
    out = _head(point)
    failed = read_failure(folder)
    if failed is not None:
        return {**out, **failed}
    try:
        s = json.loads((folder / "summary.json").read_text())
    except (OSError, ValueError):
        return {**out, "status": Status.PENDING}
    if not isinstance(s, dict):
        return {**out, "status": Status.DAMAGED, "reason": "its summary.json is not a table"}
    try:
        seed = json.loads(folder.with_name(point.name + ".seed.json").read_text())
    except (OSError, ValueError):
        seed = {}
    if not isinstance(seed, dict):
        seed = {}
    try:
        if "branch" in s:
            return _row_of_branch(out, s)
        return _row_of_summary(out, s, seed)
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        return {**out, "status": Status.DAMAGED,
                "reason": f"its summary.json is damaged ({type(err).__name__}: {err})"}


def _row_of_summary(out: dict, s: dict, seed: dict) -> dict:
    from fem_ade.analysis.sharp import reduced_energy

    f, shape = s.get("final", {}), s.get("shape") or {}
    sharp = shape.get("sharp") or {}
    ref = s.get("sharp_reference") or {}
    out.update(status=s["status"], steps=s["steps"], **{k: f.get(k) for k in ENERGY_COLUMNS},
               e=reduced_energy(f, s["parameters"]["kappa"]) if "W" in f else None,
               label=shape.get("label"), components=shape.get("components"),
               genus=" ".join(str(g) for g in shape.get("genus", [])),
               v_surface=sharp.get("reduced_volume"),
               da_surface=sharp.get("reduced_area_difference"),
               e_sharp_seed=seed.get("e_sharp"), sharp_end=ref.get("e_sharp"),
               reason="" if s["status"] != Status.DIVERGED else s.get("message", ""))
    return out


def _row_of_branch(out: dict, s: dict) -> dict:
    from fem_ade.campaigns.branch_folder import row_digest

    last = s["last"]
    record = last.get("integrity")
    if isinstance(record, dict) and record.get("row") != row_digest(last):
        return {**out, "status": Status.DAMAGED,
                "reason": "its summary.json's last point was changed after it was saved"}
    out.update(status=s["status"], steps=s["points"], end=s["end"],
               folds=" ".join(str(f) for f in s["folds"]),
               **{k: last.get(k) for k in (*ENERGY_COLUMNS, "e", "label", "v_surface",
                                          "da_surface")})
    return out


def _seed_sharp_e(point: Point) -> float | None:
    """The sharp energy of the seed's branch at the point (vesicle family), if it exists
    (the solve that seeded it, cached in this process)."""
    if point.base != "vesicle":
        return None
    from fem_ade.scenes.vesicle import sharp_of

    res = sharp_of(point.seed, **point.fixed, **point.values)
    return None if res is None else float(res.e)


# ---------------------------------------------------------------------------------------
# the driver
# ---------------------------------------------------------------------------------------
def write_sweep_table(rows: list[dict], path: Path, axes: list[str]) -> None:
    """A sweep's rows as its sweep.csv (:func:`fem_ade.store.tables.write_table`): the point,
    its axes, :data:`COLUMNS` (a branch sweep's end and folds; a listed sweep's after)."""
    from fem_ade.store.tables import write_table

    cols = ["point", *axes, *COLUMNS]
    if any("end" in r for r in rows):  # a branch sweep's
        cols[cols.index("steps") + 1:cols.index("steps") + 1] = ["end", "folds"]
    if any(r.get("after") for r in rows):  # listed points that start from another's end
        cols.insert(cols.index("seed") + 1, "after")
    write_table(path, cols, rows)


#: a sweep table's columns that stay text (a seed "1" is a name, not a number)
TEXT_COLUMNS = ("point", "seed", "genus", "label", "status", "reason", "folds", "after")


def read_sweep_table(path: Path) -> list[dict]:
    """The rows of a sweep.csv, numbers as numbers, empty cells None (what :func:`row` gives,
    without the run folders: a committed sweep's table is enough to draw and report it
    again)."""
    from fem_ade.store.tables import read_table

    return read_table(path, text=TEXT_COLUMNS, empty=None)


def run_sweep(sweep: Sweep, out: Path, *, workers: int = 2, scheduler: str | None = None,
              quiet: bool = False, retry_s: float = 2.0, retry_failed: bool = False,
              rerun_changed: bool = False) -> list[dict]:
    """Run every unfinished point on Dask (``retry_failed``: the failed ones too) — on the
    ``scheduler``'s workers, or on a local cluster of at most ``workers`` processes and no
    more than the points to run (none when every point has ended: a finished sweep's table
    in under a second); the table's rows (also written to sweep.csv). A point's folder made
    with other settings is refused (:func:`check_points`) or, with ``rerun_changed``, run
    anew."""
    from dask.distributed import as_completed

    from fem_ade.store.lock import FolderLock

    check_out(out)
    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
              "FEM_ADE_FFT_WORKERS"):
        os.environ.setdefault(k, "1")  # one thread per worker process
    if out.is_dir() and not rerun_changed:  # its points must be this sweep's: nothing made
        check_points(sweep, out, rerun_changed=False)
    client = cluster = None
    if scheduler is not None:  # a refused scheduler: nothing written
        client, cluster = connect(scheduler, workers)
    try:
        out.mkdir(parents=True, exist_ok=True)
        lock = FolderLock(out).acquire()  # one driver per sweep folder
    except BaseException:
        if client is not None:
            client.close()
        raise
    if rerun_changed:  # under the lock: remove the changed points' runs
        check_points(sweep, out, rerun_changed=True)
    points = sweep.points()
    axes = sweep.columns()
    write_json_atomic(out / "sweep.json", {"name": sweep.name, "base": sweep.base,
                                     "axes": sweep.axes, "scene": sweep.fixed,
                                     "seeds": sweep.seeds, "run": sweep.run,
                                     **({"branch": sweep.branch} if sweep.branch else {}),
                                     **({"listed": sweep.listed} if sweep.listed else {}),
                                     "points": [p.name for p in points]}, make_folder=True)
    rows = {p.name: row(p, out) for p in points}
    done = ENDED | {Status.FAILED} if not retry_failed else ENDED
    todo = [p for p in points if rows[p.name]["status"] not in done]
    try:
        if client is None and todo:  # a local cluster of no more workers than points to run
            client, cluster = connect(None, min(workers, len(todo)))
        say = (lambda text: None) if quiet else (lambda text: print(text, flush=True))
        say(f"sweep {sweep.name}: {len(points)} points, {len(points) - len(todo)} done, "
            f"{len(todo)} to run" + (f" on {_workers_text(client)}; dashboard "
                                     f"{client.dashboard_link}" if client else ""))
        if todo:
            _drive(client, todo, out, rows, axes, quiet, retry_s, as_completed)
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
        write_sweep_table([rows[p.name] for p in points], out / "sweep.csv", axes)
        lock.release()
    return [rows[p.name] for p in points]


def _workers_text(client) -> str:
    n = len(client.scheduler_info().get("workers", {}))
    return f"{n} worker{'s' if n != 1 else ''}"


def _drive(client, todo, out, rows, axes, quiet, retry_s, as_completed):
    from tqdm import tqdm

    by_name, submitted = {p.name: p for p in todo}, {}
    for p in todo:  # a listed point after the one it starts from: Dask runs them in order
        deps = [submitted[p.after]] if p.after in submitted else []
        submitted[p.name] = client.submit(run_point, p, str(out), *deps, key=f"point-{p.name}",
                                          pure=False)
    futures = as_completed(list(submitted.values()))
    failed = 0
    started = time.perf_counter()
    n_workers = max(1, _n(client))
    bar = tqdm(total=len(todo), disable=quiet, unit="point", dynamic_ncols=True)
    try:
        for fut in futures:
            try:
                r = fut.result()
            except Exception as err:  # noqa: BLE001 - a worker lost, an unexpected error
                name = fut.key.removeprefix("point-")
                record_failure(out / "points" / name, f"{type(err).__name__}: {err}")
                r = row(by_name[name], out)
            if r["status"] == Status.BUSY:  # another process runs it: ask again later
                time.sleep(retry_s)
                futures.add(client.submit(run_point, by_name[r["point"]], str(out),
                                          pure=False))
                continue
            rows[r["point"]] = r
            failed += r["status"] in (Status.FAILED, Status.DIVERGED)
            bar.update(1)
            bar.set_postfix_str(f"failed {failed}, running {min(len(todo) - bar.n, n_workers)}")
            write_sweep_table(list(rows.values()), out / "sweep.csv", axes)
    finally:
        bar.close()
    if not quiet:
        took = time.perf_counter() - started
        print(f"ran {len(todo)} point(s) in {took:.1f} s ({failed} failed)", flush=True)


def _n(client) -> int:
    try:
        return len(client.scheduler_info().get("workers", {}))
    except Exception:  # noqa: BLE001
        return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m fem_ade.sweep",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("sweep", help="the sweep file (TOML)")
    ap.add_argument("--out", help="the sweep folder (default runs/sweeps/NAME)")
    where = ap.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=2,
                       help="local Dask worker processes, at most one per point left to run "
                            "(default 2)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="an existing Dask scheduler: tcp://HOST:PORT or its scheduler file")
    ap.add_argument("--retry-failed", action="store_true",
                    help="run the points recorded as failed again (they are skipped otherwise)")
    ap.add_argument("--rerun-changed", action="store_true",
                    help="run anew the points whose folder was made with other settings (a "
                         "sweep refuses them otherwise)")
    ap.add_argument("--report-only", action="store_true",
                    help="rebuild the table and the pictures from the folders; run nothing")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)
    from fem_ade.store.lock import FolderBusy

    def stop(signum, frame):  # a kill ends the sweep as Ctrl-C does: workers closed
        raise KeyboardInterrupt

    if argv is None:  # SIGINT too: a shell that starts us in the background has it ignored
        signal.signal(signal.SIGTERM, stop)
        signal.signal(signal.SIGINT, stop)
    try:
        if args.workers < 1:
            raise ModelError(f"--workers must be >= 1, got {args.workers}")
        if args.out == "":
            raise ModelError("--out needs a folder name")
        sweep = load_sweep(args.sweep)
        out = Path(args.out or Path("runs") / "sweeps" / sweep.name)
        if args.report_only:
            rows = report_rows(sweep, out)
        else:
            rows = run_sweep(sweep, out, workers=args.workers, scheduler=args.scheduler,
                             quiet=args.quiet, retry_failed=args.retry_failed,
                             rerun_changed=args.rerun_changed)
    except FolderBusy as err:
        print(f"fem_ade.sweep: error: {err}", file=sys.stderr)
        return 2
    except ModelError as err:
        print(f"fem_ade.sweep: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fem_ade.sweep: interrupted; run the same command again to go on",
              file=sys.stderr)
        return 130
    from fem_ade.plots.sweep_plot import draw

    pictures = [] if sweep.branch else draw(rows, sweep, out)  # each branch draws its own
    return _say_ended(sweep, rows, out, pictures)


def report_rows(sweep: Sweep, out: Path) -> list[dict]:
    """``--report-only``: the rows from the folders (sweep.csv written again), nothing run."""
    if not (out / "sweep.json").is_file():
        raise ModelError(f"{out} holds no sweep to report on (run it first)")
    check_points(sweep, out, rerun_changed=False)
    rows = [row(p, out) for p in sweep.points()]
    write_sweep_table(rows, out / "sweep.csv", sweep.columns())
    return rows


def _say_ended(sweep: Sweep, rows: list[dict], out: Path, pictures: list) -> int:
    """The sweep's last line; its exit code (1 while a point has not ended)."""
    done = sum(r["status"] in ENDED for r in rows)
    bad = sum(r["status"] == Status.FAILED for r in rows)
    skipped = sum(r["status"] == Status.SKIPPED for r in rows)
    print(f"{sweep.name}: {done} of {len(rows)} points finished, {bad} failed"
          + (f", {skipped} skipped" if skipped else "") + f"; {out / 'sweep.csv'}"
          + "".join(f", {p}" for p in pictures))
    return 0 if done + bad + skipped == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
