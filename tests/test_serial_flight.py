"""A mission flown over a serial line: ``hrlsac mission run --connect serial:DEVICE:BAUD`` against the simulated
vehicle on the master end of a pseudo-terminal pair (``sitl_bridge.serial_link``), in real time.

The vehicle hears the companion through the same serial line: what it received is parsed on its side, so the test
sees the arming, OFFBOARD and the setpoint stream as the autopilot got them, not only as the runner sent them.
The whole mission (``fly_over_serial``, checked by ``assert_flown_over_serial``) is flown by the on-board install
(tests/test_onboard_install.py): the same runner, installed as a user installs it on a companion computer. This file
checks the pieces: the pseudo-terminal the simulated vehicle serves, and its serial link.
"""
from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import free_udp_ports
from pymavlink.dialects.v20 import common as mavlink

from missions.mission_file import load_mission
from missions.mission_writer import save_mission
from sitl_bridge.autopilot_base import AutopilotEvent
from sitl_bridge.serial_link import SerialLink, open_pty_link
from sitl_bridge.server import UdpPorts, VehicleServer
from sitl_bridge.vehicle_config import VehicleConfig

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "missions" / "library" / "demo.yaml"
PRETRAINED = ROOT / "policies" / "pretrained" / "hrl-sac.pt"
HRLSAC = [sys.executable, "-c", "import sys, hrlsac_cli; sys.exit(hrlsac_cli.main())"]
ALL_STATES = ["CONNECT", "PREFLIGHT", "ARM", "TAKEOFF", "OFFBOARD", "SEARCH", "RTL", "LAND", "DONE"]
BAUD = 57600
OFFBOARD_LOSS_S = 1.0
"""PX4's COM_OF_LOSS_T default: a longer gap between setpoints would end OFFBOARD."""

pytestmark = pytest.mark.slow


class HeardLink:
    """The vehicle's end of the serial line, also keeping (vehicle time, message) of everything it receives."""

    stream = True

    def __init__(self, link: SerialLink):
        self.link, self.name = link, link.name
        self.clock = lambda: 0.0
        self.parser = mavlink.MAVLink(None)
        self.parser.robust_parsing = True
        self.heard: list[tuple[float, mavlink.MAVLink_message]] = []

    def send(self, data: bytes) -> None:
        self.link.send(data)

    def receive(self) -> list[bytes]:
        chunks = self.link.receive()
        for chunk in chunks:
            self.heard += [(self.clock(), msg) for msg in self.parser.parse_buffer(chunk) or []
                           if msg.get_type() != "BAD_DATA"]
        return chunks

    def close(self) -> None:
        self.link.close()


def short_demo(tmp_path: Path) -> Path:
    """The demo mission, flown low and for 10 decisions so that a real-time flight takes about a minute."""
    mission = load_mission(DEMO)
    mission = dataclasses.replace(mission, flight=dataclasses.replace(mission.flight, altitude_m=10.0, max_steps=10))
    path = tmp_path / "demo-short.yaml"
    save_mission(mission, path)
    return path


def fly_over_serial(tmp_path: Path, runner: list[str] | None = None) -> tuple[dict, HeardLink, list[str], str]:
    """``hrlsac mission run`` (``runner``: the command, default this checkout's) of the short demo over a pty, against
    the simulated PX4 in real time; returns the report, what the vehicle heard, its log and the connection URL."""
    mission_path = short_demo(tmp_path)
    link, device = open_pty_link()
    heard = HeardLink(link)
    events: list[str] = []

    def log(event: AutopilotEvent) -> None:
        events.append(event.text)

    api_port, api_remote = free_udp_ports(2)
    config = VehicleConfig(home=load_mission(mission_path).launch_point, telemetry_profile="px4",
                           params={"RTL_RETURN_ALT": 12.0})
    server = VehicleServer(config, UdpPorts(api_port=api_port, api_remote_port=api_remote, gcs_remote_port=None),
                           on_event=log, extra_links=(heard,))
    heard.clock = lambda: server.vehicle.time_s
    url = f"serial:{device}:{BAUD}"
    with server:
        result = subprocess.run([*(runner or HRLSAC), "mission", "run", str(mission_path), "--policy", str(PRETRAINED),
                                 "--connect", url, "--out", str(tmp_path / "out"), "--accept-flight-mismatch"],
                                capture_output=True, text=True, timeout=240)
    assert server.error is None, server.error
    assert result.returncode == 0, result.stdout + result.stderr
    return json.loads((tmp_path / "out" / "report.json").read_text()), heard, events, url


def assert_flown_over_serial(report: dict, heard: HeardLink, events: list[str], url: str) -> None:
    """The whole mission over the serial line, as the runner recorded it and as the vehicle heard it."""
    assert [t["to"] for t in report["transitions"]] == ALL_STATES and report["connect"] == url
    assert report["transitions"][3]["reason"] == "armed" and report["estimator"]["accepted"] > 100
    assert report["search_end"] == "step limit" and not report["failsafes"]
    assert "Armed by external command\t" in events and any(e.startswith("mode OFFBOARD") for e in events)
    assert any(e.startswith("Disarmed by") for e in events) and not any("Failsafe" in e for e in events)
    companion = [(t, m) for t, m in heard.heard if m.get_srcComponent() == mavlink.MAV_COMP_ID_ONBOARD_COMPUTER]
    commands = {m.command for _, m in companion if m.get_type() == "COMMAND_LONG"}
    assert {mavlink.MAV_CMD_COMPONENT_ARM_DISARM, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_DO_SET_MODE,
            mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH} <= commands
    setpoints = [(t, m) for t, m in companion if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
    assert len(setpoints) == report["setpoints_sent"] and {m.type_mask for _, m in setpoints} == {3527}
    times = [t for t, _ in setpoints]
    # 20 Hz from the runner's stream, as the vehicle's clock saw them arrive; never the gap PX4 leaves OFFBOARD on
    assert (len(times) - 1) / (times[-1] - times[0]) > 15.0
    assert max(b - a for a, b in zip(times, times[1:])) < OFFBOARD_LOSS_S


def test_hrlsac_sitl_serves_a_pseudo_terminal_and_prints_its_path():
    sitl = subprocess.Popen([*HRLSAC, "sitl", "--pty", "--api-port", "0", "--gcs-remote", "0", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = [sitl.stdout.readline() for _ in range(3)]
    finally:
        sitl.terminate()
        sitl.communicate(timeout=10)
    (serial,) = [line for line in lines if line.lstrip().startswith("serial")]
    device = serial.split()[1]
    assert device.startswith("/dev/pts/") and f"--connect serial:{device}" in serial
