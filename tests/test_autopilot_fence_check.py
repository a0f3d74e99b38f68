"""The runner's preflight check of the autopilot's own geofence (autonomy/autopilot_fence.py): the parameters read
from the simulated PX4 and ArduPilot over the in-memory link, the judgement, the refusal and the warning."""
from __future__ import annotations

import pytest
from runner_helpers import small_mission
from test_runner_autopilots import events, fly, outbound, states

from autonomy.autopilot_fence import fence_conflicts, judge_autopilot_fence, read_fence
from autonomy.preflight import judge_autopilot_settings
from autonomy.vehicle_link import VehicleLink

HOME = small_mission().launch_point
PX4_FENCE = {"GF_ACTION": 2, "GF_MAX_HOR_DIST": 0.0, "GF_MAX_VER_DIST": 0.0}
COPTER_FENCE = {"FENCE_ENABLE": 1, "FENCE_TYPE": 7, "FENCE_ACTION": 1, "FENCE_RADIUS": 300.0,
                "FENCE_ALT_MAX": 100.0, "FENCE_ALT_MIN": -10.0}


def test_what_each_autopilots_parameters_mean():
    px4 = read_fence("PX4", {**PX4_FENCE, "GF_MAX_HOR_DIST": 800.0})
    assert (px4.radius_m, px4.ceiling_m, px4.floor_m, px4.acts) == (800.0, None, None, True)
    assert px4.describe() == "GF_MAX_HOR_DIST 800 m, on a breach: Hold"
    assert not read_fence("PX4", {**PX4_FENCE, "GF_ACTION": 1}).acts  # a warning changes nothing
    copter = read_fence("ArduPilot Copter", {**COPTER_FENCE, "FENCE_TYPE": 15})
    assert (copter.radius_m, copter.ceiling_m, copter.floor_m, copter.acts) == (300.0, 100.0, -10.0, True)
    off = read_fence("ArduPilot Copter", {**COPTER_FENCE, "FENCE_ENABLE": 0})
    assert (off.radius_m, off.ceiling_m, off.acts) == (None, None, False)
    assert not read_fence("ArduPilot Copter", {**COPTER_FENCE, "FENCE_ACTION": 0}).acts  # report only


def test_conflicts_name_the_parameter_and_the_value_that_fits():
    mission = small_mission()  # area north -100..500, east -300..300 from the launch point; 20 m; guard margin 20
    short = read_fence("ArduPilot Copter", COPTER_FENCE)
    (problem,) = fence_conflicts(short, mission, HOME, 20.0)
    assert problem == ("FENCE_RADIUS 300 m is short of the search: the drone may fly 556 m from home; set it to at "
                       "least 590 m (the mission's geofence)")
    assert fence_conflicts(read_fence("ArduPilot Copter", {**COPTER_FENCE, "FENCE_RADIUS": 560.0}), mission, HOME,
                           20.0) == []
    low = read_fence("PX4", {**PX4_FENCE, "GF_MAX_VER_DIST": 22.0})
    assert fence_conflicts(low, mission, HOME, 20.0) == [
        "GF_MAX_VER_DIST 22 m is too low for the search altitude 20 m; set it to at least 25 m"]
    floor = read_fence("ArduPilot Copter", {**COPTER_FENCE, "FENCE_TYPE": 8, "FENCE_ALT_MIN": 18.0})
    assert fence_conflicts(floor, mission, HOME, 20.0) == [
        "FENCE_ALT_MIN 18 m is too high for the close looks down to 20 m; set it to at most 15 m"]
    warned = read_fence("PX4", {**PX4_FENCE, "GF_ACTION": 1, "GF_MAX_HOR_DIST": 100.0})
    assert fence_conflicts(warned, mission, HOME, 20.0) == []  # it only warns: nothing stops the search


def test_a_missing_fence_is_a_warning_with_the_setting_that_would_add_it():
    record, refusal, note = judge_autopilot_fence("PX4", PX4_FENCE, small_mission(), HOME, 20.0)
    assert refusal is None and record == {"checked": True, "acts": False,
                                          "description": "no limit set, on a breach: Hold"}
    assert note == ("the autopilot's own geofence does not act (no limit set, on a breach: Hold): only the runner's "
                    "guard keeps the drone in the mission's area; GF_MAX_HOR_DIST=590 (GF_ACTION 2: Hold) would add "
                    "the autopilot's fence around it")


def test_judging_the_settings_skips_what_was_not_read_and_stops_at_a_refusal():
    """autonomy.preflight.judge_autopilot_settings, as the runner calls it with the parameters that arrived."""
    mission, failsafes = small_mission(), {"COM_OBL_RC_ACT": 3, "COM_LOW_BAT_ACT": 0}
    nothing = judge_autopilot_settings("PX4", {}, mission, HOME, 20.0, 1, 5.0)
    assert (nothing.autopilot_fence, nothing.companion_loss, nothing.refusal) == (
        {"checked": False, "reason": "its parameters were not read"},
        {"checked": False, "reason": "its parameters were not read"}, None)
    assert nothing.events == [
        ("autopilot-fence", "not checked (its parameters were not read within 5 s)"),
        ("warning", "what the autopilot does if this computer goes silent is not known: its failsafe parameters "
                    "were not read")]
    fine = judge_autopilot_settings("PX4", {**PX4_FENCE, "GF_MAX_HOR_DIST": 800.0, **failsafes}, mission, HOME, 20.0,
                                    1, 5.0)
    assert fine.refusal is None and fine.companion_loss["ends_the_flight"] is True
    assert [kind for kind, _ in fine.events] == ["autopilot-fence"]  # Return on offboard loss: no warning
    short = judge_autopilot_settings("PX4", {**PX4_FENCE, "GF_MAX_HOR_DIST": 400.0, **failsafes}, mission, HOME, 20.0,
                                     1, 5.0)
    assert short.refusal.startswith("refused before arming: the autopilot's own geofence would stop the search: "
                                    "GF_MAX_HOR_DIST 400 m is short of the search")
    assert short.companion_loss is None and short.events == []


