"""Fleet replays (``hrlsac mission replay FLEET.yaml``, ``simulation.fleet_replay``): several simulated vehicles, one
runner each on one lockstep clock, one shared search. The shipped fleet demo finds and confirms the victim with
three drones that all land at home without a separation breach; replays are byte-identical; the per-drone policy
artifact flies a fleet too; a drone that leaves early leaves its water to the others; bad input gets one line."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest
from pymavlink import mavutil

from cli_harness import assert_clean_error, run_cli
from missions.fleet import Fleet
from missions.mission_file import load_mission
from simulation.fleet_replay import replay_fleet
from autonomy.pilots import ScriptedPilot
from mavlink_signing import SIGNED_FLAG
from sitl_bridge.faults import parse_link_faults

KEY = bytes(range(32))

SMALL_FLEET = """\
name: small-fleet
flight: {altitude_m: 20, max_speed_mps: 10, step_period_s: 1.0, subgoal_interval: 30, max_steps: 300,
         reach_radius_m: 15}
geofence: {north_min_m: -150, north_max_m: 450, east_min_m: -350, east_max_m: 350}
scenario:
  home: {lat_deg: 47.397742, lon_deg: 8.545594, alt_m: 488}
  area: {north_min_m: -100, north_max_m: 400, east_min_m: -300, east_max_m: 300}
  start: {north_m: 0, east_m: 0}
  datum: {north_m: 230, east_m: -40, sigma_m: 70}
  targets:
    - {category: person, north_m: 270, east_m: -80, primary: true}
    - {category: person, north_m: 200, east_m: 30}
  conditions: {sea: calm, weather: clear, time_of_day: day, visibility: 1.0, wind: 0.1, wind_direction_deg: 60}
  current: {north_mps: 0.05, east_mps: 0.0, forecast_north_mps: 0.05, forecast_east_mps: 0.0}
  endurance_s: 450
  seed: 4
fleet:
  count: 2
  launch_line: {bearing_deg: 90, spacing_m: 40}
  separation_m: 30
  altitude_layer_m: 10
