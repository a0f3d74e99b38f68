"""The runner against both autopilot personalities, and against vehicles that do not share its clock.

Lockstep replays: the real runner against the simulated vehicle (PX4 or ArduPilot Copter personality) over the
in-memory MAVLink link; the tlog is read back with pymavlink. The ArduPilot rules the runner follows (GUIDED before
arming, NAV_TAKEOFF's param7 above home, streams to request, GUID_TIMEOUT, the GCS failsafe) are the ones
docs/sitl.md cites from ArduPilot's source; the vehicle options (boot long before the runner, reboot mid-flight)
are the realism options of the flight-side issue.
"""
from __future__ import annotations

import dataclasses
import math

import pytest
import torch
from link_faults_helpers import PilotAtTheGroundStation
from pymavlink.dialects.v20 import common as mavlink
from runner_helpers import ours, read_tlog, searched_to_its_own_end, small_mission, with_actions

from autonomy.policy import Policy
from missions.goals import TRACK_OBJECT
from simulation import mission_replay as replay_module
from simulation.mission_replay import airframe_for, replay_mission
from sitl_bridge.faults import parse_link_faults
from sitl_bridge.vehicle import VehicleConfig

ALL_STATES = ["CONNECT", "PREFLIGHT", "ARM", "TAKEOFF", "OFFBOARD", "SEARCH", "RTL", "LAND", "DONE"]


def fly(policy: Policy, autopilot: str, tmp_path=None, faults: str = "", **vehicle) -> dict:
    mission = small_mission()
    config = VehicleConfig(home=mission.launch_point, seed=5, airframe=airframe_for(mission), autopilot=autopilot,
                           **vehicle)
    return replay_mission(mission, policy, seed=5, out=tmp_path, video=False, vehicle_config=config,
                          link_faults=parse_link_faults(faults) if faults else None)


def states(report: dict) -> list[str]:
    return [t["to"] for t in report["transitions"]]


def events(report: dict, kind: str) -> list[str]:
    return [e["reason"] for e in report["events"] if e["event"] == kind]


# ---------------------------------------------------------------------------------------- ArduPilot Copter
def test_the_runner_flies_ardupilot_in_guided_with_its_own_take_off_and_streams(policy, tmp_path):
    report = fly(policy, "ardupilot", tmp_path)
    assert states(report) == ALL_STATES and report["autopilot"] == "ArduPilot Copter"
    assert report["transitions"][1]["reason"] == "vehicle 1/1 (MAV_AUTOPILOT_ARDUPILOTMEGA), flown as ArduPilot Copter"
    assert report["transitions"][5]["reason"].startswith("GUIDED after ")
    assert report["outcome"]["outcome"] == "completed" and report["outcome"]["vehicle_end"] == "landed and disarmed"
    commands = [(m.command, m.param1, m.param2, m.param7) for m in ours(read_tlog(tmp_path / "flight.tlog"),
                                                                         "COMMAND_LONG")]
    kinds = [c[0] for c in commands]
    # Streams first (ArduPilot's SRn rates are 0), then GUIDED (mode 4) before arming, then a take-off to 20 m above
    # home (ArduPilot's param7 is relative, PX4's AMSL), GUIDED again for the search, finally RTL.
    assert commands[0][:2] == (mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT)
    assert (mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION) in [c[:2] for c in commands]
    arm = kinds.index(mavlink.MAV_CMD_COMPONENT_ARM_DISARM)
    assert commands[arm - 1][:3] == (mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)
    takeoff = commands[kinds.index(mavlink.MAV_CMD_NAV_TAKEOFF)]
    assert takeoff[3] == pytest.approx(small_mission().flight.altitude_m)
    assert kinds[-1] == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
    # ArduCopter's defaults: nothing would end the flight if this computer went silent (autonomy.companion_loss)
    assert report["companion_loss"]["ends_the_flight"] is False
    assert [w for w in events(report, "warning") if "goes silent" in w] == [
        "if this computer goes silent during the search, ArduPilot Copter hovers until its battery is empty (GCS "
        "failsafe: FS_GCS_ENABLE 0, SYSID_MYGCS 255 (does not act on this computer's silence); low battery: nothing "
        "(BATT_FS_LOW_ACT 0); critical battery: nothing (BATT_FS_CRT_ACT 0)): set BATT_FS_LOW_ACT=2 (RTL at "
        "BATT_LOW_VOLT), or FS_GCS_ENABLE=1 with SYSID_MYGCS=1"]


