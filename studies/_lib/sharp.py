"""Sharp membranes from ``sharp_ref``, as the studies keep them: solved once and cached on
disk (a solve takes seconds to minutes; a report is rebuilt from the cache), or followed along
m₀ by continuation where a branch's own anchor does not reach it.

:class:`Cache` and :func:`ade_sharp` are the sharp-limit study's cache
(``OUT/sharp/solves.json``, its transitions read from it by :func:`crossing`); :func:`follow`
is the ADE plane's continuation, and :func:`sharp_line` the ADE-lines study's task that runs
it in a worker process.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from fem_ade.store.output import write_json_atomic
from sharp_ref.branches import LEVELS, solve
from sharp_ref.membrane import BranchError

#: the continuation's levels: energies to ~1e-7, ample beside the phase field's ε error
LEVELS_USED = LEVELS[:3]


def branch_key(branch: str, v) -> str:
    """A branch point's name in the caches: ``BRANCH@V`` (``BRANCH@free`` without v)."""
    return f"{branch}@{'free' if v is None else f'{v:.4f}'}"


class Cache:
    """{key: row} in a JSON file, written after each solve (atomically: a temporary file
    renamed over the old one)."""

    def __init__(self, path: Path):
        self.path = path
        self.rows = json.loads(path.read_text()) if path.is_file() else {}

    def get(self, branch: str, v, *, compute: bool = True) -> dict | None:
        name = branch_key(branch, v)
        if name not in self.rows and compute:
            t0 = time.perf_counter()
            try:
                solved = solve(branch, v).to_json()
                row = {k: solved[k] for k in ("branch", "v", "w", "e", "da", "converged",
                                              "residual")}
                row["r"], row["z"] = ([round(x, 7) for x in solved[k]] for k in ("r", "z"))
            except BranchError as err:
                row = {"branch": branch, "v": v, "missing": str(err)}
            row["seconds"] = round(time.perf_counter() - t0, 1)
            print(f"  {name}: " + (f"w = {row['w']:.10f}" if "w" in row else row["missing"])
                  + f"  ({row['seconds']} s)", flush=True)
            self.rows[name] = row
            self.path.parent.mkdir(parents=True, exist_ok=True)
            write_json_atomic(self.path, dict(sorted(self.rows.items())), indent=None)
        return self.rows.get(name)


def _ade_solve(branch: str, v: float, m0: float, kbar: float):
    """sharp_ref's membrane with ADE; where its anchor does not reach it (the pear below
    m₀ ≈ 1.68 at v = 0.85), by continuation down in m₀ from 1.8 in steps of at most 0.04
    (as :func:`follow` does for the ADE plane)."""
    try:
        return solve(branch, v, m0=m0, kbar=kbar)
    except BranchError:
        if branch != "pear" or m0 >= 1.8:
            raise
    steps = max(1, math.ceil((1.8 - m0) / 0.04))
    result = None
    for k in range(steps + 1):
        result = solve(branch, v, m0=1.8 - (1.8 - m0) * k / steps, kbar=kbar, start=result)
    return result


def ade_sharp(cache: Cache, branch: str, v: float, m0: float, kbar: float,
              compute: bool = True) -> dict | None:
    """The sharp membrane with area-difference elasticity (κ̄/κ = ``kbar``, m₀), cached in
    the same file as the minimal model's under "ade:BRANCH@V/m0=M0/kbar=K"."""
    name = f"ade:{branch_key(branch, v)}/m0={m0:g}/kbar={kbar:g}"
    if name not in cache.rows and compute:
        t0 = time.perf_counter()
        try:
            solved = _ade_solve(branch, v, m0, kbar).to_json()
            row = {k: solved[k] for k in ("branch", "v", "w", "e", "da", "converged",
                                          "residual")}
            row["r"], row["z"] = ([round(x, 7) for x in solved[k]] for k in ("r", "z"))
        except BranchError as err:
            row = {"branch": branch, "v": v, "missing": str(err)}
        row.update(m0=m0, kbar=kbar, seconds=round(time.perf_counter() - t0, 1))
        print(f"  {name}: " + (f"e = {row['e']:.10f}" if "e" in row else row["missing"]),
              flush=True)
        cache.rows[name] = row
        cache.path.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(cache.path, dict(sorted(cache.rows.items())), indent=None)
    return cache.rows.get(name)


