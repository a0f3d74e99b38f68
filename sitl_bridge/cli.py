"""``hrlsac sitl``: run the simulated multirotor (a PX4 or ArduPilot Copter autopilot) and wait for MAVLink clients."""
from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
import time

from hrlsac_cli.help_format import HelpFormatter
from missions.geodesy import GeoPoint
from mavlink_signing import load_key_file
from sitl_bridge.ardupilot.params import STREAM_GROUPS, STREAM_LINKS
from sitl_bridge.autopilot_base import AutopilotEvent
from sitl_bridge.faults import SPEC_HELP, parse_link_faults
from sitl_bridge.serial_link import SerialLink, open_pty_link, open_serial_link
from sitl_bridge.server import UdpPorts, VehicleServer, fleet_configs
from sitl_bridge.telemetry_profiles import PROFILES, resolve_profile
from sitl_bridge.vehicle import SYSTEM_ID_PARAM
from sitl_bridge.vehicle_config import AUTOPILOT_TYPES, DEFAULT_HOME, VehicleConfig
from sitl_bridge.wind import Wind

FAILSAFE_ACTIONS = {"hold": 5, "posctl": 0, "land": 4, "rtl": 3}
DEFAULT_BAUD = 57600


def build_parser(prog: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split(":", 1)[1].strip(),
                                     formatter_class=HelpFormatter)
    home = parser.add_argument_group("vehicle")
    home.add_argument("--autopilot", choices=AUTOPILOT_TYPES, default="px4",
                      help="autopilot personality: PX4 (OFFBOARD, PX4 SITL ports) or ArduPilot Copter (GUIDED, "
                           "ArduPilot SITL ports)")
    home.add_argument("--home", default=f"{DEFAULT_HOME.lat_deg},{DEFAULT_HOME.lon_deg},{DEFAULT_HOME.alt_m}",
                      help="home as LAT,LON,ALT (degrees, degrees, metres AMSL)")
    home.add_argument("--seed", type=int, default=0, help="sensor-noise seed")
    home.add_argument("--speed", type=float, default=1.0, help="simulated seconds per wall second")
    home.add_argument("--rate", type=float, default=100.0, help="physics ticks per simulated second (>= 100)")
    home.add_argument("--wind", default="0,0", help="steady wind as NORTH,EAST in m/s (the air's velocity)")
    home.add_argument("--gusts", type=float, default=0.0, help="gust amplitude in m/s")
    home.add_argument("--failsafe", choices=sorted(FAILSAFE_ACTIONS), default=None,
                      help="PX4 offboard-loss action (COM_OBL_RC_ACT; default posctl: position hold); for ArduPilot "
                           "use --param FS_GCS_ENABLE=... and GUID_TIMEOUT")
    home.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                      help="set a parameter of the autopilot at boot (repeatable)")
    home.add_argument("--telemetry-profile", choices=PROFILES, default="default",
                      help="default stream rates: default (legacy for PX4, ardupilot for ArduPilot), legacy, px4 "
                           "(onboard mode on the API link, normal on the GCS link), px4_sitl, ardupilot (nothing "
                           "but HEARTBEAT until requested)")
    home.add_argument("--boot-time", type=float, default=0.0, metavar="S",
                      help="the autopilot booted this many seconds before the simulation (time_boot_ms starts there)")
    home.add_argument("--reboot-at", type=float, default=None, metavar="S",
                      help="reboot the autopilot at this simulated time (airborne, the vehicle falls)")
    home.add_argument("--reboot-downtime", type=float, default=5.0, metavar="S",
                      help="seconds the autopilot stays silent while it reboots")
    fleet = parser.add_argument_group("several vehicles (PX4 SITL's and ArduPilot's instance numbering)")
    fleet.add_argument("--count", type=int, default=1,
                       help="vehicles to run in this process: instance N speaks as system N+1 on the instance's ports "
                            "(PX4: API 14580+N -> 14540+N, GCS 18570+N -> 14550; ArduPilot: every port +10N, GCS "
                            "-> 14550, companion -> 14551+10N)")
    fleet.add_argument("--instance", type=int, default=0,
                       help="the first vehicle's instance number (as px4 -i N or sim_vehicle.py -I N)")
    fleet.add_argument("--offset-line", metavar="BEARING,DISTANCE", default=None,
                       help="each further vehicle's home this far (m) along this bearing (degrees) from the one "
                            "before (ArduPilot's --auto-offset-line; default: PX4 0,3 as sitl_multiple_run.sh, "
                            "ArduPilot 90,10)")
    ports = parser.add_argument_group("links (defaults: PX4 SITL's, or for --autopilot ardupilot TCP 5760, "
                                      "GCS 14560 -> 14550, companion 14561 -> 14551)")
    ports.add_argument("--host", default="127.0.0.1", help="address to bind and to send to")
    ports.add_argument("--api-port", type=udp_port, default=None, help="local port of the API/companion link")
    ports.add_argument("--api-remote", type=udp_port, default=None,
                       help="port the API/companion link sends to (PX4: 14540 for MAVSDK; ArduPilot: 14551)")
    ports.add_argument("--gcs-port", type=udp_port, default=None, help="local port of the ground-station link")
    ports.add_argument("--gcs-remote", type=udp_port, default=None,
                       help="port the GCS link sends to (14550); 0 disables it")
    ports.add_argument("--tcp-port", type=udp_port, default=None,
                       help="TCP server port (ArduPilot SERIAL0, 5760; PX4: none); 0 disables it")
    ports.add_argument("--pty", action="store_true",
                       help="also serve a serial line on a new pseudo-terminal; its path is printed (a client "
                            "connects with serial:PATH, e.g. hrlsac mission run --connect serial:/dev/pts/5)")
    ports.add_argument("--serial", metavar="DEVICE[:BAUD]", default=None,
                       help=f"also serve a serial device (default {DEFAULT_BAUD} baud), e.g. /dev/ttyUSB0:921600")
    parser.add_argument("--signing-key", metavar="FILE", default=None,
                        help="MAVLink 2 signing key file (from 'hrlsac keygen'): sign everything, reject unsigned, "
                             "wrongly signed and replayed messages except PX4's unsigned allow-list")
    ports.add_argument("--link-faults", metavar="SPEC", default=None,
                       help="inject link faults on the UDP links, wall clock (seeded by --seed): " + SPEC_HELP)
    parser.add_argument("--quiet", action="store_true", help="do not log commands and mode changes")
    return parser


