"""``hrlsac mission replay MISSION.yaml --policy P.pt``: fly a search mission with an exported policy against the
in-process simulated vehicle in lockstep, as fast as the machine allows, deterministic for a seed; writes
flight.tlog, report.json, trajectory.png and replay.mp4 per episode. Its arguments and checks beyond the replay's
own are those of ``hrlsac mission run`` (``autonomy.mission_cli``).
"""
from __future__ import annotations

import argparse
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

from autonomy.mission_cli import mission_parser, prepare_mission
from hrlsac_cli import GROUPS

# mission_replay at the top, though only the workers fly it: on an on-board install (no OpenCV for the replay's
# pictures) the command then says at once which extra it needs, before it reads any file.
from simulation import mission_replay
from hrlsac_cli.progress import progress_bar  # after mission_replay: see above
from simulation.parallel_replay import ReplayEpisode, replay_episodes
from simulation.worker_pool import WorkerPoolError, add_pool_arguments, pool_from_arguments, run_tasks

REPLAY_SUMMARY = GROUPS["mission"]["replay"][1]  # written once, in the dispatcher's table


def main(argv: list[str], prog: str = "hrlsac mission replay") -> int:
    parser = mission_parser(prog, REPLAY_SUMMARY, simulated=True)
    parser.add_argument("--episodes", type=int, default=1, help="fly seeds SEED .. SEED+EPISODES-1")
    parser.add_argument("--no-video", action="store_true", help="skip replay.mp4 (faster)")
    parser.add_argument("--start-time", metavar="ISO8601", default=None,
                        help="the date and time the tlog's timestamps count from, as YYYY-MM-DDTHH:MM:SSZ (without a "
                             "zone: UTC); default the start of 2025 (UTC), fixed so that a replay's files are the same "
                             "on every run")
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
    if mission.fleet is not None:
        return _replay_fleet(mission, policy, args, out, prog)
    return _replay(mission, policy, args, out, prog)


def _check_replay_arguments(args: argparse.Namespace, mission) -> None:
    if not 1 <= args.episodes <= 100_000:
        raise ValueError(f"--episodes must be in [1, 100000], got {args.episodes}")
    args.start = mission_replay.DEFAULT_START_TIME if args.start_time is None else parse_start_time(args.start_time)
    args.faults = None
    if args.link_faults:
        from sitl_bridge.faults import parse_link_faults  # a real flight has the real link's faults

        args.faults = parse_link_faults(args.link_faults)
    try:
        args.pool = pool_from_arguments(args)
    except WorkerPoolError as exc:
        raise ValueError(str(exc)) from None


def _replay_fleet(mission, policy, args, out: Path, prog: str) -> int:
    """A fleet mission: each seed flown by the whole fleet in lockstep (``simulation.fleet_replay``); several seeds
    are tasks on the worker pool (``--workers``, ``--ray``), one folder each."""
    from autonomy.fleet_runner import fleet_summary
    from simulation.fleet_replay import FleetEpisode, fly_fleet_episode, replay_fleet

    faults = {vehicle.name: args.faults for vehicle in mission.fleet.vehicles} if args.faults else None
    started = time.perf_counter()
    if args.episodes == 1:
        say = (lambda text: None) if args.quiet else print
        report = replay_fleet(mission, policy, args.seed, out, say=say, start_time=args.start, link_faults=faults,
                              signing_key=args.key)
        wall = time.perf_counter() - started
        simulated = max(d["flight_time_s"] for d in report["vehicles"])
        print(fleet_summary(report))
        print(f"  {simulated:.0f} s simulated in {wall:.1f} s, {simulated / wall:.0f}x real time; report: "
              f"{out / 'report.json'}")
        return 0
    episodes = [FleetEpisode(mission, args.choice, args.seed + k, link_faults=faults,
                             out=out / f"seed-{args.seed + k:05d}", start_time=args.start, signing_key=args.key)
                for k in range(args.episodes)]
    reports = _fly_with_progress(lambda on_done: run_tasks(fly_fleet_episode, episodes, args.pool, on_done),
                                 args.episodes, not args.quiet, prog)
    if reports is None:
        return 2
    wall = time.perf_counter() - started
    simulated = sum(max(d["flight_time_s"] for d in report["vehicles"]) for report in reports)
    found = sum(report["success"] for report in reports)
    print(f"{mission.name} ({reports[0]['pilot']}, {reports[0]['drones']} drones): {found}/{args.episodes} searches "
          "found the victim")
    print(f"  {simulated:.0f} s simulated in {wall:.1f} s, {simulated / wall:.0f}x real time; report: {out}")
    return 0


def _fly_with_progress(fly: Callable[[Callable[[int, dict], None]], list[dict]], episodes: int, show: bool,
                       prog: str) -> list[dict] | None:
    """``fly(on_done)``'s reports, with a progress bar of the episodes and their success so far (``show``); None
    after a one-line error when the worker pool cannot be used."""
    progress = progress_bar(episodes, "episode", "episodes", enabled=show)
    successes = 0

    def on_done(index: int, report: dict) -> None:
        nonlocal successes
        successes += bool(report["success"])
        progress.set_postfix_str(f"success {successes / (progress.n + 1):.0%}", refresh=False)
        progress.update(1)

    try:
        reports = fly(on_done)
    except WorkerPoolError as exc:
        progress.close()  # before the error line, which must stand on its own
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return None
    progress.close()
    return reports


def parse_start_time(text: str) -> datetime:
    """``--start-time``: an ISO 8601 date and time (UTC without a zone), not before the Unix epoch."""
    try:
        moment = datetime.fromisoformat(text)
    except ValueError:
        moment = None
    if moment is not None and moment.tzinfo is None:
        moment = moment.replace(tzinfo=timezone.utc)
    if moment is None or moment < mission_replay.UNIX_EPOCH:
        raise ValueError(f"--start-time must be an ISO 8601 date and time from 1970 on, as YYYY-MM-DDTHH:MM:SSZ, "
                         f"got {text!r}")
    return moment


def _replay(mission, policy, args, out: Path, prog: str) -> int:
    # Each seed is one task (the same replay whether it runs here, in a worker process or on a Ray node).
    options = dict(signing_key=args.key, link_faults=args.faults, start_time=args.start)
    episodes = [ReplayEpisode(mission, args.choice, args.seed + episode,
                              out if args.episodes == 1 else out / f"seed-{args.seed + episode:05d}",
                              video=not args.no_video, narrate=args.episodes == 1 and not args.quiet, options=options)
                for episode in range(args.episodes)]
    started = time.perf_counter()
    # a single episode narrates its flight instead
    reports = _fly_with_progress(lambda on_done: replay_episodes(episodes, args.pool, on_done), args.episodes,
                                 not args.quiet and args.episodes > 1, prog)
    if reports is None:
        return 2
    wall = time.perf_counter() - started
    simulated = sum(r["flight_time_s"] for r in reports)
    successes = sum(r["success"] for r in reports)
    print(f"{mission.name} ({policy.describe()['pilot']}): {successes}/{len(reports)} searches found the victim "
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


