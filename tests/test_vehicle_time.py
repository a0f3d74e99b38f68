"""One time base: the vehicle's time_boot_ms mapped onto the runner's clock (autonomy.vehicle_time).

Regression of the second defect of the flight-side issue: the estimator was stamped with time_boot_ms but predicted
to the runner's clock. Against an autopilot that booted minutes before the runner the prediction was silently
skipped; after a reboot the pose was extrapolated over the whole gap. The telemetry here is real pymavlink
GLOBAL_POSITION_INT messages (encoded and decoded), fed through the runner's own receive path pieces.
"""
from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from autonomy.estimator import PoseEstimator
from autonomy.vehicle_time import BootTimeConfig, BootTimeMap
from missions.geodesy import GeoPoint, LocalFrame

HOME = GeoPoint(47.397742, 8.545594, 488.0)
FRAME = LocalFrame(HOME)
SPEED_MPS = 8.0


def position_message(time_boot_ms: int, north_m: float, vn_mps: float = SPEED_MPS):
    """A GLOBAL_POSITION_INT as an autopilot sends it (through the encoder and decoder)."""
    lat, lon, alt = FRAME.to_geodetic(north_m, 0.0, -50.0)
    msg = mavlink.MAVLink_global_position_int_message(
        time_boot_ms, int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)), 50_000,
        int(round(vn_mps * 100)), 0, 0, 65535)
    codec = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    return codec.decode(bytearray(msg.pack(codec)))


def fly_straight(estimator: PoseEstimator, boot_time: BootTimeMap | None, boot_start_s: float, runner_start_s: float,
                 seconds: float, latency_s: float = 0.03, north_start_m: float = 0.0) -> float:
    """10 Hz telemetry of a vehicle flying north at SPEED_MPS; returns the runner time of the last arrival."""
    arrival = runner_start_s
    for i in range(int(seconds * 10)):
        boot_s, arrival = boot_start_s + i / 10, runner_start_s + i / 10 + latency_s
        msg = position_message(int(round(boot_s * 1000)), north_start_m + SPEED_MPS * i / 10)
        if boot_time is None:  # the old way: stamped with time_boot_ms
            estimator.update_global_position_int(msg)
            continue
        time_s = boot_time.to_runner_time(msg.time_boot_ms, arrival)
        if time_s is not None:
            if boot_time.timeline_changed:
                boot_time.timeline_changed = False
                estimator.restart(boot_time.last_change)
            estimator.update_global_position_int(msg, time_s)
    return arrival


def test_a_vehicle_booted_ten_minutes_before_the_runner_is_predicted_to_the_runners_clock():
    estimator, boot_time = PoseEstimator(home=HOME), BootTimeMap()
    last = fly_straight(estimator, boot_time, boot_start_s=600.0, runner_start_s=2.0, seconds=5.0)
    # The runner asks for the pose 0.2 s after the last message arrived: predicted 0.2 s on (the constant 0.03 s
    # latency is part of the offset: a one-way map cannot see it, and 0.24 m at 8 m/s does not matter).
    measured_north = SPEED_MPS * 4.9
    predicted = estimator.predict_to(last + 0.2).position_ned[0]
    assert predicted == pytest.approx(measured_north + SPEED_MPS * 0.2, abs=0.15)
    assert boot_time.offset_s == pytest.approx(2.0 - 600.0 + 0.03, abs=1e-6)


def test_the_old_stamping_skipped_the_prediction_for_such_a_vehicle():
    """What the defect did: the same flight stamped with time_boot_ms, predicted to the runner's clock."""
    estimator = PoseEstimator(home=HOME)
    last = fly_straight(estimator, None, boot_start_s=600.0, runner_start_s=2.0, seconds=5.0)
    assert estimator.predict_to(last + 0.2).position_ned[0] == pytest.approx(SPEED_MPS * 4.9, abs=0.15)  # no 1.8 m


