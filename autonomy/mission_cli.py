"""``hrlsac mission``: fly a search mission with an exported policy.

* ``hrlsac mission replay MISSION.yaml --policy P.pt``: against the in-process simulated vehicle in lockstep,
  as fast as the machine allows, deterministic for a seed; writes flight.tlog, report.json, trajectory.png and
  replay.mp4 per episode.
* ``hrlsac mission run MISSION.yaml --policy P.pt --connect URL``: against any MAVLink vehicle (PX4 SITL, a
  real autopilot, ``hrlsac sitl``) in real time, the policy in its own thread.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from autonomy.worker_pool import WorkerPoolError, add_pool_arguments, pool_from_arguments

DEFAULT_OUT = Path("mission-output")


def build_parser(prog: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[0].split(": ", 1)[1])
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, summary in (("replay", "fly the mission in the simulated vehicle, in lockstep (deterministic)"),
                          ("run", "fly the mission on a MAVLink vehicle in real time")):
        sub = commands.add_parser(name, help=summary, description=summary,
                                  formatter_class=argparse.ArgumentDefaultsHelpFormatter)
        sub.add_argument("mission", help="mission file (YAML), e.g. missions/library/demo.yaml")
        sub.add_argument("--policy", required=True, help="policy artifact written by 'hrlsac export'")
        sub.add_argument("--out", type=Path, default=None,
                         help=f"output folder (default: {DEFAULT_OUT}/MISSION-NAME)")
        sub.add_argument("--seed", type=int, default=0,
                         help="seed of the simulated camera's detections (and of the vehicle's sensor noise)")
        sub.add_argument("--quiet", action="store_true", help="print only the summary")
        sub.add_argument("--accept-flight-mismatch", action="store_true",
                         help="fly a mission whose altitude, speed, step period, K or max_steps differ from the "
                              "policy's training settings (warns, naming each difference); refused without it")
        sub.add_argument("--signing-key", metavar="FILE", default=None,
                         help="MAVLink 2 signing key file (from 'hrlsac keygen'): sign everything sent, drop wrongly "
                              "signed or replayed messages" + (" (the simulated vehicle uses it too)"
                                                               if name == "replay" else ""))
        if name == "replay":
            sub.add_argument("--episodes", type=int, default=1, help="fly seeds SEED .. SEED+EPISODES-1")
            sub.add_argument("--no-video", action="store_true", help="skip replay.mp4 (faster)")
            add_pool_arguments(sub)
            sub.add_argument("--link-faults", metavar="SPEC", default=None,
                             help="inject link faults on the simulated clock, seeded by each episode's seed unless "
                                  "seed=N is given, e.g. 'loss=0.1,latency_ms=50,jitter_ms=20,outage=30:2' (all keys: "
                                  "docs/runner.md, Link faults)")
        else:
            sub.add_argument("--connect", required=True,
                             help="udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or serial:DEVICE[:BAUD]")
            sub.add_argument("--backend", choices=("pymavlink", "mavsdk"), default="pymavlink",
                             help="MAVLink client: pymavlink (records a tlog) or MAVSDK (Offboard.set_velocity_ned)")
    return parser


def main(argv: list[str], prog: str = "hrlsac mission") -> int:
    args = build_parser(prog).parse_args(argv)
    name = f"{prog} {args.command}"
    from autonomy.policy import PolicyArtifactError, load_policy
    from missions.mission_file import MissionFileError, load_mission
    from missions.signing import load_key_file

    try:
        mission = load_mission(args.mission)
        policy = load_policy(args.policy)
        if args.command == "replay" and not 1 <= args.episodes <= 100_000:
            raise ValueError(f"--episodes must be in [1, 100000], got {args.episodes}")
        if not 0 <= args.seed <= 2**32 - 1:  # numpy seeds the sensors and the camera with it
            raise ValueError(f"--seed must be in [0, {2**32 - 1}], got {args.seed}")
        if args.command == "run" and args.signing_key and args.backend == "mavsdk":
            raise ValueError("--signing-key needs --backend pymavlink (MAVSDK's Python API cannot sign)")
        args.key = load_key_file(args.signing_key) if args.signing_key else None
        if getattr(args, "link_faults", None):
            from sitl_bridge.faults import parse_link_faults  # replays only: a real flight has the real link's faults

            args.faults = parse_link_faults(args.link_faults)
        if args.command == "replay":
            args.pool = pool_from_arguments(args)
        _check_flight_settings(mission, policy, args.accept_flight_mismatch, args.mission)
    except (MissionFileError, PolicyArtifactError, ValueError, WorkerPoolError) as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    out = args.out or DEFAULT_OUT / (mission.name or Path(args.mission).stem)
    try:
        out.mkdir(parents=True, exist_ok=True)  # now: a bad --out is a usage error, not a failure after the flight
    except OSError as exc:
        print(f"{name}: error: --out {out}: cannot create the folder ({exc.strerror or exc})", file=sys.stderr)
        return 2
    if args.command == "replay":
        return _replay(mission, policy, args, out)
    return _run(mission, policy, args, out, name)


def _check_flight_settings(mission, policy, accept: bool, mission_path: str) -> None:
    """Refuse (ValueError) a mission flown with other flight settings than the policy was trained with, or, with
    ``accept``, warn on stderr naming each difference."""
    from autonomy.preflight import flight_mismatches

    differences = flight_mismatches(mission.flight, policy.manifest.training_config)
    if not differences:
        return
    listed = "; ".join(differences)
    if not accept:
        raise ValueError(f"{mission_path}: flight settings differ from the policy's training ({listed}): change the "
                         "mission's flight block, or pass --accept-flight-mismatch to fly it anyway")
    print(f"warning: {mission_path}: flying with flight settings the policy was not trained with ({listed})",
          file=sys.stderr)


def _replay(mission, policy, args, out: Path) -> int:
    from autonomy.parallel_replay import ReplayEpisode, replay_episodes

    # Each seed is one task (the same replay whether it runs here, in a worker process or on a Ray node).
    options = dict(signing_key=args.key, link_faults=getattr(args, "faults", None))
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
        print(f"hrlsac mission replay: error: {exc}", file=sys.stderr)
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


def _run(mission, policy, args, out: Path, name: str) -> int:
    from autonomy.estimator import PoseEstimator
    from autonomy.recorder import REPORT, TLOG, PartialReport, TlogRecorder
    from autonomy.runner import MissionRunner, WallClock
    from autonomy.search_pilot import SearchPilot
    from autonomy.vehicle_link import LinkError, VehicleLink, open_connection
    from missions.signing import wall_timestamp

    clock = WallClock()
    out.mkdir(parents=True, exist_ok=True)
    tlog = None
    try:
        if args.backend == "mavsdk":
            from autonomy.mavsdk_link import MavsdkLink

            link = MavsdkLink(args.connect, clock.now)
        else:
            connection = open_connection(args.connect)
            tlog = TlogRecorder(out / TLOG)
            # A security warning is printed even with --quiet.
            link = VehicleLink(connection, clock.now, tlog, signing_key=args.key, signing_timestamp=wall_timestamp,
                               warn=print)
    except LinkError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    except OverflowError as exc:  # from the socket module, for a port outside 0-65535 (not wrapped in a LinkError)
        print(f"{name}: error: --connect {args.connect}: {exc}", file=sys.stderr)
        return 2
    say = (lambda text: None) if args.quiet else print
    facts = dict(policy=str(policy.path), policy_sha256=policy.sha256, seed=args.seed, clock="wall",
                 connect=args.connect, backend=args.backend)
    # Rewritten atomically while flying, "complete": false until the end: a killed run leaves its record.
    partial = PartialReport(out / REPORT, lambda: {**runner.report(), **facts})
    runner = MissionRunner(mission, SearchPilot(mission, policy, args.seed), link, clock,
                           PoseEstimator(home=mission.scenario.home), threaded_policy=True, say=partial.after(say),
                           on_decision=partial.after(lambda decision: None))
    partial.start()
    try:
        report = runner.run()
    finally:
        if tlog is not None:
            tlog.close()
            connection.close()
        else:
            link.close()
    report.update(facts, tlog_messages=tlog.messages if tlog else None)
    if getattr(link, "signing", None) is not None:
        report["signing"] = {"runner": link.signing.summary()}
    partial.finish(report)
    print(f"{mission.name}: search ended: {report['search_end']}; success {report['success']}; "
          f"report: {out / REPORT}")
    aborts = [event["reason"] for event in report["events"] if event["event"] == "abort"]
    for reason in aborts:
        print(f"{name}: error: {reason}", file=sys.stderr)
    return 1 if aborts else 0
