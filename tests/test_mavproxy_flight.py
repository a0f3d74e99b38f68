"""MAVProxy flies both personalities of the simulated vehicle, headless, over real sockets.

MAVProxy (``mavproxy.py``, 1.8.75) runs as a subprocess with no console or map; its commands go to its stdin
through a pipe (its interactive shell reads lines from any stdin) and its output is read line by line. The PX4
vehicle is reached on the GCS link (``--master=udpin:...``, as QGroundControl would), the ArduPilot one on its TCP
port like ArduPilot SITL's SERIAL0 (``--master=tcp:...``). Every wait is bounded; the vehicles run at 2-3x.
"""
from __future__ import annotations

import contextlib
import math
import os
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("MAVProxy")

from sitl_bridge.ardupilot.modes import CopterMode  # noqa: E402
from sitl_bridge.px4.modes import FlightMode  # noqa: E402
from sitl_bridge.server import UdpPorts, VehicleServer  # noqa: E402
from sitl_bridge.vehicle import VehicleConfig  # noqa: E402

pytestmark = pytest.mark.slow
SPEED = 2.0
MAVPROXY = Path(sys.executable).with_name("mavproxy.py")


class MavProxy:
    """A headless MAVProxy: ``send`` writes a command line, ``expect`` waits for an output line."""

    def __init__(self, master: str, workdir: Path):
        if not MAVPROXY.exists():
            pytest.skip("mavproxy.py is not installed next to this Python")
        env = {**os.environ, "HOME": str(workdir), "PYTHONUNBUFFERED": "1"}  # no ~/.mavinit.scr of the user
        # param_ftp 0: fetch parameters with PARAM_REQUEST_LIST at once (the vehicle has no MAVLink FTP)
        self.process = subprocess.Popen([sys.executable, str(MAVPROXY), f"--master={master}", "--no-state",
                                         "--cmd=set param_ftp 0"],
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                        text=True, bufsize=1, cwd=workdir, env=env)
        self.lines: list[str] = []
        self._queue: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.process.stdout:
            self._queue.put(line.rstrip())

    def send(self, command: str) -> None:
        self.process.stdin.write(command + "\n")
        self.process.stdin.flush()

    def expect(self, text: str, timeout_s: float = 15.0) -> str:
        """The first output line (from now, or already read but not yet matched) containing ``text``."""
        deadline = time.monotonic() + timeout_s
        while True:
            for index, line in enumerate(self.lines):
                if text in line:
                    del self.lines[: index + 1]
                    return line
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(f"MAVProxy did not print {text!r} within {timeout_s} s; last lines: "
                                     f"{self.lines[-15:]}")
            try:
                self.lines.append(self._queue.get(timeout=min(remaining, 0.2)))
            except queue.Empty:
                pass

    def close(self) -> None:
        try:
            self.process.stdin.close()
            self.process.wait(timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            self.process.kill()
            self.process.wait(timeout=5)


def wait_until(condition, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(0.05)


def return_home(mavproxy: MavProxy, vehicle, command: str, answer: str) -> None:
    """RTL by a MAVProxy command; the vehicle lands at home and disarms, and MAVProxy sees it."""
    mavproxy.send(command)
    mavproxy.expect(answer)
    wait_until(lambda: not vehicle.autopilot.armed, 60, "return, landing and disarm")
    mavproxy.expect("DISARMED")
    assert vehicle.state.on_ground and abs(vehicle.state.north_m) < 1.5


@contextlib.contextmanager
def px4_and_mavproxy(udp_ports, tmp_path):
    """The PX4 personality at SPEED and a MAVProxy on its GCS link, as QGroundControl would be; yields both."""
    api_port, api_remote, gcs_port, gcs_remote = udp_ports
    ports = UdpPorts(api_port=api_port, api_remote_port=api_remote, gcs_port=gcs_port, gcs_remote_port=gcs_remote)
    with VehicleServer(VehicleConfig(seed=3), ports, speed=SPEED) as server:
        mavproxy = MavProxy(f"udpin:127.0.0.1:{gcs_remote}", tmp_path)
        try:
            yield server.vehicle, mavproxy
        finally:
            mavproxy.close()
        assert server.error is None and server.vehicle.handler_errors == 0


def test_mavproxy_flies_the_px4_personality(udp_ports, tmp_path):
    with px4_and_mavproxy(udp_ports, tmp_path) as (vehicle, mavproxy):
        start = px4_offboard_north(mavproxy, vehicle, setpoints=15)
        assert vehicle.autopilot.mode is FlightMode.OFFBOARD
        assert vehicle.state.north_m - start > 3.0
        return_home(mavproxy, vehicle, "long NAV_RETURN_TO_LAUNCH", "NAV_RETURN_TO_LAUNCH: ACCEPTED")


def px4_offboard_north(mavproxy: MavProxy, vehicle, setpoints: int, params: tuple[str, ...] = ()) -> float:
    """Parameters set with ``param set``, take-off to 8 m, OFFBOARD with MAVProxy's ``velocity`` at 3 m/s north for
    ``setpoints`` setpoints 0.15 s apart; returns where the vehicle was when OFFBOARD was accepted."""
    mavproxy.expect("Detected vehicle 1:1")
    mavproxy.expect(f"Received {len(vehicle.params)} parameters", 30)
    for line in ("MIS_TAKEOFF_ALT 8", *params):
        name, value = line.split()
        mavproxy.send(f"param set {name} {value}")
        wait_until(lambda: vehicle.params[name] == float(value), 10, name)
    mavproxy.send("arm throttle")
    mavproxy.expect("COMPONENT_ARM_DISARM: ACCEPTED")
    mavproxy.send("takeoff 8")  # param7 AMSL for PX4: below home, so PX4 takes off to MIS_TAKEOFF_ALT
    mavproxy.expect("NAV_TAKEOFF: ACCEPTED")
    wait_until(lambda: vehicle.autopilot.mode is FlightMode.HOLD and -vehicle.state.down_m > 7.5, 20,
               "takeoff to 8 m")
    mavproxy.send("velocity 3 0 0")  # one setpoint (BODY_NED), then OFFBOARD at once: PX4 accepts it
    mavproxy.send("long DO_SET_MODE 1 6 0")
    mavproxy.expect("DO_SET_MODE: ACCEPTED")
    start = vehicle.state.north_m
    for _ in range(setpoints):  # keep the setpoints coming (COM_OF_LOSS_T is 1 s of vehicle time)
        mavproxy.send("velocity 3 0 0")
        time.sleep(0.15)
    return start


def test_mavproxy_sees_px4s_geofence_hold_and_joins_its_chunked_text(udp_ports, tmp_path):
    """GF_MAX_HOR_DIST set from MAVProxy; flown past it, the vehicle holds and says why in a 54-character text,
    which STATUSTEXT carries in two chunks: MAVProxy prints it whole."""
    with px4_and_mavproxy(udp_ports, tmp_path) as (vehicle, mavproxy):
        px4_offboard_north(mavproxy, vehicle, setpoints=40, params=("GF_MAX_HOR_DIST 12",))
        mavproxy.expect("Geofence: exceeding maximum distance to Home")
        wait_until(lambda: vehicle.autopilot.mode is FlightMode.HOLD, 5, "HOLD")
        assert 12.0 <= math.hypot(vehicle.state.north_m, vehicle.state.east_m) < 16.0
        return_home(mavproxy, vehicle, "long NAV_RETURN_TO_LAUNCH", "NAV_RETURN_TO_LAUNCH: ACCEPTED")


def test_mavproxy_loads_lists_and_flies_a_px4_mission(udp_ports, tmp_path):
    """``wp load`` of a QGC WPL 110 file (three waypoints at 15 m above home), ``wp list`` back, arm and Mission
    mode: the vehicle climbs, flies the three and loiters at the last. MAVProxy sends no MISSION_ACK after a
    download, so PX4 (and the simulator) says "Operation timeout" 5 s later (mavlink_mission.cpp send())."""
    with px4_and_mavproxy(udp_ports, tmp_path) as (vehicle, mavproxy):
        corners = ((30.0, 0.0), (30.0, 30.0), (0.0, 30.0))
        lines = ["QGC WPL 110"]
        for seq, (north, east) in enumerate(corners):  # seq current frame command p1-p4 lat lon alt autocontinue
            lat, lon, _ = vehicle.frame.to_geodetic(north, east, 0.0)
            lines.append(f"{seq}\t{int(seq == 0)}\t3\t16\t0\t2\t0\t0\t{lat:.8f}\t{lon:.8f}\t15\t1")
        (tmp_path / "square.txt").write_text("\n".join(lines) + "\n")
        mavproxy.expect("Detected vehicle 1:1")
        mavproxy.send(f"wp load {tmp_path / 'square.txt'}")
        mavproxy.expect("Sent all 3 waypoints")
        mavproxy.expect("MISSION_ACK: TYPE_MISSION: ACCEPTED")
        assert [(item.command, item.relative, item.z) for item in vehicle.missions.items] == [(16, True, 15.0)] * 3
        mavproxy.send("wp list")
        listed = [mavproxy.expect("16 6 ") for _ in corners]  # command 16, GLOBAL_RELATIVE_ALT_INT
        assert all("15.000000" in line and "p2=2.0" in line for line in listed)
        mavproxy.send("arm throttle")
        mavproxy.expect("COMPONENT_ARM_DISARM: ACCEPTED")
        mavproxy.send("long DO_SET_MODE 29 4 4")  # "mode MISSION" fails inside MAVProxy for PX4 (docs/sitl.md)
        mavproxy.expect("DO_SET_MODE: ACCEPTED")
        mavproxy.expect("Climb to 15.0 meters above home")
        assert vehicle.autopilot.mode is FlightMode.MISSION
        wait_until(lambda: vehicle.autopilot.mission_finished, 60, "the three waypoints")
        mavproxy.expect("waypoint 2")  # MAVProxy prints each MISSION_ITEM_REACHED
        mavproxy.expect("Mission finished, loitering")
        assert math.hypot(vehicle.state.north_m, vehicle.state.east_m - 30.0) < 2.5
        assert -vehicle.state.down_m == pytest.approx(15.0, abs=1.0)
        return_home(mavproxy, vehicle, "long NAV_RETURN_TO_LAUNCH", "NAV_RETURN_TO_LAUNCH: ACCEPTED")


def test_mavproxy_loads_an_ardupilot_mission_and_mission_start_flies_it(udp_ports, tmp_path):
    """ArduPilot SITL's usual flow with a mission file: ``wp load`` (a QGC WPL 110 file whose row 0 is home), GUIDED,
    arm, then MISSION_START, which switches to AUTO and lets the takeoff go (there is no throttle stick here). The
    vehicle takes off, flies the two waypoints and returns; MAVProxy prints each reached command."""
    tcp_port, api_port, api_remote, _ = udp_ports
    ports = UdpPorts(api_port=api_port, api_remote_port=api_remote, gcs_remote_port=None, tcp_port=tcp_port)
    with VehicleServer(VehicleConfig(autopilot="ardupilot", seed=3), ports, speed=1.5 * SPEED) as server:
        vehicle, home = server.vehicle, server.vehicle.home
        rows = [f"0\t1\t0\t16\t0\t0\t0\t0\t{home.lat_deg:.8f}\t{home.lon_deg:.8f}\t{home.alt_m:.2f}\t1",
                "1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t12\t1"]
        for seq, (north, east) in enumerate(((30.0, 0.0), (30.0, 30.0)), start=2):
            lat, lon, _ = vehicle.frame.to_geodetic(north, east, 0.0)
            rows.append(f"{seq}\t0\t3\t16\t0\t0\t0\t0\t{lat:.8f}\t{lon:.8f}\t12\t1")
        rows.append("4\t0\t3\t20\t0\t0\t0\t0\t0\t0\t0\t1")
        (tmp_path / "survey.txt").write_text("QGC WPL 110\n" + "\n".join(rows) + "\n")
        mavproxy = MavProxy(f"tcp:127.0.0.1:{tcp_port}", tmp_path)
        try:
            mavproxy.expect("Detected vehicle 1:1")
            mavproxy.send(f"wp load {tmp_path / 'survey.txt'}")
            mavproxy.expect("Loaded 5 waypoints")
            wait_until(lambda: len(vehicle.copter_missions.items) == 4, 15, "the upload")
            assert [item.command for item in vehicle.copter_missions.items] == [22, 16, 16, 20]
            mavproxy.send("mode GUIDED")
            mavproxy.expect("DO_SET_MODE: ACCEPTED")
            mavproxy.send("arm throttle")
            mavproxy.expect("COMPONENT_ARM_DISARM: ACCEPTED")
            mavproxy.send("long MISSION_START 0 0")
            mavproxy.expect("MISSION_START: ACCEPTED")
            mavproxy.expect("Mission: 1 Takeoff")
            assert vehicle.autopilot.mode is CopterMode.AUTO
            mavproxy.expect("Reached command #3", 60)
            mavproxy.expect("Mission: 4 RTL")
            wait_until(lambda: not vehicle.autopilot.armed, 90, "the return, landing and disarm")
            assert vehicle.state.on_ground and math.hypot(vehicle.state.north_m, vehicle.state.east_m) < 1.5
        finally:
            mavproxy.close()
        assert server.error is None and vehicle.handler_errors == 0


def test_mavproxy_loads_an_ardupilot_fence_and_rally_points(udp_ports, tmp_path):
    """MAVProxy's fence and rally modules (MISSION_ITEM protocol, types FENCE and RALLY): ``fence load`` and
    ``rally load`` of QGC WPL 110 files, then ``fence list`` / ``rally list`` download them again."""
    tcp_port, api_port, api_remote, _ = udp_ports
    ports = UdpPorts(api_port=api_port, api_remote_port=api_remote, gcs_remote_port=None, tcp_port=tcp_port)
    with VehicleServer(VehicleConfig(autopilot="ardupilot", seed=3), ports, speed=SPEED) as server:
        vehicle = server.vehicle
        corners = [vehicle.frame.to_geodetic(n, e, 0.0) for n, e in ((-50, -50), (50, -50), (50, 50), (-50, 50))]
        fence = [f"{seq}\t0\t0\t5001\t4\t0\t0\t0\t{lat:.8f}\t{lon:.8f}\t0\t0"
                 for seq, (lat, lon, _) in enumerate(corners)]
        (tmp_path / "fence.txt").write_text("QGC WPL 110\n" + "\n".join(fence) + "\n")
        lat, lon, _ = vehicle.frame.to_geodetic(40.0, 0.0, 0.0)
        (tmp_path / "rally.txt").write_text(f"QGC WPL 110\n0\t0\t3\t5100\t0\t0\t0\t0\t{lat:.8f}\t{lon:.8f}\t15\t0\n")
        mavproxy = MavProxy(f"tcp:127.0.0.1:{tcp_port}", tmp_path)
        try:
            mavproxy.expect("Detected vehicle 1:1")
            mavproxy.send(f"fence load {tmp_path / 'fence.txt'}")
            mavproxy.expect("Got MISSION_ACK: TYPE_FENCE: ACCEPTED")
            mavproxy.send(f"rally load {tmp_path / 'rally.txt'}")
            mavproxy.expect("Got MISSION_ACK: TYPE_RALLY: ACCEPTED")
            mavproxy.send("fence list")
            mavproxy.expect("Requesting 4 fence items")
            listed = [mavproxy.expect("5001 0 ") for _ in corners]  # command, frame GLOBAL, lat, lon, ...
            mavproxy.send("rally list")
            mavproxy.expect("Requesting 1 rally items")
            assert mavproxy.expect("5100 3 ").split()[4] == "15.000000"  # GLOBAL_RELATIVE_ALT, 15 m above home
        finally:
            mavproxy.close()
        assert server.error is None and vehicle.handler_errors == 0
    assert [float(v) for line in listed for v in line.split()[2:4]] == pytest.approx(
        [v for lat, lon, _ in corners for v in (lat, lon)], abs=2e-7)  # MAVProxy sends int(degrees * 1e7)
    assert [(a.inclusion, len(a.vertices)) for a in vehicle.autopilot.polyfence_areas] == [(True, 4)]
    assert vehicle.autopilot.rally_points[0].z == 15.0 and vehicle.autopilot.rally_points[0].relative


def test_mavproxy_flies_the_ardupilot_personality_on_tcp_like_sitl(udp_ports, tmp_path):
    tcp_port, api_port, api_remote, _ = udp_ports
    ports = UdpPorts(api_port=api_port, api_remote_port=api_remote, gcs_remote_port=None, tcp_port=tcp_port)
    config = VehicleConfig(autopilot="ardupilot", seed=3, params={"RTL_LOIT_TIME": 2000})
    with VehicleServer(config, ports, speed=1.5 * SPEED) as server:
        vehicle = server.vehicle
        mavproxy = MavProxy(f"tcp:127.0.0.1:{tcp_port}", tmp_path)
        try:
            mavproxy.expect("Detected vehicle 1:1")
            mavproxy.expect("Mode STABILIZE")  # MAVProxy decodes ArduCopter's mode numbers
            mavproxy.send("mode GUIDED")
            mavproxy.expect("DO_SET_MODE: ACCEPTED")
            mavproxy.send("arm throttle")
            mavproxy.expect("COMPONENT_ARM_DISARM: ACCEPTED")
            mavproxy.send("takeoff 10")  # ArduPilot: metres above home
            mavproxy.expect("NAV_TAKEOFF: ACCEPTED")
            wait_until(lambda: not vehicle.autopilot.taking_off and -vehicle.state.down_m > 9.5, 20, "10 m")
            assert vehicle.autopilot.mode is CopterMode.GUIDED
            wait_until(lambda: vehicle.endpoints[0].default_rates_hz.get(33, 0) > 0, 15,
                       "MAVProxy's REQUEST_DATA_STREAM")  # GLOBAL_POSITION_INT, which ArduPilot streams only on request
            start = vehicle.state.north_m
            mavproxy.send("velocity 2 0 0")  # one setpoint: flown for GUID_TIMEOUT (3 s), then the vehicle stops
            wait_until(lambda: vehicle.autopilot.guided_timed_out, 10, "GUID_TIMEOUT")
            time.sleep(2.0 / (1.5 * SPEED))
            assert vehicle.state.north_m - start == pytest.approx(6.0, abs=1.5)
            assert abs(vehicle.state.vn_mps) < 0.3 and vehicle.autopilot.mode is CopterMode.GUIDED
            # MAVProxy's "guided LAT LON ALT" (metres above home): DO_REPOSITION by default, and with
            # guided_use_reposition off ArduPilot's older way, a MISSION_ITEM_INT with current = 2 (as DroneKit's
            # simple_goto): both fly to the point in GUIDED.
            for north, east, setting in ((30.0, 0.0, None), (30.0, 25.0, "set guided_use_reposition 0")):
                if setting:
                    mavproxy.send(setting)
                lat, lon, _ = vehicle.frame.to_geodetic(north, east, 0.0)
                mavproxy.send(f"guided {lat:.7f} {lon:.7f} 12")
                mavproxy.expect("Guided (")
                wait_until(lambda: math.hypot(vehicle.state.north_m - north, vehicle.state.east_m - east) < 1.0
                           and abs(-vehicle.state.down_m - 12.0) < 0.5, 30, f"the guided point {north, east}")
                assert vehicle.autopilot.mode is CopterMode.GUIDED
            return_home(mavproxy, vehicle, "mode RTL", "Mode RTL")
        finally:
            mavproxy.close()
        assert server.error is None and vehicle.handler_errors == 0
