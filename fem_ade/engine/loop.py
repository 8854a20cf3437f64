"""One time loop for every backend: stepping, recording, steady state, guards, adaptive Δt.

:func:`run_loop` drives any object that implements :class:`fem_ade.backends.base.Backend` and knows
nothing else about it; the loop alone holds Δt and pushes it to the backend
(:meth:`~fem_ade.backends.base.Backend.set_dt`). A run folder is :mod:`fem_ade.engine.execute`'s.

The loop reads as the scheme's: a *stepper* takes each step and decides what a failed one
means (:class:`FixedStep`, :class:`AdaptiveStep`, :class:`MomentumStep`); the side concerns
are *trackers* called after each accepted step (:class:`History`, :class:`SteadyState`,
:class:`Progress`, :class:`Every` for checkpoints and observers), in the manner of py-pde's.

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
and the message names the step and the likely cause (:func:`fem_ade.model.params.diagnose_blowup`).
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
:class:`LoopState` and the backend's :meth:`~fem_ade.backends.base.Backend.state` a run continues
bit for bit (:func:`fem_ade.engine.runs.resume`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from fem_ade.backends.base import Backend
from fem_ade.engine.trackers import Every, History, Progress, SteadyState, Tracker
from fem_ade.model.constraints import ConstraintError
from fem_ade.model.params import ModelError, diagnose_blowup, is_int, is_real
from fem_ade.store import interrupt
from fem_ade.store.status import Status

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
    #: the loop's wall time; for a resumed run, summed over its sittings (each to the
    #: checkpoint the next one started from: fem_ade.engine.execute)
    wall_s: float = 0.0
    history: list[dict] = field(default_factory=list)
    dt: float = math.nan
    rejected: int = 0
    shape: dict | None = None
    shapes: list[dict] = field(default_factory=list)
    restarts: int = 0
    #: φ on the uniform grid at the end (set by fem_ade.engine.execute for 3D and 2D runs)
    final_grid: object = None
    #: the loop's CPU time (all the process' threads), beside ``wall_s`` and summed as it is
    cpu_s: float = 0.0
    #: the backend's set-up CPU time (set by fem_ade.engine.execute)
    setup_cpu_s: float = 0.0
    #: why the shape analysis after the run failed (None: it did not; fem_ade.engine.execute)
    analysis_error: str | None = None

    @property
    def exit_code(self) -> int:
        codes = {Status.DIVERGED: EXIT_DIVERGED, Status.INTERRUPTED: EXIT_INTERRUPTED}
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


def _take_step(backend: Backend) -> tuple[dict, str | None]:
    """One step of the scheme: (its extra history values, what went wrong or None)."""
    try:
        return backend.step(), _guard(backend)
    except ConstraintError as err:
        return {}, str(err)
    except FloatingPointError as err:
        return {}, f"floating-point error ({err})"


def _measure(backend: Backend) -> tuple[dict, str | None]:
    """The backend's diagnostics and, if one is not finite, that problem."""
    try:
        diag = backend.diagnostics()
    except FloatingPointError:
        diag = {"E": math.nan}
    return diag, None if _finite(diag) else "a diagnostic is not finite"


# ---------------------------------------------------------------------------------------
# steppers: how one step is taken, judged and, when it fails, taken again
# ---------------------------------------------------------------------------------------
class FixedStep:
    """The scheme's step at the loop's Δt; a failed step ends the run."""

    def advance(self, backend: Backend, ls: LoopState, good: dict, measure: bool):
        """Take the step from ``good`` (the backend's state at step ``ls.k``): (extra
        history values, problem or None, diagnostics after it or None if not measured)."""
        extra, bad = _take_step(backend)
        diag = None
        if bad is None and measure:
            diag, bad = _measure(backend)
        return extra, bad, diag

    def retry(self, backend: Backend, ls: LoopState) -> bool:
        """After a failed step (the state restored): whether to take it again."""
        return False

    def accepted(self, backend: Backend, ls: LoopState, good: dict, diag: dict | None) -> None:
        """After step ``ls.k`` is accepted (``diag``: its diagnostics if measured)."""
        if diag is not None:
            ls.last_E = diag["E"]  # the last recorded energy (a steady-state stop resumes)

    def summary(self, ls: LoopState) -> str:
        return ""


