"""``hrlsac compare``: compare trained runs and the scripted baselines: markdown report and figures."""
from __future__ import annotations

import argparse
import shlex
import sys

from missions.generator import SPLITS


def build_parser(prog: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=prog, description=__doc__.split(":", 1)[1].strip(),
        epilog="Runs are grouped by (algo, preset); the seeds of a group give means, spreads and 95 % intervals. "
               "Writes DIR/report.md, DIR/summary.json, DIR/training_curves.png and DIR/boxplots.png.")
    parser.add_argument("runs", nargs="*", metavar="RUN", help="run folders written by hrlsac train")
    parser.add_argument("--out", metavar="DIR", help="folder for the report and the figures (required)")
    parser.add_argument("--split", choices=SPLITS, default="test",
                        help="scenario split (default: test)")
    parser.add_argument("--episodes", type=int, default=None,
                        help="episodes per run and baseline (default: the runs' eval files' count, else 100)")
    parser.add_argument("--evaluate", action="store_true",
                        help="evaluate runs without an eval_SPLIT.json of that size (saved into the run folder)")
    parser.add_argument("--streams", type=int, default=5,
                        help="SarSearch-v1: detection streams (runs) per scripted searcher (default 5)")
    parser.add_argument("--generator", default=None,
                        help="SarSearch-v1: compare on this generator config file's scenarios (the runs' "
                             "eval_SPLIT_generator-NAME.json of hrlsac evaluate --generator FILE)")
    parser.add_argument("--flight-rules", action="store_true",
                        help="SarSearch-v1: compare the runs' evaluations under the mission runner's rules (hrlsac "
                             "evaluate --flight-rules: eval_SPLIT[_generator-NAME]_flight.json); the scripted "
                             "searchers fly their own rules either way")
    parser.add_argument("--scripted", default=None, metavar="NAMES",
                        help="SarSearch-v1: the scripted searchers to fly, comma-separated (default: all; "
                             "lookahead_bayes, the strongest, takes about five times greedy_bayes' time)")
    parser.add_argument("--quiet", action="store_true", help="no progress output")
    return parser


def main(argv: list[str], prog: str = "hrlsac compare") -> int:
    args = build_parser(prog).parse_args(argv)
    from policies.reports.compare import CompareError, compare

    try:
        if args.runs and not args.out:
            raise CompareError("--out DIR is required (the folder for the report and the figures)")
        if args.streams < 1:
            raise CompareError(f"--streams must be >= 1, got {args.streams}")
        scripted = None
        if args.scripted is not None:
            from missions.searchers import SEARCHERS

            scripted = [name.strip() for name in args.scripted.split(",") if name.strip()]
            unknown = [name for name in scripted if name not in SEARCHERS]
            if unknown or not scripted:
                raise CompareError(f"--scripted: no scripted searcher {unknown[0] if unknown else args.scripted!r}; "
                                   f"choose from {', '.join(SEARCHERS)}")
        generator = scenarios = None
        if args.generator is not None:
            from pathlib import Path

            from policies.cli.evaluate import read_generator_config

            try:
                generator = read_generator_config(args.generator)
            except ValueError as exc:
                raise CompareError(str(exc)) from None
            scenarios = f"generator-{Path(args.generator).stem}"
        if args.flight_rules:  # the runs' evaluations with hrlsac evaluate --flight-rules
            scenarios = f"{scenarios}_flight" if scenarios else "flight"
        summary = compare(args.runs, args.out, split=args.split, episodes=args.episodes, evaluate=args.evaluate,
                          command=shlex.join(["hrlsac", "compare", *argv]),
                          progress=None if args.quiet else sys.stderr, streams=args.streams, generator=generator,
                          scenarios=scenarios, scripted=scripted)
    except CompareError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    for verdict in summary["verdicts"]:
        print(f"{verdict['hrl']} vs {verdict['sac']}: "
              + ("above with non-overlapping intervals across seeds"
                 if verdict["hrl_above_with_non_overlapping_intervals"] else
                 "no across-seed verdict (fewer than 2 seeds)" if verdict["seed_intervals_overlap"] is None else
                 "intervals across seeds overlap" if verdict["seed_intervals_overlap"] else
                 "below with non-overlapping intervals across seeds"))
    print(f"written {summary['files']['report']} (figures {summary['files']['training_curves']}, "
          f"{summary['files']['boxplots']})")
    return 0
