"""How fast the simulated vehicle runs in lockstep.

Figures (median of --repeats runs, each on one core):
  * lockstep_realtime_factor: simulated seconds per wall second for a vehicle flying offboard at the
    default 100 Hz physics rate, with default telemetry encoded by the vehicle and decoded by a pymavlink
    client over the in-memory link (the mission-replay configuration). Target: >= 200x.
  * vehicle_ticks_per_s: vehicle.step() with no link attached (physics, sensors, autopilot only).
  * dynamics_steps_per_s: sitl_bridge.dynamics.step alone.
  * reference_heartbeat_roundtrips_per_s: pymavlink encode + decode of one HEARTBEAT, measured in the same
    run, so figures from a noisy shared machine can be compared across runs.

Usage: python benchmarks/sitl_speed.py [--seconds 60] [--repeats 5] [--out benchmarks/results/sitl_speed.json]
"""
from __future__ import annotations

import argparse
import math
import platform
import sys
import time

from pymavlink.dialects.v20 import common as mavlink

from common import summarise, results_file, write_report  # first: it puts this checkout on sys.path

from sitl_bridge import dynamics
from sitl_bridge.px4.modes import FlightMode
from sitl_bridge.scripted_flight import LockstepPilot
from sitl_bridge.vehicle import SimulatedVehicle, VehicleConfig


def flying_pilot() -> LockstepPilot:
    """A vehicle in OFFBOARD at 10 m, flying north-east at 4 m/s, the client streaming at 20 Hz."""
    pilot = LockstepPilot.create(VehicleConfig(seed=1, wind=dynamics.Wind(3.0, 1.0, 1.0, seed=1),
                                               params={"MIS_TAKEOFF_ALT": 10.0}))
    pilot.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    pilot.command(mavlink.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7)
    pilot.stream = (3.0, 3.0, 0.0, mavlink.MAV_FRAME_LOCAL_NED)
    pilot.vehicle.run(0)
    pilot.wait_for(lambda: pilot.vehicle.time_s > 12.0, 20.0, "takeoff and stream")
    assert pilot.set_mode(FlightMode.OFFBOARD) == mavlink.MAV_RESULT_ACCEPTED
    return pilot


def lockstep_factor(seconds: float) -> tuple[float, int]:
    pilot = flying_pilot()
    ticks = int(seconds * pilot.vehicle.config.physics_rate_hz)
    received_before = len(pilot.received)
    start = time.perf_counter()
    for _ in range(ticks):
        pilot.step()
    wall = time.perf_counter() - start
    pilot.received.clear()
    return seconds / wall, received_before


def vehicle_ticks_per_s(ticks: int) -> float:
    vehicle = SimulatedVehicle(VehicleConfig(seed=1))
    vehicle.autopilot.handle_command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (1, 0, 0, 0, 0, 0, 0), 0.0, vehicle.state)
    vehicle.autopilot.handle_command(mavlink.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, math.nan), 0.0, vehicle.state)
    start = time.perf_counter()
    for _ in range(ticks):
        vehicle.step()
    return ticks / (time.perf_counter() - start)


def dynamics_steps_per_s(steps: int) -> float:
    params, wind = dynamics.MultirotorParams(), dynamics.Wind(3.0, 1.0, 1.0)
    state = dynamics.VehicleState(down_m=-10.0, on_ground=False)
    command = dynamics.VelocityCommand(3.0, 3.0, 0.0)
    start = time.perf_counter()
    for _ in range(steps):
        state = dynamics.step(state, command, params, wind, 0.01)
    return steps / (time.perf_counter() - start)


def heartbeat_roundtrips_per_s(count: int) -> float:
    encoder = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    decoder = mavlink.MAVLink(None)
    msg = mavlink.MAVLink_heartbeat_message(2, 12, 1, 0, 3, 3)
    start = time.perf_counter()
    for _ in range(count):
        decoder.parse_buffer(msg.pack(encoder))
    return count / (time.perf_counter() - start)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="simulated seconds per lockstep run")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default=results_file("sitl_speed.json"))
    args = parser.parse_args()
    runs: dict[str, list[float]] = {"lockstep_realtime_factor": [], "vehicle_ticks_per_s": [],
                                    "dynamics_steps_per_s": [], "reference_heartbeat_roundtrips_per_s": []}
    for repeat in range(args.repeats):
        runs["reference_heartbeat_roundtrips_per_s"].append(heartbeat_roundtrips_per_s(20_000))
        runs["lockstep_realtime_factor"].append(lockstep_factor(args.seconds)[0])
        runs["vehicle_ticks_per_s"].append(vehicle_ticks_per_s(int(args.seconds * 100)))
        runs["dynamics_steps_per_s"].append(dynamics_steps_per_s(100_000))
        print(f"run {repeat + 1}/{args.repeats}: " + ", ".join(f"{k} {v[-1]:,.0f}" for k, v in runs.items()),
              flush=True)
    medians = summarise(runs, f"medians over {args.repeats} runs (one core):")
    verdict = "meets" if medians["lockstep_realtime_factor"] >= 200 else "MISSES"
    print(f"lockstep {medians['lockstep_realtime_factor']:.0f}x real time: {verdict} the 200x target")
    write_report(args.out, {"python": platform.python_version(), "machine": platform.machine(),
                            "seconds_per_run": args.seconds, "repeats": args.repeats, "medians": medians, "runs": runs})
    return 0


if __name__ == "__main__":
    sys.exit(main())
