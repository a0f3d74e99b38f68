"""``hrlsac evaluate``: the paper's metrics of a trained run on a scenario split, written as JSON."""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from autonomy.worker_pool import WorkerPoolError, add_pool_arguments, pool_from_arguments


def main(argv: list[str], prog: str = "hrlsac evaluate") -> int:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split(":", 1)[1].strip(),
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("run", help="run folder (or checkpoint file) written by hrlsac train")
    parser.add_argument("--split", choices=["train", "val", "test"], default="test")
    parser.add_argument("--episodes", type=int, default=100, help="one episode on each of the first N scenarios")
    parser.add_argument("--out", default=None, help="metrics file (default: RUN/eval_SPLIT.json)")
    add_pool_arguments(parser)
    args = parser.parse_args(argv)
    if args.episodes < 1:
        print(f"{prog}: error: --episodes must be >= 1, got {args.episodes}", file=sys.stderr)
        return 2
    from policies.evaluation import evaluate_checkpoint

    try:
        pool = pool_from_arguments(args)
        if pool.workers > 1 or pool.uses_ray:
            print(f"evaluating {args.episodes} episodes on {pool.describe()}", file=sys.stderr, flush=True)
        metrics = evaluate_checkpoint(args.run, args.split, args.episodes, pool, _chunk_done)
    except (FileNotFoundError, ValueError, KeyError, WorkerPoolError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    run = Path(args.run)
    out = Path(args.out) if args.out else (run if run.is_dir() else run.parent) / f"eval_{args.split}.json"
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(json.dumps(metrics, indent=2))
    os.replace(tmp, out)
    low, high = metrics["success_ci95"]
    print(f"{metrics['algo']} seed {metrics['seed']} on {args.split} ({args.episodes} episodes): success "
          f"{metrics['success_rate']:.1%} [{low:.1%}, {high:.1%}], reward {metrics['reward_mean']:.1f}, coverage "
          f"{metrics['coverage_mean']:.1%}, length {metrics['length_mean']:.0f}"
          + (f", sub-goal reachability {metrics['subgoal_reachability']:.1%}"
             if metrics["subgoal_reachability"] is not None else ""))
    print(f"written {out}")
    return 0


def _chunk_done(done: int, chunks: int) -> None:
    if chunks > 1:
        print(f"  {done}/{chunks} chunks of episodes done", file=sys.stderr, flush=True)