@pytest.mark.parametrize("autopilot, params, refusal", [
    ("px4", {"GF_MAX_HOR_DIST": 400.0}, "GF_MAX_HOR_DIST 400 m is short of the search"),
    ("ardupilot", {"FENCE_ENABLE": 1}, "FENCE_RADIUS 300 m is short of the search")])
def test_the_runner_reads_the_vehicles_fence_and_refuses_one_that_would_stop_the_search(policy, autopilot, params,
                                                                                        refusal):
    report = fly(policy, autopilot, params=params)
    (abort,) = events(report, "abort")
    assert abort.startswith("refused before arming: the autopilot's own geofence would stop the search: " + refusal)
    assert states(report) == ["CONNECT", "PREFLIGHT", "DONE"] and not report["trajectory"]


@pytest.mark.parametrize("autopilot, params, description", [
    ("px4", {"GF_MAX_HOR_DIST": 600.0, "GF_MAX_VER_DIST": 120.0},
     "GF_MAX_HOR_DIST 600 m, GF_MAX_VER_DIST 120 m, on a breach: Hold"),
    ("ardupilot", {"FENCE_ENABLE": 1, "FENCE_RADIUS": 600.0},
     "FENCE_RADIUS 600 m, FENCE_ALT_MAX 100 m, on a breach: RTL or Land")])
def test_a_fence_that_encloses_the_mission_is_recorded_and_flown(policy, autopilot, params, description):
    report = fly(outbound(policy), autopilot, params=params)
    assert report["autopilot_fence"] == {"checked": True, "acts": True, "description": description}
    assert events(report, "autopilot-fence") == [description]
    assert report["outcome"]["outcome"] == "completed" and report["outcome"]["vehicle_failsafes"] == []


def test_without_answers_the_fence_is_not_checked_and_the_flight_goes_on(policy, monkeypatch):
    monkeypatch.setattr(VehicleLink, "request_params", lambda self, names: None)
    report = fly(policy, "px4")
    unread = {"checked": False, "reason": "its parameters were not read"}
    assert report["autopilot_fence"] == report["companion_loss"] == unread
    assert events(report, "autopilot-fence") == ["not checked (its parameters were not read within 5 s)"]
    assert "what the autopilot does if this computer goes silent is not known: its failsafe parameters were not " \
           "read" in events(report, "warning")
    assert report["outcome"]["outcome"] == "completed"


def test_fence_reached_names_the_limit_the_drone_is_at_and_only_for_a_fence_that_acts():
    from autonomy.autopilot_fence import fence_reached
    px4 = {"GF_ACTION": 2, "GF_MAX_HOR_DIST": 300.0, "GF_MAX_VER_DIST": 120.0}
    assert fence_reached("PX4", px4, 190.0, 230.0, 50.0) == "GF_MAX_HOR_DIST 300 m reached: 298 m from home"
    assert fence_reached("PX4", px4, 180.0, 220.0, 50.0) is None  # 284 m: more than 5 m inside
    assert fence_reached("PX4", px4, 0.0, 0.0, 118.5) == "GF_MAX_VER_DIST 120 m reached: 118 m above home"
    assert fence_reached("PX4", {**px4, "GF_ACTION": 1}, 190.0, 230.0, 50.0) is None  # warns only
    assert fence_reached("PX4", {"GF_ACTION": 2}, 190.0, 230.0, 50.0) is None  # not read yet
    copter = {"FENCE_ENABLE": 1, "FENCE_TYPE": 15, "FENCE_ACTION": 1, "FENCE_RADIUS": 300.0, "FENCE_ALT_MAX": 100.0,
              "FENCE_ALT_MIN": 10.0}
    assert fence_reached("ArduPilot Copter", copter, 0.0, 10.0, 11.5) == "FENCE_ALT_MIN 10 m reached: 12 m above home"
    assert fence_reached("ArduPilot Copter", {**copter, "FENCE_ENABLE": 0}, 0.0, 299.0, 11.5) is None


def test_the_link_loss_modes_follow_the_autopilots_failsafe_parameter():
    from autonomy.autopilots import ARDUPILOT_COPTER, PX4, link_loss_modes
    assert link_loss_modes(PX4, {}) == PX4.failsafe_modes  # not read: any failsafe mode
    assert link_loss_modes(PX4, {"COM_OBL_RC_ACT": 0.0}) == {"POSCTL", "LOITER"}  # Position, or Hold without RC
    assert link_loss_modes(PX4, {"COM_OBL_RC_ACT": 4.0}) == {"LAND"}
    assert link_loss_modes(ARDUPILOT_COPTER, {"FS_GCS_ENABLE": 0.0}) == frozenset()  # GUIDED just stops
    assert link_loss_modes(ARDUPILOT_COPTER, {"FS_GCS_ENABLE": 7.0}) == {"BRAKE", "LAND"}
