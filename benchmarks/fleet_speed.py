"""Fleet speed: how fast a fleet replays in lockstep, and whether every drone's setpoint stream keeps its rate when a
fleet flies in real time over UDP.

1. **Lockstep**: ``missions/library/fleet-demo.yaml`` flown by 4 drones (its launch line extended), in this process
   (one core), simulated seconds per wall second; the reference in the same run is the single-drone replay of
   ``missions/library/demo.yaml`` (``hrlsac mission replay``'s own speed). Medians over ``--repeats`` runs.
2. **Real UDP**: ``hrlsac sitl --count 4`` and ``hrlsac mission run`` with one ``--connect`` per drone, as separate
   processes, a short 4-drone mission; from each drone's tlog (the runner's own send times), the setpoint rate
   while it streamed and the largest gap between two setpoints. The runner streams at 20 Hz (50 ms); the target
   is every gap under 100 ms.

Usage: python benchmarks/fleet_speed.py [--repeats 3] [--skip-udp] [--out benchmarks/results/fleet_speed.json]
"""
from __future__ import annotations

import argparse
import dataclasses
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch
from common import ROOT, results_file, write_report
from pymavlink import mavutil

from autonomy.pilots import ScriptedPilot
from missions.fleet import Fleet, FleetVehicle
from missions.mission_file import load_mission
from missions.mission_writer import save_mission
from simulation.fleet_replay import replay_fleet
from simulation.mission_replay import replay_mission
from simulation.parallel_replay import speak_mavlink2

HRLSAC = [sys.executable, "-m", "hrlsac_cli"]


def four_drones(mission, spacing_m: float = 40.0):
    vehicles = tuple(FleetVehicle(f"drone{k + 1}", k + 1, 0.0, k * spacing_m) for k in range(4))
    return dataclasses.replace(mission, fleet=Fleet(vehicles, mission.fleet.separation_m,
                                                    mission.fleet.altitude_layer_m))


def lockstep(repeats: int) -> dict:
    fleet = four_drones(load_mission(Path(ROOT) / "missions/library/fleet-demo.yaml"))
    single = load_mission(Path(ROOT) / "missions/library/demo.yaml")
    runs: dict[str, list[float]] = {"fleet_4_x_real_time": [], "single_x_real_time": []}
    for _ in range(repeats):
        started = time.perf_counter()
        report = replay_fleet(fleet, ScriptedPilot("greedy_bayes"), seed=0)
        runs["fleet_4_x_real_time"].append(report["vehicles"][0]["flight_time_s"] / (time.perf_counter() - started))
        started = time.perf_counter()
        one = replay_mission(single, ScriptedPilot("greedy_bayes"), seed=0, video=False)
        runs["single_x_real_time"].append(one["flight_time_s"] / (time.perf_counter() - started))
    medians = {name: statistics.median(values) for name, values in runs.items()}
    for name, values in runs.items():
        print(f"  {name:24s} {medians[name]:6.1f}x   (runs {', '.join(f'{v:.1f}' for v in values)})")
    ratio = medians["fleet_4_x_real_time"] / medians["single_x_real_time"]
    print(f"  4 drones against 1: {ratio:.2f} of the single drone's speed (1/4 = 0.25 if a fleet costs its drones)")
    return {"runs": runs, "medians": medians, "fleet_over_single": ratio, "target_x_real_time": 50.0}


def stream_gaps(tlog: Path, system_id: int) -> dict:
    """The runner's setpoints to ``system_id`` in a tlog: how many, over how long, the largest gap (s)."""
    log = mavutil.mavlink_connection(str(tlog), dialect="common")
    times = []
    while (msg := log.recv_match(type="SET_POSITION_TARGET_LOCAL_NED")) is not None:
        if msg.target_system == system_id:
            times.append(msg._timestamp)
    gaps = [b - a for a, b in zip(times, times[1:])]
    span = times[-1] - times[0] if len(times) > 1 else 0.0
    return {"setpoints": len(times), "rate_hz": (len(times) - 1) / span if span else 0.0,
            "largest_gap_ms": 1000.0 * max(gaps) if gaps else None}


def real_udp(folder: Path) -> dict:
    mission = load_mission(Path(ROOT) / "missions/library/fleet-demo.yaml")
    flight = dataclasses.replace(mission.flight, altitude_m=20.0, max_steps=30)
    short = four_drones(dataclasses.replace(mission, flight=flight, name="fleet-speed"))
    path = folder / "fleet-speed.yaml"
    save_mission(short, path)
    sitl = subprocess.Popen([*HRLSAC, "sitl", "--count", "4", "--offset-line", "90,40", "--api-port", "34580",
                             "--api-remote", "34540", "--gcs-remote", "0", "--param", "RTL_RETURN_ALT=25"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(3.0)
        connects = [arg for k in range(4) for arg in ("--connect", f"udpin:127.0.0.1:{34540 + k}")]
        result = subprocess.run([*HRLSAC, "mission", "run", str(path), "--pilot", "greedy_bayes", *connects,
                                 "--out", str(folder / "out"), "--quiet"], capture_output=True, text=True, timeout=900)
    finally:
        sitl.send_signal(signal.SIGINT)
        sitl.communicate(timeout=10)
    print("  " + result.stdout.strip().splitlines()[-1] if result.stdout.strip() else result.stderr)
    drones = {}
    for k in range(4):
        drones[f"drone{k + 1}"] = stream_gaps(folder / "out" / f"drone{k + 1}" / "flight.tlog", k + 1)
        d = drones[f"drone{k + 1}"]
        print(f"  drone{k + 1}: {d['setpoints']} setpoints at {d['rate_hz']:.1f} Hz, largest gap "
              f"{d['largest_gap_ms']:.0f} ms")
    return {"exit_code": result.returncode, "drones": drones,
            "largest_gap_ms": max(d["largest_gap_ms"] for d in drones.values())}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--skip-udp", action="store_true")
    parser.add_argument("--out", default=results_file("fleet_speed.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    speak_mavlink2()
    print("Lockstep replay, this process (one core):")
    report = {"lockstep": lockstep(args.repeats)}
    if not args.skip_udp:
        print("Real UDP, hrlsac sitl --count 4 and mission run, real time:")
        with tempfile.TemporaryDirectory() as folder:
            report["real_udp"] = real_udp(Path(folder))
    write_report(args.out, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
