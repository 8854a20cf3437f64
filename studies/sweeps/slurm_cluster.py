"""Start Dask workers as Slurm jobs (dask-jobqueue) for ``python -m fem_ade.sweep``.

    pip install dask-jobqueue
    python studies/sweeps/slurm_cluster.py --jobs 8 &          # on the login node
    python -m fem_ade.sweep studies/sweeps/ade.toml --scheduler runs/scheduler.json

Reads ``studies/sweeps/slurm.yaml`` (``--config``), starts a scheduler here, asks Slurm for
``--jobs`` jobs of workers, writes the scheduler's address to ``--scheduler-file`` and keeps
the cluster alive until interrupted (Ctrl-C cancels the jobs). ``--print-script`` prints the
job script it would submit and exits (nothing submitted: how the tests check the config).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def make_cluster(config: Path):
    import dask.config
    import yaml
    from dask_jobqueue import SLURMCluster

    dask.config.update(dask.config.config, yaml.safe_load(config.read_text()), priority="new")
    return SLURMCluster()


def main(argv=None) -> str | None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=HERE / "slurm.yaml")
    ap.add_argument("--jobs", type=int, default=4)
    ap.add_argument("--scheduler-file", type=Path, default=Path("runs/scheduler.json"))
    ap.add_argument("--print-script", action="store_true")
    args = ap.parse_args(argv)
    cluster = make_cluster(args.config)
    try:
        if args.print_script:
            script = cluster.job_script()
            print(script)
            return script
        args.scheduler_file.parent.mkdir(parents=True, exist_ok=True)
        args.scheduler_file.write_text(json.dumps({"address": cluster.scheduler_address}))
        cluster.scale(jobs=args.jobs)
        print(f"scheduler {cluster.scheduler_address} (in {args.scheduler_file}); "
              f"{args.jobs} Slurm jobs asked for; Ctrl-C to stop", flush=True)
        while True:
            time.sleep(60)
    except KeyboardInterrupt:
        return None
    finally:
        cluster.close()


if __name__ == "__main__":
    main()