class AdaptiveStep(FixedStep):
    """Adaptive Δt (:class:`AdaptiveDt`): every step is measured; a step that raises E_M
    or fails is taken again at half Δt; Δt grows after steps that lower it."""

    def __init__(self, control: AdaptiveDt):
        self.control = control

    def advance(self, backend, ls, good, measure):
        extra, bad, diag = super().advance(backend, ls, good, True)
        c = self.control
        if (bad is None and backend.dissipative
                and diag["E"] > ls.last_E + c.tol * abs(ls.last_E)):
            bad = f"E_M rose from {ls.last_E:.6g} to {diag['E']:.6g}"
        return extra, bad, diag

    def retry(self, backend, ls):
        c = self.control
        if ls.dt * c.shrink < c.dt_min:
            return False
        ls.dt *= c.shrink
        ls.rejected += 1
        ls.accepted = 0
        backend.set_dt(ls.dt)
        return True

    def accepted(self, backend, ls, good, diag):
        c = self.control
        ls.accepted = ls.accepted + 1 if diag["E"] <= ls.last_E else 0
        ls.last_E = diag["E"]
        if ls.accepted >= c.grow_after and ls.dt < c.dt_max:
            ls.dt = min(ls.dt * c.grow, c.dt_max)
            ls.accepted = 0
            backend.set_dt(ls.dt)

    def summary(self, ls):
        return f" (dt now {ls.dt:.3g}, {ls.rejected} rejected steps)"


class MomentumStep(FixedStep):
    """The step with FISTA-type momentum and adaptive restart (see the module docstring):
    every step is measured; the iterates x are the states the loop keeps."""

    t_next = 1.0

    def advance(self, backend, ls, good, measure):
        self.t_next = _extrapolate(backend, ls)
        extra, bad = _take_step(backend)
        if bad is not None:
            return extra, bad, None
        extra, bad, diag, self.t_next = _momentum_step(backend, ls, good, extra, self.t_next)
        return extra, bad, diag

    def accepted(self, backend, ls, good, diag):
        ls.anchor, ls.momentum_t, ls.last_E = good, self.t_next, diag["E"]

    def summary(self, ls):
        return f" (momentum, {ls.restarts} restarts)"


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
    diag, bad = _measure(backend)
    if bad is not None:
        return extra, bad, diag, t_next
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


# ---------------------------------------------------------------------------------------
# the loop
# ---------------------------------------------------------------------------------------
def option(name: str) -> str:
    """A run option as an error names it: the Python keyword, and the command line's flag
    beside it (one message for both front ends: ``simulate(max_steps=0)`` and
    ``--max-steps 0``)."""
    return f"{name} (--{name.replace('_', '-')})"


