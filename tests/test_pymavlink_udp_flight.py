"""A plain pymavlink script flies the simulated vehicle over real UDP sockets, in real time."""
from __future__ import annotations

import math
import struct
import time

import pytest
from conftest import UdpClient
from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.px4.modes import FlightMode
from sitl_bridge.server import UdpPorts, VehicleServer
from sitl_bridge.vehicle import VehicleConfig

pytestmark = pytest.mark.slow


def mode_of(heartbeat) -> FlightMode | None:
    return FlightMode.from_custom_mode(heartbeat.custom_mode)


def is_armed(heartbeat) -> bool:
    return bool(heartbeat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)


def test_pymavlink_script_flies_a_full_mission_over_udp(udp_ports):
    api_port, client_port = udp_ports[:2]
    config = VehicleConfig(seed=7)
    server = VehicleServer(config, UdpPorts(api_port=api_port, api_remote_port=client_port, gcs_remote_port=None))
    with server:
        client = UdpClient(f"udpin:127.0.0.1:{client_port}")
        try:
            _fly(client, config)
        finally:
            client.close()


def _fly(client: UdpClient, config: VehicleConfig) -> None:
    # Heartbeats: PX4 quadrotor, sysid 1 / compid 1, disarmed in HOLD.
    hb = client.wait_message("HEARTBEAT", 5.0)
    assert (hb.type, hb.autopilot) == (mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4)
    assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and not is_armed(hb)
    assert mode_of(hb) is FlightMode.HOLD and hb.system_status == mavlink.MAV_STATE_STANDBY

    # Parameters: the whole list, floats as floats and integers bytewise (PX4's encoding).
    client.conn.mav.param_request_list_send(1, 1)
    first = client.wait_message("PARAM_VALUE", 3.0)
    client.wait(lambda: len({m.param_id for m in client.received if m.get_type() == "PARAM_VALUE"})
                >= first.param_count, 3.0, "all parameters")
    params = {m.param_id: m for m in client.received if m.get_type() == "PARAM_VALUE"}
    assert {"MIS_TAKEOFF_ALT", "COM_OF_LOSS_T", "COM_OBL_RC_ACT", "MPC_XY_CRUISE"} <= set(params)
    assert params["COM_OF_LOSS_T"].param_value == pytest.approx(1.0)
    assert params["MPC_XY_CRUISE"].param_value == pytest.approx(5.0)
    obl = params["COM_OBL_RC_ACT"]
    assert obl.param_type == mavlink.MAV_PARAM_TYPE_INT32
    assert struct.unpack("<i", struct.pack("<f", obl.param_value))[0] == 0

    # AUTOPILOT_VERSION on request, after the ACK.
    before = len(client.received)
    ack = client.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    assert (ack.target_system, ack.target_component) == (255, 190)
    version = client.wait_message("AUTOPILOT_VERSION", 2.0, since=before)
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT  # missions (MAVSDK needs the bit)

    # GPS, then arm and take off to 10 m (param7 is AMSL, as in PX4).
    client.wait(lambda: "GLOBAL_POSITION_INT" in client.latest, 5.0, "a global position")
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink.MAV_RESULT_ACCEPTED
    client.wait(lambda: is_armed(client.latest["HEARTBEAT"]), 2.0, "an armed heartbeat")
    ack = client.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, config.home.alt_m + 10)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    client.wait(lambda: mode_of(client.latest["HEARTBEAT"]) is FlightMode.HOLD
                and client.latest["GLOBAL_POSITION_INT"].relative_alt > 9_000, 20.0, "takeoff to 10 m")
    assert client.latest["GLOBAL_POSITION_INT"].relative_alt == pytest.approx(10_000, abs=1_000)

    # Stream setpoints for more than 1 s, then OFFBOARD is accepted and announced.
    client.stream = (0.0, 0.0, 0.0)
    client.pump(1.5)
    assert client.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 6, 0).result == mavlink.MAV_RESULT_ACCEPTED
    client.wait(lambda: mode_of(client.latest["HEARTBEAT"]) is FlightMode.OFFBOARD, 1.0, "OFFBOARD heartbeat")

    # North at 3 m/s for 5 s of vehicle time.
    start = client.latest["LOCAL_POSITION_NED"]
    client.stream = (3.0, 0.0, 0.0)
    client.wait(lambda: client.latest["LOCAL_POSITION_NED"].time_boot_ms - start.time_boot_ms >= 5000, 10.0, "5 s")
    end = client.latest["LOCAL_POSITION_NED"]
    assert 13.0 <= end.x - start.x <= 16.0
    assert abs(end.y - start.y) < 1.5 and end.vx == pytest.approx(3.0, abs=0.5)

    # Stop the stream: within COM_OF_LOSS_T (+ margin) the failsafe takes over and the vehicle stops.
    client.stream = None
    client.wait(lambda: mode_of(client.latest["HEARTBEAT"]) is FlightMode.POSCTL, 3.0, "offboard-loss failsafe")
    # the announcement goes out in its own message, possibly after the heartbeat that shows the new mode
    client.wait(lambda: any(m.get_type() == "STATUSTEXT" and "Failsafe" in m.text for m in client.received), 2.0,
                "the failsafe's STATUSTEXT")
    client.pump(3.0)
    stopped = client.latest["LOCAL_POSITION_NED"]
    assert math.hypot(stopped.vx, stopped.vy) < 0.5, "the failsafe must not keep flying the last velocity"

    # Land and auto-disarm.
    assert client.command(mavlink.MAV_CMD_NAV_LAND).result == mavlink.MAV_RESULT_ACCEPTED
    client.wait(lambda: client.latest["EXTENDED_SYS_STATE"].landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND,
                40.0, "landed")
    client.wait(lambda: not is_armed(client.latest["HEARTBEAT"]), 5.0, "auto-disarm")
    assert client.latest["GLOBAL_POSITION_INT"].relative_alt < 1_000


