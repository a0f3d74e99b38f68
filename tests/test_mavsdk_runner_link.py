"""The runner's MAVSDK backend (``autonomy.mavsdk_link.MavsdkLink``) against the simulated PX4 over real UDP: it
hears the autopilot's status texts (Telemetry.status_text) and probes the uplink with TIMESYNC (the MavlinkDirect
plugin).

MAVSDK listens with ``udpin://0.0.0.0:PORT`` and the vehicle's API link sends to PORT, as with PX4 SITL. Every await
is bounded; the vehicle runs at 2x real time to keep the test short (mavsdk_helpers.py).
"""
from __future__ import annotations

import pytest

mavsdk = pytest.importorskip("mavsdk.asyncio")
from mavsdk_helpers import T, vehicle_server  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.mavsdk]


def test_the_runners_mavsdk_link_hears_the_autopilots_status_texts(udp_ports):
    """The runner's safety vetoes read the autopilot's STATUSTEXTs (autonomy.link_loss): the MAVSDK backend gets them
    from Telemetry.status_text, joined as the pymavlink backend joins them."""
    import time

    from autonomy.mavsdk_link import MavsdkLink

    server, mavsdk_port = vehicle_server(udp_ports, 11)
    with server:
        link = MavsdkLink(f"udpin:0.0.0.0:{mavsdk_port}", time.monotonic)
        try:
            text = "Geofence: exceeding maximum distance to Home"  # PX4's health check text (sitl_bridge.px4.geofence)
            deadline = time.monotonic() + T
            while text not in [t for _, t in link.status_since(0)] and time.monotonic() < deadline:
                server.vehicle.autopilot._event(server.vehicle.time_s, text, 2)  # again until MAVSDK has subscribed
                time.sleep(0.5)
            received = [t for _, t in link.status_since(0)]
        finally:
            link.close()
    assert text in received and link.status_count == len(received)
    assert link.status_since(link.status_count) == []


def test_the_runners_mavsdk_link_probes_the_uplink_with_timesync(udp_ports):
    """The uplink probe (autonomy.uplink_probe) through MAVSDK's MavlinkDirect plugin: requests with tc1 = 0 go out,
    the vehicle's replies come back with the same ts1, and the probe counts them answered."""
    import time

    from autonomy.mavsdk_link import MavsdkLink
    from autonomy.uplink_probe import UplinkProbe, UplinkProbeConfig

    server, mavsdk_port = vehicle_server(udp_ports, 12)
    with server:
        link = MavsdkLink(f"udpin:0.0.0.0:{mavsdk_port}", time.monotonic)
        try:
            probe = UplinkProbe(UplinkProbeConfig(), link.send_timesync_request)
            deadline = time.monotonic() + T
            while probe.answered < 5 and time.monotonic() < deadline:
                probe.tick(time.monotonic(), link.take_timesync_replies(), active=True)
                time.sleep(0.1)
            link.send_timesync_request(424242)
            while 424242 not in (replies := link.take_timesync_replies()) and time.monotonic() < deadline:
                time.sleep(0.05)
        finally:
            link.close()
    assert probe.answered >= 5 and probe.sent - probe.answered <= 2  # the last ones may still be in flight
    assert 424242 in replies
