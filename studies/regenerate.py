"""Regenerate the committed results in ``studies/results`` — the one command that writes there.

Every study writes under ``runs/`` (ignored by git) unless told otherwise; this script runs
each of them with the committed folder as ``--out``, in an order where each finds what it
reads (cost.py reads convergence.json and axisymmetric.md). The whole set takes hours on 2
cores (the gallery most of them); ``--only`` picks studies, ``--dry-run`` prints the
commands, each with the sweeps it runs (:data:`SWEEPS`) or why it is a measurement
(:data:`MEASUREMENTS`). The sweeps' points are run folders made through
:func:`fem_ade.engine.jobs.ensure`, so a killed regeneration goes on where it stopped; ten rebuild
their committed report from their committed rows with ``--report-only``
(``tests/test_studies.py`` checks it byte for byte).

    python studies/regenerate.py --dry-run
    python studies/regenerate.py --only convergence cost bench
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = "studies/results"
#: (name, the script and its arguments), in the order they run
STEPS = (
    ("convergence", ["studies/convergence.py", "--out", RESULTS]),
    ("axisymmetric", ["studies/axisymmetric.py", "--out", RESULTS]),
    ("cost", ["studies/cost.py", "--out", RESULTS]),
    ("bench", ["studies/bench.py", "--out", RESULTS]),
    ("scaling", ["studies/scaling.py", "--out", RESULTS]),
    ("hard_cases", ["studies/hard_cases.py", "--out", RESULTS]),
    ("constraints_study", ["studies/constraints_study.py", "--out", RESULTS]),
    ("gallery", ["studies/gallery.py", "--out", f"{RESULTS}/gallery", "--max-steps", "5000"]),
    ("readme_figure", ["studies/readme_figure.py", "--out", f"{RESULTS}/readme"]),
    ("sharp_limit", ["studies/sharp_limit.py", "--out", RESULTS]),
    ("eps_ladder", ["studies/eps_ladder.py", "--out", RESULTS]),
    ("ade_plane", ["studies/ade_plane.py", "--out", RESULTS]),
    ("branches", ["studies/branches.py", "--out", RESULTS]),
    ("ade_branches", ["studies/ade_branches.py", "--out", RESULTS]),
    ("ade_limit", ["studies/ade_limit.py", "--out", RESULTS]),
    ("ade_bifurcations", ["studies/ade_bifurcations.py", "--out", RESULTS]),
    ("azimuthal", ["studies/azimuthal.py", "--out", RESULTS]),
    ("ade_azimuthal", ["studies/ade_azimuthal.py", "--out", RESULTS]),
    ("solver_bench", ["studies/solver_bench.py", "--out", RESULTS]),
    ("switch", ["studies/switch.py", "--out", RESULTS]),
    ("branch3d", ["studies/branch3d.py", "--out", RESULTS]),
    ("branch3d_octant", ["studies/branch3d_octant.py", "--out", RESULTS]),
    ("starfish", ["studies/starfish.py", "--out", RESULTS]),
    ("starfish_octant", ["studies/starfish_octant.py", "--out", RESULTS]),
    ("ade_octant", ["studies/ade_octant.py", "--out", RESULTS]),
    ("triaxial", ["studies/triaxial.py", "--out", RESULTS]),
    ("newton3d_bench", ["studies/newton3d_bench.py", "--out", RESULTS]),
    ("fourier_bench", ["studies/fourier_bench.py", "--out", RESULTS]),
    ("nonaxisymmetric", ["studies/nonaxisymmetric.py", "--out", RESULTS, "--eps", "0.02"]),
    ("sweep_scaling", ["studies/sweep_scaling.py", "--out", RESULTS]),
    ("phase_diagram", ["studies/phase_diagram.py", "--out", RESULTS]),
)


#: the sweeps a study runs through fem_ade.campaigns.sweep: its sweep files, or the sweep it builds
#: from its plan (the gallery: a listed point per case, a kick after each; the
#: non-axisymmetric check: a point per 3D run, its revolved scene as its base; the sharp
#: limit and the ADE plane: a point per seeded run, its scene as its base; the ADE lines: a
#: branch per line of fixed v, the pear's seed as its base; the constraints study: a
#: point per case once its Δt trial has run, one after another). The others are
#: :data:`MEASUREMENTS`
SWEEPS = {"gallery": ("built from its plan: studies/gallery.py point_spec, kick_spec",),
          "sharp_limit": ("built per stage: studies/sharp_limit.py make_runs",),
          "eps_ladder": ("studies/sweeps/eps_ladder.toml",),
          "ade_plane": ("built from its planes: studies/sharp_limit.py make_runs",),
          "nonaxisymmetric": ("built from its cases: studies/nonaxisymmetric.py point_spec",),
          "phase_diagram": ("studies/sweeps/minimal.toml", "studies/sweeps/ade.toml"),
          "branches": ("studies/sweeps/branches.toml",),
          "ade_branches": ("built from its lines: studies/_lib/lines.py line_point",),
          "ade_limit": ("built from its spans: studies/ade_limit.py region_keys and cell_keys, "
                        "studies/_lib/lines.py line_point",),
          "ade_bifurcations": ("built from its lines and their ends' windows: "
                               "studies/ade_bifurcations.py coarse_keys and fine_keys, "
                               "studies/_lib/lines.py line_point",),
          "azimuthal": ("built from its branches: studies/azimuthal.py plan",),
          "constraints_study": ("built from its Δt trials: studies/constraints_study.py "
                                "case_point",)}

#: the studies that measure — timings (CPU seconds one beside another, in one process:
#: workers on a shared machine would measure each other) or the errors of runs made at once
#: to compare them — and so run their runs themselves, not as a sweep
MEASUREMENTS = {"convergence": "errors and times of each resolution, in one process",
                "axisymmetric": "CPU seconds at equal accuracy, in one process",
                "cost": "CPU seconds at equal accuracy, in one process",
                "bench": "step costs side by side, in one process",
                "scaling": "MPI ranks' timings under mpirun",
                "hard_cases": "each case's outcome and wall time, in memory in one process",
                "readme_figure": "one run and its picture",
                "sweep_scaling": "a sweep's wall time on 1 and 2 workers",
                "solver_bench": "one point's Newton and stability by each solver, in one "
                                "process",
                "switch": "3D runs from switched starts and their stability, timed, in "
                          "one process",
                "branch3d": "a 3D branch's points, each its Newton and stability seconds, "
                            "one after another in one process",
                "branch3d_octant": "a 3D branch's points on the octant, each its Newton and "
                                   "stability seconds, one after another in one process",
                "starfish": "a 3D run's CPU seconds, after its branches, one after another "
                            "in one process",
                "starfish_octant": "3D runs' CPU seconds and their stability, one after "
                                   "another in one process",
                "newton3d_bench": "one 3D steady state by Newton with and without its pins, "
                                  "CPU seconds in one process",
                "fourier_bench": "one Fourier-(r, z) solve and Newton with and without the "
                                 "coarse step, CPU seconds in one process",
                "ade_octant": "each state's (r, z) point, then its two 3D octant runs in a "
                              "process pool (runs from switched starts, with their CPU "
                              "seconds)",
                "triaxial": "a Fourier-(r, z) branch's points, each its seconds, one after "
                            "another in one process",
                "ade_azimuthal": "one point per cell of the ADE plane and its modes, in a "
                                 "process pool (a one-point branch: a sweep's [branch] has "
                                 "no max_points)"}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="*", choices=[name for name, _ in STEPS], default=None)
    ap.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    ap.add_argument("--quick", action="store_true", help="the same as --dry-run (the tests)")
    args = ap.parse_args(argv)
    chosen = [(name, cmd) for name, cmd in STEPS if args.only is None or name in args.only]
    done = {}
    for name, cmd in chosen:
        sweeps = SWEEPS.get(name)
        line = " ".join(["python", *cmd]) + (f"    # sweeps: {', '.join(sweeps)}" if sweeps
                                             else f"    # a measurement: {MEASUREMENTS[name]}")
        print(line, flush=True)
        if args.dry_run or args.quick:
            done[name] = line
            continue
        code = subprocess.call([sys.executable, *cmd], cwd=ROOT)
        if code != 0:
            raise SystemExit(f"regenerate: {name} failed with exit code {code}")
        done[name] = line
    return done


if __name__ == "__main__":
    main()
