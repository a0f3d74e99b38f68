"""One ground-station port carrying a fleet (``autonomy.shared_port``): two simulated PX4 vehicles send their
ground-station links from their own UDP ports to one port, as PX4 SITL instances send theirs to 14550; the runner's
links on that port each see only their own vehicle, and what each sends reaches only its own vehicle. Real UDP
sockets, the vehicles stepped in lockstep."""
from __future__ import annotations

import socket

import pytest
from conftest import free_udp_ports
from pymavlink.dialects.v20 import common as mavlink

from autonomy.shared_port import frame_system_id, open_shared_port
from autonomy.vehicle_link import COMPANION_COMPONENT, LinkError, VehicleLink
from missions.geodesy import LocalFrame
from sitl_bridge.link import UdpLink
from sitl_bridge.vehicle import SimulatedVehicle
from sitl_bridge.vehicle_config import DEFAULT_HOME, VehicleConfig


def test_the_system_id_is_read_from_the_first_frame_header():
    encoder = mavlink.MAVLink(None, srcSystem=7, srcComponent=1)
    v2 = encoder.heartbeat_encode(2, 12, 0, 0, 0).pack(encoder)
    assert frame_system_id(v2) == 7 and frame_system_id(v2 + v2) == 7
    v1 = bytes([0xFE, 9, 0, 42, 1, 0]) + bytes(11)  # MAVLink 1: magic, length, sequence, system, component, id
    assert frame_system_id(v1) == 42
    assert frame_system_id(b"hello, not mavlink") is None and frame_system_id(v2[:5]) is None


@pytest.fixture
def two_vehicles_on_one_port():
    shared_port, first_port, second_port = free_udp_ports(3)
    port = open_shared_port(f"udpin:127.0.0.1:{shared_port}")
    frame = LocalFrame(DEFAULT_HOME)
    vehicles = []
    for system_id, (own_port, east_m) in enumerate(((first_port, 0.0), (second_port, 40.0)), start=1):
        lat, lon, alt = frame.to_geodetic(0.0, east_m, 0.0)
        home = DEFAULT_HOME.__class__(lat, lon, alt)
        gcs = UdpLink(f"gcs{system_id}", ("127.0.0.1", own_port), ("127.0.0.1", shared_port))
        vehicles.append(SimulatedVehicle(VehicleConfig(home=home, seed=system_id, system_id=system_id), [gcs]))
    clock = [0.0]
    links = [VehicleLink(port.channel(system_id, COMPANION_COMPONENT), lambda: clock[0]) for system_id in (1, 2)]

    def run(seconds: float) -> None:
        for _ in range(int(seconds * 100)):
            for vehicle in vehicles:
                vehicle.step()
            clock[0] = vehicles[0].time_s
            for link in links:
                link.tick()

    yield port, vehicles, links, run
    for link in links:
        link.close()
    for vehicle in vehicles:
        for link in vehicle.links:
            link.close()


def test_each_drone_of_a_fleet_hears_only_its_own_vehicle_on_one_port(two_vehicles_on_one_port):
    port, vehicles, links, run = two_vehicles_on_one_port
    run(3.0)
    assert [link.target_system for link in links] == [1, 2]
    frame = LocalFrame(DEFAULT_HOME)
    east = [frame.to_ned(p.lat / 1e7, p.lon / 1e7, p.alt / 1e3)[1]
            for p in (link.latest["GLOBAL_POSITION_INT"] for link in links)]
    assert east == pytest.approx([0.0, 40.0], abs=3.0)
    assert all(link.conn.sysid_state.keys() <= {0, link.target_system} for link in links)

    # a datagram of a system id no drone flies, and one that is not MAVLink: dropped, not delivered
    stranger = mavlink.MAVLink(None, srcSystem=9, srcComponent=1)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.sendto(stranger.heartbeat_encode(2, 12, 0, 0, 0).pack(stranger), port.sock.getsockname())
        sock.sendto(b"not mavlink", port.sock.getsockname())
    run(0.1)
    assert port.dropped == 2 and [link.target_system for link in links] == [1, 2]


def test_what_a_drone_sends_on_the_shared_port_reaches_only_its_own_vehicle(two_vehicles_on_one_port):
    _, vehicles, links, run = two_vehicles_on_one_port
    run(3.0)  # both vehicles heard: the port knows where each one is
    links[1].send_command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,))
    run(0.5)
    ack = links[1].ack_for(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0.0)
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
    assert links[1].armed and vehicles[1].autopilot.armed
    assert not links[0].armed and not vehicles[0].autopilot.armed
    assert links[0].ack_for(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0.0) is None


def test_a_fleet_port_must_be_a_udpin_port_and_free():
    with pytest.raises(LinkError, match="write udpin:HOST:PORT"):
        open_shared_port("udpout:127.0.0.1:14550")
    (busy,) = free_udp_ports(1)
    port = open_shared_port(f"udpin:127.0.0.1:{busy}")
    try:
        with pytest.raises(LinkError, match=f"cannot open connection 'udpin:127.0.0.1:{busy}'"):
            open_shared_port(f"udpin:127.0.0.1:{busy}")
        with pytest.raises(ValueError, match="already has a channel for system id 1"):
            port.channel(1, COMPANION_COMPONENT), port.channel(1, COMPANION_COMPONENT)
    finally:
        port.close()