def test_an_ardupilot_without_a_battery_monitor_is_judged_without_waiting_for_its_hidden_battery_parameters(policy):
    """BATT_MONITOR 0 hides the other BATT_* parameters (AP_PARAM_FLAG_ENABLE): they never answer, so the runner
    must not wait its parameter timeout (5 s) for them, and the warning says there is no battery failsafe."""
    report = fly(policy, "ardupilot", params={"BATT_MONITOR": 0})
    assert states(report) == ALL_STATES
    assert report["companion_loss"]["params"] == {"FS_GCS_ENABLE": 0, "SYSID_MYGCS": 255, "BATT_MONITOR": 0}
    assert [w for w in events(report, "warning") if "goes silent" in w] == [
        "if this computer goes silent during the search, ArduPilot Copter hovers until its battery is empty (GCS "
        "failsafe: FS_GCS_ENABLE 0, SYSID_MYGCS 255 (does not act on this computer's silence); low battery: nothing "
        "(no battery monitor); critical battery: nothing (no battery monitor)): set BATT_FS_LOW_ACT=2 (RTL at "
        "BATT_LOW_VOLT), or FS_GCS_ENABLE=1 with SYSID_MYGCS=1"]
    # simulated time, lockstep: the parameters are judged as soon as the ones that exist are in (well under 5 s)
    (fence,) = [e["time_s"] for e in report["events"] if e["event"] == "autopilot-fence"]
    preflight = next(t["time_s"] for t in report["transitions"] if t["to"] == "PREFLIGHT")
    assert fence - preflight < 2.0


def test_px4_gets_an_amsl_take_off_and_no_mode_request_before_arming(policy, tmp_path):
    report = fly(policy, "px4", tmp_path)
    assert states(report) == ALL_STATES and report["autopilot"] == "PX4"
    assert [w for w in events(report, "warning") if "goes silent" in w] == [
        "if this computer goes silent during the search, PX4 hovers until its battery is empty (offboard loss: holds "
        "(Position, Hold without RC) (COM_OBL_RC_ACT 0); battery: only warns (COM_LOW_BAT_ACT 0)): set "
        "COM_OBL_RC_ACT=3 (Return) or COM_LOW_BAT_ACT=3 (Return at critical charge)"]
    commands = [(m.command, m.param7) for m in ours(read_tlog(tmp_path / "flight.tlog"), "COMMAND_LONG")]
    kinds = [c[0] for c in commands]
    assert mavlink.MAV_CMD_DO_SET_MODE not in kinds[:kinds.index(mavlink.MAV_CMD_COMPONENT_ARM_DISARM)]
    takeoff = commands[kinds.index(mavlink.MAV_CMD_NAV_TAKEOFF)]
    assert takeoff[1] == pytest.approx(small_mission().launch_point.alt_m + small_mission().flight.altitude_m, abs=0.01)


def test_an_autopilot_that_comes_home_without_the_companion_gets_no_warning(policy):
    report = fly(policy, "px4", params={"COM_LOW_BAT_ACT": 3})
    assert report["companion_loss"] == {
        "checked": True, "ends_the_flight": True, "params": {"COM_OBL_RC_ACT": 0, "COM_LOW_BAT_ACT": 3},
        "steps": ["offboard loss: holds (Position, Hold without RC) (COM_OBL_RC_ACT 0)",
                  "battery: returns home at critical charge, lands at emergency (COM_LOW_BAT_ACT 3)"]}
    assert not [w for w in events(report, "warning") if "goes silent" in w]


