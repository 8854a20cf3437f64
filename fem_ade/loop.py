"""One time loop for every backend: stepping, recording, steady state, guards, adaptive Δt.

:func:`run_loop` drives any object that implements :class:`fem_ade.backend.Backend` and knows
nothing else about it; the loop alone holds Δt and pushes it to the backend
(:meth:`~fem_ade.backend.Backend.set_dt`). Writing a run folder is :mod:`fem_ade.runs`.

Stopping rules
--------------
* ``steps=K``: until step K.
* ``until_steady=TOL``: stop at the first record where the relative change of E_M per step,
  averaged over the last record interval, is below TOL::

      |E(k) − E(k − every)| / (every · |E(k)|) < TOL

  or after ``max_steps`` steps (status ``max_steps``).

Guards
------
After every step, a non-finite φ or max|φ| > 2 stops the run (status ``diverged``, exit code
3): the state of the last finite step is restored and saved, no non-finite row is written,
and the message names the step and the likely cause (:func:`fem_ade.model.diagnose_blowup`).
A diagnostics record with a non-finite value, a ``FloatingPointError`` (under
``np.errstate(all="raise")``) or a failed constraint solve during the step are treated the
same way.

Adaptive Δt
-----------
With an :class:`AdaptiveDt`, E_M is measured after every step. A step that raises E_M by more
than ``tol``·|E_M| or trips a guard is rejected: the state is restored and Δt is halved (below
``dt_min`` the run stops as diverged). After ``grow_after`` accepted steps in a row with
decreasing energy, Δt grows by ``grow`` up to ``dt_max``. History gains a ``dt`` column.

Momentum (``accelerate=True``)
------------------------------
For steady states, not transients: the step T of the scheme (its fixed points are the
steady states) is iterated with FISTA-type momentum and adaptive restart (O'Donoghue &
Candès, Found. Comput. Math. 15, 2015): x_{k+1} = T(y_k), y_{k+1} = x_{k+1} + β_k(x_{k+1} − x_k)
with β_k = (t_k − 1)/t_{k+1}, t_{k+1} = (1 + √(1 + 4t_k²))/2; a step whose E_M exceeds E(x_k)
is taken again from x_k with the momentum reset (t = 1). The fixed points are those of T,
so the steady state is the scheme's own; it is reached in far fewer steps (measured:
``discocyte`` n = 32, exact constraints, stabilized 100× Δt, to 1e-8: 300 steps instead of
8700). ``t`` is then steps × Δt, not a physical time. Records and the final state are the
iterates x; E_M is measured after every step.

Checkpoints
-----------
``on_checkpoint(state)`` is called every ``checkpoint_every`` steps and on Ctrl-C (status
``interrupted``, exit code 130), with the backend in the state of ``state.k``; with the
:class:`LoopState` and the backend's :meth:`~fem_ade.backend.Backend.state` a run continues
bit for bit (:func:`fem_ade.runs.resume`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from tqdm.auto import tqdm

from .backend import Backend
from .constraints import ConstraintError
from .model import HISTORY_COLUMNS, ModelError, diagnose_blowup

PHI_BOUND = 2.0

EXIT_OK, EXIT_BAD_INPUT, EXIT_DIVERGED, EXIT_INTERRUPTED = 0, 2, 3, 130


@dataclass
class AdaptiveDt:
    """Bounds and factors of the adaptive time step (see the module docstring)."""

    dt_min: float
    dt_max: float
    grow: float = 1.25
    shrink: float = 0.5
    grow_after: int = 5
    tol: float = 1e-12

    def __post_init__(self):
        if not (0 < self.dt_min <= self.dt_max):
            raise ModelError(f"adaptive dt bounds must satisfy 0 < dt_min <= dt_max, "
                             f"got {self.dt_min:g}, {self.dt_max:g}")
        if not (self.grow > 1 and 0 < self.shrink < 1 and self.grow_after >= 1):
            raise ModelError("adaptive dt needs grow > 1, 0 < shrink < 1, grow_after >= 1")


@dataclass
class LoopState:
    """Where the loop is: what a checkpoint stores beside the backend's state."""

    k: int = 0
    t: float = 0.0
    dt: float = 0.0
    last_E: float = math.nan
    accepted: int = 0
    rejected: int = 0
    extra: dict = field(default_factory=dict)
    #: momentum (``accelerate``): t_k, the number of restarts, and the previous iterate
    #: x_{k−1} (a backend state; not part of the JSON of a checkpoint, which stores its arrays)
    momentum_t: float = 1.0
    restarts: int = 0
    anchor: dict | None = field(default=None, repr=False)

    def to_json(self) -> dict:
        return {k: v for k, v in vars(self).items() if k != "anchor"}


