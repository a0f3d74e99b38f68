"""``hrlsac mission run FLEET.yaml --pilot NAME | --policy P.pt --connect URL --connect URL ...``: fly a fleet mission
in real time, one connection per drone in the fleet's order (PX4 SITL instance N on ``udpin:0.0.0.0:14540+N``,
``hrlsac sitl --count N`` alike), or one ``udpin`` ground-station port carrying every drone, told apart by the fleet
section's system ids (``autonomy.shared_port``); every drone on one wall clock (``autonomy.fleet_runner``), the
decision rounds in their own thread. Writes ``report.json`` (rewritten while flying, ``"complete": false`` until
the end) and one folder per drone with its ``flight.tlog``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from autonomy.fleet_runner import build_fleet, fleet_summary
from autonomy.recorder import REPORT, TLOG, PartialReport, TlogRecorder
from autonomy.runner import WallClock
from autonomy.search_pilot import FlownPolicy
from autonomy.shared_port import open_shared_port
from autonomy.vehicle_link import COMPANION_COMPONENT, LinkError, VehicleLink, open_connection
from mavlink_signing import wall_timestamp
from missions.mission import Mission


def run_fleet(mission: Mission, policy: FlownPolicy, args: argparse.Namespace, out: Path, prog: str) -> int:
    clock = WallClock()
    tlogs: list[TlogRecorder] = []
    links: list[VehicleLink] = []
    shared = len(args.connect) == 1 and len(mission.fleet.vehicles) > 1
    try:
        port = open_shared_port(args.connect[0]) if shared else None
        for vehicle, url in zip(mission.fleet.vehicles, args.connect * len(mission.fleet.vehicles)):
            connection = (port.channel(vehicle.system_id, COMPANION_COMPONENT) if port is not None
                          else open_connection(url, vehicle.system_id))
            folder = out / vehicle.name
            folder.mkdir(parents=True, exist_ok=True)
            tlogs.append(TlogRecorder(folder / TLOG, clock.started_unix_us))
            links.append(VehicleLink(connection, clock.now, tlogs[-1], signing_key=args.key,
                                     signing_timestamp=wall_timestamp, warn=print))
    except (LinkError, OverflowError) as exc:
        for link in links:
            link.close()
        print(f"{prog}: error: --connect: {exc}", file=sys.stderr)
        return 2
    say = (lambda text: None) if args.quiet else print
    facts = dict(**policy.describe(), seed=args.seed, clock="wall", connect=list(args.connect))
    partial = PartialReport(out / REPORT, lambda: {**fleet.report(), **facts})
    fleet = build_fleet(mission, policy, args.seed, links, clock, say=partial.after(say), threaded=True)
    partial.start()
    try:
        report = fleet.run()
    finally:
        for tlog in tlogs:
            tlog.close()
        for link in links:
            link.close()
    report.update(facts)
    partial.finish(report)
    print(f"{fleet_summary(report)}; report: {out / REPORT}")
    aborts = [f"{d['name']}: {e['reason']}" for d in report["vehicles"] for e in d["events"] if e["event"] == "abort"]
    for reason in aborts:
        print(f"{prog}: error: {reason}", file=sys.stderr)
    return 1 if aborts else 0
