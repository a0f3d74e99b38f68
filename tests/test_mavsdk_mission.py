"""MAVSDK's mission plugin flies a mission uploaded to the simulated PX4 over real UDP.

The flow is MAVSDK-Python's ``examples/mission.py`` with the 4.x API: progress printed from a task, three waypoints
at 25 m and 10 m/s (fly-through), return to launch after the mission, upload, wait for a global position and
home, arm, start, and done once the vehicle has been in the air and landed again. MAVSDK turns that into seven
MAVLink items (a waypoint and a DO_CHANGE_SPEED each, then RETURN_TO_LAUNCH; docs/sitl.md, "PX4 missions"), sent
with MISSION_COUNT / MISSION_REQUEST_INT / MISSION_ITEM_INT / MISSION_ACK, and follows the flight through
MISSION_CURRENT and MISSION_ITEM_REACHED. MAVSDK refuses the transfer outright against a vehicle whose
AUTOPILOT_VERSION lacks MAV_PROTOCOL_CAPABILITY_MISSION_INT, as the simulator's did before missions were emulated.
MAVSDK-Python's ``examples/geofence.py`` uploads a fence the same way (mission type FENCE), and the vehicle then
keeps to it; MissionRaw imports a QGroundControl plan's rally points and uploads them (type RALLY), and RTL lands
at the closest. Against ArduPilot MAVSDK's Mission plugin refuses to upload (INVALID_ARGUMENT, before sending anything:
MAVSDK-Python issue #819, MAVSDK #2029); MissionRaw is MAVSDK's way there, with home as item 0.
"""
from __future__ import annotations

import asyncio
import json
import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

pytest.importorskip("mavsdk.asyncio")  # the tests below need MAVSDK 4.x

from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.geofence import FenceType, GeofenceAsync, GeofenceData, Point, Polygon  # noqa: E402
from mavsdk.asyncio.plugins.mission import MissionAsync, MissionItem, MissionPlan  # noqa: E402
from mavsdk.asyncio.plugins.mission_raw import MissionItem as RawItem  # noqa: E402
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from mavsdk_helpers import COMPANION_STREAMS, SPEED, T, autopilot_at, bounded, first, vehicle_server  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.mavsdk]
WAYPOINTS_NE = ((40.0, 0.0), (40.0, 50.0), (0.0, 50.0))
"""The example's three waypoints are about 40-60 m apart near Zurich; these are as far apart around our home."""
ALTITUDE_M, SPEED_MPS = 25.0, 10.0


def flown_against(udp_ports: list[int], flight, seed: int, autopilot: str = "px4", params: dict | None = None,
                  timeout_s: float = 200.0):
    """``flight(port, server)`` (a coroutine) against a vehicle served over UDP: its result and the vehicle, which
    must have raised nothing."""
    server, mavsdk_port = vehicle_server(udp_ports, seed, autopilot, params)
    with server:
        result = asyncio.run(asyncio.wait_for(flight(mavsdk_port, server), timeout_s))
        assert server.error is None and server.vehicle.handler_errors == 0
    return result, server.vehicle


def example_item(lat: float, lon: float) -> MissionItem:
    """``MissionItem(lat, lon, 25, 10, True, nan, nan, CameraAction.NONE, nan, nan, nan, nan, nan,
    VehicleAction.NONE)``, as examples/mission.py builds each of its three."""
    return MissionItem(lat, lon, ALTITUDE_M, SPEED_MPS, True, math.nan, math.nan, MissionItem.CameraAction.NONE,
                       math.nan, math.nan, math.nan, math.nan, math.nan, MissionItem.VehicleAction.NONE)


