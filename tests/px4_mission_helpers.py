"""What the tests of PX4's mission protocol share (tests/test_px4_*.py, test_ardupilot_mission.py,
test_autopilot_fences.py): mission, fence and rally items as a pymavlink client sends them, and the upload
handshake. Not a test module (pytest does not collect it)."""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.scripted_flight import LockstepPilot


ACCEPTED = mavlink.MAV_MISSION_ACCEPTED
MISSION_START = mavlink.MAV_CMD_MISSION_START
WAYPOINT, LAND, TAKEOFF = mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_LAND, mavlink.MAV_CMD_NAV_TAKEOFF
RELATIVE = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


def item(pilot: LockstepPilot, seq: int, north: float, east: float, alt: float, command: int = WAYPOINT,
         hold_s: float = 0.0, radius_m: float = 2.0, frame: int = RELATIVE) -> mavlink.MAVLink_message:
    lat, lon, _ = pilot.vehicle.frame.to_geodetic(north, east, 0.0)
    return mavlink.MAVLink_mission_item_int_message(1, 1, seq, frame, command, int(seq == 0), 1, hold_s, radius_m,
                                                    0.0, math.nan, round(lat * 1e7), round(lon * 1e7), alt)


def since(pilot: LockstepPilot, start: int, kind: str) -> list:
    return [m for m in pilot.received[start:] if m.get_type() == kind]


def upload(pilot: LockstepPilot, items: list, mission_type: int = 0) -> tuple[int, list]:
    """MISSION_COUNT, then each requested item: the final MISSION_ACK's type and the requests seen."""
    start = len(pilot.received)
    pilot.mav.mission_count_send(1, 1, len(items), mission_type)
    requests: list = []
    for _ in range(400):
        pilot.step()
        for m in pilot.received[start:]:
            if m.get_type() == "MISSION_ACK":
                return m.type, requests
            if m.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
                requests.append(m)
                pilot.mav.send(items[m.seq])
        start = len(pilot.received)
    raise AssertionError("no MISSION_ACK")


def square(pilot: LockstepPilot, alt: float = 15.0) -> list:
    return [item(pilot, 0, 30.0, 0.0, alt), item(pilot, 1, 30.0, 30.0, alt), item(pilot, 2, 0.0, 30.0, alt)]


# ------------------------------------------------------------------ uploaded fences
FENCE = mavlink.MAV_MISSION_TYPE_FENCE


def fence_item(pilot: LockstepPilot, seq: int, command: int, north: float, east: float,
               param1: float) -> mavlink.MAVLink_message:
    lat, lon, _ = pilot.vehicle.frame.to_geodetic(north, east, 0.0)
    return mavlink.MAVLink_mission_item_int_message(1, 1, seq, mavlink.MAV_FRAME_GLOBAL_INT, command, int(seq == 0),
                                                    0, param1, 0, 0, 0, round(lat * 1e7), round(lon * 1e7), 0.0,
                                                    FENCE)


def square_fence(pilot: LockstepPilot, half_m: float = 25.0, no_go: tuple[float, float, float] | None = None) -> list:
    """An inclusion square of side 2 x half_m around home, and optionally an exclusion circle (north, east, r)."""
    corners = ((-half_m, -half_m), (half_m, -half_m), (half_m, half_m), (-half_m, half_m))
    inclusion = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
    items = [fence_item(pilot, seq, inclusion, n, e, 4) for seq, (n, e) in enumerate(corners)]
    if no_go:
        items.append(fence_item(pilot, 4, mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, no_go[0], no_go[1], no_go[2]))
    return items


# ------------------------------------------------------------------ rally points
RALLY = mavlink.MAV_MISSION_TYPE_RALLY


def rally_point(pilot: LockstepPilot, seq: int, north: float, east: float, alt: float = 10.0,
                frame: int = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT) -> mavlink.MAVLink_message:
    """A rally point as QGroundControl sends one (MISSION_ITEM_INT, MAV_FRAME_GLOBAL_RELATIVE_ALT, no parameters)."""
    lat, lon, _ = pilot.vehicle.frame.to_geodetic(north, east, 0.0)
    return mavlink.MAVLink_mission_item_int_message(1, 1, seq, frame, mavlink.MAV_CMD_NAV_RALLY_POINT, 0, 0, 1, 2, 3,
                                                    4, round(lat * 1e7), round(lon * 1e7), alt, RALLY)