# ---------------------------------------------------------------- the ArduPilot personality over UDP and TCP
ARDUPILOT_SPEED = 3.0  # simulated seconds per wall second


def test_pymavlink_script_flies_the_ardupilot_personality_over_udp(udp_ports):
    companion_bind, companion_port, gcs_bind = udp_ports[:3]
    config = VehicleConfig(autopilot="ardupilot", seed=8, boot_time_s=600.0)
    ports = UdpPorts(api_port=companion_bind, api_remote_port=companion_port, gcs_port=gcs_bind,
                     gcs_remote_port=None, tcp_port=None)
    with VehicleServer(config, ports, speed=ARDUPILOT_SPEED) as server:
        client = UdpClient(f"udpin:127.0.0.1:{companion_port}")
        try:
            _fly_ardupilot(client, server)
        finally:
            client.close()
        assert server.error is None and server.vehicle.handler_errors == 0


def _sim_seconds(client: UdpClient, seconds: float) -> None:
    client.pump(seconds / ARDUPILOT_SPEED)


def _fly_ardupilot(client: UdpClient, server: VehicleServer) -> None:
    hb = client.wait_message("HEARTBEAT", 5.0)
    assert (hb.autopilot, hb.custom_mode) == (mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0)  # ArduCopter, STABILIZE
    _sim_seconds(client, 2.0)
    assert "GLOBAL_POSITION_INT" not in client.latest  # SRn_* = 0: nothing streams until asked
    client.conn.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_ALL, 10, 1)
    client.wait(lambda: "GLOBAL_POSITION_INT" in client.latest, 3.0, "streams after REQUEST_DATA_STREAM")
    assert client.latest["GLOBAL_POSITION_INT"].time_boot_ms > 600_000  # booted ten minutes before

    assert client.command(mavlink.MAV_CMD_DO_SET_MODE, 1, 4).result == mavlink.MAV_RESULT_ACCEPTED  # GUIDED
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink.MAV_RESULT_ACCEPTED
    ack = client.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10.0)  # relative to home
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    client.wait(lambda: client.latest["GLOBAL_POSITION_INT"].relative_alt > 9_500, 15.0, "takeoff to 10 m")
    assert client.latest["HEARTBEAT"].custom_mode == 4  # still GUIDED

    start = client.latest["LOCAL_POSITION_NED"]
    client.stream = (3.0, 0.0, 0.0)
    client.wait(lambda: client.latest["LOCAL_POSITION_NED"].time_boot_ms - start.time_boot_ms >= 5000, 5.0, "5 s")
    assert client.latest["LOCAL_POSITION_NED"].vx == pytest.approx(3.0, abs=0.5)
    client.stream = None
    _sim_seconds(client, 6.0)  # past GUID_TIMEOUT (3 s): the vehicle stops and stays in GUIDED
    stopped = client.latest["LOCAL_POSITION_NED"]
    assert math.hypot(stopped.vx, stopped.vy) < 0.5 and client.latest["HEARTBEAT"].custom_mode == 4

    assert client.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == mavlink.MAV_RESULT_ACCEPTED
    client.wait(lambda: not is_armed(client.latest["HEARTBEAT"]), 30.0, "RTL, landing and disarm")
    assert client.latest["HEARTBEAT"].custom_mode == 6  # ArduPilot stays in RTL after landing
    assert any(m.get_type() == "STATUSTEXT" and m.text == "Disarming motors" for m in client.received)
    assert math.hypot(server.vehicle.state.north_m, server.vehicle.state.east_m) < 1.5


def test_pymavlink_reaches_the_ardupilot_personality_on_tcp_like_sitl_serial0(udp_ports):
    from pymavlink import mavutil

    tcp_port, companion_bind, companion_port = udp_ports[:3]
    ports = UdpPorts(api_port=companion_bind, api_remote_port=companion_port, gcs_remote_port=None, tcp_port=tcp_port)
    with VehicleServer(VehicleConfig(autopilot="ardupilot", seed=2), ports, speed=2.0) as server:
        conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{tcp_port}", source_system=255, source_component=190)
        try:
            hb = conn.wait_heartbeat(timeout=5)
            assert hb is not None and hb.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
            conn.mav.param_request_list_send(1, 1)
            names = set()
            deadline = time.monotonic() + 5
            while time.monotonic() < deadline and len(names) < len(server.vehicle.params):
                msg = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=1)
                if msg is not None:
                    names.add(msg.param_id)
            assert len(names) == len(server.vehicle.params)  # every frame intact over the byte stream
            assert server.vehicle.endpoints[0].bad_frames == 0 and server.links[0].name == "tcp"
        finally:
            conn.close()