"""


@pytest.fixture(scope="module")
def small_fleet(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("fleet") / "small-fleet.yaml"
    path.write_text(SMALL_FLEET)
    return path


@pytest.fixture(scope="module")
def demo_replay(tmp_path_factory):
    out = tmp_path_factory.mktemp("fleet-demo")
    result = run_cli("mission", "replay", "missions/library/fleet-demo.yaml", "--pilot", "greedy_bayes",
                     "--out", str(out), "--quiet")
    return result, out, json.loads((out / "report.json").read_text())


def test_the_fleet_demo_finds_confirms_and_every_drone_lands_at_home_apart(demo_replay):
    result, out, report = demo_replay
    assert result.code == 0, result.err
    assert "fleet-demo (greedy_bayes, 3 drones): found by drone" in result.out
    assert report["success"] and report["complete"] and report["drones"] == 3
    finder = next(d for d in report["vehicles"] if d["name"] == report["found_by"])
    assert finder["search_end"] == "victim reached" and finder["victim_confirmed"]
    assert report["found_at_s"] > 0
    assert [d["system_id"] for d in report["vehicles"]] == [1, 2, 3]
    for drone in report["vehicles"]:
        if drone is not finder:
            assert drone["search_end"] == "victim reached by another drone"
        assert drone["transitions"][-1]["reason"] == "landed and disarmed"
        # "completed": landed and disarmed within 10 m of its own home (else the watch says "ditched")
        assert drone["outcome"]["outcome"] == "completed", drone["outcome"]
    assert report["all_landed"] and report["all_completed"]
    separation = report["separation"]
    assert not separation["breached"] and separation["breaches"] == []
    assert separation["closest_unlayered_m"] >= separation["horizontal_m"]
    # the drones flew their own layers: 50, 60 and 70 m above home at the start of the search
    layers = [d["transitions"][[t["to"] for t in d["transitions"]].index("OFFBOARD")]["reason"]
              for d in report["vehicles"]]
    assert [float(text.split()[1]) for text in layers] == pytest.approx([50, 60, 70], abs=1.5)


def test_each_drone_has_its_own_tlog_of_its_own_system(demo_replay):
    _, out, _ = demo_replay
    for system_id, name in enumerate(("drone1", "drone2", "drone3"), start=1):
        log = mavutil.mavlink_connection(str(out / name / "flight.tlog"), dialect="common")
        sources = set()
        while (msg := log.recv_match(type=["HEARTBEAT", "SET_POSITION_TARGET_LOCAL_NED"])) is not None:
            sources.add(msg.get_srcSystem())
            if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
                assert msg.target_system == system_id
        assert sources == {system_id}  # the vehicle, and its companion sharing its system id


def test_a_drone_that_loses_its_link_holds_and_two_signed_replays_write_identical_tlogs(small_fleet, tmp_path):
    """A 12 s two-way outage of drone 2's link in the search: its runner holds (blind) and the fleet's rounds go on
    without it; once the link is back it searches on, and both drones land at home, never breaching separation.
    Every link is signed, and nothing unsigned or forged was accepted. The same seed and faults replayed again
    write the same bytes."""
    mission = load_mission(small_fleet)
    faults = {"drone2": parse_link_faults("outage=45:12")}
    reports = [replay_fleet(mission, ScriptedPilot("greedy_bayes"), seed=3, out=tmp_path / run, link_faults=faults,
                            signing_key=KEY) for run in "ab"]
    report = reports[0]
    first, second = report["vehicles"]
    assert any(e["event"] == "link" and "holding position" in e["reason"] for e in second["events"])
    assert not any(e["event"] == "link" for e in first["events"])
    assert report["success"] and report["all_completed"] and not report["separation"]["breached"]
    assert report["link_faults"] == {"drone2": "both ways outage=45:12"}
    assert reports[0] == reports[1]
    for drone in report["vehicles"]:
        vehicle, runner = drone["signing"]["vehicle"], drone["signing"]["runner"]
        assert vehicle["rejected_total"] == runner["rejected_total"] == 0
        assert vehicle["accepted_unsigned"] == runner["accepted_unsigned"] == {}
        assert vehicle["accepted_signed"] > 500 and runner["accepted_signed"] > 1000
    for name in ("drone1", "drone2"):
        tlogs = [(tmp_path / run / name / "flight.tlog").read_bytes() for run in "ab"]
        assert tlogs[0] == tlogs[1] and len(tlogs[0]) > 100_000
        assert tlogs[0][8] == 0xFD and tlogs[0][10] & SIGNED_FLAG  # the first frame: MAVLink 2, signed


def test_the_shield_keeps_two_drones_flying_the_same_pattern_on_one_layer_apart(small_fleet):
    """Uncoordinated expanding squares from the same datum, both drones on one altitude layer: the two would fly
    the same track; every setpoint goes through the separation shield, which turns them away from each other."""
    mission = load_mission(small_fleet)
    one_layer = dataclasses.replace(mission, fleet=Fleet(mission.fleet.vehicles, separation_m=30.0,
                                                         altitude_layer_m=0.0),
                                    flight=dataclasses.replace(mission.flight, max_steps=120))
    report = replay_fleet(one_layer, ScriptedPilot("expanding_square"), seed=3)
    separation = report["separation"]
    assert separation["vertical_m"] == 0.0 and not separation["breached"]
    assert separation["closest_unlayered_m"] >= 30.0
    assert all(d["separation_shield_changes"] > 100 for d in report["vehicles"])
    assert report["all_landed"]
    assert all(d["outcome"]["outcome"] in ("completed", "safe") for d in report["vehicles"])


def test_the_shipped_policy_flies_each_drone_of_a_fleet_over_several_seeds(small_fleet, tmp_path):
    result = run_cli("mission", "replay", str(small_fleet), "--policy", "policies/pretrained/hrl-sac.pt",
                     "--accept-flight-mismatch", "--out", str(tmp_path), "--quiet", "--seed", "1", "--episodes", "2")
    assert result.code == 0, result.err
    assert "small-fleet (hrl-sac, 2 drones): " in result.out and "/2 searches found the victim" in result.out
    for seed in (1, 2):  # one folder per seed, each with the fleet's report and every drone's tlog
        folder = tmp_path / f"seed-{seed:05d}"
        report = json.loads((folder / "report.json").read_text())
        assert report["complete"] and report["seed"] == seed
        assert report["pilot"] == "hrl-sac" and report["drones"] == 2
        assert report["all_landed"] and not report["separation"]["breached"]
        assert all(d["outcome"]["outcome"] in ("completed", "safe") for d in report["vehicles"])
        assert all((folder / name / "flight.tlog").stat().st_size > 0 for name in ("drone1", "drone2"))


def test_a_drone_that_goes_home_early_leaves_its_water_to_the_other(small_fleet):
    """Drone 2's battery is nearly flat: the runner's low-battery failsafe sends it home early; drone 1 searches
    on alone and finds the victim."""
    mission = load_mission(small_fleet)
    report = replay_fleet(mission, ScriptedPilot("greedy_bayes"), seed=3,
                          battery_percent={"drone2": 26.0})
    first, second = report["vehicles"]
    assert "battery" in second["search_end"]
    assert second["transitions"][-1]["reason"] == "landed and disarmed"
    assert report["success"] and report["found_by"] == "drone1"
    left = next(t["time_s"] for t in second["transitions"] if t["to"] == "RTL")
    assert left < report["found_at_s"]  # it went home first, and drone 1 searched on alone


def test_a_fleet_replay_refuses_a_bad_key_file_in_one_line(small_fleet, tmp_path):
    out = tmp_path / "never"
    missing = tmp_path / "link.key"
    assert_clean_error(run_cli("mission", "replay", str(small_fleet), "--pilot", "greedy_bayes", "--out", str(out),
                               "--signing-key", str(missing)), f"key file {missing} does not exist", "hrlsac keygen")
    assert not out.exists()


def test_a_fleet_run_needs_one_connection_per_drone_or_one_ground_station_port(small_fleet, tmp_path):
    out = tmp_path / "never"
    result = run_cli("mission", "run", str(small_fleet), "--pilot", "greedy_bayes", "--out", str(out),
                     "--connect", "udpout:127.0.0.1:14540")
    assert_clean_error(result, "--connect udpout:127.0.0.1:14540 for all 2 drones",
                       "only as a ground station's udpin:HOST:PORT")
    assert not out.exists()
    three = run_cli("mission", "run", str(small_fleet), "--pilot", "greedy_bayes", "--out", str(out),
                    *[arg for port in (14540, 14541, 14542) for arg in ("--connect", f"udpin:127.0.0.1:{port}")])
    assert_clean_error(three, "--connect given 3 times", "2 drones", "or one udpin port for all")
    assert not out.exists()
    single = run_cli("mission", "run", "missions/library/demo.yaml", "--pilot", "greedy_bayes", "--out", str(out),
                     "--connect", "udpin:127.0.0.1:14540", "--connect", "udpin:127.0.0.1:14541")
    assert_clean_error(single, "--connect given 2 times", "1 drone")
    assert not out.exists()
