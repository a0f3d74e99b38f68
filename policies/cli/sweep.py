"""``hrlsac sweep``: train a grid of runs (algorithm x preset x seed x hyper-parameters) on Ray, resumably.

Each grid point is one run folder, written exactly as ``hrlsac train --out FOLDER`` would. Running the same
command again skips finished runs and resumes the others from their checkpoints. The sweep file's format is
described in policies/training/sweep_config.py and docs/scaling.md.
"""
from __future__ import annotations

import argparse
import sys

from hrlsac_cli.help_format import HelpFormatter
from simulation.worker_pool import RAY_EXTRA, WorkerPoolError


def build_parser(prog: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split(":", 1)[1].split("\n\n")[0].strip(),
                                     formatter_class=HelpFormatter)
    parser.add_argument("config", help="sweep file (YAML), see docs/scaling.md")
    parser.add_argument("--ray", metavar="ADDRESS", default="local",
                        help="'local' (start Ray on this machine), 'auto' (the cluster this machine joined with "
                             f"'ray start') or 'ray://HOST:PORT'; needs {RAY_EXTRA}")
    parser.add_argument("--max-parallel", type=int, default=None,
                        help="runs trained at once (default: the sweep file's max_parallel, else one per Ray CPU)")
    parser.add_argument("--out", default=None, help="sweep folder (overrides the file's 'out')")
    parser.add_argument("--dry-run", action="store_true", help="list the runs and their folders, train nothing")
    parser.add_argument("--quiet", action="store_true", help="no progress table")
    return parser


def main(argv: list[str], prog: str = "hrlsac sweep") -> int:
    args = build_parser(prog).parse_args(argv)
    from policies.reports.sweep_table import ProgressTable
    from policies.training.sweep import check_run_folders, pending_runs, run_sweep
    from policies.training.sweep_config import load_sweep

    try:
        if args.max_parallel is not None and not 1 <= args.max_parallel <= 4096:
            raise ValueError(f"--max-parallel must be in [1, 4096], got {args.max_parallel}")
        sweep = load_sweep(args.config, out=args.out)
        check_run_folders(sweep)
    except ValueError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    print(f"sweep {sweep.name}: {len(sweep.runs)} runs in {sweep.out}", flush=True)
    if args.dry_run:
        for spec in sweep.runs:
            print(f"  {spec.name}  ({spec.config.total_steps:,} steps)")
        return 0
    try:
        statuses = run_sweep(sweep, args.ray, args.max_parallel, ProgressTable(enabled=not args.quiet))
    except (WorkerPoolError, ValueError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"\n{prog}: interrupted; finished runs are kept and the others keep their last checkpoints: run "
              f"the same command again to resume", file=sys.stderr)
        return 130
    unfinished = pending_runs(statuses)
    if unfinished:
        print(f"{prog}: {len(unfinished)} runs did not finish ({', '.join(unfinished)}); run the same command "
              f"again to resume them from their checkpoints", file=sys.stderr)
        return 1
    print(f"all {len(statuses)} runs finished; summary {sweep.out / 'sweep.json'}")
    return 0