def test_after_a_reboot_the_pose_restarts_from_the_new_timeline_instead_of_extrapolating_the_gap():
    estimator, boot_time = PoseEstimator(home=HOME), BootTimeMap()
    fly_straight(estimator, boot_time, boot_start_s=600.0, runner_start_s=0.0, seconds=20.0)
    # 20 s of silence, then the autopilot is back with time_boot_ms near 0, the vehicle 100 m farther north.
    last = fly_straight(estimator, boot_time, boot_start_s=0.5, runner_start_s=40.0, seconds=2.0,
                        north_start_m=SPEED_MPS * 20.0 - 60.0)
    assert boot_time.timeline_changes == 1 and boot_time.last_change.startswith("vehicle rebooted: time_boot_ms")
    assert boot_time.ignored == 2  # the first two messages of the new timeline wait for the third
    assert estimator.reinitialisations == 1 and estimator.last_reinit_reason == boot_time.last_change
    north = estimator.predict_to(last).position_ned[0]
    newest = SPEED_MPS * 20.0 - 60.0 + SPEED_MPS * 1.9
    assert north == pytest.approx(newest + SPEED_MPS * 0.03, abs=0.5)  # not extrapolated over the 20 s gap


def test_the_old_stamping_extrapolated_the_reboot_gap():
    estimator = PoseEstimator(home=HOME)
    fly_straight(estimator, None, boot_start_s=0.0, runner_start_s=0.0, seconds=20.0)
    fly_straight(estimator, None, boot_start_s=0.0, runner_start_s=40.0, seconds=2.0, north_start_m=100.0)
    north = estimator.predict_to(41.93).position_ned[0]  # the runner's clock: 40 s in
    assert north > 100.0 + SPEED_MPS * 1.9 + 100.0  # well over 100 m beyond where the vehicle is


def test_one_corrupted_stamp_does_not_move_the_clock():
    boot_time = BootTimeMap()
    for i in range(10):
        boot_time.to_runner_time(100_000 + 100 * i, 5.0 + i / 10)
    offset = boot_time.offset_s
    assert boot_time.to_runner_time(900_000, 6.0) is None  # a stamp 800 s in the future
    assert boot_time.to_runner_time(2_000, 6.1) is None  # one far in the past
    assert boot_time.to_runner_time(101_100, 6.1) == pytest.approx(6.1)
    assert boot_time.offset_s == offset and boot_time.timeline_changes == 0


def test_late_messages_keep_the_offset_and_faster_ones_lower_it():
    boot_time = BootTimeMap()
    assert boot_time.to_runner_time(10_000, 1.05) == pytest.approx(1.05)  # first: latency unknown, taken as 0
    # 0.25 s late: still 1.15 (give or take the drift allowance, 200 ppm of 0.35 s)
    assert boot_time.to_runner_time(10_100, 1.40) == pytest.approx(1.15, abs=1e-4)
    assert boot_time.to_runner_time(10_200, 1.21) == pytest.approx(1.21)  # 0.04 s faster than the first
    assert boot_time.offset_s == pytest.approx(1.21 - 10.2)


def test_a_slow_vehicle_clock_is_followed_within_the_drift_allowance():
    boot_time = BootTimeMap(BootTimeConfig(drift_ppm=200.0))
    # The vehicle's clock runs 100 ppm slow: over an hour its stamps fall 0.36 s behind.
    for minute in range(61):
        runner_s = minute * 60.0
        boot_time.to_runner_time(int(round(runner_s * (1 - 100e-6) * 1000)), runner_s)
    assert boot_time.offset_s == pytest.approx(3600.0 * 100e-6, abs=0.002)
    assert boot_time.timeline_changes == 0


def test_a_forward_jump_of_the_vehicle_clock_is_adopted_after_three_messages():
    boot_time = BootTimeMap()
    for i in range(5):
        boot_time.to_runner_time(1_000 + 100 * i, 10.0 + i / 10)
    results = [boot_time.to_runner_time(60_000 + 100 * i, 10.5 + i / 10) for i in range(4)]
    assert results[:2] == [None, None] and results[2] == pytest.approx(10.7) and results[3] == pytest.approx(10.8)
    assert boot_time.last_change == "vehicle clock jumped: time_boot_ms 1.4 s -> 60.2 s"


@pytest.mark.parametrize("field, value", [("drift_ppm", -1.0), ("jump_tolerance_s", 0.0), ("confirm_messages", 0)])
def test_bad_settings_are_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"BootTimeConfig.{field}"):
        BootTimeConfig(**{field: value})
    assert math.isfinite(BootTimeConfig().drift_ppm)
