"""Property-based fuzzing of the two MAVLink receive paths (the vehicle's and the runner's), deterministic.

Random bytes and valid frames damaged by every mutation of ``benchmarks/fuzz.py`` (bit flips, truncation, lying
length bytes, wrong CRCs, unknown message ids, MAVLink 1/2 markers swapped, the signed flag with a garbage
signature, splices, valid frames with hostile field values) go to the real receive paths. Properties: nothing
escapes as an exception, the vehicle keeps its safety invariants (with a signing key, garbage never arms it,
changes its mode or its key; without, its state stays finite), the runner's pose estimate stays finite, and a
valid frame after the garbage is still decoded. The long run (>= 1,000,000 frames) is ``benchmarks/fuzz.py``.
"""
from __future__ import annotations

import math
import random
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import fuzz  # noqa: E402  (the fuzzing harness shared with the benchmark)
import fuzz_frames  # noqa: E402  (its frames and mutations)

from autonomy.vehicle_link import enum_name  # noqa: E402

FUZZ = settings(derandomize=True, deadline=None, max_examples=500,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
CORPUS = fuzz_frames.corpus(random.Random(0))
garbage_bytes = st.binary(min_size=1, max_size=300)


@st.composite
def mutated_frames(draw) -> bytes:
    """A corpus frame damaged by one mutation, all choices drawn by hypothesis (so failures shrink)."""
    rng = draw(st.randoms(use_true_random=False))
    kind = draw(st.sampled_from(fuzz_frames.MUTATIONS))
    return fuzz_frames.mutate(draw(st.sampled_from(CORPUS)), kind, rng, draw(st.sampled_from(CORPUS)))


garbage = st.one_of(garbage_bytes, mutated_frames())


def signed_by_the_owner(msg: mavlink.MAVLink_message) -> bytes:
    """``msg`` packed and signed with the targets' key (what the real ground station would send)."""
    return msg.pack(fuzz_frames.encoder(255, 190, fuzz.TARGET_KEY))


def param_values_sent(target: fuzz.VehicleTarget) -> list[str]:
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    messages = [m for chunk in target.client_end.receive() for m in parser.parse_buffer(chunk) or ()]
    return [m.param_id for m in messages if m.get_type() == "PARAM_VALUE"]


# ---------------------------------------------------------------------------------------------- the vehicle
@FUZZ
@given(chunks=st.lists(garbage, min_size=1, max_size=5), signed=st.booleans())
def test_vehicle_survives_garbage_and_still_answers_the_next_valid_frame(chunks, signed):
    target = fuzz.VehicleTarget(fuzz.TARGET_KEY if signed else None)
    for chunk in chunks:
        target.feed(chunk)  # an exception here fails the test: none may escape
    assert target.violations() == []
    target.client_end.receive()
    target.feed(signed_by_the_owner(mavlink.MAVLink_param_request_read_message(1, 1, b"MIS_TAKEOFF_ALT", -1)))
    assert param_values_sent(target) == ["MIS_TAKEOFF_ALT"]


@FUZZ
@given(chunks=st.lists(garbage, min_size=1, max_size=5))
def test_signed_vehicle_never_arms_or_changes_mode_from_garbage(chunks):
    target = fuzz.VehicleTarget(fuzz.TARGET_KEY)
    target.vehicle.run(1.0)  # a GPS fix: arming would be allowed to a signed command
    assert target.vehicle.autopilot.gps_ok
    for chunk in chunks:
        target.feed(chunk)
    target.vehicle.run(0.1)
    assert not target.vehicle.autopilot.armed and target.violations() == []
    assert target.vehicle.signing.accepted_signed == 0  # nothing the fuzzer made passed as signed


@FUZZ
@given(seed=st.integers(0, 2**32 - 1), autopilot=st.sampled_from(["px4", "ardupilot"]))
def test_vehicle_flies_hostile_commands_and_keeps_a_finite_state(seed, autopilot):
    rng = random.Random(seed)
    target = fuzz.VehicleTarget(None, autopilot=autopilot)
    target.vehicle.run(1.0)
    for _ in range(40):
        target.feed(fuzz_frames.hostile_frame(rng))
    target.vehicle.run(0.5)
    assert target.violations() == [] and target.vehicle.handler_errors == 0


def test_a_lying_length_byte_does_not_swallow_the_next_datagram():
    """Regression: a header claiming 255 payload bytes used to make the parser eat the next datagram too."""
    target = fuzz.VehicleTarget(None)
    target.feed(bytes([0xFD, 0xFF, 0, 0, 0, 255, 190, 0, 0, 0]))
    target.feed(signed_by_the_owner(mavlink.MAVLink_param_request_read_message(1, 1, b"MPC_XY_VEL_MAX", -1)))
    assert param_values_sent(target) == ["MPC_XY_VEL_MAX"] and target.endpoint.bad_frames == 1


# ---------------------------------------------------------------------------------------------- the runner
def vehicle_heartbeat(sequence: int, key: bytes | None = None) -> bytes:
    mav = fuzz_frames.encoder(1, 1, key)
    mav.seq = sequence % 256
    heartbeat = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 3, 3)
    return heartbeat.pack(mav)