@dataclass
class RunResult:
    """What a run ended with. ``status``: completed, steady, max_steps, diverged, interrupted."""

    status: str
    steps: int
    t: float
    final: dict
    message: str = ""
    wall_s: float = 0.0
    history: list[dict] = field(default_factory=list)
    dt: float = math.nan
    rejected: int = 0
    shape: dict | None = None
    shapes: list[dict] = field(default_factory=list)
    restarts: int = 0
    #: φ on the uniform grid at the end (set by fem_ade.runs for 3D and 2D runs)
    final_grid: object = None
    #: the loop's CPU time (all the process' threads), beside ``wall_s``
    cpu_s: float = 0.0
    #: the backend's set-up CPU time (set by fem_ade.runs)
    setup_cpu_s: float = 0.0

    @property
    def exit_code(self) -> int:
        codes = {"diverged": EXIT_DIVERGED, "interrupted": EXIT_INTERRUPTED}
        return codes.get(self.status, EXIT_OK)


def _finite(d: dict) -> bool:
    return all(math.isfinite(float(v)) for v in d.values())


def _guard(backend: Backend) -> str | None:
    m = backend.max_abs_phi()
    if not math.isfinite(m):
        return "phi is not finite"
    if m > PHI_BOUND:
        return f"max|phi| = {m:.3g} > {PHI_BOUND:g}"
    return None


class _Progress:
    """The progress bar: steps done of ``--steps``; toward a steady state, how far the
    criterion has come — log₁₀ of the relative energy change per step, from its first
    measured value to the tolerance, as a percentage — with tqdm's rate-based ETA and the
    step, E and the change beside it (a bar to the step cap would show 1 % of a run that is
    nearly done)."""

    def __init__(self, total: int, start: int, until_steady: float | None, quiet: bool,
                 label: str):
        self.tol, self.first = until_steady, None
        if until_steady is None:
            self.bar = tqdm(total=total, initial=start, disable=quiet, desc=label or "run",
                            unit="step", mininterval=0.5, dynamic_ncols=True)
        else:
            self.bar = tqdm(total=100, disable=quiet, desc=f"{label or 'run'} to steady",
                            unit="%", mininterval=0.5, dynamic_ncols=True,
                            bar_format="{l_bar}{bar}| {n:.0f}/100 [{elapsed}<{remaining}"
                                       "{postfix}]")

    def step(self) -> None:
        if self.tol is None:
            self.bar.update(1)

    def record(self, k: int, t: float, E: float, change: float | None) -> None:
        if self.tol is None:
            self.bar.set_postfix(t=f"{t:.3g}", E=f"{E:.6g}", refresh=False)
            return
        if change is not None and change > 0 and math.isfinite(change):
            if self.first is None:
                self.first = max(change, 10.0 * self.tol)
            span = math.log10(self.first) - math.log10(self.tol)
            done = (math.log10(self.first) - math.log10(change)) / span if span > 0 else 1.0
            self.bar.update(100.0 * min(max(done, 0.0), 1.0) - self.bar.n)
        self.bar.set_postfix(step=k, E=f"{E:.8g}",
                             change="—" if change is None else f"{change:.2g}", refresh=False)

    def close(self) -> None:
        self.bar.close()


