"""The numbers a study's report draws from its rows: Richardson extrapolation to ε → 0 with
the observed order, the observed order alone, and the time at which an error reaches a
target (the cost studies')."""

from __future__ import annotations

import math

import numpy as np


def extrapolate(eps: list[float], e: list[float]) -> tuple[float, float, bool]:
    """(e₀, p, observed): the observed order from the three smallest ε (p = 2, not observed,
    if there are two or they do not give one in [0.5, 6]) and Richardson over the two
    smallest."""
    from scipy.optimize import brentq

    order = np.argsort(eps)
    x = [eps[i] for i in order]
    y = [e[i] for i in order]
    p, observed = 2.0, False
    if len(x) >= 3:
        ratio = (y[2] - y[1]) / (y[1] - y[0]) if y[1] != y[0] else math.nan

        def f(q):
            return (x[2] ** q - x[1] ** q) / (x[1] ** q - x[0] ** q) - ratio

        try:
            if math.isfinite(ratio) and f(0.5) * f(6.0) < 0:
                p, observed = brentq(f, 0.5, 6.0), True
        except ValueError:
            pass
    e0 = y[0] - (y[1] - y[0]) / ((x[1] / x[0]) ** p - 1.0)
    return e0, p, observed


def slope(eps: list[float], err: list[float]) -> float | None:
    """The observed order: the least-squares slope of log|err| against log ε over the three
    smallest ε (None with fewer, or where an error is 0)."""
    pts = sorted(zip(eps, err, strict=True))[:3]
    if len(pts) < 3 or any(e == 0 for _, e in pts):
        return None
    x = np.log([p[0] for p in pts])
    y = np.log([abs(p[1]) for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def time_to(points: list[tuple[float, float]], target: float) -> float | None:
    """The time at which a discretisation's error first reaches ``target``, interpolated in
    log–log between its measured (time, error) points in order of time; None if none does."""
    pts = sorted(points)
    best = math.inf
    prev = None
    for t, e in pts:
        e = min(e, best)  # a finer, dearer level is never worse than a cheaper one was
        if e <= target:
            if prev is None or prev[1] <= target:
                return t
            (t0, e0), (t1, e1) = prev, (t, e)
            w = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + w * (math.log(t1) - math.log(t0)))
        best = e
        prev = (t, e)
    return None
