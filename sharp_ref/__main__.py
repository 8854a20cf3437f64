"""``python -m sharp_ref BRANCH --v V [--da DA0] [--kbar KB] [--C C] [--json]``

The axisymmetric sharp membrane of one branch at reduced volume ``V``: without ``--kbar`` and
``--C`` the minimal model (bending only, fixed area and volume); ``--kbar`` (κ̄/κ) adds the
phase-field model's area-difference elasticity toward the reduced area difference ``--da``,
``--C`` its spontaneous curvature (in units of 1/R₀, R₀ = √(A/4π)). ``torus`` without
``--v`` is Willmore's problem (fixed area only). Prints one line (``--json``: one JSON object
with the meridian); a branch that does not exist at these parameters exits with status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

from .branches import solve
from .membrane import BRANCHES, BranchError

#: the longest a solve may take before the command gives up (``--max-seconds``)
MAX_SECONDS = 120.0


class _Parser(argparse.ArgumentParser):
    """One line and exit 2 on a usage error (argparse prints its usage too)."""

    def error(self, message):
        self.exit(2, f"sharp_ref: error: {message}\n")


class _TimeUp(Exception):
    pass


def main(argv=None) -> int:
    for stream in (sys.stdout, sys.stderr):  # π, R₀ under an ASCII locale: never a traceback
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")
    ap = _Parser(prog="python -m sharp_ref", description=__doc__.split("\n\n")[1],
                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("branch", choices=BRANCHES, metavar="BRANCH",
                    help=f"one of {', '.join(BRANCHES)}")
    ap.add_argument("--v", type=float, default=None, metavar="V",
                    help="reduced volume V / (4πR₀³/3), in (0, 1]")
    ap.add_argument("--da", type=float, default=0.0, metavar="DA0",
                    help="relaxed reduced area difference ΔA₀ / (8πDR₀) (with --kbar)")
    ap.add_argument("--kbar", type=float, default=0.0, metavar="KB",
                    help="area-difference elasticity κ̄/κ (default 0: off)")
    ap.add_argument("--C", type=float, default=0.0, metavar="C",
                    help="the phase-field model's spontaneous curvature C, units of 1/R₀")
    ap.add_argument("--tol", type=float, default=1e-10,
                    help="refine the meridian until e changes by less than this")
    ap.add_argument("--max-seconds", type=float, default=MAX_SECONDS,
                    help=f"give up (exit 2) when the solve takes longer (default "
                         f"{MAX_SECONDS:g})")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--quiet", action="store_true", help="no progress on stderr")
    args = ap.parse_args(argv)
    for name in ("v", "da", "kbar", "C", "tol"):
        value = getattr(args, name)
        if value is not None and not math.isfinite(value):
            ap.error(f"--{name} must be a finite number, got {value}")
    if args.kbar < 0:
        ap.error(f"--kbar must be ≥ 0, got {args.kbar}")
    if args.da != 0.0 and args.kbar == 0.0:
        ap.error("--da sets the relaxed area difference of the ADE term: give --kbar > 0 too")
    if not (math.isfinite(args.max_seconds) and args.max_seconds > 0):
        ap.error(f"--max-seconds must be > 0, got {args.max_seconds}")
    if args.v is None and args.branch != "torus":
        ap.error(f"{args.branch} needs --v (only torus without it: Willmore's problem)")
    if args.v is not None and not 0.0 < args.v <= 1.0:
        ap.error(f"--v must be in (0, 1], got {args.v}")
    if not args.tol > 0:
        ap.error(f"--tol must be > 0, got {args.tol}")

    def progress(text: str) -> None:
        if not args.quiet:
            print(f"  {text}", file=sys.stderr, flush=True)

    import signal

    def time_up(signum, frame):
        raise _TimeUp

    alarm = hasattr(signal, "SIGALRM")
    if alarm:
        signal.signal(signal.SIGALRM, time_up)
        signal.setitimer(signal.ITIMER_REAL, args.max_seconds)
    try:
        result = solve(args.branch, args.v, m0=args.da, kbar=args.kbar,
                       c=math.sqrt(2.0) * args.C, tol=args.tol, progress=progress)
    except BranchError as err:
        print(f"sharp_ref: {err}", file=sys.stderr)
        return 2
    except _TimeUp:
        print(f"sharp_ref: the solve did not converge within {args.max_seconds:g} s (these "
              "parameters may have no such shape; --max-seconds allows longer)",
              file=sys.stderr)
        return 2
    except (ArithmeticError, ValueError, np.linalg.LinAlgError) as err:
        print(f"sharp_ref: the solve failed at these parameters ({type(err).__name__}: "
              f"{err})", file=sys.stderr)
        return 2
    finally:
        if alarm:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
    if args.json:
        text = json.dumps(result.to_json())
    else:
        text = (f"{result.branch} at v = {result.v:.6f}: w = {result.w:.10f}, "
                f"e = {result.e:.10f}, da = {result.da:.6f} "
                f"({'converged' if result.converged else 'NOT converged'}, "
                f"misfit {result.residual:.1e}, {len(result.x)} unknowns)")
    try:
        print(text)
        sys.stdout.flush()
    except BrokenPipeError:  # the reader went away: nothing to tell it
        sys.stdout = None
        return 1
    except OSError as err:
        print(f"sharp_ref: cannot write the result: {err.strerror or err}", file=sys.stderr)
        return 3
    return 0 if result.converged else 1


if __name__ == "__main__":
    sys.exit(main())
