"""The time loop's trackers: what :func:`fem_ade.engine.loop.run_loop` calls around its
steps without changing them — the history it records, the steady-state stop, the progress
bar, the checkpoints and observers (after py-pde's trackers). Each gets the loop's state
``ls`` (a :class:`fem_ade.engine.loop.LoopState`: step, time, Δt, the extra columns) and
the step's diagnostics; a separate module so that the loop reads as its steppers and its
order of calls."""

from __future__ import annotations

import math

from tqdm.auto import tqdm

from fem_ade.model.params import HISTORY_COLUMNS
from fem_ade.store.status import Status


class Tracker:
    """Something the loop calls around its steps, without changing them.

    ``start(ls, diag)`` before the first step (or the first of a resumed run);
    ``handle(ls, diag)`` after every accepted step — ``diag`` is the state's diagnostics
    when some tracker's :meth:`wants_diagnostics` asked for them at this step, else None —
    returning ``(status, message)`` to end the run there (the trackers after it are not
    called for that step); ``interrupted(ls)`` on Ctrl-C, returning a note for the message
    or None; ``close()`` at the end, whatever happened."""

    def wants_diagnostics(self, k: int) -> bool:
        return False

    def start(self, ls, diag: dict) -> None:
        pass

    def handle(self, ls, diag: dict | None) -> tuple[str, str] | None:
        return None

    def interrupted(self, ls) -> str | None:
        return None

    def close(self) -> None:
        pass


class History(Tracker):
    """The history rows, every ``every`` steps and at step ``total`` (and at the start of a
    new run); each is also written to ``writer`` (``write(row)``) as it is made."""

    def __init__(self, every: int, total: int, writer=None, with_dt: bool = False,
                 fresh: bool = True):
        self.every, self.total, self.writer = every, total, writer
        self.with_dt, self.fresh = with_dt, fresh
        self.rows: list[dict] = []

    def wants_diagnostics(self, k):
        return k % self.every == 0 or k == self.total

    def record(self, ls, diag: dict) -> None:
        row = {"step": ls.k, "t": ls.t, **{c: diag[c] for c in HISTORY_COLUMNS[2:]}, **ls.extra}
        if self.with_dt:
            row["dt"] = ls.dt
        self.rows.append(row)
        if self.writer is not None:
            self.writer.write(row)

    def start(self, ls, diag):
        if self.fresh:
            self.record(ls, diag)

    def handle(self, ls, diag):
        if self.wants_diagnostics(ls.k):
            self.record(ls, diag)


def _relative_change(E: float, E_before: float, every: int) -> float:
    """|E(k) − E(k − every)| / (every · |E(k)|): the steady-state criterion."""
    return abs(E - E_before) / (every * max(abs(E), 1e-300))


class SteadyState(Tracker):
    """Stop at the first record (a multiple of ``every``) where the relative energy change
    per step is below ``tol``."""

    def __init__(self, tol: float, every: int):
        self.tol, self.every = tol, every
        self.E_before = math.nan

    def wants_diagnostics(self, k):
        return k % self.every == 0

    def start(self, ls, diag):
        self.E_before = ls.last_E

    def handle(self, ls, diag):
        if ls.k % self.every:
            return None
        change = _relative_change(diag["E"], self.E_before, self.every)
        self.E_before = diag["E"]
        if change < self.tol:
            return Status.STEADY, (f"steady at step {ls.k}: relative energy change per step "
                              f"{change:.3g} < {self.tol:g}")
        return None


class Progress(Tracker):
    """The progress bar: steps done of ``--steps``; toward a steady state, how far the
    criterion has come — log₁₀ of the relative energy change per step, from its first
    measured value to the tolerance, as a percentage — with tqdm's rate-based ETA and the
    step, E and the change beside it (a bar to the step cap would show 1 % of a run that is
    nearly done)."""

    def __init__(self, total: int, start: int, until_steady: float | None, every: int,
                 quiet: bool, label: str):
        self.tol, self.every, self.first = until_steady, every, None
        self.records = History(every, total).wants_diagnostics
        self.E_before = math.nan
        if until_steady is None:
            self.bar = tqdm(total=total, initial=start, disable=quiet, desc=label or "run",
                            unit="step", mininterval=0.5, dynamic_ncols=True)
        else:
            self.bar = tqdm(total=100, disable=quiet, desc=f"{label or 'run'} to steady",
                            unit="%", mininterval=0.5, dynamic_ncols=True,
                            bar_format="{l_bar}{bar}| {n:.0f}/100 [{elapsed}<{remaining}"
                                       "{postfix}]")

    def start(self, ls, diag):
        self.E_before = ls.last_E

    def handle(self, ls, diag):
        if self.tol is None:
            self.bar.update(1)
            if self.records(ls.k):
                self.bar.set_postfix(t=f"{ls.t:.3g}", E=f"{diag['E']:.6g}", refresh=False)
            return None
        if not self.records(ls.k):
            return None
        change = None
        if ls.k % self.every == 0:
            change = _relative_change(diag["E"], self.E_before, self.every)
            self.E_before = diag["E"]
        if change is not None and change > 0 and math.isfinite(change):
            if self.first is None:
                self.first = max(change, 10.0 * self.tol)
            span = math.log10(self.first) - math.log10(self.tol)
            done = (math.log10(self.first) - math.log10(change)) / span if span > 0 else 1.0
            self.bar.update(100.0 * min(max(done, 0.0), 1.0) - self.bar.n)
        self.bar.set_postfix(step=ls.k, E=f"{diag['E']:.8g}",
                             change="—" if change is None else f"{change:.2g}", refresh=False)
        return None

    def close(self):
        self.bar.close()


class Every(Tracker):
    """``action(ls)`` every ``interval`` steps (with ``at_start``, also before the first
    step; with ``on_interrupt``, also on Ctrl-C — a checkpoint)."""

    def __init__(self, interval: int | None, action, *, at_start: bool = False,
                 on_interrupt: str | None = None):
        self.interval, self.action = interval, action
        self.at_start, self.on_interrupt = at_start, on_interrupt

    def start(self, ls, diag):
        if self.at_start:
            self.action(ls)

    def handle(self, ls, diag):
        if self.interval and ls.k % self.interval == 0:
            self.action(ls)

    def interrupted(self, ls):
        if self.on_interrupt is None:
            return None
        self.action(ls)
        return self.on_interrupt
