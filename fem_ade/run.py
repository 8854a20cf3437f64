"""The command line: ``python -m fem_ade.run SCENE_OR_TOML [options]``, thin over
:func:`fem_ade.runs.simulate`; its choices come from :mod:`fem_ade.registry`.

Exit codes: 0 finished (completed, steady, or max-steps reached), 2 bad input (one line on
stderr, nothing written), 3 diverged (diagnosis printed, last finite state saved),
130 interrupted.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path

from .initial import IC_VARIANTS
from .loop import EXIT_BAD_INPUT
from .model import ModelError
from .output import read_json
from .registry import BACKENDS, CONSTRAINTS, SCHEMES, VOLUMES
from .runs import resume, simulate, verdict
from .scenes import PAPER_SCENES, SCENES, TEACHING_SCENES, resolve_scene, scene_from_mapping


class _Parser(argparse.ArgumentParser):
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
    p.add_argument("--n", type=int, help="cells (grid points) per direction (default: the scene's)")
    p.add_argument("--dt", type=float, help="time step (default: the paper's, per scene)")
    stop = p.add_mutually_exclusive_group()
    stop.add_argument("--steps", type=int, help="number of steps (default: the scene's, 200)")
    stop.add_argument("--until-steady", type=float, metavar="TOL",
                      help="stop when |dE|/(every*|E|) over a record interval < TOL")
    p.add_argument("--max-steps", type=int, default=100_000,
                   help="cap for --until-steady (default 100000)")
    p.add_argument("--every", type=int, default=10, help="record every K steps (default 10)")
    p.add_argument("--ic", choices=IC_VARIANTS, default="consistent",
                   help="initial condition: the paper's ellipsoid with c read consistently "
                        "(default) or as printed (SPEC §7), or seeded: the shape of the "
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
    p.add_argument("--out", help="output folder (default: runs/SCENE-BACKEND-TIME)")
    p.add_argument("--force", action="store_true", help="write into a non-empty --out folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--allow-underresolved", action="store_true",
                   help="allow h = L/n > eps (the interface is not resolved)")
    for spec in BACKENDS.values():  # each backend's own options, default None = not given
        if not spec.options:
            continue
        group = p.add_argument_group(f"{spec.name} backend (--backend {spec.name})")
        for o in spec.options:
            group.add_argument(f"--{o.name}", type=o.type, choices=o.choices, default=None,
                               help=o.help)
    return p


def list_scenes() -> str:
    lines = ["paper scenes (SPEC §7):"]
    for s in PAPER_SCENES.values():
        lines.append(f"  {s.name:16s} {s.figure:9s} eps={s.params.eps:<5g} dt={s.dt:<6g} "
                     f"n={s.n:<4d} {s.description}")
    lines.append("teaching scenes:")
    for s in TEACHING_SCENES.values():
        lines.append(f"  {s.name:16s} {s.figure:9s} eps={s.params.eps:<5g} dt={s.dt:<6g} "
                     f"n={s.n:<4d} {s.description}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.list:
        print(list_scenes())
        return 0
    signal.signal(signal.SIGTERM, _interrupt)
    if args.resume is not None:
        if args.scene is not None:
            print("fem_ade.run: error: --resume DIR takes no scene (it is stored in DIR)",
                  file=sys.stderr)
            return EXIT_BAD_INPUT
        try:
            result = resume(args.resume, steps=args.steps, quiet=args.quiet)
            summary = read_json(Path(args.resume) / "run.json")
        except (ModelError, FileNotFoundError) as err:
            print(f"fem_ade.run: error: {err}", file=sys.stderr)
            return EXIT_BAD_INPUT
        return _report(scene_from_mapping(summary["scene"]), summary["backend"], result,
                       args.resume)
    if args.scene is None:
        print(f"fem_ade.run: error: give a scene ({', '.join(SCENES)}) or a .toml file",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        scene = resolve_scene(args.scene)
        if args.volume is not None:
            scene = scene.with_(volume_functional=args.volume)
        out = args.out or (Path("runs") / f"{scene.name}-{args.backend}-"
                           f"{time.strftime('%Y%m%d-%H%M%S')}")
        options = backend_options(args)
        result = simulate(
            scene, backend=args.backend, n=args.n, dt=args.dt, steps=args.steps,
            until_steady=args.until_steady, max_steps=args.max_steps, every=args.every,
            ic=args.ic, perturb=args.perturb, seed=args.seed, phi0=args.phi0, out=out,
            force=args.force,
            quiet=args.quiet, allow_underresolved=args.allow_underresolved,
            backend_options=options, scheme=args.scheme, constraints=args.constraints,
            adaptive=args.adaptive, accelerate=args.accelerate,
            checkpoint_every=args.checkpoint_every, save_every=args.save_every,
            shape_every=args.shape_every,
            render=not args.no_render,
        )
    except ModelError as err:
        print(f"fem_ade.run: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return _report(scene, args.backend, result, out)


def backend_options(args) -> dict:
    """The chosen backend's options that were given; an option of another backend is an
    error (it would be ignored)."""
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


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def _report(scene, backend: str, result, out) -> int:
    f, p = result.final, scene.params
    stream = sys.stderr if result.exit_code else sys.stdout
    print(f"{scene.name} [{backend}]: {result.message}", file=stream)
    print(f"  t = {result.t:.4g}  E = {f['E']:.6g}  W = {f['W']:.6g}  G = {f['G']:.4g}  "
          f"V/alpha = {f['V'] / p.alpha:.4f}  A/beta = {f['A'] / p.beta:.4f}  "
          f"dA = {f['dA']:.4g}  ({result.wall_s:.1f} s)")
    if result.shape is not None:
        d = result.shape
        genus = ", ".join(map(str, d["genus"])) or "-"
        print(f"  shape: {d['label']}: {d['components']} component(s), genus {genus}"
              f"{', nested' if d['nested'] else ''}, arms {d['arms']}, reduced volume "
              f"{d['reduced_volume']:.3f}, reduced area difference "
              f"{d['reduced_area_difference']:.3f} (sharp surface)")
        v = verdict(scene, d)
        if v is not None:
            print(f"  {v['line']}")
    written = sorted(p.name for p in Path(out).iterdir()) if Path(out).is_dir() else []
    print(f"  results in {out}/ ({', '.join(written)})")
    if result.status == "interrupted":
        print(f"  to continue: python -m fem_ade.run --resume {out} [--steps N]", file=stream)
    return result.exit_code


if __name__ == "__main__":
    sys.exit(main())
