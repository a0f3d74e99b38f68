"""``hrlsac demo`` (until the mission runner exists): a scripted flight of the simulated vehicle.

A plain pymavlink client flies the vehicle over the in-memory MAVLink link in lockstep: set the
takeoff altitude, arm, take off, stream velocity setpoints, switch to OFFBOARD, fly a dog-leg, stop the
stream (the offboard-loss failsafe holds position), return to launch and land. Every byte crosses the
link as real MAVLink 2, and the whole flight is deterministic for a seed.

:class:`LockstepPilot` is the client side of that: send a command, then step the simulation until a
reply or a condition arrives. The tests use it too.
"""
from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass, field
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.link import MemoryMavConnection, memory_link_pair
from sitl_bridge.px4.modes import FlightMode
from sitl_bridge.vehicle import SimulatedVehicle, VehicleConfig

VELOCITY_ONLY = 3527  # SET_POSITION_TARGET_LOCAL_NED type_mask: use vx, vy, vz only


class LockstepTimeout(RuntimeError):
    """The awaited reply or condition did not arrive within the simulated time allowed."""


@dataclass
class LockstepPilot:
    """A pymavlink client (sysid 255, compid 190) wired to a vehicle over the in-memory link."""

    vehicle: SimulatedVehicle
    conn: MemoryMavConnection
    received: list = field(default_factory=list)  # every message received, in order
    stream: tuple[float, float, float, int] | None = None  # (vn, ve, vd, frame) re-sent every stream period
    stream_period_s: float = 0.05
    _next_stream_s: float = 0.0

    @classmethod
    def create(cls, config: VehicleConfig | None = None, on_event=None) -> "LockstepPilot":
        vehicle_end, client_end = memory_link_pair()
        vehicle = SimulatedVehicle(config, [vehicle_end], on_event=on_event)
        return cls(vehicle, MemoryMavConnection(client_end))

    @property
    def mav(self):
        return self.conn.mav

    def step(self) -> None:
        """One vehicle tick, plus the client's setpoint stream and reception."""
        now = self.vehicle.time_s
        if self.stream is not None and now + 1e-9 >= self._next_stream_s:
            vn, ve, vd, frame = self.stream
            self.send_velocity(vn, ve, vd, frame)
            self._next_stream_s = now + self.stream_period_s
        self.vehicle.step()
        while (msg := self.conn.recv_msg()) is not None:
            self.received.append(msg)

    def send_velocity(self, vn: float, ve: float, vd: float, frame: int = mavlink.MAV_FRAME_LOCAL_NED,
                      type_mask: int = VELOCITY_ONLY) -> None:
        self.mav.set_position_target_local_ned_send(self.vehicle.time_boot_ms, 1, 1, frame, type_mask,
                                                    0, 0, 0, vn, ve, vd, 0, 0, 0, 0, 0)

    def wait_for(self, condition: Callable[[], bool], timeout_s: float, what: str) -> float:
        """Step until ``condition()`` holds; returns the simulated time it took."""
        start = self.vehicle.time_s
        while not condition():
            if self.vehicle.time_s - start > timeout_s:
                raise LockstepTimeout(f"{what}: not within {timeout_s:g} s of simulated time")
            self.step()
        return self.vehicle.time_s - start

    def wait_message(self, msg_type: str, timeout_s: float = 2.0,
                     match: Callable[[object], bool] = lambda m: True):
        """Step until a message of ``msg_type`` (and matching) arrives after now; returns it."""
        seen = len(self.received)

        def arrived() -> bool:
            return any(m.get_type() == msg_type and match(m) for m in self.received[seen:])

        self.wait_for(arrived, timeout_s, f"waiting for {msg_type}")
        return next(m for m in self.received[seen:] if m.get_type() == msg_type and match(m))

    def command(self, command: int, *params: float, timeout_s: float = 1.0) -> int:
        """COMMAND_LONG to the autopilot; returns the ACK's MAV_RESULT."""
        p = list(params) + [0.0] * (7 - len(params))
        self.mav.command_long_send(1, 1, command, 0, *p)
        ack = self.wait_message("COMMAND_ACK", timeout_s, lambda m: m.command == command)
        return ack.result

    def set_mode(self, mode: FlightMode | CopterMode) -> int:
        """DO_SET_MODE as each autopilot wants it: PX4 (main, sub) in param2/3, ArduCopter the number in param2."""
        custom = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if isinstance(mode, CopterMode):
            return self.command(mavlink.MAV_CMD_DO_SET_MODE, custom, int(mode))
        main, sub = mode.value
        return self.command(mavlink.MAV_CMD_DO_SET_MODE, custom, main, sub)

    def set_param(self, name: str, value: float, timeout_s: float = 1.0) -> float:
        self.mav.param_set_send(1, 1, name.encode(), value, mavlink.MAV_PARAM_TYPE_REAL32)
        return self.wait_message("PARAM_VALUE", timeout_s, lambda m: m.param_id == name).param_value

    def heartbeat_mode(self) -> FlightMode | CopterMode | None:
        """The mode of the last HEARTBEAT, decoded for the autopilot it names (None: none yet, or not emulated)."""
        beat = next((m for m in reversed(self.received) if m.get_type() == "HEARTBEAT"), None)
        if beat is None:
            return None
        if beat.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA:
            return CopterMode(beat.custom_mode) if beat.custom_mode in CopterMode._value2member_map_ else None
        return FlightMode.from_custom_mode(beat.custom_mode)

    def local_position(self):
        return next((m for m in reversed(self.received) if m.get_type() == "LOCAL_POSITION_NED"), None)


