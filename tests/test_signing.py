"""MAVLink 2 signing end to end: key files, the vehicle's checks (unsigned, wrong key, replay, stale, downgrade,
PX4's unsigned allow-list, SETUP_SIGNING), the runner's side and a signed replay mission.

Clients are real pymavlink (its own ``setup_signing``) over the in-memory link in lockstep, so timestamps are
simulated (time 0 = the MAVLink epoch); the last test runs ``hrlsac sitl --signing-key`` over real UDP.
"""
from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys

import pytest
from conftest import UdpClient, free_udp_ports
from pymavlink.dialects.v20 import common as mavlink
from runner_helpers import ALL_STATES, policy, small_mission  # noqa: F401  (policy is a module fixture)

import hrlsac_cli
from autonomy.vehicle_link import VehicleLink
from missions.mission_writer import save_mission
from mavlink_signing import NEW_STREAM_MAX_AGE, SIGNED_FLAG, KeyFileError, generate_key, load_key_file, write_key_file
from simulation.mission_replay import replay_mission
from sitl_bridge.link import MemoryMavConnection, memory_link_pair
from sitl_bridge.scripted_flight import LockstepPilot, LockstepTimeout
from sitl_bridge.vehicle import SimulatedVehicle, VehicleConfig

ARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
KEY = bytes(range(32))
OTHER_KEY = bytes(range(100, 132))
HRLSAC = [sys.executable, "-m", "hrlsac_cli"]


# ---------------------------------------------------------------------------------------------- key files
def test_keygen_writes_64_hex_characters_owner_only_and_refuses_to_overwrite(tmp_path, capsys):
    path = tmp_path / "link.key"
    assert hrlsac_cli.main(["keygen", str(path)]) == 0
    text = path.read_text()
    assert len(text) == 65 and text.endswith("\n") and all(c in "0123456789abcdef" for c in text[:64])
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert load_key_file(path) == bytes.fromhex(text[:64])
    assert hrlsac_cli.main(["keygen", str(path)]) == 2
    assert capsys.readouterr().err.strip() == (f"hrlsac keygen: error: key file {path} exists; pass --force to "
                                               "replace it (clients using it must be updated)")
    assert path.read_text() == text  # untouched
    assert hrlsac_cli.main(["keygen", str(path), "--force"]) == 0
    assert path.read_text() != text and stat.S_IMODE(path.stat().st_mode) == 0o600
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.key"]  # no temporary file left behind


def test_two_generated_keys_differ_and_have_32_bytes():
    first, second = generate_key(), generate_key()
    assert len(first) == len(second) == 32 and first != second


@pytest.mark.parametrize("content", [b"", b"00" * 31 + b"\n", b"00" * 33 + b"\n", b"zz" * 32 + b"\n",
                                     b"00" * 16 + b"\n" + b"00" * 16 + b"\n", b" " + b"00" * 32, b"00" * 4000])
def test_malformed_key_files_are_refused_with_the_fix(tmp_path, content):
    path = tmp_path / "bad.key"
    path.write_bytes(content)
    path.chmod(0o600)
    with pytest.raises(KeyFileError) as error:
        load_key_file(path)
    assert str(error.value) == (f"key file {path} is malformed: expected 64 hexadecimal characters on one line; "
                                f"write a new one with 'hrlsac keygen {path}'")


@pytest.mark.parametrize("mode, what", [(0o644, "readable"), (0o640, "readable"), (0o604, "readable"),
                                        (0o620, "writable"), (0o602, "writable")])
def test_key_files_open_to_others_are_refused_like_ssh_keys(tmp_path, mode, what):
    path = tmp_path / "shared.key"
    write_key_file(path, KEY)
    path.chmod(mode)
    with pytest.raises(KeyFileError) as error:
        load_key_file(path)
    assert str(error.value) == f"key file {path} is {what} by others (mode {mode:04o}); run chmod 600 {path}"


def test_key_file_with_crlf_ending_is_accepted_and_missing_file_names_the_fix(tmp_path):
    path = tmp_path / "dos.key"
    path.write_bytes(KEY.hex().upper().encode() + b"\r\n")
    path.chmod(0o600)
    assert load_key_file(path) == KEY
    with pytest.raises(KeyFileError, match="does not exist; write one with 'hrlsac keygen"):
        load_key_file(tmp_path / "missing.key")