@pytest.mark.parametrize("guid_timeout_s", [1.0, 3.0, 5.0])  # 3 s: ArduPilot's default
def test_ardupilot_stops_in_guided_during_a_ten_second_outage_and_the_search_carries_on(policy, guid_timeout_s):
    report = fly(policy, "ardupilot", faults="outage=20:10", params={"GUID_TIMEOUT": guid_timeout_s})
    assert events(report, "link") == ["no telemetry for 1 s: holding position",
                                      "telemetry lost for 3.0 s: waiting up to 60 s for it to come back"]
    assert events(report, "resume") == [] and report["failsafes"] == []  # GUID_TIMEOUT: no mode change
    assert searched_to_its_own_end(report) and report["outcome"]["outcome"] == "completed"
    assert report["outcome"]["longest_offboard_setpoint_gap_s"] > 9.0  # it really flew without setpoints


def test_ardupilots_gcs_failsafe_rtl_is_resumed_from(policy):
    """With the companion computer as ArduPilot's GCS (SYSID_MYGCS = its system id, 1) and the GCS failsafe on, an
    outage longer than FS_GCS_TIMEOUT (5 s) makes the vehicle return; the runner takes it back into GUIDED."""
    report = fly(policy, "ardupilot", faults="outage=20:10", params={"FS_GCS_ENABLE": 1, "SYSID_MYGCS": 1})
    assert [f["reason"] for f in report["outcome"]["vehicle_failsafes"]] == ["GCS Failsafe"]
    (resume,) = events(report, "resume")
    assert resume.startswith("the vehicle's link-loss failsafe switched it to RTL (the link was lost for 10.1 s")
    assert states(report)[5:8] == ["SEARCH", "OFFBOARD", "SEARCH"] and searched_to_its_own_end(report)
    assert report["outcome"]["outcome"] == "completed"


# ---------------------------------------------------------------------------------------- the autopilot's fence
def outbound(policy: Policy) -> Policy:
    """The artifact made to head north at full speed (TrackObject at every decision), whatever it learned."""
    return dataclasses.replace(
        with_actions(policy, lambda obs: torch.tensor([[1.0, 0.0, 1.0, 0.0]]).expand(obs.shape[0], 4).contiguous()),
        _select_goal=lambda meta_obs: torch.full((meta_obs.shape[0],), TRACK_OBJECT, dtype=torch.int64))


@pytest.mark.parametrize("autopilot, fence, mode, quoted, text", [
    # the STATUSTEXT the runner quotes (the last safety text), then the vehicle's log line of its failsafe
    ("px4", {"GF_MAX_HOR_DIST": 150.0}, "LOITER", "Geofence: exceeding maximum distance to Home",
     "Failsafe: geofence breached, switching to HOLD"),
    # GF_ACTION 3 (Return) holds COM_FAIL_ACT_T first: the runner's RTL in that Hold takes over, nothing else comes
    ("px4", {"GF_ACTION": 3, "GF_MAX_HOR_DIST": 150.0}, "LOITER", "Failsafe activated, entering Hold for 5 seconds\t",
     "Failsafe: geofence breached, holding 5 s before RTL"),
    ("ardupilot", {"FENCE_ENABLE": 1, "FENCE_RADIUS": 150.0}, "RTL", "Circle fence breached", "Circle fence breached")])
def test_the_autopilots_own_geofence_ends_the_search_and_is_never_resumed_over(policy, monkeypatch, autopilot, fence,
                                                                               mode, quoted, text):
    """The ground station tightens the autopilot's fence to 150 m during the search (the runner's preflight would
    refuse such a fence), inside the mission's area, so the runner's guard does not act first. The runner must not
    take the vehicle back into OFFBOARD / GUIDED as it does after a link-loss failsafe (it did: any STATUSTEXT with
    "failsafe" in it counted as link-loss evidence), and it brings the vehicle home."""
    name = list(fence)[-1]
    params = {**fence, name: 0.0} if autopilot == "px4" else {**fence, name: 1000.0}  # wide at the preflight
    kind = mavlink.MAV_PARAM_TYPE_REAL32

    def tighten(gcs):
        return gcs.param_set_encode(1, 1, name.encode(), fence[name], kind)

    monkeypatch.setattr(replay_module, "apply_faults",
                        lambda links, faults, clock, seed: [PilotAtTheGroundStation(links[0], clock, 30.0, tighten)])
    report = fly(outbound(policy), autopilot, params=params)
    assert report["link_packets"] == {"pilot_commands": 1}
    assert events(report, "resume") == [] and report["resumptions"] == 0
    (failsafe,) = events(report, "failsafe")
    companion = "OFFBOARD" if autopilot == "px4" else "GUIDED"
    assert failsafe.startswith(f"the vehicle left {companion} (now {mode}): the autopilot's own failsafe (")
    assert failsafe.endswith(f"({quoted!r})")
    assert report["search_end"] == f"vehicle switched to {mode}" and states(report)[-3:] == ["RTL", "LAND", "DONE"]
    assert [f["reason"] for f in report["outcome"]["vehicle_failsafes"]] == [text]
    assert report["outcome"]["outcome"] == "safe" and report["outcome"]["vehicle_end"] == "landed and disarmed"
    assert report["outcome"]["max_fence_excursion_m"] == 0.0