async def fly_mission_example(port: int, server) -> dict:
    vehicle = server.vehicle
    flown: dict = {"progress": [], "track": [], "max_speed": 0.0}

    async def sample_track():  # the true flight, for the assertions (not part of the example)
        while True:
            s = vehicle.state
            flown["track"].append((s.north_m, s.east_m, -s.down_m))
            flown["max_speed"] = max(flown["max_speed"], math.hypot(s.vn_mps, s.ve_mps))
            await asyncio.sleep(0.05)

    async with autopilot_at(port) as system:
        mission, telemetry, action = MissionAsync(system), TelemetryAsync(system), ActionAsync(system)

        async def print_mission_progress():
            async for progress in mission.subscribe_mission_progress():
                flown["progress"].append((progress.current, progress.total))

        async def observe_is_in_air():
            was_in_air = False
            async for is_in_air in telemetry.subscribe_in_air():
                was_in_air = was_in_air or is_in_air
                if was_in_air and not is_in_air:
                    return

        progress_task = asyncio.ensure_future(print_mission_progress())
        track_task = asyncio.ensure_future(sample_track())
        termination = asyncio.ensure_future(observe_is_in_air())
        try:
            items = [example_item(*vehicle.frame.to_geodetic(n, e, 0.0)[:2]) for n, e in WAYPOINTS_NE]
            await bounded(mission.set_return_to_launch_after_mission(True))
            await bounded(mission.upload_mission(MissionPlan(items)))
            flown["stored"] = list(vehicle.missions.items)
            await first(telemetry.subscribe_health(), lambda h: h.is_global_position_ok and h.is_home_position_ok,
                        20, "global position and home")
            await bounded(action.arm())
            await bounded(mission.start_mission())
            await asyncio.wait_for(termination, 150 / SPEED)
            await asyncio.sleep(2.0)  # the last MISSION_CURRENT / MISSION_ITEM_REACHED repeats
            flown["finished"] = await bounded(mission.is_mission_finished())
            flown["downloaded"] = await bounded(mission.download_mission(), T)
        finally:
            for task in (progress_task, track_task, termination):
                task.cancel()
    return flown


def test_mavsdk_mission_example_uploads_flies_the_waypoints_and_returns(udp_ports):
    flown, vehicle = flown_against(udp_ports, fly_mission_example, 21, params={"RTL_RETURN_ALT": 30.0})

    stored = flown["stored"]  # what MAVSDK sent, as the vehicle parsed it
    commands = [item.command for item in stored]
    assert commands == [16, 178, 16, 178, 16, 178, 20]  # WAYPOINT, DO_CHANGE_SPEED, ..., RETURN_TO_LAUNCH
    assert [item.params[1] for item in stored[1::2][:3]] == [SPEED_MPS] * 3
    assert all(item.relative and item.z == ALTITUDE_M and item.params[1] == 3.0 for item in stored[0:6:2])

    track = flown["track"]
    for north, east in WAYPOINTS_NE:  # each waypoint passed within its 3 m acceptance radius, at 25 m
        arrival = next(p for p in track if math.hypot(p[0] - north, p[1] - east) < 3.5)
        assert arrival[2] == pytest.approx(ALTITUDE_M, abs=1.0)
    assert flown["max_speed"] > 8.0  # DO_CHANGE_SPEED 10 m/s, not MPC_XY_CRUISE's 5
    assert max(p[2] for p in track) < ALTITUDE_M + 6.0  # RTL_RETURN_ALT 30 m: the return climbs 5 m
    assert flown["progress"][-1] == (3, 3) and flown["finished"] is True
    downloaded = flown["downloaded"].mission_items  # MAVSDK's download_mission: the same three waypoints
    assert [p.latitude_deg for p in downloaded] == pytest.approx(
        [vehicle.frame.to_geodetic(n, e, 0.0)[0] for n, e in WAYPOINTS_NE], abs=1e-6)
    assert [(p.relative_altitude_m, p.speed_m_s) for p in downloaded] == [(ALTITUDE_M, SPEED_MPS)] * 3
    assert vehicle.state.on_ground and not vehicle.autopilot.armed
    assert math.hypot(vehicle.state.north_m, vehicle.state.east_m) < 1.5  # landed home


async def fly_geofence_example(port: int, server) -> list[str]:
    """examples/geofence.py (home, a second's wait, a square of +-0.0001 degrees around it, upload), then a flight
    out of the square; returns the STATUSTEXTs MAVSDK heard."""
    heard: list[str] = []
    async with autopilot_at(port) as system:
        telemetry, geofence, action = TelemetryAsync(system), GeofenceAsync(system), ActionAsync(system)

        async def listen():
            async for status in telemetry.subscribe_status_text():
                heard.append(status.text)

        listener = asyncio.ensure_future(listen())
        try:
            home = await first(telemetry.subscribe_home(), lambda h: True, 20, "home")
            await asyncio.sleep(1)
            lat, lon = home.latitude_deg, home.longitude_deg
            square = Polygon([Point(lat - 0.0001, lon - 0.0001), Point(lat + 0.0001, lon - 0.0001),
                              Point(lat + 0.0001, lon + 0.0001), Point(lat - 0.0001, lon + 0.0001)],
                             FenceType.INCLUSION)
            # The example adds Circle(Point(0, 0), 0, INCLUSION), "necessary" for the gRPC bindings; MAVSDK 4.x
            # refuses it (INVALID_ARGUMENT: a radius of 0), so this flow sends the square alone
            await bounded(geofence.upload_geofence(GeofenceData([square], [])))
            # beyond the example: take off and go 40 m east, out of the square (its half-width is 7.5 m east)
            await first(telemetry.subscribe_health(), lambda h: h.is_global_position_ok and h.is_armable, 20,
                        "armable")
            await bounded(action.arm())
            await bounded(action.takeoff())
            await first(telemetry.subscribe_position(), lambda p: p.relative_altitude_m > 2.0, 20, "2.5 m")
            target_lat, target_lon, _ = server.vehicle.frame.to_geodetic(0.0, 40.0, 0.0)
            await bounded(action.goto_location(target_lat, target_lon, home.absolute_altitude_m + 2.5, 0.0))
            await first(telemetry.subscribe_status_text(), lambda t: "outside geofence" in t.text, 30 / SPEED,
                        "the fence's breach")
            await asyncio.sleep(4.0 / SPEED)
        finally:
            listener.cancel()
    return heard