def run_loop(
    backend: Backend,
    *,
    dt: float,
    steps: int | None = None,
    until_steady: float | None = None,
    max_steps: int = 100_000,
    every: int = 10,
    quiet: bool = True,
    history=None,
    label: str = "",
    adaptive: AdaptiveDt | None = None,
    checkpoint_every: int | None = None,
    on_checkpoint=None,
    observers=(),
    start: LoopState | None = None,
    accelerate: bool = False,
) -> RunResult:
    """Advance ``backend`` from ``start`` (default: step 0) and record every ``every`` steps.

    ``history``: anything with ``write(row: dict)`` (e.g. :class:`fem_ade.output.HistoryWriter`),
    called with each recorded row as it is made.
    ``on_checkpoint(state: LoopState)`` is called every ``checkpoint_every`` steps and on
    Ctrl-C; each ``(every, observe)`` of ``observers`` has ``observe(state)`` called at the start
    and every ``every`` steps (``every`` None: at the start only), each with the
    backend in the state of ``state.k``. Returns a :class:`RunResult`; the backend is left in
    the last finite state.
    """
    if (steps is None) == (until_steady is None):
        raise ModelError("give exactly one of steps and until_steady")
    if accelerate and adaptive is not None:
        raise ModelError("--accelerate and --adaptive do not go together (momentum needs a "
                         "fixed step map)")
    if every < 1:
        raise ModelError(f"--every must be >= 1, got {every}")
    for value in (checkpoint_every, *(k for k, _ in observers)):
        if value is not None and value < 1:
            raise ModelError(f"checkpoint and observer intervals must be >= 1, got {value}")
    total = steps if steps is not None else max_steps
    if total < 0:
        raise ModelError(f"steps must be >= 0, got {total}")
    params = backend.scene.params
    rows: list[dict] = []
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    ls = start or LoopState(dt=dt, extra={c: 0 for c in backend.extra_columns})
    backend.set_dt(ls.dt)  # the loop holds Δt

    def record(diag: dict) -> None:
        row = {"step": ls.k, "t": ls.t, **{c: diag[c] for c in HISTORY_COLUMNS[2:]}, **ls.extra}
        if adaptive is not None:
            row["dt"] = ls.dt
        rows.append(row)
        if history is not None:
            history.write(row)

    def result(status, message, diag):
        return RunResult(status, ls.k, ls.t, diag, message, time.perf_counter() - t_wall, rows,
                         ls.dt, ls.rejected, restarts=ls.restarts,
                         cpu_s=time.process_time() - t_cpu)

    diag = backend.diagnostics()
    if not _finite(diag):
        return result("diverged", "the state to start from is not finite", diag)
    if start is None:
        record(diag)
        ls.last_E = diag["E"]
    for _, observe in observers:
        observe(ls)
    last_diag, last_recorded_E = diag, ls.last_E
    status, message = "completed", ""
    bar = _Progress(total, ls.k, until_steady, quiet, label)
    good, good_k = None, None
    try:
        while ls.k < total:
            good, good_k = backend.state(), ls.k  # with momentum: the iterate x_k
            if accelerate:
                t_next = _extrapolate(backend, ls)
            try:
                extra = backend.step()
                bad = _guard(backend)
            except ConstraintError as err:
                extra, bad = {}, str(err)
            except FloatingPointError as err:
                extra, bad = {}, f"floating-point error ({err})"
            is_record = (ls.k + 1) % every == 0 or ls.k + 1 == total
            if accelerate and bad is None:
                extra, bad, diag, t_next = _momentum_step(backend, ls, good, extra, t_next)
            elif bad is None and (is_record or adaptive is not None):
                try:
                    diag = backend.diagnostics()
                except FloatingPointError:
                    diag = {"E": math.nan}
                if not _finite(diag):
                    bad = "a diagnostic is not finite"
            if (adaptive is not None and bad is None and backend.dissipative
                    and diag["E"] > ls.last_E + adaptive.tol * abs(ls.last_E)):
                bad = f"E_M rose from {ls.last_E:.6g} to {diag['E']:.6g}"
            can_shrink = adaptive is not None and ls.dt * adaptive.shrink >= adaptive.dt_min
            if bad is not None and can_shrink:
                backend.set_state(good)  # reject: halve dt and retry
                ls.dt *= adaptive.shrink
                ls.rejected += 1
                ls.accepted = 0
                backend.set_dt(ls.dt)
                continue
            if bad is not None:
                backend.set_state(good)
                status = "diverged"
                message = (f"diverged at step {ls.k + 1} (t = {ls.t + ls.dt:.4g}): {bad}; "
                           f"likely cause: {diagnose_blowup(params, ls.dt, last_diag)}. "
                           f"The last finite state (step {ls.k}) is saved.")
                last_diag = backend.diagnostics()
                if ls.k > 0 and rows and rows[-1]["step"] != ls.k and _finite(last_diag):
                    record(last_diag)  # the last finite state, for the record
                break
            ls.k += 1
            ls.t += ls.dt
            ls.extra = {**ls.extra, **extra}
            bar.step()
            if accelerate:
                ls.anchor, ls.momentum_t, ls.last_E = good, t_next, diag["E"]
            if adaptive is not None:
                ls.accepted = ls.accepted + 1 if diag["E"] <= ls.last_E else 0
                ls.last_E, last_diag = diag["E"], diag
                if ls.accepted >= adaptive.grow_after and ls.dt < adaptive.dt_max:
                    ls.dt = min(ls.dt * adaptive.grow, adaptive.dt_max)
                    ls.accepted = 0
                    backend.set_dt(ls.dt)
            if is_record:
                record(diag)
                last_diag = diag
                change = None
                if until_steady is not None and ls.k % every == 0:
                    scale = every * max(abs(diag["E"]), 1e-300)
                    change = abs(diag["E"] - last_recorded_E) / scale
                bar.record(ls.k, ls.t, diag["E"], change)
                if change is not None:
                    if change < until_steady:
                        status = "steady"
                        message = (f"steady at step {ls.k}: relative energy change per step "
                                   f"{change:.3g} < {until_steady:g}")
                        break
                last_recorded_E = diag["E"]
                if adaptive is None and not accelerate:
                    ls.last_E = diag["E"]
            if on_checkpoint is not None and checkpoint_every and ls.k % checkpoint_every == 0:
                on_checkpoint(ls)
            for every_k, observe in observers:
                if every_k and ls.k % every_k == 0:
                    observe(ls)
        else:
            if until_steady is not None:
                status = "max_steps"
                message = f"not steady after max_steps = {total} steps"
    except KeyboardInterrupt:
        if good is not None and good_k == ls.k:
            backend.set_state(good)  # the interrupted step may be half done
        status = "interrupted"
        message = f"interrupted at step {ls.k}"
        last_diag = backend.diagnostics()
        if on_checkpoint is not None:
            on_checkpoint(ls)
            message += "; checkpoint written"
    finally:
        bar.close()
    if status == "completed":
        message = f"completed {ls.k} steps"
    if adaptive is not None:
        message += f" (dt now {ls.dt:.3g}, {ls.rejected} rejected steps)"
    if accelerate:
        message += f" (momentum, {ls.restarts} restarts)"
    return result(status, message, last_diag)