# ---------------------------------------------------------------------------------------- one time base
@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_a_vehicle_booted_ten_minutes_before_the_runner_is_flown_on_the_runners_clock(policy, autopilot):
    report = fly(policy, autopilot, boot_time_s=600.0)
    assert report["vehicle_time"]["offset_s"] == pytest.approx(-600.0, abs=0.02)
    assert report["vehicle_time"]["timeline_changes"] == 0 and report["estimator"]["reinitialisations"] == 0
    assert report["outcome"]["outcome"] == "completed" and searched_to_its_own_end(report)
    # the pose the policy got moves on every step (no prediction skipped): consecutive decisions at 1 s apart
    path = report["trajectory"]
    assert len(path) >= 30 and all(b[0] - a[0] == pytest.approx(1.0, abs=0.02) for a, b in zip(path[2:], path[3:]))


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_a_reboot_in_the_air_ends_the_search_without_acting_on_an_extrapolated_pose(policy, autopilot):
    """The autopilot reboots 10 s into the search and is silent for 20 s; it falls (motors off). The runner holds,
    never decides or guards on the pose extrapolated over the gap, and ends the search on the disarmed vehicle.
    The policy is made to head for the search area (TrackObject, full speed towards its point), so that the fall
    happens away from home whatever the shipped policy would do there."""
    outbound = dataclasses.replace(
        with_actions(policy, lambda obs: torch.tensor([[1.0, 0.0, 1.0, 0.0]]).expand(obs.shape[0], 4).contiguous()),
        _select_goal=lambda meta_obs: torch.full((meta_obs.shape[0],), TRACK_OBJECT, dtype=torch.int64))
    report = fly(outbound, autopilot, boot_time_s=600.0, reboot_at_s=27.0, reboot_downtime_s=20.0)
    assert report["search_end"] == "vehicle disarmed" and states(report)[-2:] == ["SEARCH", "DONE"]
    assert events(report, "failsafe") == ["the vehicle is disarmed"]
    assert events(report, "geofence") == []
    path = report["trajectory"]
    assert all(b[0] < 27.0 + 1.05 for b in path)  # no decision once the link has been silent for gap_s (1 s)
    steps = [math.dist(a[1:], b[1:]) for a, b in zip(path, path[1:])]
    assert max(steps) <= small_mission().flight.max_speed_mps * 1.2
    assert report["outcome"]["outcome"] == "ditched"  # a reboot in the air is the loss of the drone


def test_a_reboot_on_the_ground_before_arming_restarts_the_estimate_and_the_mission_flies(policy):
    report = fly(policy, "px4", boot_time_s=600.0, reboot_at_s=0.5, reboot_downtime_s=5.0)
    change = report["vehicle_time"]["last_change"]
    assert report["vehicle_time"]["timeline_changes"] == 1 and change.startswith("vehicle rebooted: time_boot_ms 600.")
    assert report["estimator"]["reinitialisations"] == 1
    assert states(report) == ALL_STATES and report["outcome"]["outcome"] == "completed"


