"""The branches of axisymmetric membranes, each reached by continuation from a shape it owns.

:func:`solve` returns the membrane of one branch at the given reduced volume (and, with
area-difference elasticity, relaxed area difference and κ̄): it starts from the branch's
anchor — the sphere deformed a little for ``prolate`` and ``oblate``, a sphere with its top
cap pushed in for ``stomatocyte``, the Clifford torus for ``torus``, the prolate with an
up-down asymmetric kick for ``pear`` — walks the reduced volume to the target in small
steps on a coarse meridian, then refines the meridian (more modes and nodes) until the
energy changes by less than ``tol``. The result is checked to be a shape of the branch
(:class:`~sharp_ref.membrane.BranchError` otherwise): a meridian that stays off the axis and
does not cross itself, elongated (``prolate``) or flattened (``oblate``), invaginated
(``stomatocyte``), up-down asymmetric (``pear``).
"""

from __future__ import annotations

import math

import numpy as np

from .membrane import (
    BRANCHES,
    BranchError,
    Problem,
    Result,
    Spheroidal,
    Toroidal,
    minimise,
)

#: (modes, nodes) of the meridian, coarse to fine; a branch stops refining when the energy
#: changes by less than ``tol`` from one level to the next
LEVELS = ((12, 64), (24, 128), (40, 200), (64, 320), (96, 448))
#: the step of the continuation in v
DV = 0.05
#: the level the continuation walks on, per branch (default the coarsest): an invaginated
#: meridian needs more modes than 12 to stay invaginated on its way (at 12 modes the
#: stomatocyte relaxes to the oblate between v = 0.55 and 0.6; at 40 it stays to 0.65)
WALK_LEVEL = {"stomatocyte": 2}


def _family(branch: str, modes: int, nodes: int):
    if branch == "torus":
        return Toroidal(range(1, modes + 1), nodes)
    if branch in ("prolate", "oblate", "sphere"):
        return Spheroidal(range(2, 2 * modes + 1, 2), nodes)  # even k: up-down symmetric
    return Spheroidal(range(1, modes + 1), nodes)


def _resize(x: np.ndarray, old, new) -> np.ndarray:
    """The unknowns of ``old`` on ``new`` (more modes: the new ones zero)."""
    coef = dict(zip(old.modes.tolist(), x[:-old.extra], strict=True))
    return np.concatenate([[coef.get(k, 0.0) for k in new.modes.tolist()], x[-old.extra:]])


def _stomatocyte_guess(family) -> np.ndarray:
    """A sphere with its top cap (polar angle < 1.2) reflected inwards, fitted by the
    family's modes (a least-squares fit of the tangent angle smooths the rim)."""
    th = np.linspace(0.0, np.pi, 4001)
    r, z = np.sin(th), np.cos(th)
    cap = th < 1.2
    z = np.where(cap, 2.0 * math.cos(1.2) - z, z)
    r = np.where(cap, r * (1.0 - 0.15 * (1.0 - th / 1.2)), r)
    d = np.hypot(np.diff(r), np.diff(z))
    s = np.concatenate([[0.0], np.cumsum(d)])
    angle = np.unwrap(np.arctan2(-np.diff(z), np.diff(r)))
    tm = 0.5 * (s[1:] + s[:-1]) / s[-1]
    B = np.sin(np.pi * np.outer(tm, family.modes)) / family.modes
    u = np.linalg.lstsq(B, angle - np.pi * tm, rcond=None)[0]
    return np.concatenate([u, [s[-1]]])


def _anchor(branch: str, family) -> tuple[np.ndarray, float | None]:
    """(unknowns, their reduced volume) of the branch's starting shape."""
    x = np.zeros(len(family.modes) + family.extra)
    if branch == "torus":  # the Clifford torus: tube radius a, centre line R = √2 a, area 4π
        a = 1.0 / math.sqrt(math.pi * math.sqrt(2.0))
        x[-2], x[-1] = 2.0 * math.pi * a, (math.sqrt(2.0) + 1.0) * a
        return x, None
    x[-1] = math.pi  # the unit sphere: ψ = πt, S = π
    if branch == "sphere":
        return x, 1.0
    if branch == "stomatocyte":
        return _stomatocyte_guess(family), 0.55
    # prolate: the first even mode positive lengthens the axis; oblate: negative
    x[0] = {"prolate": 0.1, "oblate": -0.1, "pear": 0.1}[branch]
    return x, 0.99


