"""The command line: ``python -m fem_ade.run SCENE_OR_TOML [options]``, thin over
:func:`fem_ade.engine.runs.simulate`; its choices come from :mod:`fem_ade.registry`.

Exit codes: 0 finished (completed, steady, or max-steps reached), 2 bad input (one line on
stderr, nothing written), 3 diverged (diagnosis printed, last finite state saved),
130 interrupted (SIGINT or SIGTERM, at any moment: one line, and the run folder, if one was
started, consistent — with a checkpoint to resume from once the loop has begun).

The heavy modules are imported inside :func:`main`, after the signal handlers are set, so
that an interrupt during start-up is one line too.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from fem_ade.registry import (
    BACKENDS,
    CONSTRAINTS,
    IC_VARIANTS,
    RECIPES,
    SCHEMES,
    VESICLE_BRANCHES,
    VOLUMES,
)
from fem_ade.store.status import Status

EXIT_BAD_INPUT, EXIT_FAILED, EXIT_INTERRUPTED = 2, 3, 130
#: the options --resume takes; every other one is stored in the run folder
RESUME_OPTIONS = {"resume", "steps", "quiet"}


class _Parser(argparse.ArgumentParser):
    """The command line's parser: one clear line and exit 2 on an error; ``options`` lists
    every option added (the Actions ``add_argument`` returns, also from argument groups)."""

    def __init__(self, *args, **kwargs):
        self.options: list[argparse.Action] = []  # before argparse adds its -h
        super().__init__(*args, **kwargs)

    def add_argument(self, *args, **kwargs):
        action = super().add_argument(*args, **kwargs)
        self.options.append(action)
        return action

    def _recording(self, group):
        add, options = group.add_argument, self.options

        def recorded(*a, **kw):
            action = add(*a, **kw)
            options.append(action)
            return action

        group.add_argument = recorded
        return group

    def add_argument_group(self, *args, **kwargs):
        return self._recording(super().add_argument_group(*args, **kwargs))

    def add_mutually_exclusive_group(self, *args, **kwargs):
        return self._recording(super().add_mutually_exclusive_group(*args, **kwargs))

    def error(self, message):  # one clear line, exit code 2
        self.exit(EXIT_BAD_INPUT, f"fem_ade.run: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="python -m fem_ade.run",
        description="Run a vesicle scene of the ADE phase-field model (see --list).",
        allow_abbrev=False,
    )
    p.add_argument("scene", nargs="?", help="a scene name (see --list) or a .toml scene file")
    p.add_argument("--resume", metavar="DIR",
                   help="continue the run in DIR from its checkpoint (up to --steps)")
    p.add_argument("--list", action="store_true", help="list the scenes with their paper figure")
    p.add_argument("--backend", choices=tuple(BACKENDS), default="fem",
                   help="; ".join(f"{b.name}: {b.description}" for b in BACKENDS.values())
                   + " (default fem)")
    p.add_argument("--recipe", choices=tuple(RECIPES), default=None,
                   help="what the run is for; sets defaults that the options below override: "
                   + "; ".join(f"{k}: {v}" for k, v in RECIPES.items())
                   + " (default: paper for the paper's scenes, steady for the vesicle family)")
    p.add_argument("--n", type=int,
                   help="nodes per axis, for every backend and order (the spectral grid; "
                        "the fem's n/order cells of order + 1 nodes, so a multiple of --order; "
                        "axisymmetric: per L at the finest spacing) (default: the scene's grid)")
    p.add_argument("--dt", type=float, help="time step (default: the paper's, per scene)")
    stop = p.add_mutually_exclusive_group()
    stop.add_argument("--steps", type=int, help="number of steps (default: the scene's, 200)")
    stop.add_argument("--until-steady", type=float, metavar="TOL",
                      help="stop when |dE|/(every*|E|) over a record interval < TOL")
    p.add_argument("--max-steps", type=int, default=None,
                   help="cap for --until-steady (default 100000)")
    p.add_argument("--every", type=int, default=10, help="record every K steps (default 10)")
    p.add_argument("--ic", choices=IC_VARIANTS, default="consistent",
                   help="initial condition: the paper's ellipsoid with c read consistently "
                        "(default) or as printed (docs/model.md §7), or seeded: the shape of the "
                        "paper's figure, sized so that its diffuse V, A are alpha, beta")
    p.add_argument("--perturb", type=float, default=0.0,
                   help="amplitude of a smooth seeded level-set perturbation (default 0)")
    p.add_argument("--seed", type=int, default=0, help="seed of --perturb (default 0)")
    p.add_argument("--phi0", metavar="RUN",
                   help="start from the final field of an earlier run (its folder or its "
                        "final.npz), resampled to this grid or mesh")
    p.add_argument("--scheme", choices=tuple(SCHEMES), default="paper",
                   help="; ".join(f"{k}: {v}" for k, v in SCHEMES.items()) + " (default paper)")
    p.add_argument("--constraints", choices=tuple(CONSTRAINTS), default="penalty",
                   help="; ".join(f"{k}: {v}" for k, v in CONSTRAINTS.items())
                   + " (default penalty)")
    p.add_argument("--volume", choices=tuple(VOLUMES), default=None,
                   help="the volume functional held at alpha: "
                   + "; ".join(f"{k}: {v}" for k, v in VOLUMES.items())
                   + " (default: the scene's, paper)")
    p.add_argument("--accelerate", action="store_true",
                   help="towards a steady state only: iterate the step with momentum and "
                        "adaptive restart (same steady states, far fewer steps; t is then not "
                        "a physical time)")
    p.add_argument("--adaptive", action="store_true",
                   help="adapt dt: grow while E_M decays, halve on a rejected step")
    p.add_argument("--checkpoint-every", type=int, metavar="K",
                   help="write OUT/checkpoint.npz every K steps (Ctrl-C writes one too)")
    p.add_argument("--save-every", type=int, metavar="K",
                   help="add phi (and mu) to the ParaView series OUT/phi.xdmf every K steps "
                        "(it always holds the first and the last state)")
    p.add_argument("--shape-every", type=int, metavar="K",
                   help="record the shape descriptors (label, components, genus, reduced "
                        "volume, axes ratios, necks, dimple) every K steps in OUT/shapes.csv")
    p.add_argument("--no-render", action="store_true",
                   help="skip OUT/shape.png and OUT/history.png")
    p.add_argument("--no-sharp", action="store_true",
                   help="skip the end shape's comparison with its sharp membrane (a sharp_ref "
                        "solve of 0.3-10 s)")
    p.add_argument("--out", help="output folder (default: runs/SCENE-BACKEND-TIME-XXXX, a new "
                                 "folder)")
    p.add_argument("--dry-run", action="store_true",
                   help="check every input, print what would run, write nothing")
    p.add_argument("--force", action="store_true", help="write into a non-empty --out folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--allow-underresolved", action="store_true",
                   help="allow h = L/n > eps (the interface is not resolved)")
    ves = p.add_argument_group("the vesicle scene (scene vesicle: a vesicle by its physical "
                               "parameters; the sharp shape of --branch as its seed)")
    ves.add_argument("--v", type=float, help="reduced volume, 0 < v <= 1 (default 0.9)")
    ves.add_argument("--da0", type=float,
                     help="relaxed reduced area difference (1 for a sphere; ADE with --kbar)")
    ves.add_argument("--kbar", type=float, help="ADE modulus over kappa (default 0: no ADE)")
    ves.add_argument("--C", type=float, help="spontaneous curvature (default 0)")
    ves.add_argument("--eps", type=float, help="interface width (default 0.04)")
    ves.add_argument("--branch", choices=VESICLE_BRANCHES,
                     help="the shape it starts from (default prolate)")
    ves.add_argument("--R0", type=float,
                     help="its size sqrt(A/4pi) in the unit box (default: the largest <= 0.25 "
                          "that fits)")
    for spec in BACKENDS.values():  # each backend's own options, default None = not given
        if not spec.options:
            continue
        group = p.add_argument_group(f"{spec.name} backend (--backend {spec.name})")
        for o in spec.options:
            group.add_argument(f"--{o.name}", type=o.type, choices=o.choices, default=None,
                               help=o.help)
    return p


def vesicle_options() -> tuple[str, ...]:
    """The vesicle scene's options: :class:`fem_ade.scenes.vesicle.Vesicle`'s fields but the box
    (each is a ``--NAME`` of the parser's vesicle group)."""
    from dataclasses import fields

    from fem_ade.scenes.vesicle import Vesicle

    return tuple(f.name for f in fields(Vesicle) if f.name != "L")


def list_scenes() -> str:
    from fem_ade.scenes.catalogue import PAPER_SCENES, TEACHING_SCENES

    verdicts = gallery_verdicts()
    lines = ["paper scenes (docs/model.md §7; under each, what the gallery found: "
             "studies/gallery.py, variants a-d in docs/results.md):"]
    for s in PAPER_SCENES.values():
        lines.append(f"  {s.name:16s} {s.figure:9s} eps={s.params.eps:<5g} dt={s.dt:<6g} "
                     f"n={s.n:<4d} {s.description}")
        headline = verdicts.get(s.name, {}).get("headline", "not run yet")
        lines.append(f"  {'':16s} gallery: {headline}")
    lines.append("teaching scenes:")
    for s in TEACHING_SCENES.values():
        lines.append(f"  {s.name:16s} {s.figure:9s} eps={s.params.eps:<5g} dt={s.dt:<6g} "
                     f"n={s.n:<4d} {s.description}")
    lines += ["scene families (made from physical parameters):",
              f"  {'vesicle':16s} reduced volume --v, area difference --da0, --kbar, --C, "
              "--eps, seeded on --branch from its sharp shape (sharp_ref), run to a steady state "
              "(--recipe steady); e.g. vesicle --v 0.8 --branch oblate [--geometry "
              "axisymmetric]"]
    return "\n".join(lines)


def gallery_verdicts() -> dict:
    """Each paper scene's verdicts from the gallery (fem_ade/verdicts.json, written by
    studies/gallery.py); empty when the file is missing or unreadable."""
    import json

    try:
        return json.loads((Path(__file__).parents[1] / "verdicts.json").read_text())
    except (OSError, ValueError):
        return {}


def world() -> tuple[int, int]:
    """(rank, size) of the MPI job this process is part of, from the launcher's environment
    (without initialising MPI): (0, 1) when not started by mpirun/mpiexec."""
    for rank, size in (("OMPI_COMM_WORLD_RANK", "OMPI_COMM_WORLD_SIZE"),
                       ("PMI_RANK", "PMI_SIZE"), ("PMIX_RANK", "PMI_SIZE")):
        if rank in os.environ and size in os.environ:
            try:
                r, p = int(os.environ[rank]), int(os.environ[size])
            except ValueError:
                continue  # not a launcher's: a malformed variable is no MPI job
            if p >= 1 and 0 <= r < p:
                return r, p
    return 0, 1


RANK, SIZE = world()


def _error(message: str) -> int:
    if RANK == 0:  # under mpirun every rank checks the same input: rank 0 says it once
        print(f"fem_ade.run: error: {message}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _failed(message: str) -> int:
    """A run that could not write its folder mid-way: one line, exit 3."""
    if RANK == 0:
        print(f"fem_ade.run: error: {message}", file=sys.stderr)
    return EXIT_FAILED


def main(argv: list[str] | None = None) -> int:
    """Run the command line; under ``mpirun -n P`` (``--linalg petsc``) every rank runs it,
    rank 0 writes the run folder and prints, the others work in a private temporary folder
    (removed at the end), and a failure on any rank ends all of them (MPI_Abort) with its
    exit code."""
    from fem_ade.store.interrupt import install

    install()  # SIGINT too: a shell that starts us in the background has it ignored
    for stream in (sys.stdout, sys.stderr):  # a folder's name must never cost a traceback
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")
    scratch = None
    if RANK > 0:
        import tempfile

        scratch = tempfile.mkdtemp(prefix=f"fem_ade-rank{RANK}-")
    stdout = sys.stdout
    try:
        if scratch is not None:
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 (closed below)
        code = _main(argv, scratch=scratch)
    except KeyboardInterrupt:
        if RANK == 0:
            print("fem_ade.run: interrupted", file=sys.stderr)
        code = EXIT_INTERRUPTED
    finally:
        if sys.stdout is not stdout:
            sys.stdout.close()
            sys.stdout = stdout
        if scratch is not None:
            import shutil

            shutil.rmtree(scratch, ignore_errors=True)
    if code != 0 and SIZE > 1 and "mpi4py" in sys.modules:
        from mpi4py import MPI

        if MPI.Is_initialized() and not MPI.Is_finalized():
            sys.stdout.flush()
            sys.stderr.flush()
            MPI.COMM_WORLD.Abort(code)
    return code


def given_options(argv, parser) -> set[str]:
    """The options the user typed (their ``dest`` names), whatever their values."""
    given = set()
    for action in parser.options:
        for opt in action.option_strings:
            if any(a == opt or a.startswith(opt + "=") for a in argv):
                given.add(action.dest)
    return given


def _main(argv, scratch: str | None = None) -> int:
    """The command line; ``scratch``: this rank's private folder (MPI ranks > 0), where it
    writes what rank 0 writes into the run folder."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        os.getcwd()
    except OSError:
        return _error("the working directory no longer exists")
    if args.list:
        print(list_scenes())
        return 0
    given = given_options(sys.argv[1:] if argv is None else argv, parser)
    if args.resume is not None:
        return _resume_main(args, given, scratch)
    if args.scene is None:
        from fem_ade.scenes.catalogue import SCENES

        return _error(f"give a scene ({', '.join(SCENES)}) or a .toml file")
    if args.out == "":
        return _error("--out needs a folder name")
    return _run_main(args, given, scratch)


def _resume_main(args, given: set[str], scratch: str | None) -> int:
    """``--resume DIR``: continue the run stored in DIR (only --steps and --quiet may be
    given) and report it; returns the exit code."""
    from fem_ade.engine.execute import WriteFailed
    from fem_ade.engine.runs import resume
    from fem_ade.model.params import ModelError

    if args.scene is not None:
        return _error("--resume DIR takes no scene (it is stored in DIR)")
    extra = sorted(given - RESUME_OPTIONS)
    if extra:
        return _error(f"--resume continues with the run's own options; it takes only "
                      f"--steps and --quiet, not --{', --'.join(extra).replace('_', '-')}")
    folder = args.resume
    if scratch is not None and Path(folder).is_dir():  # read the run, write the copy
        import shutil

        shutil.copytree(folder, scratch, dirs_exist_ok=True)
        folder = scratch
    try:
        result, scene, config = resume(folder, steps=args.steps,
                                       quiet=args.quiet or scratch is not None,
                                       with_config=True)
    except ModelError as err:
        return _error(str(err))
    except WriteFailed as err:
        return _failed(str(err))
    return _printed(lambda: _report(scene, config.backend, result, args.resume))


def _run_main(args, given: set[str], scratch: str | None) -> int:
    """A new run of ``args.scene`` with the options given and the recipe's for the others
    (``--dry-run``: only checked), and its report; returns the exit code."""
    from fem_ade.engine.execute import WriteFailed
    from fem_ade.engine.runs import default_out, plan, simulate
    from fem_ade.model.params import ModelError

    try:
        scene = _chosen_scene(args, given)
        _apply_recipe(args, given, scene)
        if args.volume is not None:
            scene = scene.with_(volume_functional=args.volume)
        options = backend_options(args)
        _check_backend_options(args, options)
        out = args.out or default_out(scene.name, args.backend)
        if scratch is not None:  # an MPI rank > 0: the same run, written to its own folder
            out, args.out, args.force, args.quiet, args.no_render = scratch, scratch, True, \
                True, True
        run = dict(config=_run_config(args, scene, options), phi0=args.phi0, out=out,
                   force=args.force, allow_underresolved=args.allow_underresolved)
        if args.dry_run:
            line = plan(scene, **run)
            return _printed(lambda: print(f"fem_ade.run: would run {line}"), 0)
        result = simulate(scene, **run, fresh=not args.out, quiet=args.quiet)
    except ModelError as err:
        return _error(str(err))
    except WriteFailed as err:
        return _failed(str(err))
    return _printed(lambda: _report(scene, args.backend, result, out))


def _chosen_scene(args, given: set[str]):
    """The scene named on the command line (``vesicle``: made from its options, which no
    other scene takes); ModelError for an option the scene does not take."""
    from fem_ade.model.params import ModelError
    from fem_ade.scenes.catalogue import resolve_scene

    chosen = {k: getattr(args, k) for k in vesicle_options() if k in given}
    if args.scene == "vesicle":
        from fem_ade.scenes.catalogue import vesicle_scene

        if "ic" in given:
            raise ModelError("--ic picks a reading of the paper's initial ellipsoid; a "
                             "vesicle starts from the sharp shape of its --branch")
        return vesicle_scene(**chosen)
    if chosen:
        raise ModelError(f"--{', --'.join(chosen)} describe the vesicle scene; "
                         f"{args.scene} is another")
    return resolve_scene(args.scene)


def _apply_recipe(args, given: set[str], scene) -> None:
    """Set on ``args`` the recipe's numerics for the options not given (``--steps N``: N
    steps, without the recipe's stopping rule); ModelError for a --max-steps left without
    --until-steady."""
    from fem_ade.engine.runs import recipe
    from fem_ade.model.params import ModelError

    if args.recipe is None:  # the paper's numerics for its scenes; a vesicle: its shape
        args.recipe = "steady" if args.scene == "vesicle" else "paper"
    for key, value in recipe(args.recipe, scene).items():
        if key in ("until_steady", "max_steps") and "steps" in given:
            continue  # --steps N: N steps (with the recipe's numerics)
        if key not in given:
            setattr(args, key, value)
    if args.max_steps is not None and args.until_steady is None:
        raise ModelError("--max-steps caps --until-steady; with --steps it would be "
                         "ignored")


def _check_backend_options(args, options: dict) -> None:
    """ModelError for backend options that do not go together: --n with a mesh file, or
    several MPI ranks without the PETSc linear algebra."""
    from fem_ade.model.params import ModelError

    if options.get("mesh"):
        from fem_ade.backends.fem.mesh import parse_option as parse_mesh_option
    if args.n is not None and options.get("mesh") and \
            parse_mesh_option(options["mesh"])[0] == "file":
        raise ModelError("--n does not apply to --mesh FILE: the file sets the resolution")
    if SIZE > 1 and options.get("linalg") != "petsc":
        raise ModelError(f"{SIZE} MPI ranks would each run the whole job: under mpirun "
                         "use --backend fem --linalg petsc")


def _run_config(args, scene, options: dict):
    """The run's :class:`fem_ade.engine.config.RunConfig` from the command line's options."""
    from fem_ade.engine.config import RunConfig

    return RunConfig.build(
        scene, backend=args.backend, n=args.n, dt=args.dt, steps=args.steps,
        until_steady=args.until_steady,
        max_steps=100_000 if args.max_steps is None else args.max_steps,
        every=args.every, ic=args.ic, perturb=args.perturb, seed=args.seed,
        backend_options=options, scheme=args.scheme, constraints=args.constraints,
        adaptive=args.adaptive, accelerate=args.accelerate,
        checkpoint_every=args.checkpoint_every, save_every=args.save_every,
        shape_every=args.shape_every, render=not args.no_render, sharp=not args.no_sharp)


def _printed(report, code: int | None = None) -> int:
    """Run ``report`` (which prints and returns the exit code); a stdout that is a full
    device or a closed pipe costs the report, not a traceback (the run folder is written
    already): exit 3 with one line on stderr, or quietly for a closed pipe."""
    try:
        result = report()
        sys.stdout.flush()
    except BrokenPipeError:
        try:
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 (no more writes to the pipe)
            print("fem_ade.run: error: the report's reader went away (a closed pipe); the "
                  "run folder is written", file=sys.stderr)
        except OSError:
            pass
        return EXIT_FAILED
    except OSError as err:
        try:
            print(f"fem_ade.run: error: cannot write the report: {err.strerror or err}",
                  file=sys.stderr)
        except OSError:
            pass
        return EXIT_FAILED
    return result if code is None else code


def backend_options(args) -> dict:
    """The chosen backend's options that were given; an option of another backend is an
    error (it would be ignored)."""
    from fem_ade.model.params import ModelError

    options = {}
    for spec in BACKENDS.values():
        for o in spec.options:
            value = getattr(args, o.name)
            if value is None:
                continue
            if spec.name != args.backend:
                raise ModelError(f"--{o.name} applies to --backend {spec.name} only")
            options[o.name] = value
    return options


def _report(scene, backend: str, result, out) -> int:
    from fem_ade.analysis.shape import symmetry_group
    from fem_ade.engine.execute import verdict

    f, p = result.final, scene.params
    line = f"{scene.name} [{backend}]: {result.message}"
    if result.status == Status.INTERRUPTED:
        line += f"; continue with: python -m fem_ade.run --resume {out} [--steps N]"
    if result.exit_code:  # one line on stderr: what happened; the details on stdout
        print(f"fem_ade.run: {line}", file=sys.stderr)
    else:
        print(line)
    print(f"  t = {result.t:.4g}  E = {f['E']:.6g}  W = {f['W']:.6g}  G = {f['G']:.4g}  "
          f"V/alpha = {f['V'] / p.alpha:.4f}  A/beta = {f['A'] / p.beta:.4f}  "
          f"dA = {f['dA']:.4g}  ({result.wall_s:.1f} s)")
    if result.shape is not None:
        d = result.shape
        genus = ", ".join(map(str, d["genus"])) or "-"
        group = symmetry_group(d)
        print(f"  shape: {d['label']}: {d['components']} component(s), genus {genus}"
              f"{', nested' if d['nested'] else ''}, arms {d['arms']}"
              f"{f', symmetry {group}' if group else ''}, reduced volume "
              f"{d['reduced_volume']:.3f}, reduced area difference "
              f"{d['reduced_area_difference']:.3f} (sharp surface)")
        v = verdict(scene, d)
        if v is not None:
            print(f"  {v['line']}")
        if d.get("sharp_reference"):
            print(f"  {d['sharp_reference']['line']}")
    print(f"  results in {out}/ ({', '.join(_listing(Path(out)))})")
    return result.exit_code


def _listing(out: Path) -> list[str]:
    """A run folder's files for the last line: the series' step files counted, not named,
    the lock and owner files left out."""
    import re

    from fem_ade.store.lock import HIDDEN

    if not out.is_dir():
        return []
    names = sorted(p.name for p in out.iterdir() if p.name not in HIDDEN)
    steps = [n for n in names if re.fullmatch(r"phi-\d{8}\.h5", n)]
    shown = [n for n in names if n not in steps]
    if steps:
        shown.append(f"{len(steps)} step file{'s' if len(steps) != 1 else ''} phi-K.h5")
    return shown


if __name__ == "__main__":
    sys.exit(main())
