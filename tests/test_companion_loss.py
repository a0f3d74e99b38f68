"""autonomy.companion_loss: what each autopilot's parameters make it do if the companion computer goes silent."""
from __future__ import annotations

import pytest

from autonomy.companion_loss import (ARDUPILOT_BATTERY, ARDUPILOT_REQUIRED, companion_loss_params,
                                     judge_companion_loss)

ARDUPILOT_DEFAULTS = {"FS_GCS_ENABLE": 0, "SYSID_MYGCS": 255, "BATT_MONITOR": 4, "BATT_FS_LOW_ACT": 0,
                      "BATT_LOW_VOLT": 10.5, "BATT_LOW_MAH": 0, "BATT_FS_CRT_ACT": 0, "BATT_CRT_VOLT": 0,
                      "BATT_CRT_MAH": 0}


@pytest.mark.parametrize("obl, battery, ends", [
    (0, 0, False), (5, 0, False), (1, 0, False), (6, 0, False),  # holds, or falls (Terminate): not an end
    (3, 0, True), (4, 0, True), (0, 2, True), (0, 3, True), (5, 3, True)])
def test_px4_ends_the_flight_by_itself_with_return_or_land_on_offboard_loss_or_a_battery_action(obl, battery, ends):
    record, warning = judge_companion_loss("PX4", {"COM_OBL_RC_ACT": obl, "COM_LOW_BAT_ACT": battery}, 1)
    assert record["ends_the_flight"] is ends and (warning is None) is ends
    if warning:
        assert warning.endswith("set COM_OBL_RC_ACT=3 (Return) or COM_LOW_BAT_ACT=3 (Return at critical charge)")


@pytest.mark.parametrize("changes, companion, ends", [
    ({}, 1, False),
    ({"FS_GCS_ENABLE": 1}, 1, False),  # SYSID_MYGCS is the ground station (255), not this computer
    ({"FS_GCS_ENABLE": 1, "SYSID_MYGCS": 1}, 1, True),
    ({"FS_GCS_ENABLE": 1, "SYSID_MYGCS": 1}, None, False),  # this computer's id unknown (MAVSDK): not counted
    ({"BATT_FS_LOW_ACT": 2}, 1, True),  # RTL at BATT_LOW_VOLT 10.5 V
    ({"BATT_FS_LOW_ACT": 2, "BATT_LOW_VOLT": 0}, 1, False),  # an action without a threshold never fires
    ({"BATT_FS_CRT_ACT": 1, "BATT_CRT_MAH": 500}, 1, True),
    ({"BATT_FS_LOW_ACT": 5}, 1, False)])  # Terminate: it falls
def test_ardupilot_ends_it_with_its_gcs_failsafe_on_this_computer_or_an_armed_battery_failsafe(changes, companion,
                                                                                              ends):
    record, warning = judge_companion_loss("ArduPilot Copter", {**ARDUPILOT_DEFAULTS, **changes}, companion)
    assert record["ends_the_flight"] is ends and (warning is None) is ends


def test_an_ardupilot_without_a_battery_monitor_has_no_battery_failsafe():
    """BATT_MONITOR 0 hides every other BATT_* parameter: only the GCS failsafe is left, even if stale BATT_* values
    (read before the monitor was switched off) would act."""
    gcs_only = {"FS_GCS_ENABLE": 0, "SYSID_MYGCS": 255, "BATT_MONITOR": 0}
    record, warning = judge_companion_loss("ArduPilot Copter", gcs_only, 1)
    assert not record["ends_the_flight"] and "low battery: nothing (no battery monitor)" in warning
    record, warning = judge_companion_loss("ArduPilot Copter", {**ARDUPILOT_DEFAULTS, "BATT_FS_LOW_ACT": 2,
                                                                "BATT_MONITOR": 0}, 1)
    assert not record["ends_the_flight"]
    record, warning = judge_companion_loss("ArduPilot Copter", {"FS_GCS_ENABLE": 2, "SYSID_MYGCS": 1,
                                                                "BATT_MONITOR": 0}, 1)
    assert record["ends_the_flight"] and warning is None


@pytest.mark.parametrize("read, wanted", [
    (None, ARDUPILOT_REQUIRED + ARDUPILOT_BATTERY),  # before anything is read: all that may exist
    ({}, ARDUPILOT_REQUIRED),  # BATT_MONITOR not read yet: wait for it first
    ({"BATT_MONITOR": 0}, ARDUPILOT_REQUIRED),  # hidden: not waited for
    ({"BATT_MONITOR": 4}, ARDUPILOT_REQUIRED + ARDUPILOT_BATTERY)])
def test_ardupilots_battery_parameters_are_wanted_only_once_a_battery_monitor_is_known(read, wanted):
    assert companion_loss_params("ArduPilot Copter", read) == wanted
    assert companion_loss_params("PX4", read) == ("COM_OBL_RC_ACT", "COM_LOW_BAT_ACT")
