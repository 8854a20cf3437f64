"""``python -m fem_ade.switch``: from a bifurcation of an axisymmetric branch to its 3D state
— the flow's run (:func:`fem_ade.campaigns.switch.switch`) or, with ``--follow``, the branch
born there followed in 3D (:func:`fem_ade.campaigns.switch_branch.follow_switched`)."""

from __future__ import annotations

import argparse
import sys

from fem_ade.campaigns.switch import DELTA, NODES_PER_EPS, switch
from fem_ade.model.params import ModelError
from fem_ade.registry import RUN_ORDERS


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m fem_ade.switch",
        description="Switch from a bifurcation of an axisymmetric branch (fem_ade.branch "
                    "--modes) to the 3D state its instability leads to: a 3D run folder.")
    ap.add_argument("branch", help="a branch folder with its points and bifurcations.json")
    ap.add_argument("--bifurcation", type=int, default=None,
                    help="which of bifurcations.json's (default 0, the first)")
    ap.add_argument("--mode", type=int, default=None,
                    help="with --point: switch along this block m >= 1 at that point (no "
                         "bifurcation needed: a branch unstable in m all along)")
    ap.add_argument("--out", required=True, help="the 3D run folder to write")
    ap.add_argument("--point", type=int, default=None,
                    help="switch from this point of the branch (its block m unstable) "
                         "instead of the bifurcation's nearest")
    ap.add_argument("--delta", type=float, default=DELTA,
                    help=f"the start's max |delta psi| (default {DELTA}; 0: the revolved "
                         "state alone, a control)")
    ap.add_argument("--n", type=int, default=None,
                    help=f"nodes per axis (default {NODES_PER_EPS} L/eps, with --follow "
                         "2.56 L/eps, with --geometry octant 1.92 L/eps; up to the order)")
    ap.add_argument("--order", type=int, default=None,
                    help=f"FEM element order (default {RUN_ORDERS['tensor']}, with --follow "
                         "or --geometry octant 8)")
    ap.add_argument("--backend", choices=("fem", "spectral"), default="fem")
    ap.add_argument("--geometry", choices=("cartesian", "octant"), default="cartesian",
                    help="cartesian (default: the periodic box) or octant: the run or "
                         "--follow's branch on one eighth of the box with the mirrors x, y, "
                         "z = L/2 (even m and a state with an equatorial mirror; default "
                         "order 8, 1.92 L/eps nodes)")
    ap.add_argument("--max-steps", type=int, default=None,
                    help="at most this many steps (default: the steady recipe's)")
    ap.add_argument("--checkpoint-every", type=int, default=200,
                    help="a checkpoint every K steps, for --resume (default 200)")
    ap.add_argument("--follow", type=int, default=None, metavar="POINTS",
                    help="follow the branch born there in 3D by continuation for POINTS "
                         "points (--out: a branch folder) instead of the flow's run")
    ap.add_argument("--step", type=float, default=None,
                    help="with --follow: the mode's amplitude per step (default 0.1)")
    ap.add_argument("--stability", action="store_true",
                    help="with --follow: each point's 3D eigenvalues too")
    ap.add_argument("--quiet", action="store_true")
    return ap


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    from fem_ade.store.interrupt import install

    install()  # SIGTERM as SIGINT: the run keeps its checkpoint; --resume goes on
    if args.follow is not None:
        return _follow(args)
    if args.step is not None or args.stability:
        print("fem_ade.switch: error: --step and --stability go with --follow",
              file=sys.stderr)
        return 2
    try:
        result, origin = switch(args.branch, args.bifurcation, args.out, delta=args.delta,
                                n=args.n, order=args.order, backend=args.backend,
                                geometry=args.geometry,
                                max_steps=args.max_steps, point=args.point,
                                checkpoint_every=args.checkpoint_every, mode=args.mode,
                                quiet=args.quiet)
    except ModelError as err:
        print(f"fem_ade.switch: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"fem_ade.switch: interrupted; python -m fem_ade.run --resume {args.out} goes "
              "on", file=sys.stderr)
        return 130
    where = ("" if origin["bifurcation"] is None else
             f" bifurcation {origin['bifurcation']}")
    print(f"switched from {origin['branch']}{where} (m = "
          f"{origin['m']}, point {origin['point']}, eigenvalue {origin['eigenvalue']:.3e}): "
          f"{args.out} ({result.status})")
    return 0


def _follow(args) -> int:
    """``--follow``: :func:`fem_ade.campaigns.switch_branch.follow_switched`."""
    from fem_ade.campaigns.switch_branch import ORDER, STEP, follow_switched

    if args.delta != DELTA or args.backend != "fem" or args.max_steps is not None:
        print("fem_ade.switch: error: --delta, --backend and --max-steps are the flow's; "
              "--follow continues the branch on the FEM", file=sys.stderr)
        return 2
    order = ORDER if args.order is None else args.order
    try:
        rows = follow_switched(args.branch, args.bifurcation, args.out, points=args.follow,
                               step=STEP if args.step is None else args.step, n=args.n,
                               order=order, stability=args.stability, point=args.point,
                               mode=args.mode, quiet=args.quiet, geometry=args.geometry)
    except ModelError as err:
        print(f"fem_ade.switch: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"fem_ade.switch: interrupted; the same command goes on from the last point "
              f"in {args.out}", file=sys.stderr)
        return 130
    print(f"followed {len(rows)} points: {args.out}/branch.csv, branch3d.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