def udp_port(text: str) -> int:
    """argparse type of a UDP port number: an integer in [0, 65535] (the socket module overflows beyond)."""
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"invalid port {text!r} (an integer in 0-65535)")
    return port


def _floats(text: str, count: int, what: str) -> list[float]:
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        values = []
    if len(values) != count:
        raise ValueError(f"{what}: expected {count} comma-separated numbers, got {text!r}")
    return values


def config_from_args(args: argparse.Namespace) -> VehicleConfig:
    lat, lon, alt = _floats(args.home, 3, "--home")
    wind_north, wind_east = _floats(args.wind, 2, "--wind")
    params: dict[str, float] = {}
    if args.failsafe is not None:
        if args.autopilot != "px4":
            raise ValueError("--failsafe sets PX4's COM_OBL_RC_ACT; for ArduPilot use --param FS_GCS_ENABLE=N "
                             "(and GUID_TIMEOUT)")
        params["COM_OBL_RC_ACT"] = FAILSAFE_ACTIONS[args.failsafe]
    for item in args.param:
        name, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--param: expected NAME=VALUE, got {item!r}")
        params[name.strip().upper()] = _floats(value, 1, f"--param {name}")[0]
    key = load_key_file(args.signing_key) if args.signing_key else None
    return VehicleConfig(home=GeoPoint(lat, lon, alt), seed=args.seed, physics_rate_hz=args.rate,
                         wind=Wind(north_mps=wind_north, east_mps=wind_east, gust_mps=args.gusts, seed=args.seed),
                         params=params, signing_key=key, autopilot=args.autopilot,
                         telemetry_profile=args.telemetry_profile, boot_time_s=args.boot_time,
                         reboot_at_s=args.reboot_at, reboot_downtime_s=args.reboot_downtime)


def serial_links_from_args(args: argparse.Namespace) -> tuple[SerialLink, ...]:
    """The serial lines asked for: a new pseudo-terminal (--pty), a serial device (--serial DEVICE[:BAUD])."""
    links = []
    if args.serial:
        device, _, baud = args.serial.rpartition(":")
        if not baud.isdigit():
            device, baud = args.serial, str(DEFAULT_BAUD)
        links.append(open_serial_link(device, int(baud)))
    if args.pty:
        links.append(open_pty_link("pty")[0])
    return tuple(links)


