"""``hrlsac sitl``: run the simulated PX4-like multirotor and wait for MAVLink clients."""
from __future__ import annotations

import argparse
import signal
import sys
import time

from missions.geodesy import GeoPoint
from missions.signing import load_key_file
from sitl_bridge.autopilot import AutopilotEvent
from sitl_bridge.dynamics import Wind
from sitl_bridge.faults import SPEC_HELP, parse_link_faults
from sitl_bridge.server import UdpPorts, VehicleServer
from sitl_bridge.vehicle import DEFAULT_HOME, VehicleConfig

FAILSAFE_ACTIONS = {"hold": 5, "posctl": 0, "land": 4, "rtl": 3}


def build_parser(prog: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description=__doc__.split(":", 1)[1].strip(),
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    home = parser.add_argument_group("vehicle")
    home.add_argument("--home", default=f"{DEFAULT_HOME.lat_deg},{DEFAULT_HOME.lon_deg},{DEFAULT_HOME.alt_m}",
                      help="home as LAT,LON,ALT (degrees, degrees, metres AMSL)")
    home.add_argument("--seed", type=int, default=0, help="sensor-noise seed")
    home.add_argument("--speed", type=float, default=1.0, help="simulated seconds per wall second")
    home.add_argument("--rate", type=float, default=100.0, help="physics ticks per simulated second (>= 100)")
    home.add_argument("--wind", default="0,0", help="steady wind as NORTH,EAST in m/s (the air's velocity)")
    home.add_argument("--gusts", type=float, default=0.0, help="gust amplitude in m/s")
    home.add_argument("--failsafe", choices=sorted(FAILSAFE_ACTIONS), default="posctl",
                      help="offboard-loss action (COM_OBL_RC_ACT); posctl holds position")
    home.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                      help="set a PX4 parameter at boot (repeatable)")
    ports = parser.add_argument_group("links")
    ports.add_argument("--host", default="127.0.0.1", help="address to bind and to send to")
    ports.add_argument("--api-port", type=udp_port, default=14580, help="local port of the API/offboard link")
    ports.add_argument("--api-remote", type=udp_port, default=14540, help="port the API link sends to (MAVSDK)")
    ports.add_argument("--gcs-port", type=udp_port, default=18570, help="local port of the ground-station link")
    ports.add_argument("--gcs-remote", type=udp_port, default=14550, help="port the GCS link sends to; 0 disables it")
    parser.add_argument("--signing-key", metavar="FILE", default=None,
                        help="MAVLink 2 signing key file (from 'hrlsac keygen'): sign everything, reject unsigned, "
                             "wrongly signed and replayed messages except PX4's unsigned allow-list")
    ports.add_argument("--link-faults", metavar="SPEC", default=None,
                       help="inject link faults on the wall clock (seeded by --seed): " + SPEC_HELP)
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
    params = {"COM_OBL_RC_ACT": FAILSAFE_ACTIONS[args.failsafe]}
    for item in args.param:
        name, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--param: expected NAME=VALUE, got {item!r}")
        params[name.strip().upper()] = _floats(value, 1, f"--param {name}")[0]
    key = load_key_file(args.signing_key) if args.signing_key else None
    return VehicleConfig(home=GeoPoint(lat, lon, alt), seed=args.seed, physics_rate_hz=args.rate,
                         wind=Wind(north_mps=wind_north, east_mps=wind_east, gust_mps=args.gusts, seed=args.seed),
                         params=params, signing_key=key)


def main(argv: list[str], prog: str = "hrlsac sitl") -> int:
    args = build_parser(prog).parse_args(argv)
    try:
        config = config_from_args(args)
        ports = UdpPorts(args.host, args.api_port, args.api_remote, args.gcs_port, args.gcs_remote or None)

        def log(event: AutopilotEvent) -> None:
            if not args.quiet:
                print(f"[{event.time_s:9.2f} s] {event.text}", flush=True)

        faults = parse_link_faults(args.link_faults) if args.link_faults else None
        server = VehicleServer(config, ports, speed=args.speed, on_event=log, link_faults=faults)
    except (ValueError, OSError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    home = config.home
    print(f"Simulated PX4 multirotor (sysid {config.system_id}) at {home.lat_deg:.6f}, {home.lon_deg:.6f}, "
          f"{home.alt_m:.1f} m AMSL; {args.speed:g}x real time, seed {args.seed}")
    print(f"  API link  udp {args.host}:{args.api_port} -> {args.host}:{args.api_remote}"
          f"   MAVSDK: udpin://0.0.0.0:{args.api_remote}   pymavlink: udpin:0.0.0.0:{args.api_remote}"
          f" or udpout:{args.host}:{args.api_port}")
    if ports.gcs_remote_port:
        print(f"  GCS link  udp {args.host}:{args.gcs_port} -> {args.host}:{args.gcs_remote}"
              f"   QGroundControl / MAVProxy: --master=udpin:0.0.0.0:{args.gcs_remote}")
    if config.signing_key is not None:
        print(f"  MAVLink 2 signing on (key {args.signing_key}): unsigned messages accepted only for "
              "HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE, COLLISION")
    if faults is not None:
        print(f"  link faults: {faults.describe()} (wall clock from start)")
    print("Ctrl-C stops.", flush=True)
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
    if server.vehicle.signing is not None:
        print(f"signing: {server.vehicle.signing.describe_rejections()}", flush=True)
    if server.error is not None:
        print(f"{prog}: error: {server.error}", file=sys.stderr)
        return 1
    return 0