def _path(v0: float, v: float) -> list[float]:
    n = max(1, math.ceil(abs(v - v0) / DV))
    return [v0 + (v - v0) * (i + 1) / n for i in range(n)]


def _check(branch: str, result: Result) -> None:
    """BranchError unless the shape is a shape of ``branch``."""
    g = result.geometry
    r, z = np.real(g.r), np.real(g.z)
    inner = r[1:-1] if branch != "torus" else r
    if not result.converged:
        raise BranchError(f"the {branch} branch did not converge here ({result.message}; "
                          f"misfit {result.residual:.1e})")
    if inner.min() <= 0.0:
        raise BranchError(f"no {branch} here: the meridian reaches the axis "
                          f"(r = {inner.min():.3g})")
    if _crosses_itself(r, z, closed=branch == "torus"):
        raise BranchError(f"no {branch} here: the meridian crosses itself (the membrane "
                          "would touch itself)")
    height, width = np.ptp(z), 2.0 * r.max()
    if branch == "prolate" and height <= width:
        raise BranchError(f"no prolate here: the shape is not elongated (height {height:.3f}, "
                          f"width {width:.3f})")
    if branch == "oblate" and height >= width:
        raise BranchError(f"no oblate here: the shape is not flattened (height {height:.3f}, "
                          f"width {width:.3f})")
    if branch in ("stomatocyte", "pear") and _symmetric(result.x[:-1]):
        raise BranchError(f"no {branch} here: the shape relaxed to an up-down symmetric one")
    if branch == "stomatocyte" and np.real(g.psi).min() > -math.pi / 4:
        raise BranchError("no stomatocyte here: the shape relaxed to one without an "
                          "invagination")


def _symmetric(coef: np.ndarray) -> bool:
    """Whether the coefficients of modes 1, 2, … have no odd part (up-down symmetric)."""
    coef = np.abs(coef)
    odd = coef[np.arange(1, len(coef) + 1) % 2 == 1].max(initial=0.0)
    return odd < 1e-4 * max(coef.max(initial=0.0), 1e-300)


def _crosses_itself(r: np.ndarray, z: np.ndarray, closed: bool) -> bool:
    """Whether the polyline (r, z) (closed: back to its start) has two non-adjacent
    segments that intersect."""
    p = np.stack([r, z], axis=1)
    if closed:
        p = np.vstack([p, p[:1]])
    a, b = p[:-1], p[1:]
    n = len(a)
    d = b - a
    for i in range(n - 2):
        j = np.arange(i + 2, n - (1 if closed and i == 0 else 0))
        if len(j) == 0:
            continue
        e = a[j] - a[i]
        den = d[i, 0] * d[j, 1] - d[i, 1] * d[j, 0]
        ok = np.abs(den) > 1e-300
        s = np.where(ok, (e[:, 0] * d[j, 1] - e[:, 1] * d[j, 0]) / np.where(ok, den, 1.0), -1)
        u = np.where(ok, (e[:, 0] * d[i, 1] - e[:, 1] * d[i, 0]) / np.where(ok, den, 1.0), -1)
        if np.any(ok & (s > 0) & (s < 1) & (u > 0) & (u < 1)):
            return True
    return False


