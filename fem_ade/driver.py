"""One time loop for every backend: stepping, recording, steady state, guards and output.

:func:`run_loop` drives any object that implements :class:`fem_ade.backend.Backend`;
:func:`simulate` is the Python API behind the CLI (scene + backend + output folder).

Stopping rules
--------------
* ``steps=K``: exactly K steps.
* ``until_steady=TOL``: stop at the first record where the relative change of E_M per step,
  averaged over the last record interval, is below TOL::

      |E(k) − E(k − every)| / (every · |E(k)|) < TOL

  or after ``max_steps`` steps (status ``max_steps``).

Guards
------
After every step, a non-finite φ or max|φ| > 2 stops the run (status ``diverged``, exit code
3): the state of the last finite step is restored and saved, no non-finite row is written,
and the message names the step and the likely cause (:func:`fem_ade.model.diagnose_blowup`).
A diagnostics record with a non-finite value is treated the same way.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

from tqdm.auto import tqdm

from .backend import Backend, make_backend
from .model import HISTORY_COLUMNS, ModelError, check_resolution, diagnose_blowup
from .output import HistoryWriter, check_out_dir, package_versions, write_fields, write_json_atomic
from .scenes import Scene

PHI_BOUND = 2.0

EXIT_OK, EXIT_BAD_INPUT, EXIT_DIVERGED, EXIT_INTERRUPTED = 0, 2, 3, 130


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

    @property
    def exit_code(self) -> int:
        codes = {"diverged": EXIT_DIVERGED, "interrupted": EXIT_INTERRUPTED}
        return codes.get(self.status, EXIT_OK)


def _finite(d: dict) -> bool:
    return all(math.isfinite(float(v)) for v in d.values())


def run_loop(
    backend: Backend,
    *,
    dt: float,
    steps: int | None = None,
    until_steady: float | None = None,
    max_steps: int = 100_000,
    every: int = 10,
    quiet: bool = True,
    history: HistoryWriter | None = None,
    label: str = "",
) -> RunResult:
    """Advance ``backend`` and record every ``every`` steps (and the first and last step).

    Returns a :class:`RunResult`; the backend is left in the last finite state.
    """
    if (steps is None) == (until_steady is None):
        raise ModelError("give exactly one of steps and until_steady")
    if every < 1:
        raise ModelError(f"--every must be >= 1, got {every}")
    total = steps if steps is not None else max_steps
    if total < 0:
        raise ModelError(f"steps must be >= 0, got {total}")
    params = backend.scene.params
    rows: list[dict] = []
    extra = {c: 0 for c in backend.extra_columns}
    t0 = time.perf_counter()

    def record(k: int, diag: dict) -> dict:
        row = {"step": k, "t": k * dt, **{c: diag[c] for c in HISTORY_COLUMNS[2:]}, **extra}
        rows.append(row)
        if history is not None:
            history.write(row)
        return row

    diag = backend.diagnostics()
    if not _finite(diag):
        return RunResult("diverged", 0, 0.0, diag, "the initial condition is not finite",
                         time.perf_counter() - t0, rows)
    record(0, diag)
    last_E, last_diag = diag["E"], diag
    status, message, k = "completed", "", 0
    bar = tqdm(total=total, disable=quiet, desc=label or "run", unit="step", mininterval=0.5,
               dynamic_ncols=True)
    try:
        while k < total:
            good = backend.state()
            extra = {**extra, **backend.step()}
            k += 1
            bar.update(1)
            m = backend.max_abs_phi()
            bad = None
            if not math.isfinite(m):
                bad = "phi is not finite"
            elif m > PHI_BOUND:
                bad = f"max|phi| = {m:.3g} > {PHI_BOUND:g}"
            if bad is None and (k % every == 0 or k == total):
                diag = backend.diagnostics()
                if not _finite(diag):
                    bad = "a diagnostic is not finite"
            if bad is not None:
                backend.set_state(good)
                k -= 1
                status = "diverged"
                message = (f"diverged at step {k + 1} (t = {(k + 1) * dt:.4g}): {bad}; "
                           f"likely cause: {diagnose_blowup(params, dt, last_diag)}. "
                           f"The last finite state (step {k}) is saved.")
                last_diag = backend.diagnostics()
                if k > 0 and rows[-1]["step"] != k and _finite(last_diag):
                    diag = last_diag
                    record(k, diag)  # the last finite state, for the record
                break
            if k % every == 0 or k == total:
                record(k, diag)
                bar.set_postfix(t=f"{k * dt:.3g}", E=f"{diag['E']:.6g}", refresh=False)
                if until_steady is not None and k % every == 0:
                    change = abs(diag["E"] - last_E) / (every * max(abs(diag["E"]), 1e-300))
                    if change < until_steady:
                        status = "steady"
                        message = (f"steady at step {k}: relative energy change per step "
                                   f"{change:.3g} < {until_steady:g}")
                        last_diag = diag
                        break
                last_E, last_diag = diag["E"], diag
        else:
            if until_steady is not None:
                status = "max_steps"
                message = f"not steady after max_steps = {total} steps"
    except KeyboardInterrupt:
        status = "interrupted"
        message = f"interrupted at step {k}; the state of step {k} is saved"
        last_diag = backend.diagnostics()
    finally:
        bar.close()
    if status == "completed":
        message = f"completed {k} steps"
    return RunResult(status, k, k * dt, last_diag, message, time.perf_counter() - t0, rows)


def simulate(
    scene: Scene,
    *,
    backend: str = "spectral",
    n: int | None = None,
    dt: float | None = None,
    steps: int | None = None,
    until_steady: float | None = None,
    max_steps: int = 100_000,
    every: int = 10,
    ic: str = "consistent",
    perturb: float = 0.0,
    seed: int = 0,
    out: str | Path | None = None,
    force: bool = False,
    quiet: bool = True,
    allow_underresolved: bool = False,
    backend_options: dict | None = None,
) -> RunResult:
    """Run ``scene`` with ``backend`` and, if ``out`` is given, write its results there.

    Writes ``out/history.csv``, ``out/summary.json`` and ``out/final.npz`` (the final field;
    on divergence the last finite one). All input is checked before anything is written;
    bad input raises :class:`fem_ade.model.ModelError`.
    """
    n = scene.n if n is None else n
    dt = scene.dt if dt is None else dt
    if steps is None and until_steady is None:
        steps = scene.steps
    scene.params.validate()
    check_resolution(scene.params, n, dt, allow_underresolved=allow_underresolved)
    if perturb < 0:
        raise ModelError(f"--perturb must be >= 0, got {perturb}")
    out = check_out_dir(out, force=force) if out is not None else None
    be = make_backend(backend, scene, n=n, dt=dt, ic=ic, perturb=perturb, seed=seed,
                      **(backend_options or {}))
    writer = None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        writer = HistoryWriter(out / "history.csv", HISTORY_COLUMNS + tuple(be.extra_columns))
    try:
        result = run_loop(be, dt=dt, steps=steps, until_steady=until_steady, max_steps=max_steps,
                          every=every, quiet=quiet, history=writer, label=scene.name)
    finally:
        if writer is not None:
            writer.close()
    if out is not None:
        write_fields(out / "final.npz", be.fields(), step=result.steps, t=result.t, dt=dt,
                     status=result.status)
        write_json_atomic(out / "summary.json", {
            "scene": scene.name,
            "figure": scene.figure,
            "parameters": scene.params.as_dict(),
            "backend": be.name,
            "backend_info": be.info(),
            "n": n,
            "dt": dt,
            "ic": ic,
            "perturb": perturb,
            "seed": seed,
            "steps": result.steps,
            "t": result.t,
            "status": result.status,
            "message": result.message,
            "final": result.final,
            "wall_s": result.wall_s,
            "versions": package_versions(),
        })
    return result
