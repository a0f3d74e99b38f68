"""How fast a whole mission replay runs: vehicle, MAVLink both ways, Kalman filter, policy, on one core.

Figures (median of --repeats replays of missions/library/demo.yaml, no video):
  * replay_realtime_factor: simulated seconds per wall second of ``hrlsac mission replay``. Target: >= 100x.
  * vehicle_only_realtime_factor: the simulated vehicle alone over the same simulated time (physics, sensors,
    autopilot, telemetry encoding), measured in the same run as the reference for a noisy machine.

Usage: python benchmarks/replay_speed.py --policy policies/pretrained/hrl-sac.pt [--repeats 3]
"""
from __future__ import annotations

import argparse
import platform
import sys
import time

import torch
from common import results_file, summarise, write_report

from autonomy.policy import load_policy
from missions.mission_file import load_mission
from simulation.mission_replay import airframe_for, replay_mission, start_point
from sitl_bridge.link import memory_link_pair
from sitl_bridge.vehicle import SimulatedVehicle, VehicleConfig


def vehicle_only(mission, seconds: float) -> float:
    """Simulated seconds per wall second of the vehicle alone (telemetry encoded, nobody listening)."""
    vehicle_end, _ = memory_link_pair()
    vehicle = SimulatedVehicle(VehicleConfig(home=start_point(mission), airframe=airframe_for(mission)), [vehicle_end])
    start = time.perf_counter()
    vehicle.run(seconds)
    return seconds / (time.perf_counter() - start)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="policies/pretrained/hrl-sac.pt")
    parser.add_argument("--mission", default="missions/library/demo.yaml")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=results_file("replay_speed.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    mission, policy = load_mission(args.mission), load_policy(args.policy)
    runs: dict[str, list[float]] = {"replay_realtime_factor": [], "vehicle_only_realtime_factor": []}
    for repeat in range(args.repeats):
        start = time.perf_counter()
        report = replay_mission(mission, policy, seed=repeat, video=False)
        wall = time.perf_counter() - start
        runs["replay_realtime_factor"].append(report["flight_time_s"] / wall)
        runs["vehicle_only_realtime_factor"].append(vehicle_only(mission, report["flight_time_s"]))
        print(f"  replay {repeat}: {report['flight_time_s']:.0f} s simulated in {wall:.1f} s "
              f"({report['search_end']})", file=sys.stderr)
    medians = summarise(runs, f"mission replay of {args.mission} with {args.policy} (one thread)")
    target = 100.0
    met = medians["replay_realtime_factor"] >= target
    print(f"  target: replay >= {target:g}x real time: {'met' if met else 'MISSED'}")
    write_report(args.out, {"medians": medians, "runs": runs, "target_realtime_factor": target,
                            "python": platform.python_version(), "torch": torch.__version__})
    return 0


if __name__ == "__main__":
    sys.exit(main())