def solve(branch: str, v: float | None, *, m0: float = 0.0, kbar: float = 0.0,
          c: float = 0.0, tol: float = 1e-10, levels=LEVELS, progress=None,
          start: Result | None = None) -> Result:
    """The membrane of ``branch`` at reduced volume ``v`` (None: the torus at fixed area
    only, Willmore's problem), with area-difference elasticity ``kbar`` = κ̄/κ toward the
    reduced area difference ``m0``, and spontaneous 2H ``c`` (units of 1/R₀).

    ``start``: a result of the same branch to start from instead of the branch's anchor —
    a continuation in ``m0``, ``kbar``, ``c`` or (a small step in) ``v``; it follows a branch
    where the anchor's path would not reach it (a pear away from the prolate it buds from).
    ``progress(text)`` (optional) is told each continuation step and refinement. Raises
    :class:`BranchError` if the branch does not exist there (or is left)."""
    if branch not in BRANCHES:
        raise ValueError(f"unknown branch {branch!r}; choose from {', '.join(BRANCHES)}")
    if v is None and branch != "torus":
        raise ValueError(f"the {branch} branch needs a reduced volume")
    if v is not None and not (0.0 < v <= 1.0):
        raise ValueError(f"the reduced volume must be in (0, 1], got {v}")
    if branch == "sphere" and v is not None and v != 1.0:
        raise BranchError(f"a sphere has reduced volume 1, not {v}")
    say = progress or (lambda text: None)
    if start is not None:
        return _continue(branch, v, Problem(v, m0, kbar, c), start, tol, levels, say)
    modes, nodes = levels[0]
    family = _family(branch, modes, nodes)
    x, v0 = _anchor(branch, family)
    steps = [] if v is None or v0 is None else _path(v0, v)
    if branch == "torus" and v is not None:
        x, _, _, _ = minimise(family, Problem(None, 0.0, 0.0, c), x)
        g = family.at(x, c)
        steps = _path(float(np.real(g.reduced_volume)), v)
    if branch == "pear":  # from the prolate at v, kicked up-down asymmetrically
        prolate = solve("prolate", v, m0=m0, kbar=kbar, c=c, tol=1e-6, levels=levels[:1])
        x = _resize(prolate.x, _family("prolate", modes, nodes), family)
        x[0] += 0.05  # the k = 1 mode
        steps = []
    walk = min(WALK_LEVEL.get(branch, 0), len(levels) - 1)
    if walk:  # settle the anchor, then carry it to the walking level
        x, _, _, _ = minimise(family, Problem(v0, 0.0, 0.0, c), x)
        new = _family(branch, *levels[walk])
        x, family = _resize(x, family, new), new
        x, _, _, _ = minimise(family, Problem(v0, 0.0, 0.0, c), x)
    for target in steps:
        say(f"{branch}: v = {target:.4f}")
        x, ok, msg, res = minimise(family, Problem(target, 0.0 if branch != "pear" else m0,
                                                   0.0 if branch != "pear" else kbar, c), x)
        if not ok:
            raise BranchError(f"the {branch} branch is lost at v = {target:.4f} ({msg}; "
                              f"misfit {res:.1e})")
    return _refine(branch, Problem(v, m0, kbar, c), family, x, walk, tol, levels, say)


def _refine(branch, problem, family, x, first, tol, levels, say) -> Result:
    """Minimise on ``levels[first:]`` (``family`` is that level's) until the energy changes
    by less than ``tol`` from one level to the next; the result checked to be of ``branch``."""
    previous = None
    result = None
    for level, (modes, nodes) in enumerate(levels):
        if level < first:
            continue
        if level > first:
            new = _family(branch, modes, nodes)
            x, family = _resize(x, family, new), new
        say(f"{branch}: {len(family.modes)} modes, {nodes} nodes")
        x, ok, msg, res = minimise(family, problem, x)
        g = family.at(x, problem.c)
        result = Result(branch, problem, g, x, ok, msg, res, family)
        e = result.e
        if previous is not None and abs(e - previous) < tol:
            break
        previous = e
    _check(branch, result)
    return result


def _continue(branch, v, problem, start: Result, tol, levels, say) -> Result:
    """:func:`solve` from ``start`` (see there): on the level ``start`` was solved on, then
    finer ones as needed."""
    if start.branch != branch or start.family is None:
        raise ValueError(f"start must be a {branch} result of solve(), got {start.branch}")
    family = start.family
    level = next((i for i, (modes, nodes) in enumerate(levels)
                  if modes == len(family.modes) and nodes == family.m), None)
    if level is None:
        raise ValueError("start was solved on a level not in levels")
    if v is not None and start.problem.v is not None and abs(v - start.problem.v) > DV:
        raise ValueError(f"a continuation step in v must be at most {DV}, "
                         f"got {abs(v - start.problem.v):.3g}")
    return _refine(branch, problem, family, start.x.copy(), level, tol, levels, say)

