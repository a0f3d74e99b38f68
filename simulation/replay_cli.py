"""``hrlsac mission replay MISSION.yaml --policy P.pt``: fly a search mission with an exported policy against the
in-process simulated vehicle in lockstep, as fast as the machine allows, deterministic for a seed; writes
flight.tlog, report.json, trajectory.png and replay.mp4 per episode. Its arguments and checks beyond the replay's
own are those of ``hrlsac mission run`` (``autonomy.mission_cli``).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from autonomy.mission_cli import mission_parser, prepare_mission
from hrlsac_cli import GROUPS

# mission_replay at the top, though only the workers use it: on an on-board install (no OpenCV for the replay's
# pictures) the command then says at once which extra it needs, before it reads any file.
from simulation import mission_replay  # noqa: F401
from simulation.parallel_replay import ReplayEpisode, replay_episodes
from simulation.worker_pool import WorkerPoolError, add_pool_arguments, pool_from_arguments

REPLAY_SUMMARY = GROUPS["mission"]["replay"][1]  # written once, in the dispatcher's table


def main(argv: list[str], prog: str = "hrlsac mission replay") -> int:
    parser = mission_parser(prog, REPLAY_SUMMARY, simulated=True)
    parser.add_argument("--episodes", type=int, default=1, help="fly seeds SEED .. SEED+EPISODES-1")
    parser.add_argument("--no-video", action="store_true", help="skip replay.mp4 (faster)")
    add_pool_arguments(parser)
    parser.add_argument("--link-faults", metavar="SPEC", default=None,
                        help="inject link faults on the simulated clock, seeded by each episode's seed unless "
                             "seed=N is given, e.g. 'loss=0.1,latency_ms=50,jitter_ms=20,outage=30:2' (all keys: "
                             "docs/runner.md, Link faults)")
    args = parser.parse_args(argv)
    prepared = prepare_mission(args, prog, _check_replay_arguments)
    if isinstance(prepared, int):
        return prepared
    mission, policy, out = prepared
    return _replay(mission, policy, args, out, prog)


def _check_replay_arguments(args: argparse.Namespace) -> None:
    if not 1 <= args.episodes <= 100_000:
        raise ValueError(f"--episodes must be in [1, 100000], got {args.episodes}")
    args.faults = None
    if args.link_faults:
        from sitl_bridge.faults import parse_link_faults  # a real flight has the real link's faults

        args.faults = parse_link_faults(args.link_faults)
    try:
        args.pool = pool_from_arguments(args)
    except WorkerPoolError as exc:
        raise ValueError(str(exc)) from None


def _replay(mission, policy, args, out: Path, prog: str) -> int:
    # Each seed is one task (the same replay whether it runs here, in a worker process or on a Ray node).
    options = dict(signing_key=args.key, link_faults=args.faults)
    episodes = [ReplayEpisode(mission, args.policy, args.seed + episode,
                              out if args.episodes == 1 else out / f"seed-{args.seed + episode:05d}",
                              video=not args.no_video, narrate=args.episodes == 1 and not args.quiet, options=options)
                for episode in range(args.episodes)]
    finished = []
    started = time.perf_counter()

    def show_progress(index: int, report: dict) -> None:
        finished.append(report)
        if args.episodes > 1 and not args.quiet:
            done = len(finished)
            rate = sum(r["success"] for r in finished) / done
            print(f"\r[{'#' * (30 * done // args.episodes):<30}] {done}/{args.episodes} episodes  "
                  f"success {rate:.0%}  ({time.perf_counter() - started:.0f} s)", end="", file=sys.stderr)

    try:
        reports = replay_episodes(episodes, args.pool, show_progress)
    except WorkerPoolError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    if args.episodes > 1 and not args.quiet:
        print(file=sys.stderr)
    wall = time.perf_counter() - started
    simulated = sum(r["flight_time_s"] for r in reports)
    successes = sum(r["success"] for r in reports)
    print(f"{mission.name}: {successes}/{len(reports)} searches found the victim "
          f"({simulated:.0f} s simulated in {wall:.1f} s, {simulated / wall:.0f}x real time)")
    if len(reports) == 1:
        r = reports[0]
        detection = f"{r['time_to_detection_s']:.0f} s" if r["time_to_detection_s"] is not None else "never"
        print(f"  search ended: {r['search_end']} after {r['steps']} decisions; victim detected: {detection}; "
              f"coverage {r['coverage_ratio']:.0%}; path {r['path_length_m']:.0f} m; "
              f"{r['setpoints_sent']} setpoints")
        print(f"  outcome: {r['outcome']['outcome']} ({r['outcome']['reason']}); vehicle {r['outcome']['vehicle_end']}")
    print(f"  report: {out / 'report.json' if len(reports) == 1 else out}")
    return 0