def test_mavsdk_geofence_example_uploads_a_fence_the_vehicle_keeps_to(udp_ports):
    heard, vehicle = flown_against(udp_ports, fly_geofence_example, 22, timeout_s=120.0)
    assert [(item.command, item.params[0]) for item in vehicle.missions.fence] == [(5001, 4.0)] * 4
    assert [(area.inclusion, len(area.vertices)) for area in vehicle.autopilot.fence_areas] == [(True, 4)]
    assert "Geofence: approaching or outside geofence" in heard
    assert vehicle.autopilot.mode.name == "HOLD" and 7.0 <= vehicle.state.east_m < 11.0  # held at the fence, not 40 m


def qgc_plan(home, rally_points: list[tuple[float, float, float]]) -> str:
    """A QGroundControl .plan (JSON) with no mission items, no fence and these rally points (lat, lon, altitude
    above home), in the format QGroundControl's Plan view saves."""
    return json.dumps({
        "fileType": "Plan", "groundStation": "QGroundControl", "version": 1,
        "mission": {"version": 2, "firmwareType": 12, "vehicleType": 2, "cruiseSpeed": 15, "hoverSpeed": 5,
                    "plannedHomePosition": [home.lat_deg, home.lon_deg, home.alt_m], "items": []},
        "geoFence": {"version": 2, "circles": [], "polygons": []},
        "rallyPoints": {"version": 2, "points": [list(point) for point in rally_points]}})


async def fly_rtl_to_a_rally_point(port: int, server) -> dict:
    """A QGroundControl plan's rally points imported and uploaded with MissionRaw, downloaded again; then take off,
    go 60 m north and return (PX4's RTL_TYPE 0: the closest of home and the rally points)."""
    vehicle, flown = server.vehicle, {}
    async with autopilot_at(port) as system:
        raw, telemetry, action = MissionRawAsync(system), TelemetryAsync(system), ActionAsync(system)
        points = [(*vehicle.frame.to_geodetic(north, east, 0.0)[:2], 0.0) for north, east in ((60.0, 40.0), (-60.0, 0))]
        imported = await bounded(raw.import_qgroundcontrol_mission_from_string(qgc_plan(vehicle.home, points)))
        flown["imported"] = [(item.command, item.frame, item.mission_type) for item in imported.rally_items]
        await bounded(raw.upload_rally_points(imported.rally_items))
        flown["downloaded"] = [(i.command, i.x, i.y, i.z) for i in await bounded(raw.download_rallypoints())]
        home = await first(telemetry.subscribe_home(), lambda h: True, 20, "home")
        await first(telemetry.subscribe_health(), lambda h: h.is_global_position_ok and h.is_armable, 20, "armable")
        await bounded(action.arm())
        await bounded(action.takeoff())
        await first(telemetry.subscribe_position(), lambda p: p.relative_altitude_m > 2.0, 20, "in the air")
        lat, lon, _ = vehicle.frame.to_geodetic(60.0, 0.0, 0.0)
        await bounded(action.goto_location(lat, lon, home.absolute_altitude_m + 10.0, 0.0))
        await first(telemetry.subscribe_position(),
                    lambda p: abs(p.latitude_deg - lat) < 2e-5 and abs(p.longitude_deg - lon) < 3e-5, 60, "60 m north")
        await bounded(action.return_to_launch())
        await first(telemetry.subscribe_armed(), lambda armed: not armed, 120 / SPEED + 30, "landed and disarmed")
    flown["points"] = points
    return flown