def ports_from_args(args: argparse.Namespace, k: int = 0) -> UdpPorts:
    """The ports of the ``k``-th vehicle (from 0): its instance's defaults, or the ones given on the command line,
    which with ``--count`` are the first vehicle's and move up with the instance as the defaults do (by 1 for PX4,
    10 for ArduPilot), except the GCS port all of them send to. 0 disables GCS and TCP."""
    ports = UdpPorts.for_instance(args.autopilot, args.instance + k, args.host)
    step = k * (10 if args.autopilot == "ardupilot" else 1)
    given = {"api_port": args.api_port, "api_remote_port": args.api_remote, "gcs_port": args.gcs_port,
             "gcs_remote_port": args.gcs_remote, "tcp_port": args.tcp_port}
    given = {name: (None if value == 0 and name in ("gcs_remote_port", "tcp_port")
                    else value if name == "gcs_remote_port" or value == 0 else value + step)
             for name, value in given.items() if value is not None}
    return dataclasses.replace(ports, **given)


def fleet_from_args(args: argparse.Namespace, base: VehicleConfig) -> list[tuple[VehicleConfig, UdpPorts]]:
    """Every vehicle of ``--count`` with its ports; one-line errors for what a fleet cannot take."""
    if not 1 <= args.count <= 32:
        raise ValueError(f"--count must be in [1, 32], got {args.count}")
    if not 0 <= args.instance <= 200:
        raise ValueError(f"--instance must be in [0, 200], got {args.instance}")
    if args.count == 1:
        single = dataclasses.replace(base, system_id=args.instance + 1) if args.instance else base
        return [(single, ports_from_args(args))]
    if args.pty or args.serial:
        raise ValueError(f"{'--pty' if args.pty else '--serial'} serves one vehicle; run one hrlsac sitl per "
                         "vehicle on a serial line")
    if SYSTEM_ID_PARAM[args.autopilot] in base.params:
        raise ValueError(f"--param {SYSTEM_ID_PARAM[args.autopilot]}: with --count each instance N is system N+1")
    line = tuple(_floats(args.offset_line, 2, "--offset-line")) if args.offset_line else None
    configs = fleet_configs(base, args.count, args.instance, line)
    return [(config, ports_from_args(args, k)) for k, config in enumerate(configs)]


