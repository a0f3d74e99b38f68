"""The ``hrlsac`` command: dispatcher, ``hrlsac sitl`` as a real process, ``hrlsac demo``."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import socket
import sys

import pytest
from conftest import UdpClient, free_udp_ports

HRLSAC = [sys.executable, "-m", "hrlsac_cli"]


def run(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([*HRLSAC, *args], capture_output=True, text=True, timeout=timeout)


def test_help_lists_commands_without_importing_heavy_packages():
    code = ("import sys, hrlsac_cli; hrlsac_cli.main(['--help']); "
            "print(sorted(m for m in ('torch', 'pymavlink', 'gymnasium', 'cv2') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60).stdout
    assert "sitl" in out and "demo" in out
    assert out.strip().endswith("[]")


@pytest.mark.parametrize("command", [["sitl"], ["train"], ["sweep"], ["evaluate"], ["export"], ["mission", "replay"],
                                     ["mission", "run"], ["dataset", "synth"]])
def test_help_states_real_defaults_once_and_no_empty_ones(command):
    from cli_harness import run_cli

    result = run_cli(*command, "--help")
    text = " ".join(result.out.split())  # argparse wraps lines
    assert result.code == 0 and "--help" in text
    assert "(default: None)" not in text and "(default: False)" not in text and "(default: [])" not in text
    assert not re.search(r"\(default[^)]*\) \(default", text), text  # never twice for one option
    if command == ["sitl"]:
        assert "--home HOME home as LAT,LON,ALT (degrees, degrees, metres AMSL) (default: 47.397742,8.545594,488.0)" \
            in text
    if command == ["mission", "replay"]:
        assert "output folder (default: mission-output/MISSION-NAME) --seed" in text


def test_unknown_command_is_a_one_line_error():
    result = run("fly-to-the-moon")
    assert result.returncode == 2
    assert result.stderr.startswith("hrlsac: error: unknown command 'fly-to-the-moon' (choose from sitl, demo")
    assert len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("args, message", [
    (["--home", "47.3,8.5"], "--home: expected 3 comma-separated numbers"),
    (["--home", "95,8.5,400"], "lat_deg"),
    (["--speed", "0"], "speed must be > 0"),
    (["--rate", "20"], "VehicleConfig.physics_rate_hz must be a number in [100, 2000]"),
    (["--param", "MPC_XY_CRUISE=99"], "MPC_XY_CRUISE: 99 is outside"),
    (["--param", "NOPE=1"], "unknown parameter 'NOPE'"),
])
def test_sitl_rejects_bad_arguments_with_a_clear_error(args, message):
    result = run("sitl", "--api-port", str(free_udp_ports(1)[0]), *args)
    assert result.returncode == 2
    assert message in result.stderr
    assert "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_demo_flies_and_reports():
    result = run("demo", "--seed", "3", timeout=120)
    assert result.returncode == 0, result.stderr
    assert "Commands: arm ACCEPTED, takeoff ACCEPTED, offboard ACCEPTED, rtl ACCEPTED" in result.stdout
    assert "Failsafe: offboard setpoints lost" in result.stdout
    assert "Landed and disarmed 0.0 m from home" in result.stdout


@pytest.mark.slow
def test_sitl_process_serves_both_links_answers_peers_and_stops_on_ctrl_c():
    api_port, api_remote, gcs_port, gcs_remote = free_udp_ports(4)
    process = subprocess.Popen([*HRLSAC, "sitl", "--api-port", str(api_port), "--api-remote", str(api_remote),
                                "--gcs-port", str(gcs_port), "--gcs-remote", str(gcs_remote), "--speed", "2"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env={**os.environ, "PYTHONUNBUFFERED": "1"})
    gcs = UdpClient(f"udpin:127.0.0.1:{gcs_remote}")  # QGroundControl-style listener
    peer = UdpClient(f"udpout:127.0.0.1:{api_port}")  # a script that writes to the vehicle first
    try:
        assert gcs.wait_message("HEARTBEAT", 10.0).autopilot == 12
        peer.conn.mav.heartbeat_send(6, 8, 0, 0, 0)  # GCS heartbeat: now the vehicle knows this peer
        ack = peer.command(400, 1, timeout_s=5.0)
        assert ack.result == 0 and ack.target_system == 255
        # the mode/arming change reaches the other link too
        gcs.wait(lambda: gcs.latest["HEARTBEAT"].base_mode & 128, 5.0, "armed heartbeat on the GCS link")
    finally:
        gcs.close()
        peer.close()
        process.send_signal(signal.SIGINT)
        stdout, stderr = process.communicate(timeout=10)
    assert process.returncode == 0, stderr
    assert f"udpin://0.0.0.0:{api_remote}" in stdout  # tells MAVSDK users where to connect
    assert "command COMPONENT_ARM_DISARM from 255/190: ACCEPTED" in stdout
    assert "stopping" in stdout


def test_sitl_reports_a_busy_port():
    api_port, api_remote = free_udp_ports(2)
    blocker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    blocker.bind(("127.0.0.1", api_port))
    try:
        result = run("sitl", "--api-port", str(api_port), "--api-remote", str(api_remote), "--gcs-remote", "0")
    finally:
        blocker.close()
    assert result.returncode == 2
    assert f"cannot bind UDP 127.0.0.1:{api_port}" in result.stderr