def _extrapolate(backend: Backend, ls: LoopState) -> float:
    """Move the backend from x_k to y_k = x_k + β(x_k − x_{k−1}); return t_{k+1}. No momentum
    at the start, nor across a step that moved the targets of the constraints."""
    t_next = 0.5 * (1.0 + math.sqrt(1.0 + 4.0 * ls.momentum_t**2))
    beta = (ls.momentum_t - 1.0) / t_next
    if ls.anchor is None or not backend.dissipative or beta <= 0.0:
        return 1.0 if ls.anchor is None or not backend.dissipative else t_next
    backend.extrapolate(ls.anchor, beta)
    return t_next


def _momentum_step(backend: Backend, ls: LoopState, x: dict, extra: dict, t_next: float):
    """After the step from y_k: (extra, problem or None, diagnostics of x_{k+1}, t_{k+1}). A
    step whose E_M rose above E(x_k) is taken again from x_k with the momentum reset."""
    diag = backend.diagnostics()
    if not _finite(diag):
        return extra, "a diagnostic is not finite", diag, t_next
    if backend.dissipative and diag["E"] > ls.last_E and ls.momentum_t > 1.0:
        backend.set_state(x)
        ls.restarts += 1
        extra = backend.step()
        bad = _guard(backend)
        diag = backend.diagnostics()
        if bad is None and not _finite(diag):
            bad = "a diagnostic is not finite"
        return extra, bad, diag, 1.0
    return extra, None, diag, t_next
