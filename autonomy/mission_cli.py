"""``hrlsac mission run MISSION.yaml --policy P.pt | --pilot NAME --connect URL``: fly a search mission with an
exported policy or a scripted searcher against any MAVLink vehicle (PX4 SITL, a real autopilot, ``hrlsac sitl``) in
real time, the pilot's decisions in their own thread. The arguments and checks every ``hrlsac mission`` subcommand
shares are here too; the lockstep replay in the simulated vehicle (``hrlsac mission replay``) is
``simulation.replay_cli``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable

from hrlsac_cli import GROUPS
from missions.mission import Mission
from hrlsac_cli.help_format import HelpFormatter
from missions.searchers import BEST_SEARCHER, SEARCHERS

DEFAULT_OUT = Path("mission-output")
RUN_SUMMARY = GROUPS["mission"]["run"][1]  # written once, in the dispatcher's table (``hrlsac mission --help``)


def mission_parser(prog: str, summary: str, simulated: bool) -> argparse.ArgumentParser:
    """The arguments of every ``hrlsac mission`` subcommand (``simulated``: the vehicle is the simulated one)."""
    parser = argparse.ArgumentParser(prog=prog, description=summary,
                                     formatter_class=HelpFormatter)
    parser.add_argument("mission", help="mission file (YAML), e.g. missions/library/demo.yaml")
    pilot = parser.add_mutually_exclusive_group(required=True)
    pilot.add_argument("--policy", metavar="FILE", help="policy artifact written by 'hrlsac export'")
    pilot.add_argument("--pilot", metavar="NAME",
                       help=f"fly a scripted searcher instead of a policy artifact: {', '.join(SEARCHERS)} "
                            f"({BEST_SEARCHER} measures best: docs/results.md)")
    parser.add_argument("--out", type=Path, default=None, help=f"output folder (default: {DEFAULT_OUT}/MISSION-NAME)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the simulated camera's detections (and of the vehicle's sensor noise)")
    parser.add_argument("--quiet", action="store_true", help="print only the summary")
    parser.add_argument("--accept-flight-mismatch", action="store_true",
                        help="fly a mission whose altitude, speed, step period, K or max_steps differ from the "
                             "policy's training settings (warns, naming each difference); refused without it")
    parser.add_argument("--signing-key", metavar="FILE", default=None,
                        help="MAVLink 2 signing key file (from 'hrlsac keygen'): sign everything sent, drop wrongly "
                             "signed or replayed messages"
                             + (" (the simulated vehicle uses it too)" if simulated else ""))
    return parser


def prepare_mission(args: argparse.Namespace, name: str, check: Callable[[argparse.Namespace, Mission], None]):
    """Load and check what a mission subcommand flies: ``(mission, policy, out)`` (``args.choice``: the
    :class:`autonomy.pilots.PilotChoice`), or an exit code after one error line. ``check`` validates the
    subcommand's own arguments against the mission (raising ValueError)."""
    from autonomy.pilots import PilotChoice
    from autonomy.policy import Policy, PolicyArtifactError
    from missions.mission_file import MissionFileError, load_mission
    from mavlink_signing import load_key_file

    try:
        mission = load_mission(args.mission)
        args.choice = PilotChoice(policy=args.policy, scripted=args.pilot)
        policy = args.choice.load()
        if not 0 <= args.seed <= 2**32 - 1:  # numpy seeds the sensors and the camera with it
            raise ValueError(f"--seed must be in [0, {2**32 - 1}], got {args.seed}")
        check(args, mission)
        args.key = load_key_file(args.signing_key) if args.signing_key else None
        if isinstance(policy, Policy):  # a scripted searcher flies any flight settings
            _check_flight_settings(mission, policy, args.accept_flight_mismatch, args.mission)
    except (MissionFileError, PolicyArtifactError, ValueError) as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    out = args.out or DEFAULT_OUT / (mission.name or Path(args.mission).stem)
    try:
        out.mkdir(parents=True, exist_ok=True)  # now: a bad --out is a usage error, not a failure after the flight
    except OSError as exc:
        print(f"{name}: error: --out {out}: cannot create the folder ({exc.strerror or exc})", file=sys.stderr)
        return 2
    return mission, policy, out