def test_mavsdk_uploads_a_qgroundcontrol_plans_rally_points_and_rtl_lands_at_the_closest(udp_ports):
    flown, vehicle = flown_against(udp_ports, fly_rtl_to_a_rally_point, 24, params={"RTL_RETURN_ALT": 10.0})
    rally_point = (mavlink.MAV_CMD_NAV_RALLY_POINT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                   mavlink.MAV_MISSION_TYPE_RALLY)
    assert flown["imported"] == [rally_point] * 2  # as QGroundControl sends them
    assert [(c, x, y) for c, x, y, _ in flown["downloaded"]] == [
        (mavlink.MAV_CMD_NAV_RALLY_POINT, round(lat * 1e7), round(lon * 1e7)) for lat, lon, _ in flown["points"]]
    assert len(vehicle.autopilot.rally_points) == 2
    assert math.hypot(vehicle.state.north_m - 60.0, vehicle.state.east_m - 40.0) < 2.0  # 40 m away; home 60 m


async def fly_raw_mission_on_ardupilot(port: int, server) -> dict:
    """MissionRaw: home, takeoff to 12 m, two waypoints, RTL (MAVSDK's ArduPilot integration test's shape), upload,
    arm, start (AUTO; AUTO_OPTIONS bit 1 lets the takeoff go without a throttle stick), until landed again."""
    vehicle, flown = server.vehicle, {"progress": []}
    async with autopilot_at(port) as system:
        mission, telemetry, action = MissionRawAsync(system), TelemetryAsync(system), ActionAsync(system)

        async def progress():
            async for step in mission.subscribe_mission_progress():
                flown["progress"].append((step.current, step.total))

        def raw(seq: int, command: int, frame: int, x: int = 0, y: int = 0, z: float = 0.0) -> RawItem:
            return RawItem(seq, frame, command, int(seq == 0), 1, 0.0, 0.0, 0.0, 0.0, x, y, z, 0)

        progress_task = asyncio.ensure_future(progress())
        try:
            home = vehicle.home
            items = [raw(0, 16, 0, round(home.lat_deg * 1e7), round(home.lon_deg * 1e7), home.alt_m),
                     raw(1, 22, 3, z=12.0)]
            for seq, (north, east) in enumerate(WAYPOINTS_NE[:2], start=2):
                lat, lon, _ = vehicle.frame.to_geodetic(north, east, 0.0)
                items.append(raw(seq, 16, 3, round(lat * 1e7), round(lon * 1e7), 12.0))
            items.append(raw(4, 20, 2))
            await bounded(mission.upload_mission(items))
            flown["stored"] = [item.command for item in vehicle.copter_missions.items]
            await first(telemetry.subscribe_health(), lambda h: h.is_global_position_ok and h.is_home_position_ok,
                        20, "global position and home")
            await bounded(action.arm())
            await bounded(mission.start_mission())
            flown["mode"] = vehicle.autopilot.mode.name
            await first(telemetry.subscribe_in_air(), bool, 30, "in the air")
            await first(telemetry.subscribe_in_air(), lambda in_air: not in_air, 150 / SPEED, "landed")
            flown["finished"] = await bounded(mission.is_mission_finished())
            flown["downloaded"] = [(i.seq, i.command, i.frame, i.z) for i in await bounded(mission.download_mission())]
        finally:
            progress_task.cancel()
    return flown


def test_mavsdk_mission_raw_flies_an_ardupilot_mission_in_auto(udp_ports):
    flown, vehicle = flown_against(udp_ports, fly_raw_mission_on_ardupilot, 23, "ardupilot",
                                   {**COMPANION_STREAMS, "AUTO_OPTIONS": 2})
    assert flown["stored"] == [22, 16, 16, 20] and flown["mode"] == "AUTO"  # home (item 0) is not stored
    assert flown["finished"] is True and (5, 5) in flown["progress"]
    home_alt = round(vehicle.home.alt_m, 2)
    assert [(seq, cmd, frame, round(z, 2)) for seq, cmd, frame, z in flown["downloaded"]] == [
        (0, 16, 0, home_alt), (1, 22, 3, 12.0), (2, 16, 3, 12.0), (3, 16, 3, 12.0), (4, 20, 0, 0.0)]
    assert vehicle.state.on_ground and not vehicle.autopilot.armed
    assert math.hypot(vehicle.state.north_m, vehicle.state.east_m) < 1.5
