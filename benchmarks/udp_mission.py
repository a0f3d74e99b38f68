"""A whole mission over real UDP, as a user runs it: ``hrlsac sitl`` first, ``hrlsac mission run`` a while later.

Starts ``hrlsac sitl`` (PX4 or ArduPilot personality) as its own process, waits ``--delay`` seconds (60 by default:
the autopilot has been up for a minute when the companion computer connects, so its time_boot_ms is far ahead of
the runner's clock), then flies ``hrlsac mission run`` with the shipped policy in real time, and checks the end:
landed and disarmed, the victim found. Prints the figures and writes them to a JSON file.

Usage: python benchmarks/udp_mission.py [--autopilot px4|ardupilot|both] [--delay 60] [--mission ...] [--policy ...]
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import results_file, write_report

ROOT = Path(__file__).resolve().parent.parent
HRLSAC = [sys.executable, "-m", "hrlsac_cli"]
# Where each personality sends, and the runner listens (hrlsac sitl prints the same strings at start).
CONNECT = {"px4": ["--api-remote", "{port}"], "ardupilot": ["--api-remote", "{port}"]}


def fly(autopilot: str, delay_s: float, mission: str, policy: str, port: int, out: Path) -> dict:
    sitl_args = [*HRLSAC, "sitl", "--autopilot", autopilot, "--gcs-remote", "0",
                 *[a.format(port=port) for a in CONNECT[autopilot]]]
    sitl = subprocess.Popen(sitl_args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        time.sleep(delay_s)
        if sitl.poll() is not None:
            raise RuntimeError(f"hrlsac sitl --autopilot {autopilot} exited: {sitl.stdout.read()}")
        started = time.monotonic()
        result = subprocess.run([*HRLSAC, "mission", "run", mission, "--policy", policy, "--connect",
                                 f"udpin:127.0.0.1:{port}", "--out", str(out)], cwd=ROOT, capture_output=True,
                                text=True, timeout=1800)
        wall_s = time.monotonic() - started
    finally:
        sitl.send_signal(signal.SIGINT)
        vehicle_log, _ = sitl.communicate(timeout=20)
    report = json.loads((out / "report.json").read_text())
    landed = report["transitions"][-1]["reason"] == "landed and disarmed"
    figures = {"autopilot": autopilot, "delay_s": delay_s, "exit_code": result.returncode,
               "landed_and_disarmed": landed, "victim_found": report["success"], "search_end": report["search_end"],
               "decisions": report["steps"], "wall_s": round(wall_s, 1), "flight_time_s": report["flight_time_s"],
               "vehicle_time_offset_s": report["vehicle_time"]["offset_s"], "flown_as": report["autopilot"],
               "states": [t["to"] for t in report["transitions"]], "events": report["events"],
               "vehicle_log_tail": vehicle_log.strip().splitlines()[-5:]}
    print(f"{autopilot:9s} exit {result.returncode}  flown as {report['autopilot']}  {report['search_end']} after "
          f"{report['steps']} decisions  landed and disarmed: {landed}  victim found: {report['success']}  "
          f"vehicle clock ahead of the runner's by {-report['vehicle_time']['offset_s']:.1f} s  ({wall_s:.0f} s)")
    return figures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--autopilot", choices=("px4", "ardupilot", "both"), default="both")
    parser.add_argument("--delay", type=float, default=60.0, help="seconds between starting the vehicle and the runner")
    parser.add_argument("--mission", default="missions/library/demo.yaml")
    parser.add_argument("--policy", default="policies/pretrained/hrl-sac.pt")
    parser.add_argument("--port", type=int, default=14640, help="UDP port the runner listens on")
    parser.add_argument("--out", default=results_file("udp_mission.json"))
    args = parser.parse_args()
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    flights = []
    with tempfile.TemporaryDirectory() as scratch:
        for autopilot in (("px4", "ardupilot") if args.autopilot == "both" else (args.autopilot,)):
            flights.append(fly(autopilot, args.delay, args.mission, args.policy, args.port,
                               Path(scratch) / autopilot))
    write_report(args.out, {"mission": args.mission, "policy": args.policy, "flights": flights})
    return 0 if all(f["landed_and_disarmed"] and f["victim_found"] and f["exit_code"] == 0 for f in flights) else 1


if __name__ == "__main__":
    sys.exit(main())
