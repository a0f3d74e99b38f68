"""The search altitude is held above the vehicle's own home, and a mission written for another place is refused.

Regression of the first defect of the flight-side issue: the runner took off to the vehicle's HOME_POSITION but then
held its altitude relative to the *mission's* home altitude, so a mission with ``home.alt_m: 0`` flown by a vehicle
whose home is 488 m AMSL descended during SEARCH until it touched the water, graded "safe". Every flight here is a
lockstep replay: the real runner against the simulated vehicle over the in-memory MAVLink link; heights are read
back from the vehicle's own GLOBAL_POSITION_INT.relative_alt in the tlog (the autopilot's height above its home).
"""
from __future__ import annotations

import dataclasses

import pytest
from runner_helpers import read_tlog, small_mission

from autonomy.policy import Policy, load_policy
from missions.geodesy import GeoPoint, LocalFrame
from missions.mission import Mission
from missions.mission_file import load_mission
from missions.mission_writer import mission_to_dict, save_mission
from simulation.flight_outcome import FlightWatch, FlyawayLimits
from simulation.mission_replay import airframe_for, replay_mission
from sitl_bridge.vehicle import SimulatedVehicle, VehicleConfig

PRETRAINED = "policies/pretrained/hrl-sac.pt"
VEHICLE_HOME = GeoPoint(47.397742, 8.545594, 488.0)  # hrlsac sitl's default home


@pytest.fixture(scope="module")
def policy() -> Policy:
    return load_policy(PRETRAINED)


def mission_at(home: GeoPoint, **changes) -> Mission:
    mission = small_mission()
    return dataclasses.replace(mission, scenario=dataclasses.replace(mission.scenario, home=home), **changes)


def fly(policy: Policy, mission: Mission, tmp_path, vehicle_home: GeoPoint = VEHICLE_HOME) -> dict:
    config = VehicleConfig(home=vehicle_home, seed=5, airframe=airframe_for(mission))
    return replay_mission(mission, policy, seed=5, out=tmp_path, video=False, vehicle_config=config)


def search_heights(report: dict, tmp_path) -> list[float]:
    """The vehicle's own height above its home (relative_alt, m) for every position it sent during SEARCH."""
    start = next(t["time_s"] for t in report["transitions"] if t["to"] == "SEARCH")
    end = next(t["time_s"] for t in report["transitions"] if t["to"] == "RTL")
    return [m.relative_alt / 1000.0 for m in read_tlog(tmp_path / "flight.tlog")
            if m.get_type() == "GLOBAL_POSITION_INT" and start + 2.0 <= m._timestamp <= end]


def states(report: dict) -> list[str]:
    return [t["to"] for t in report["transitions"]]


def test_a_mission_home_at_sea_level_is_refused_by_a_vehicle_whose_home_is_488_m_before_arming(policy, tmp_path):
    report = fly(policy, mission_at(GeoPoint(VEHICLE_HOME.lat_deg, VEHICLE_HOME.lon_deg, 0.0)), tmp_path)
    assert states(report) == ["CONNECT", "PREFLIGHT", "DONE"]  # never armed
    (abort,) = [e["reason"] for e in report["events"] if e["event"] == "abort"]
    assert abort == ("refused before arming: the mission's launch point 47.397742, 8.545594, 0.0 m AMSL is 0 m from "
                     "the vehicle's home 47.397742, 8.545594, 488.0 m AMSL horizontally and 488.0 m vertically "
                     "(tolerance 50 m and 15 m): correct the mission's scenario.home and start, or fly it from its "
                     "own launch point")
    assert report["outcome"]["vehicle_end"] == "landed and disarmed"


def test_a_launch_point_200_m_from_the_vehicles_home_is_refused(policy, tmp_path):
    lat, lon, _ = LocalFrame(VEHICLE_HOME).to_geodetic(0.0, 200.0, 0.0)
    report = fly(policy, mission_at(GeoPoint(lat, lon, 488.0)), tmp_path)
    assert states(report) == ["CONNECT", "PREFLIGHT", "DONE"]
    (abort,) = [e["reason"] for e in report["events"] if e["event"] == "abort"]
    assert " is 200 m from the vehicle's home " in abort and "and 0.0 m vertically" in abort


def test_within_tolerance_the_search_altitude_is_held_above_the_vehicles_home_not_the_missions(policy, tmp_path):
    """The mission says home is at 478 m, the vehicle's home is at 488 m: the search flies 20 m above the vehicle's
    home (it flew 10 m above it, and would have flown into the water with a larger difference)."""
    report = fly(policy, mission_at(GeoPoint(VEHICLE_HOME.lat_deg, VEHICLE_HOME.lon_deg, 478.0)), tmp_path)
    assert states(report)[-4:] == ["SEARCH", "RTL", "LAND", "DONE"]
    heights = search_heights(report, tmp_path)
    assert len(heights) > 50
    altitude = small_mission().flight.altitude_m
    assert altitude - 1.5 <= min(heights) and max(heights) <= altitude + 1.5
    assert report["outcome"]["outcome"] == "completed"


def test_a_mission_file_without_alt_m_is_flown_above_the_vehicles_home_with_a_warning(policy, tmp_path):
    path = tmp_path / "no-alt.yaml"
    save_mission(mission_at(VEHICLE_HOME), path)
    path.write_text(path.read_text().replace("alt_m: 488.0", "").replace("lon_deg: 8.545594,", "lon_deg: 8.545594"))
    mission = load_mission(path)
    assert mission.home_altitude_known is False and mission.scenario.home.alt_m == 0.0
    assert "alt_m" not in mission_to_dict(mission)["scenario"]["home"]  # saved as read: still unknown
    report = fly(policy, mission, tmp_path)
    assert states(report)[-4:] == ["SEARCH", "RTL", "LAND", "DONE"]
    warnings = [e["reason"] for e in report["events"] if e["event"] == "warning"]
    (warning,) = [w for w in warnings if "home altitude" in w]  # (the other: PX4's defaults without the companion)
    assert "the mission gives no home altitude" in warning and "488.0 m AMSL" in warning
    assert len(warnings) == 2 and "goes silent" in warnings[1]
    heights = search_heights(report, tmp_path)
    altitude = mission.flight.altitude_m
    assert altitude - 1.5 <= min(heights) and max(heights) <= altitude + 1.5


def test_touching_the_water_away_from_home_is_graded_ditched_not_safe():
    """The ground truth watch: a vehicle landed 100 m from home (LAND over the sea) has ditched."""
    mission = small_mission()
    vehicle = SimulatedVehicle(VehicleConfig(home=mission.launch_point, airframe=airframe_for(mission)))
    watch = FlightWatch(vehicle, mission, FlyawayLimits())
    vehicle.state = dataclasses.replace(vehicle.state, north_m=100.0, down_m=0.0)
    watch.observe()
    report = {"events": [], "transitions": [{"reason": "landed and disarmed"}], "search_end": "step limit"}
    outcome = watch.outcome(report)
    assert outcome["outcome"] == "ditched"
    assert outcome["reason"].startswith("touched the surface 100 m from home at 0.0 s")