def fly_demo(seed: int = 0, say: Callable[[str], None] = print) -> dict:
    """The scripted flight; returns a summary (times in simulated seconds, positions in metres)."""
    pilot = LockstepPilot.create(VehicleConfig(seed=seed),
                                 on_event=lambda e: say(f"  [{e.time_s:7.2f} s] vehicle: {e.text}"))
    v = pilot.vehicle
    pilot.wait_message("HEARTBEAT", 2.0)
    pilot.wait_for(lambda: v.autopilot.gps_ok, 5.0, "GPS fix")
    pilot.set_param("MIS_TAKEOFF_ALT", 10.0)
    results = {"arm": pilot.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1),
               "takeoff": pilot.command(mavlink.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7)}
    pilot.wait_for(lambda: pilot.heartbeat_mode() is FlightMode.HOLD and not v.state.on_ground, 30.0, "takeoff")
    say(f"  climbed to {-v.state.down_m:.1f} m")
    pilot.stream = (0.0, 0.0, 0.0, mavlink.MAV_FRAME_LOCAL_NED)
    _fly(pilot, 1.2)  # stream before asking for OFFBOARD (good practice; PX4 only needs one recent setpoint)
    results["offboard"] = pilot.set_mode(FlightMode.OFFBOARD)
    start = (v.state.north_m, v.state.east_m)
    pilot.stream = (3.0, 0.0, 0.0, mavlink.MAV_FRAME_LOCAL_NED)
    _fly(pilot, 5.0)
    north_leg = v.state.north_m - start[0]
    say(f"  flew {north_leg:.1f} m north in 5 s at 3 m/s")
    pilot.stream = (2.0, 0.0, 0.0, mavlink.MAV_FRAME_BODY_NED)
    _fly(pilot, 3.0)
    pilot.stream = None
    failsafe_s = pilot.wait_for(lambda: pilot.heartbeat_mode() is FlightMode.POSCTL, 3.0, "offboard-loss failsafe")
    say(f"  setpoints stopped: failsafe after {failsafe_s:.2f} s, vehicle holds position")
    results["rtl"] = pilot.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    pilot.wait_for(lambda: not v.autopilot.armed, 120.0, "return, landing and disarm")
    return {
        "results": {k: mavlink.enums["MAV_RESULT"][r].name for k, r in results.items()},
        "north_leg_m": north_leg,
        "landed_at_m": (v.state.north_m, v.state.east_m),
        "flight_time_s": v.time_s,
        "battery_used_pct": 100.0 * (1.0 - v.state.battery_wh / v.config.airframe.battery_capacity_wh),
        "messages_received": len(pilot.received),
    }


def _fly(pilot: LockstepPilot, seconds: float) -> None:
    end = pilot.vehicle.time_s + seconds
    pilot.wait_for(lambda: pilot.vehicle.time_s >= end - 1e-9, seconds + 1.0, "flight leg")


def main(argv: list[str], prog: str = "hrlsac demo") -> int:
    parser = argparse.ArgumentParser(prog=prog, description="Fly a short scripted mission in the simulated vehicle.")
    parser.add_argument("--seed", type=int, default=0, help="sensor-noise seed")
    args = parser.parse_args(argv)
    print("Scripted flight: pymavlink client -> in-memory MAVLink 2 link -> simulated PX4 multirotor (lockstep)")
    wall_start = time.perf_counter()
    summary = fly_demo(seed=args.seed)
    wall = time.perf_counter() - wall_start
    acks = ", ".join(f"{name} {result.removeprefix('MAV_RESULT_')}" for name, result in summary["results"].items())
    print(f"Commands: {acks}")
    north, east = summary["landed_at_m"]
    print(f"Landed and disarmed {math.hypot(north, east):.1f} m from home after {summary['flight_time_s']:.1f} s "
          f"of simulated flight ({wall:.1f} s wall, {summary['flight_time_s'] / wall:.0f}x real time); "
          f"battery used {summary['battery_used_pct']:.1f} %, {summary['messages_received']} messages received.")
    return 0