def main(argv: list[str], prog: str = "hrlsac sitl") -> int:
    args = build_parser(prog).parse_args(argv)
    try:
        fleet = fleet_from_args(args, config_from_args(args))
        faults = parse_link_faults(args.link_faults) if args.link_faults else None
        if len(fleet) == 1:
            (config, ports), = fleet

            def log(event: AutopilotEvent) -> None:
                if not args.quiet:
                    print(f"[{event.time_s:9.2f} s] {event.text}", flush=True)

            server = VehicleServer(config, ports, speed=args.speed, on_event=log, link_faults=faults,
                                   extra_links=serial_links_from_args(args))
        else:
            def log_vehicle(index: int, event: AutopilotEvent) -> None:
                if not args.quiet:
                    print(f"[{event.time_s:9.2f} s] sysid {fleet[index][0].system_id}: {event.text}", flush=True)

            server = VehicleServer.fleet(fleet, speed=args.speed, on_event=log_vehicle, link_faults=faults)
    except (ValueError, OSError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    for index, (config, ports) in enumerate(fleet):
        print_connections(config, ports, server, args, index)
    print_settings(fleet[0][0], server, args)
    # A process started in the background by a non-interactive shell inherits SIGINT as ignored, and Python then
    # installs no KeyboardInterrupt handler: install it, and treat SIGTERM (service managers, kill) the same.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    server.start()
    try:
        while server.running:
            time.sleep(0.2)
    except KeyboardInterrupt:
        print("\nstopping", flush=True)
    finally:
        server.stop()
    for vehicle in server.vehicles:
        if vehicle.signing is not None:
            which = f" (sysid {vehicle.system_id})" if len(server.vehicles) > 1 else ""
            print(f"signing{which}: {vehicle.signing.describe_rejections()}", flush=True)
    if server.error is not None:
        print(f"{prog}: error: {server.error}", file=sys.stderr)
        return 1
    return 0


def print_connections(config: VehicleConfig, ports: UdpPorts, server: VehicleServer, args: argparse.Namespace,
                      index: int = 0) -> None:
    """What vehicle ``index`` of the server is, and the connection string of each of its links for the usual
    clients."""
    home, host = config.home, ports.host
    name = "ArduPilot Copter" if config.autopilot == "ardupilot" else "PX4"
    which = f"vehicle {index + 1} of {len(server.vehicles)}: " if len(server.vehicles) > 1 else ""
    print(f"{which}Simulated {name} multirotor (sysid {server.vehicles[index].system_id}) at {home.lat_deg:.6f}, "
          f"{home.lon_deg:.6f}, {home.alt_m:.1f} m AMSL; {args.speed:g}x real time, seed {config.seed}")
    ardupilot = config.autopilot == "ardupilot"
    for link_index, link in enumerate(server.vehicle_links[index]):
        streams = f" (SR{link_index}_*)" if ardupilot else ""
        if isinstance(link, SerialLink):
            print(f"  serial    {link.device}{streams}   mission run: --connect serial:{link.device}"
                  f"   MAVProxy: --master={link.device}")
        elif link.name == "tcp":
            print(f"  SERIAL0   tcp {host}:{ports.tcp_port}{streams}   MAVProxy: --master=tcp:{host}:{ports.tcp_port}"
                  f"   pymavlink: tcp:{host}:{ports.tcp_port}")
        elif link.name == "gcs":
            print(f"  GCS link  udp {host}:{ports.gcs_port} -> {host}:{ports.gcs_remote_port}{streams}"
                  f"   QGroundControl / MAVProxy: --master=udpin:0.0.0.0:{ports.gcs_remote_port}")
        else:
            label = "companion" if ardupilot else "API link "
            print(f"  {label} udp {host}:{ports.api_port} -> {host}:{ports.api_remote_port}{streams}"
                  f"   MAVSDK: udpin://0.0.0.0:{ports.api_remote_port}   pymavlink / mission run: "
                  f"udpin:0.0.0.0:{ports.api_remote_port} or udpout:{host}:{ports.api_port}")


def print_settings(config: VehicleConfig, server: VehicleServer, args: argparse.Namespace) -> None:
    """What every vehicle of the server shares: telemetry, boot, signing, link faults."""
    if len(server.vehicles) > 1:
        print(f"  all {len(server.vehicles)} vehicles send to the GCS port, each as its own system id "
              "(QGroundControl and MAVProxy's 'vehicle N' tell them apart)")
    profile = resolve_profile(config.telemetry_profile, config.autopilot)
    if profile == "ardupilot":
        print_ardupilot_streams(server)
    else:
        print(f"  telemetry profile: {profile}")
    if config.boot_time_s or config.reboot_at_s is not None:
        reboot = f", reboots at {config.reboot_at_s:g} s for {config.reboot_downtime_s:g} s" \
            if config.reboot_at_s is not None else ""
        print(f"  autopilot booted {config.boot_time_s:g} s before the start{reboot}")
    if config.signing_key is not None:
        print(f"  MAVLink 2 signing on (key {args.signing_key}): unsigned messages accepted only for "
              "HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE, COLLISION")
    if args.link_faults:
        print(f"  link faults: {parse_link_faults(args.link_faults).describe()} (UDP links, wall clock from start)")
    print("Ctrl-C stops.", flush=True)


def print_ardupilot_streams(server: VehicleServer) -> None:
    """The SRn_* stream rates of each link, and what a MAVSDK user must add when the companion link streams no
    SYS_STATUS (MAVSDK asks ArduPilot for no stream; its ``telemetry.health()`` is read from SYS_STATUS)."""
    params = server.vehicle.params
    streaming = {index: {group: params[f"SR{index}_{group}"] for group in STREAM_GROUPS
                         if params[f"SR{index}_{group}"] > 0}
                 for index in range(min(len(server.links), STREAM_LINKS))}
    if not any(streaming.values()):
        print("  telemetry: ArduPilot defaults (SRn_* = 0): only HEARTBEAT until a client sends REQUEST_DATA_STREAM "
              "or MAV_CMD_SET_MESSAGE_INTERVAL")
    for index, rates in streaming.items():
        if rates:
            print(f"  telemetry: SR{index}_* " + ", ".join(f"{group} {rate:g} Hz" for group, rate in rates.items()))
    companion = next((i for i, link in enumerate(server.links) if link.name == "api"), None)
    if companion is not None and companion < STREAM_LINKS and not streaming[companion].get("EXT_STAT"):
        sr = f"SR{companion}"
        print(f"  MAVSDK on the companion link: it requests no streams from ArduPilot, so telemetry.health() never "
              f"reports a global position; start with --param {sr}_EXT_STAT=2 --param {sr}_POSITION=5 "
              f"--param {sr}_EXTRA1=4 (docs/sitl.md, \"MAVSDK and ArduPilot\")")