def main(argv: list[str], prog: str = "hrlsac mission run") -> int:
    parser = mission_parser(prog, RUN_SUMMARY, simulated=False)
    parser.add_argument("--connect", required=True, action="append", metavar="URL",
                        help="udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or serial:DEVICE[:BAUD]; a fleet "
                             "mission: once per drone, in the fleet's order (PX4 SITL instance N: udpin:0.0.0.0:"
                             "14540+N), or once with a ground station's udpin port that carries every drone "
                             "(udpin:0.0.0.0:14550), the drones told apart by their system ids")
    parser.add_argument("--backend", choices=("pymavlink", "mavsdk"), default="pymavlink",
                        help="MAVLink client: pymavlink (records a tlog) or MAVSDK (Offboard.set_velocity_ned)")
    args = parser.parse_args(argv)

    def check(args: argparse.Namespace, mission: Mission) -> None:
        if args.signing_key and args.backend == "mavsdk":
            raise ValueError("--signing-key needs --backend pymavlink (MAVSDK's Python API cannot sign)")
        from autonomy.shared_port import is_shared_port

        drones = len(mission.fleet.vehicles) if mission.fleet is not None else 1
        if drones > 1 and len(args.connect) == 1 and not is_shared_port(args.connect[0]):
            raise ValueError(f"--connect {args.connect[0]} for all {drones} drones of {args.mission}: one connection "
                             "carries a fleet only as a ground station's udpin:HOST:PORT; or give one --connect per "
                             "drone")
        if len(args.connect) != drones and not (drones > 1 and len(args.connect) == 1):
            raise ValueError(f"--connect given {len(args.connect)} times: {args.mission} flies {drones} "
                             f"drone{'s' if drones > 1 else ''}, one --connect each" +
                             (" (in the fleet's order), or one udpin port for all" if drones > 1 else ""))
        if drones > 1 and args.backend == "mavsdk":
            raise ValueError("a fleet flies with --backend pymavlink (one tlog per drone)")

    prepared = prepare_mission(args, prog, check)
    if isinstance(prepared, int):
        return prepared
    mission, policy, out = prepared
    if mission.fleet is not None:
        from autonomy.fleet_cli import run_fleet

        return run_fleet(mission, policy, args, out, prog)
    args.connect = args.connect[0]
    return _run(mission, policy, args, out, prog)


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


def _run(mission, policy, args, out: Path, name: str) -> int:
    from autonomy.estimator import PoseEstimator
    from autonomy.recorder import REPORT, TLOG, PartialReport, TlogRecorder
    from autonomy.runner import MissionRunner, WallClock
    from autonomy.search_pilot import SearchPilot
    from autonomy.vehicle_connection import VehicleConnection
    from autonomy.vehicle_link import LinkError, VehicleLink, open_connection
    from mavlink_signing import wall_timestamp

    clock = WallClock()
    out.mkdir(parents=True, exist_ok=True)
    tlog = None
    link: VehicleConnection
    try:
        if args.backend == "mavsdk":
            from autonomy.mavsdk_link import MavsdkLink

            link = MavsdkLink(args.connect, clock.now)
        else:
            connection = open_connection(args.connect)
            tlog = TlogRecorder(out / TLOG, clock.started_unix_us)  # dated: mavtogpx and log viewers need it
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
    facts = dict(**policy.describe(), seed=args.seed, clock="wall",
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
        link.close()
    report.update(facts, tlog_messages=tlog.messages if tlog else None)
    if link.signing is not None:
        report["signing"] = {"runner": link.signing.summary()}
    partial.finish(report)
    print(f"{mission.name} ({report['pilot']}): search ended: {report['search_end']}; success {report['success']}; "
          f"report: {out / REPORT}")
    aborts = [event["reason"] for event in report["events"] if event["event"] == "abort"]
    for reason in aborts:
        print(f"{name}: error: {reason}", file=sys.stderr)
    return 1 if aborts else 0