def crossing(cache: Cache, upper: str, lower: str, guess: float, compute: bool = True) -> dict:
    """The v where ``upper`` (lowest above it) and ``lower`` (lowest below) have equal w:
    the root of a quadratic through their differences at three v, 0.01 apart, that bracket
    it (moved along until they do)."""
    vs = [round(guess - 0.01, 2), round(guess, 2), round(guess + 0.01, 2)]
    for _ in range(8):
        rows = [(cache.get(upper, v, compute=compute), cache.get(lower, v, compute=compute))
                for v in vs]
        if any(a is None or b is None or "w" not in a or "w" not in b for a, b in rows):
            return {"between": [upper, lower], "v": None, "note": "a branch is missing near "
                    f"v = {guess}"}
        d = [a["w"] - b["w"] for a, b in rows]  # > 0 where ``lower`` is the lower one
        if d[0] > 0 > d[-1] or d[0] < 0 < d[-1]:
            c = np.polyfit(vs, d, 2)
            roots = [x.real for x in np.roots(c) if abs(x.imag) < 1e-12 and vs[0] <= x.real
                     <= vs[-1]]
            v = float(roots[0])
            w = float(np.polyval(np.polyfit(vs, [a["w"] for a, _ in rows], 2), v))
            return {"between": [upper, lower], "v": v, "w": w, "samples": vs,
                    "differences": d}
        step = -0.01 if d[0] > 0 else 0.01  # lower already lower everywhere: move up
        vs = [round(x + step, 2) for x in vs]
    return {"between": [upper, lower], "v": None, "note": "no sign change found"}


def follow(branch: str, v: float, plane, *, kbar: float, say=print) -> list[dict]:
    """The branch along the plane's m₀ grid (``plane.m0``) at κ̄/κ = ``kbar``: solved at its
    anchor (``plane.anchor[branch]``), then continued up and down the grid (each solve
    starting from its neighbour's shape) until it is lost; ``plane.levels`` where given,
    else :data:`LEVELS_USED`."""
    grid = list(plane.m0)
    a = min(range(len(grid)), key=lambda i: abs(grid[i] - plane.anchor[branch]))
    rows = {}

    def one(i, start):
        t0 = time.perf_counter()
        try:
            r = solve(branch, v, m0=grid[i], kbar=kbar, tol=1e-7,
                      levels=getattr(plane, "levels", LEVELS_USED),
                      start=start)
        except BranchError as err:
            rows[i] = {"branch": branch, "v": v, "m0": grid[i], "missing": str(err)}
            say(f"  {branch} v = {v} m0 = {grid[i]}: {err}")
            return None
        j = r.to_json(points=101)
        rows[i] = {"branch": branch, "v": v, "m0": grid[i], "e": r.e, "w": r.w, "da": r.da,
                   "residual": r.residual, "seconds": round(time.perf_counter() - t0, 1),
                   "r": [round(x, 7) for x in j["r"]], "z": [round(x, 7) for x in j["z"]]}
        say(f"  {branch} v = {v} m0 = {grid[i]}: e = {r.e:.6f} da = {r.da:.5f}")
        return r

    anchor = one(a, None)
    for direction in (1, -1):
        r = anchor
        i = a + direction
        while r is not None and 0 <= i < len(grid):
            r = one(i, r)
            i += direction
    return [rows[i] for i in sorted(rows)]


def sharp_line(out: str, branch: str, v: float, grid, anchors, kbar: float) -> dict:
    """One sharp branch continued along the m₀ grid at one v, from the first of ``anchors``
    that reaches it (a worker process's task: this module is importable there), kept in the
    file ``out`` and read back from it."""
    path = Path(out)
    if path.is_file():
        return json.loads(path.read_text())
    rows = []
    for anchor in anchors:
        if anchor < grid[0] or anchor > grid[-1]:
            continue
        plane = SimpleNamespace(m0=grid, anchor={branch: anchor})
        rows = follow(branch, v, plane, kbar=kbar, say=lambda text: None)
        if any("e" in r for r in rows):
            break
    rows = [{k: r[k] for k in ("m0", "e", "w", "da") if k in r} for r in rows if "e" in r]
    result = {"branch": branch, "v": v, "rows": rows}
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, result)
    return result