# ---------------------------------------------------------------------------------------- telemetry rates
@pytest.mark.parametrize("autopilot, profile", [("px4", "px4"), ("px4", "px4_sitl"), ("ardupilot", "ardupilot")])
def test_the_runner_flies_with_each_autopilots_default_telemetry_rates(policy, autopilot, profile, tmp_path):
    """PX4's onboard-mode rates on the companion link (GLOBAL_POSITION_INT 50 Hz, LOCAL_POSITION_NED 30 Hz), PX4
    SITL's, and ArduPilot's (nothing streams until the runner asks): the same mission flies to its own end."""
    report = fly(policy, autopilot, tmp_path=tmp_path, telemetry_profile=profile)
    assert report["outcome"]["outcome"] == "completed" and searched_to_its_own_end(report)
    assert report["failsafes"] == [] and report["estimator"]["reinitialisations"] == 0
    positions = [m for m in read_tlog(tmp_path / "flight.tlog") if m.get_type() == "GLOBAL_POSITION_INT"]
    rate_hz = (len(positions) - 1) / ((positions[-1].time_boot_ms - positions[0].time_boot_ms) / 1000.0)
    expected = {"px4": 50.0, "px4_sitl": 50.0, "ardupilot": None}[profile]  # ArduPilot: what the runner asked for
    if expected is not None:
        assert rate_hz == pytest.approx(expected, rel=0.1)
    else:
        assert rate_hz >= 4.0  # streams were requested: without, ArduPilot sends no positions at all


AT_THE_FENCE = "the autopilot's own failsafe ('{} 150 m reached: 1"


@pytest.mark.parametrize("autopilot, fence, outage, mode, why", [
    ("px4", {"GF_MAX_HOR_DIST": 150.0}, "outage=35.5:3.5", "LOITER", ": " + AT_THE_FENCE.format("GF_MAX_HOR_DIST")),
    ("ardupilot", {"FS_GCS_ENABLE": 1, "FENCE_ENABLE": 1, "FENCE_RADIUS": 150.0}, "outage=30.1:3.5", "RTL",
     ": " + AT_THE_FENCE.format("FENCE_RADIUS")),
    ("ardupilot", {"FENCE_ENABLE": 1, "FENCE_RADIUS": 150.0}, "outage=29.5:3.5", "RTL",
     "; not its link-loss failsafe (FS_GCS_ENABLE 0 does not switch to RTL)")])
def test_a_geofence_failsafe_whose_text_was_lost_in_an_outage_is_still_not_resumed_over(
        policy, monkeypatch, autopilot, fence, outage, mode, why):
    """As above, but a two-way outage swallows the breach's STATUSTEXT (and, from 29.5 s, the PARAM_VALUE of the new
    fence): the silence reads as link-loss evidence. The runner reads the parameters again while it settles the
    switch and ends the search: the drone was at the autopilot's fence, or (ArduPilot's default FS_GCS_ENABLE 0) the
    vehicle's link-loss failsafe does not switch modes at all."""
    name = list(fence)[-1]
    params = {**fence, name: 0.0} if autopilot == "px4" else {**fence, name: 1000.0}

    def tighten(gcs):
        return gcs.param_set_encode(1, 1, name.encode(), fence[name], mavlink.MAV_PARAM_TYPE_REAL32)

    faulty = replay_module.apply_faults
    monkeypatch.setattr(replay_module, "apply_faults", lambda links, faults, clock, seed: [
        PilotAtTheGroundStation(faulty(links, faults, clock, seed)[0], clock, 30.0, tighten)])
    report = fly(outbound(policy), autopilot, faults=outage, params=params)
    assert report["link_packets"] == {"pilot_commands": 1}
    assert "no telemetry for 1 s: holding position" in events(report, "link")  # the outage
    assert events(report, "resume") == [] and report["resumptions"] == 0
    (failsafe,) = events(report, "failsafe")
    companion = "OFFBOARD" if autopilot == "px4" else "GUIDED"
    assert failsafe.startswith(f"the vehicle left {companion} (now {mode}){why}"), failsafe
    assert report["search_end"] == f"vehicle switched to {mode}" and states(report)[-3:] == ["RTL", "LAND", "DONE"]
    assert report["outcome"]["outcome"] == "safe" and report["outcome"]["vehicle_end"] == "landed and disarmed"
