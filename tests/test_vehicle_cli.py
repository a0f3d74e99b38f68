"""``hrlsac sitl`` options of the vehicle: the autopilot personality, its ports and the realism options.

Bad input is one line on stderr and exit code 2, before any socket is opened.
"""
from __future__ import annotations

import dataclasses

import pytest

from sitl_bridge import cli


def error_of(capsys, argv: list[str]) -> str:
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("hrlsac sitl: error: ")
    return err


@pytest.mark.parametrize("argv, message", [
    (["--autopilot", "ardupilot", "--failsafe", "rtl"], "--failsafe sets PX4's COM_OBL_RC_ACT"),
    (["--boot-time", "-5"], "VehicleConfig.boot_time_s must be a number in [0, 1e+07], got -5.0"),
    (["--reboot-at", "10", "--reboot-downtime", "0"], "VehicleConfig.reboot_downtime_s must be a number in [0.1, 600]"),
    (["--autopilot", "ardupilot", "--param", "COM_OF_LOSS_T=3"], "unknown parameter 'COM_OF_LOSS_T'"),
    (["--autopilot", "ardupilot", "--param", "GUID_TIMEOUT=9"], "GUID_TIMEOUT: 9 is outside [0.1, 5]"),
])
def test_bad_vehicle_options_are_one_line_errors(capsys, argv, message):
    assert message in error_of(capsys, argv)


def test_an_unknown_autopilot_or_profile_is_refused_by_argparse(capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["--autopilot", "inav"])
    assert exit_info.value.code == 2 and "invalid choice: 'inav'" in capsys.readouterr().err


def test_ardupilot_options_make_the_config_and_sitl_like_ports():
    args = cli.build_parser("hrlsac sitl").parse_args(
        ["--autopilot", "ardupilot", "--home", "43.1,5.9,12", "--boot-time", "600", "--reboot-at", "90",
         "--reboot-downtime", "8", "--telemetry-profile", "legacy", "--param", "GUID_TIMEOUT=1.5"])
    config = cli.config_from_args(args)
    assert (config.autopilot, config.telemetry_profile, config.boot_time_s) == ("ardupilot", "legacy", 600.0)
    assert (config.reboot_at_s, config.reboot_downtime_s, config.params) == (90.0, 8.0, {"GUID_TIMEOUT": 1.5})
    assert (config.home.lat_deg, config.home.lon_deg, config.home.alt_m) == (43.1, 5.9, 12.0)
    ports = cli.ports_from_args(args)
    assert (ports.tcp_port, ports.gcs_port, ports.gcs_remote_port, ports.api_port, ports.api_remote_port) == (
        5760, 14560, 14550, 14561, 14551)
    no_tcp = cli.ports_from_args(cli.build_parser("x").parse_args(["--autopilot", "ardupilot", "--tcp-port", "0",
                                                                   "--api-remote", "14600"]))
    assert (no_tcp.tcp_port, no_tcp.api_remote_port) == (None, 14600)


def test_px4_keeps_its_sitl_ports_and_its_failsafe_flag():
    args = cli.build_parser("hrlsac sitl").parse_args(["--failsafe", "rtl"])
    assert cli.config_from_args(args).params == {"COM_OBL_RC_ACT": 3}
    assert cli.config_from_args(cli.build_parser("x").parse_args([])).params == {}  # PX4's own default (0)
    ports = cli.ports_from_args(args)
    assert (ports.api_port, ports.api_remote_port, ports.gcs_port, ports.gcs_remote_port, ports.tcp_port) == (
        14580, 14540, 18570, 14550, None)


def banner(capsys, server_params: dict[str, float], udp_ports: list[int]) -> list[str]:
    """The ``hrlsac sitl`` banner's telemetry lines of an ArduPilot vehicle (links: GCS, then companion)."""
    from sitl_bridge.server import UdpPorts, VehicleServer

    args = cli.build_parser("hrlsac sitl").parse_args(["--autopilot", "ardupilot"])
    config = dataclasses.replace(cli.config_from_args(args), params=server_params)
    ports = UdpPorts(api_port=udp_ports[0], api_remote_port=udp_ports[1], gcs_port=udp_ports[2],
                     gcs_remote_port=udp_ports[3])
    server = VehicleServer(config, ports)
    try:
        cli.print_connections(config, ports, server, args)
        cli.print_settings(config, server, args)
    finally:
        server.close()
    return [line.strip() for line in capsys.readouterr().out.splitlines() if "telemetry" in line or "MAVSDK on" in line]


def test_the_ardupilot_banner_says_what_streams_and_what_mavsdk_needs(capsys, udp_ports):
    lines = banner(capsys, {}, udp_ports)  # without a TCP port the API link is link 0 and the GCS link 1
    assert lines[0].startswith("telemetry: ArduPilot defaults (SRn_* = 0)")
    assert lines[1].startswith("MAVSDK on the companion link") and "--param SR0_EXT_STAT=2" in lines[1]
    lines = banner(capsys, {"SR0_EXT_STAT": 2.0, "SR0_POSITION": 5.0, "SR1_EXTRA1": 4.0}, udp_ports)
    assert lines == ["telemetry: SR0_* EXT_STAT 2 Hz, POSITION 5 Hz", "telemetry: SR1_* EXTRA1 4 Hz"]