@FUZZ
@given(chunks=st.lists(garbage, min_size=1, max_size=5), signed=st.booleans())
def test_runner_survives_garbage_and_resynchronises_on_valid_frames(chunks, signed):
    target = fuzz.RunnerTarget(fuzz.TARGET_KEY if signed else None)
    for chunk in chunks:
        target.feed(chunk)
    assert target.violations() == []
    # pymavlink parses a byte stream: a lying length may swallow the next frames, but never more than 280 bytes.
    for attempt in range(20):
        target.link.latest.pop("HEARTBEAT", None)
        target.feed(vehicle_heartbeat(attempt, fuzz.TARGET_KEY if signed else None))
        if "HEARTBEAT" in target.link.latest and target.link.target_system == 1:
            break
    else:
        pytest.fail("no valid HEARTBEAT decoded after 20 frames")


@FUZZ
@given(seed=st.integers(0, 2**32 - 1))
def test_runner_keeps_a_finite_estimate_under_hostile_telemetry(seed):
    rng = random.Random(seed)
    target = fuzz.RunnerTarget(None)
    target.feed(vehicle_heartbeat(0))
    mav = fuzz_frames.encoder(1, 1)
    for _ in range(30):
        kind = rng.choice(("GLOBAL_POSITION_INT", "HEARTBEAT", "HOME_POSITION", "SYS_STATUS", "COMMAND_ACK"))
        target.feed(fuzz_frames.hostile_message(rng, kind).pack(mav))
    assert target.violations() == []


@pytest.mark.parametrize("lat, lon, alt", [(2**31 - 1, 2**31 - 1, 2**31 - 1), (-2**31, -2**31, -2**31),
                                           (900_000_000, 1_800_000_000, 0)])
def test_extreme_global_positions_leave_the_estimate_finite(lat, lon, alt):
    target = fuzz.RunnerTarget(None)
    target.feed(vehicle_heartbeat(0))
    mav = fuzz_frames.encoder(1, 1)
    for step in range(5):
        target.feed(mavlink.MAVLink_global_position_int_message(step * 10, lat, lon, alt, alt, 32767, -32768,
                                                                32767, 65535).pack(mav))
    assert target.violations() == []
    if target.estimator.time_s is not None:
        assert all(math.isfinite(v) for v in target.estimator.position_ned)


def test_garbage_with_unknown_ids_and_hostile_chatter_keeps_memory_bounded():
    """Regression (found by the fuzzer's slowing frame rate): any frame with an unknown message id is "decoded" without
    a CRC check, and the vehicle's counters, the link's latest messages and pymavlink's own per-type and parameter
    stores kept one entry per id or parameter name."""
    vehicle, runner = fuzz.VehicleTarget(None), fuzz.RunnerTarget(fuzz.TARGET_KEY)
    runner.feed(vehicle_heartbeat(0))
    mav = fuzz_frames.encoder(1, 1)
    for index in range(1500):
        unknown = bytes([0xFD, 1, 0, 0, index % 256, 1, 1]) + (100_000 + index).to_bytes(3, "little") + bytes(3)
        vehicle.feed(unknown)
        runner.feed(unknown)
        runner.feed(mavlink.MAVLink_param_value_message(f"P{index}".encode(), 1.0, 9, 1500, index).pack(mav))
        runner.feed(mavlink.MAVLink_statustext_message(6, f"text {index}".encode()).pack(mav))
    assert vehicle.vehicle.unhandled["UNKNOWN"] == 1500 and len(vehicle.vehicle.unhandled) <= 5
    kept = runner.kept_state()
    assert (kept["latest_types"], kept["status_texts"], kept["pymavlink_params"]) == (3, 100, 0)
    assert kept["pymavlink_messages"] <= 10  # its fixed entries (HOME, per-system ones) and our three types
    assert runner.link.status_texts[-1] == "text 1499"
    assert len(runner.link.signing.accepted_unsigned) == 4  # HEARTBEAT, UNKNOWN, PARAM_VALUE, STATUSTEXT


def test_forged_signed_frames_from_made_up_streams_keep_no_state():
    """Regression: pymavlink records a stream's timestamp before it checks the signature, one entry per forged
    (link id, system, component); the signing code now keeps streams only after a signature verified."""
    vehicle, runner = fuzz.VehicleTarget(fuzz.TARGET_KEY), fuzz.RunnerTarget(fuzz.TARGET_KEY)
    rng = random.Random(1)
    for _ in range(500):
        forger = fuzz_frames.encoder(rng.randrange(256), rng.randrange(256), fuzz_frames.ATTACKER_KEY)
        forger.signing.link_id = rng.randrange(256)
        frame = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3).pack(forger)
        vehicle.feed(frame)
        runner.feed(frame)
    for mav, signing in ((vehicle.endpoint.mav, vehicle.vehicle.signing), (runner.link.conn.mav, runner.link.signing)):
        assert len(mav.signing.stream_timestamps) == 0 and len(signing.verifier.stream_timestamps) == 0
        assert signing.rejected["bad_signature"] == 500


def test_vehicle_with_an_unknown_autopilot_enum_is_described_not_crashed():
    """Regression (found by the fuzzer): a HEARTBEAT with autopilot 255 made vehicle_description raise KeyError."""
    target = fuzz.RunnerTarget(None)
    target.feed(mavlink.MAVLink_heartbeat_message(2, 255, 0, 0, 3, 3).pack(fuzz_frames.encoder(1, 1)))
    assert target.link.discovered
    assert target.link.vehicle_description() == "vehicle 1/1 (MAV_AUTOPILOT 255)"
    assert enum_name("MAV_RESULT", 200) == "MAV_RESULT 200"  # the runner names a refused command with it
    assert enum_name("MAV_RESULT", 0) == "MAV_RESULT_ACCEPTED"