def test_commands_refuse_a_bad_key_file_in_one_line_without_traceback(tmp_path):
    path = tmp_path / "open.key"
    write_key_file(path, KEY)
    path.chmod(0o644)
    result = subprocess.run([*HRLSAC, "sitl", "--signing-key", str(path)], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 2
    assert result.stderr.strip() == (f"hrlsac sitl: error: key file {path} is readable by others (mode 0644); "
                                     f"run chmod 600 {path}")


# ---------------------------------------------------------------------------------------------- the vehicle
def signed_pilot(key: bytes = KEY, client_key: bytes | None = KEY) -> LockstepPilot:
    """A lockstep vehicle signing with ``key`` and a pymavlink client signing with ``client_key`` (None: none)."""
    pilot = LockstepPilot.create(VehicleConfig(seed=1, signing_key=key))
    if client_key is not None:
        pilot.conn.setup_signing(client_key, sign_outgoing=True, initial_timestamp=0, link_id=7)
    pilot.wait_for(lambda: pilot.vehicle.autopilot.gps_ok, 2.0, "GPS")
    return pilot


def no_ack(pilot: LockstepPilot, command: int) -> bool:
    try:
        pilot.wait_message("COMMAND_ACK", 1.0, lambda m: m.command == command)
    except LockstepTimeout:
        return True
    return False


def test_signed_client_commands_the_vehicle_and_verifies_its_signed_telemetry():
    pilot = signed_pilot()
    assert pilot.command(ARM, 1) == ACCEPTED and pilot.vehicle.autopilot.armed
    beats = [m for m in pilot.received if m.get_type() == "HEARTBEAT"]
    assert beats and all(m.get_signed() for m in beats)  # pymavlink checked the vehicle's signatures
    assert pilot.conn.mav.signing.badsig_count == 0
    summary = pilot.vehicle.signing.summary()
    assert summary["rejected_total"] == 0 and summary["accepted_signed"] >= 1


def test_unsigned_command_is_rejected_and_counted():
    pilot = signed_pilot(client_key=None)
    pilot.mav.command_long_send(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert no_ack(pilot, ARM) and not pilot.vehicle.autopilot.armed
    assert pilot.vehicle.signing.rejected == {"unsigned": 1}


def test_command_signed_with_another_key_is_rejected_and_counted():
    pilot = signed_pilot(client_key=OTHER_KEY)
    pilot.mav.command_long_send(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert no_ack(pilot, ARM) and not pilot.vehicle.autopilot.armed
    assert pilot.vehicle.signing.rejected == {"bad_signature": 1}


def test_replayed_signed_frame_is_rejected():
    pilot = signed_pilot()
    arm_frame = pilot.mav.command_long_encode(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0).pack(pilot.mav)
    pilot.conn.write(arm_frame)
    assert pilot.wait_message("COMMAND_ACK", 1.0).result == ACCEPTED
    assert pilot.command(ARM, 0) == ACCEPTED and not pilot.vehicle.autopilot.armed
    pilot.conn.write(arm_frame)  # an attacker re-sends the captured, correctly signed ARM
    assert no_ack(pilot, ARM) and not pilot.vehicle.autopilot.armed
    assert pilot.vehicle.signing.rejected == {"replay": 1}


def test_new_stream_more_than_a_minute_old_is_rejected_as_stale():
    pilot = signed_pilot(client_key=None)
    pilot.vehicle.run(61.0)
    pilot.conn.setup_signing(KEY, sign_outgoing=True, initial_timestamp=0, link_id=7)  # signs as of time 0
    pilot.mav.command_long_send(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert no_ack(pilot, ARM) and pilot.vehicle.signing.rejected == {"stale": 1}
    pilot.mav.signing.timestamp = int(pilot.vehicle.time_s * 1e5) - NEW_STREAM_MAX_AGE + 1000  # within a minute
    assert pilot.command(ARM, 1) == ACCEPTED


def test_downgrade_to_unsigned_mavlink1_is_rejected():
    pilot = signed_pilot()
    pilot.mav.command_long_send(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0, force_mavlink1=True)
    assert no_ack(pilot, ARM) and not pilot.vehicle.autopilot.armed
    assert pilot.vehicle.signing.rejected == {"mavlink1": 1}
    pilot.conn.disable_signing()  # and unsigned MAVLink 2 from the same client
    pilot.mav.command_long_send(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert no_ack(pilot, ARM) and pilot.vehicle.signing.rejected == {"mavlink1": 1, "unsigned": 1}


def test_px4_unsigned_allow_list_is_accepted_unsigned():
    pilot = signed_pilot(client_key=None)
    mav = pilot.mav
    mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    mav.radio_status_send(200, 190, 90, 80, 70, 0, 0)
    mav.adsb_vehicle_send(0xABCDEF, 473977420, 85455940, 0, 500000, 0, 0, 0, b"TEST", 0, 1, 0, 0)
    mav.collision_send(0, 0xABCDEF, 0, 0, 10.0, 5.0, 2.0)
    mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, force_mavlink1=True)
    pilot.vehicle.run(0.1)
    signing = pilot.vehicle.signing
    assert signing.accepted_unsigned == {"HEARTBEAT": 2, "RADIO_STATUS": 1, "ADSB_VEHICLE": 1, "COLLISION": 1}
    assert not signing.rejected


def setup_signing(pilot: LockstepPilot, new_key: bytes) -> None:
    pilot.mav.setup_signing_send(1, 1, list(new_key), int(pilot.vehicle.time_s * 1e5))
    pilot.vehicle.run(0.1)


def test_setup_signing_is_refused_while_armed_and_installs_the_key_when_disarmed():
    pilot = signed_pilot()
    assert pilot.command(ARM, 1) == ACCEPTED
    setup_signing(pilot, OTHER_KEY)
    assert pilot.vehicle.setup_signing_refused == 1 and pilot.vehicle.signing.key == KEY
    assert pilot.command(ARM, 0) == ACCEPTED  # the old key still works
    setup_signing(pilot, OTHER_KEY)
    assert pilot.vehicle.signing.key == OTHER_KEY and pilot.vehicle.setup_signing_refused == 1
    pilot.mav.command_long_send(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)  # still signed with the old key
    assert no_ack(pilot, ARM) and pilot.vehicle.signing.rejected == {"bad_signature": 1}
    pilot.conn.setup_signing(OTHER_KEY, sign_outgoing=True, initial_timestamp=int(pilot.vehicle.time_s * 1e5))
    assert pilot.command(ARM, 1) == ACCEPTED


def test_unsigned_setup_signing_cannot_take_over_a_signed_vehicle():
    pilot = signed_pilot(client_key=None)
    setup_signing(pilot, OTHER_KEY)
    assert pilot.vehicle.signing.key == KEY and pilot.vehicle.signing.rejected == {"unsigned": 1}


# ---------------------------------------------------------------------------------------------- the runner
def runner_against(vehicle_key: bytes | None, runner_key: bytes, seconds: float = 3.0):
    """A VehicleLink with ``runner_key`` ticking against a lockstep vehicle with ``vehicle_key``."""
    vehicle_end, client_end = memory_link_pair()
    vehicle = SimulatedVehicle(VehicleConfig(seed=2, signing_key=vehicle_key), [vehicle_end])
    warnings: list[str] = []
    link = VehicleLink(MemoryMavConnection(client_end, source_system=1, source_component=191),
                       lambda: vehicle.time_s, signing_key=runner_key, warn=warnings.append)
    for _ in range(int(seconds * 100)):
        link.tick()
        vehicle.step()
    return vehicle, link, warnings


def test_runner_warns_once_when_the_vehicle_does_not_sign():
    vehicle, link, warnings = runner_against(None, KEY)
    assert link.discovered and link.signing.accepted_unsigned["HEARTBEAT"] >= 3
    assert warnings == ["warning: signing is on but the vehicle's messages arrive unsigned (first: HEARTBEAT); "
                        "they are not authenticated: give the vehicle the same key"]


def test_runner_with_the_vehicles_key_refuses_a_later_unsigned_downgrade():
    vehicle, link, warnings = runner_against(KEY, KEY)
    assert link.discovered and link.flight_mode == "LOITER" and not warnings  # PX4 HOLD
    assert link.signing.accepted_signed > 100 and not link.signing.accepted_unsigned
    forged = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)  # claims to be the vehicle, cannot sign
    rtl = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 157, 84148224,
                                            4, 3)  # armed, in RTL
    vehicle.endpoints[0].link.send(rtl.pack(forged))
    vehicle.endpoints[0].link.send(rtl.pack(forged, force_mavlink1=True))
    link.tick()
    assert link.flight_mode == "LOITER" and not link.armed
    assert link.signing.rejected == {"unsigned": 1, "mavlink1": 1} and not warnings


def test_runner_drops_vehicle_messages_signed_with_another_key():
    vehicle, link, warnings = runner_against(OTHER_KEY, KEY)
    assert not link.discovered and link.signing.rejected["bad_signature"] > 10 and not warnings
    assert vehicle.signing.accepted_unsigned["HEARTBEAT"] == 0  # the runner's heartbeats are signed (wrong key)
    assert vehicle.signing.rejected["bad_signature"] >= 3


def test_runner_keeps_signing_when_pymavlink_replaces_its_encoder():
    """Regression: pymavlink swaps in a new encoder when it switches to MAVLink 2 on the first received frame,
    which silently dropped signing: ``hrlsac mission run --signing-key`` sent its commands unsigned."""
    vehicle, link, _ = runner_against(KEY, KEY, seconds=1.0)
    link.conn.mav = mavlink.MAVLink(link.conn, srcSystem=1, srcComponent=191)  # what auto_mavlink_version does
    link.send_command(mavlink.MAV_CMD_REQUEST_MESSAGE, (mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION,))
    before = vehicle.signing.accepted_signed
    vehicle.step()
    assert vehicle.signing.accepted_signed == before + 1 and not vehicle.signing.rejected


def test_runner_connections_speak_mavlink2_from_the_first_byte():
    code = ("from autonomy.vehicle_link import open_connection; "
            "print(open_connection('udpout:127.0.0.1:9').WIRE_PROTOCOL_VERSION)")
    env = {key: value for key, value in os.environ.items() if key != "MAVLINK20"}
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=env)
    assert result.stdout.strip() == "2.0", result.stderr


def test_signed_replay_mission_completes_and_is_byte_identical(policy, tmp_path):  # noqa: F811
    reports = [replay_mission(small_mission(), policy, seed=5, out=tmp_path / name, video=False, signing_key=KEY)
               for name in ("a", "b")]
    report = reports[0]
    assert [t["to"] for t in report["transitions"]] == ALL_STATES
    vehicle, runner = report["signing"]["vehicle"], report["signing"]["runner"]
    assert vehicle["rejected_total"] == runner["rejected_total"] == 0
    assert vehicle["accepted_unsigned"] == runner["accepted_unsigned"] == {}
    assert vehicle["accepted_signed"] > 500 and runner["accepted_signed"] > 1000
    tlog = (tmp_path / "a" / "flight.tlog").read_bytes()
    assert tlog == (tmp_path / "b" / "flight.tlog").read_bytes()
    # Every frame in the tlog (8-byte time, then the frame) is MAVLink 2 with the signed flag.
    offset, frames = 0, 0
    while offset < len(tlog):
        frame = tlog[offset + 8:]
        assert frame[0] == 0xFD and frame[2] & SIGNED_FLAG
        offset += 8 + 12 + frame[1] + 13
        frames += 1
    assert frames == report["tlog_messages"]


def test_mission_replay_command_signs_with_a_key_file_and_refuses_a_shared_one(policy, tmp_path):  # noqa: F811
    mission_path, key_path = tmp_path / "small.yaml", tmp_path / "link.key"
    save_mission(small_mission(), mission_path)
    write_key_file(key_path, KEY)
    command = [*HRLSAC, "mission", "replay", str(mission_path), "--policy", str(policy.path), "--no-video",
               "--quiet", "--out", str(tmp_path / "out"), "--signing-key", str(key_path)]
    result = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["signing"]["vehicle"]["rejected_total"] == 0 and report["signing"]["runner"]["accepted_signed"] > 0
    key_path.chmod(0o640)
    result = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2
    assert result.stderr.strip() == (f"hrlsac mission replay: error: key file {key_path} is readable by others "
                                     f"(mode 0640); run chmod 600 {key_path}")


# ---------------------------------------------------------------------------------------------- over UDP
@pytest.mark.slow
def test_hrlsac_sitl_with_a_key_over_udp_accepts_signed_and_rejects_unsigned_commands(tmp_path):
    key_path = tmp_path / "link.key"
    write_key_file(key_path, KEY)
    api_port, client_port = free_udp_ports(2)
    sitl = subprocess.Popen([*HRLSAC, "sitl", "--api-port", str(api_port), "--api-remote", str(client_port),
                             "--gcs-remote", "0", "--signing-key", str(key_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    client = None
    try:
        client = UdpClient(f"udpin:127.0.0.1:{client_port}")
        client.conn.setup_signing(KEY, sign_outgoing=True)  # pymavlink's defaults: wall-clock timestamps
        beat = client.wait_message("HEARTBEAT", 10.0)
        assert beat.get_signed()  # verified by pymavlink with the key
        client.wait(lambda: client.latest.get("SYS_STATUS") and client.latest.get("GPS_RAW_INT")
                    and client.latest["GPS_RAW_INT"].fix_type >= 3, 10.0, "GPS fix")
        client.conn.disable_signing()
        client.conn.mav.command_long_send(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
        client.pump(1.0)
        assert not any(m.get_type() == "COMMAND_ACK" for m in client.received)
        client.conn.setup_signing(KEY, sign_outgoing=True)
        assert client.command(ARM, 1).result == ACCEPTED
        assert client.command(ARM, 0).result == ACCEPTED
    finally:
        if client is not None:
            client.close()
        sitl.send_signal(signal.SIGTERM)
        out, _ = sitl.communicate(timeout=10)
    assert "MAVLink 2 signing on" in out
    assert "signing: rejected COMMAND_LONG from 255/190 (unsigned)" in out
    assert "signing: rejected 1 message (unsigned 1)" in out