def check_loop_options(*, steps, until_steady, max_steps, every, checkpoint_every=None,
                       save_every=None, shape_every=None, accelerate=False, adaptive=None,
                       min_steps: int = 1) -> None:
    """The loop's numbers and stepping, before anything is built or written (ModelError,
    one line): the one check of them, by :func:`run_loop` and by
    :meth:`fem_ade.engine.config.RunConfig.check` (a run's ``steps`` >= 1; the loop also
    takes 0, a run that only measures its start)."""
    if (steps is None) == (until_steady is None):
        raise ModelError("give exactly one of steps and until_steady")
    for name, value, low in (("steps", steps, min_steps), ("max_steps", max_steps, 1),
                             ("every", every, 1), ("checkpoint_every", checkpoint_every, 1),
                             ("save_every", save_every, 1), ("shape_every", shape_every, 1)):
        if value is None:
            continue
        if not is_int(value, low):
            raise ModelError(f"{option(name)} must be an integer >= {low}, got {value!r}")
    if until_steady is not None and not (is_real(until_steady) and until_steady > 0):
        raise ModelError(f"{option('until_steady')} must be a positive number, got "
                         f"{until_steady}")
    if accelerate and adaptive:
        raise ModelError(f"{option('accelerate')} and {option('adaptive')} do not go "
                         "together (momentum needs a fixed step map)")


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

    ``history``: anything with ``write(row: dict)`` (e.g.
    :class:`fem_ade.store.output.HistoryWriter`),
    called with each recorded row as it is made.
    ``on_checkpoint(state: LoopState)`` is called every ``checkpoint_every`` steps and on
    Ctrl-C; each ``(every, observe)`` of ``observers`` has ``observe(state)`` called at the start
    and every ``every`` steps (``every`` None: at the start only), each with the
    backend in the state of ``state.k``. Returns a :class:`RunResult`; the backend is left in
    the last finite state.

    The loop itself is the scheme's: a stepper (:class:`FixedStep`, :class:`AdaptiveStep`,
    :class:`MomentumStep`) takes each step; everything else — the history, the steady-state
    stop, the progress bar, checkpoints, observers — is a :class:`Tracker`.
    """
    check_loop_options(steps=steps, until_steady=until_steady, max_steps=max_steps,
                       every=every, checkpoint_every=checkpoint_every, accelerate=accelerate,
                       adaptive=adaptive, min_steps=0)
    if start is None and not (is_real(dt) and dt > 0):
        raise ModelError(f"dt must be a positive number, got {dt!r}")
    for value, _ in observers:
        if value is not None and not is_int(value, 1):
            raise ModelError(f"an observer's interval must be an integer >= 1, got {value!r}")
    total = steps if steps is not None else max_steps
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    ls = start or LoopState(dt=dt, extra={c: 0 for c in backend.extra_columns})
    backend.set_dt(ls.dt)  # the loop holds Δt
    stepper = (AdaptiveStep(adaptive) if adaptive is not None
               else MomentumStep() if accelerate else FixedStep())
    recorder = History(every, total, history, with_dt=adaptive is not None,
                       fresh=start is None)
    trackers: list[Tracker] = [recorder, Progress(total, ls.k, until_steady, every, quiet,
                                                  label)]
    if until_steady is not None:  # after the bar, which shows the last change too
        trackers.append(SteadyState(until_steady, every))
    if on_checkpoint is not None:
        trackers.append(Every(checkpoint_every, on_checkpoint,
                              on_interrupt="; checkpoint written"))
    trackers += [Every(k, observe, at_start=True) for k, observe in observers]

    def result(status, message, diag):
        return RunResult(status, ls.k, ls.t, diag, message, time.perf_counter() - t_wall,
                         recorder.rows, ls.dt, ls.rejected, restarts=ls.restarts,
                         cpu_s=time.process_time() - t_cpu)

    diag, bad = _measure(backend)
    if bad is not None:
        for tracker in trackers:
            tracker.close()
        return result(Status.DIVERGED, "the state to start from is not finite", diag)
    if start is None:
        ls.last_E = diag["E"]
    last_diag = diag
    status, message = Status.COMPLETED, ""
    good, good_k = None, None
    try:
        for tracker in trackers:
            tracker.start(ls, diag)
        while ls.k < total:
            interrupt.check()  # a signal whose exception Python dropped (fem_ade.store.interrupt)
            good, good_k = backend.state(), ls.k  # with momentum: the iterate x_k
            measure = any(tr.wants_diagnostics(ls.k + 1) for tr in trackers)
            extra, bad, diag = stepper.advance(backend, ls, good, measure)
            if bad is not None:
                backend.set_state(good)
                if stepper.retry(backend, ls):
                    continue
                status = Status.DIVERGED
                cause = diagnose_blowup(backend.scene.params, ls.dt, last_diag)
                message = (f"diverged at step {ls.k + 1} (t = {ls.t + ls.dt:.4g}): {bad}; "
                           f"likely cause: {cause}. "
                           f"The last finite state (step {ls.k}) is saved.")
                last_diag = backend.diagnostics()
                rows = recorder.rows
                if ls.k > 0 and rows and rows[-1]["step"] != ls.k and _finite(last_diag):
                    recorder.record(ls, last_diag)  # the last finite state, for the record
                break
            with interrupt.critical():  # the step's count, time, rows and checkpoint whole
                ls.k += 1                # (a signal between them lost a row of history.csv)
                ls.t += ls.dt
                ls.extra = {**ls.extra, **extra}
                stepper.accepted(backend, ls, good, diag)
                if diag is not None:
                    last_diag = diag
                stop = None
                for tracker in trackers:
                    stop = tracker.handle(ls, diag)
                    if stop is not None:
                        break
            if stop is not None:
                status, message = stop
                break
        else:
            if until_steady is not None:
                status = Status.MAX_STEPS
                message = f"not steady after max_steps = {total} steps"
    except KeyboardInterrupt:
        interrupt.handled()
        if good is not None and good_k == ls.k:
            backend.set_state(good)  # the interrupted step may be half done
        status = Status.INTERRUPTED
        message = f"interrupted at step {ls.k}"
        last_diag = backend.diagnostics()
        for tracker in trackers:
            message += tracker.interrupted(ls) or ""
    finally:
        for tracker in trackers:
            tracker.close()
    if status == Status.COMPLETED:
        message = f"completed {ls.k} steps"
    return result(status, message + stepper.summary(ls), last_diag)
