"""The runner's evidence of an uplink-only outage (autonomy.uplink_probe) and the settle before judging a mode change.

Real PX4 >= 1.14 announces every failsafe with the same STATUSTEXT, "Failsafe activated" (FailsafeBase::notifyUser),
so the runner learns of an uplink outage from the vehicle no longer answering its TIMESYNC requests, and waits
``settle_s`` after a mode change for a safety text that PX4's health report may send up to 2 s late.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import pytest

from autonomy.autopilots import PX4
from autonomy.failsafes import judge_search
from autonomy.link_loss import LinkLossConfig, LinkLossMonitor
from autonomy.runner_config import RunnerConfig
from autonomy.uplink_probe import UplinkProbe, UplinkProbeConfig
from autonomy.vehicle_link import VehicleLink
from autonomy.vehicle_time import BootTimeMap
from sitl_bridge.link import MemoryMavConnection, memory_link_pair
from sitl_bridge.vehicle import SimulatedVehicle, VehicleConfig

TICK = 0.01


def run_probe(probe: UplinkProbe, start: float, end: float, answered) -> list[float | None]:
    """Tick ``probe`` from ``start`` to ``end``; a request is answered at once when ``answered(sent_at)``. Returns
    unanswered_since at every tick."""
    seen, in_flight = [], []
    probe_send = probe._send
    probe._send = lambda ts1: in_flight.append(ts1)
    for step in range(int(round((end - start) / TICK))):
        now = start + step * TICK
        replies = [ts1 for ts1 in in_flight if answered(ts1 / 1e9)]
        in_flight.clear()
        probe.tick(now, replies, active=True)
        seen.append(probe.unanswered_since(now))
    probe._send = probe_send
    return seen


def test_a_deaf_stretch_is_a_run_of_unanswered_requests_not_one_lost_reply():
    probe = UplinkProbe(UplinkProbeConfig(), lambda ts1: None)
    lost_one = run_probe(probe, 0.0, 3.0, lambda sent: not math.isclose(sent, 1.0, abs_tol=1e-6))
    assert lost_one == [None] * len(lost_one)  # a single lost request or reply is ordinary on a radio
    assert probe.take_ended() == []
    deaf = run_probe(probe, 3.0, 6.0, lambda sent: not 4.0 <= sent < 5.5)  # the vehicle hears nothing for 1.5 s
    first = next(i for i, since in enumerate(deaf) if since is not None)
    # seen while it lasts once the requests unanswered past the 0.5 s timeout span 0.5 s: at 4.0 + 0.5 + 0.5
    assert 3.0 + first * TICK == pytest.approx(5.0, abs=0.015) and deaf[first] == pytest.approx(4.0, abs=1e-6)
    assert deaf[-1] is None  # answered again from 5.5
    assert [(round(a, 3), round(b, 3)) for a, b in probe.take_ended()] == [(4.0, 5.5)]
    short = run_probe(probe, 6.0, 9.0, lambda sent: not 7.0 <= sent < 7.8)  # too short to see while it lasts...
    assert short == [None] * len(short)
    assert [(round(a, 3), round(b, 3)) for a, b in probe.take_ended()] == [(7.0, 7.8)]  # ...but its end shows it
    assert probe.answered == probe.sent - 1 - 15 - 8  # every other request was answered


def test_a_paused_probe_is_not_deafness():
    probe = UplinkProbe(UplinkProbeConfig(), lambda ts1: None)
    probe.tick(0.0, [], active=True)
    probe.tick(0.1, [], active=False)  # the companion stopped flying the vehicle: nothing pending any more
    assert probe.unanswered_since(10.0) is None and probe.sent == 1


def test_deafness_counts_only_while_telemetry_flows():
    monitor = LinkLossMonitor(LinkLossConfig(), PX4, send_probe=lambda ts1: None)
    now = 0.0
    while now < 2.0:  # requests unanswered from 0, telemetry flowing
        monitor.observe(now, now, [], [], probing=True)
        now = round(now + TICK, 6)
    assert len(monitor.deaf) == 1 and monitor.deaf[0].start_s == 0.0 and monitor.deaf[0].end_s is None
    assert monitor.failsafe_evidence(2.0, "POSCTL") == (
        "the vehicle stopped answering the runner (its uplink was lost) for 2.0 s from 0.0 s")
    silent = LinkLossMonitor(LinkLossConfig(), PX4, send_probe=lambda ts1: None)
    for step in range(200):  # nothing heard at all: an ordinary silence, not a deaf stretch
        silent.observe(step * TICK, 0.0 if step else None, [], [], probing=True)
    assert silent.deaf == [] and silent.failsafe_evidence(2.0, "POSCTL").startswith("the link was lost for")


def test_the_vehicle_answers_the_runners_timesync_requests_over_mavlink_until_its_uplink_is_cut():
    """Real bytes: VehicleLink's TIMESYNC request (tc1 0) and the simulated vehicle's reply (ts1 echoed)."""
    vehicle_end, client_end = memory_link_pair()
    vehicle = SimulatedVehicle(VehicleConfig(seed=2), [vehicle_end])
    link = VehicleLink(MemoryMavConnection(client_end, source_system=1, source_component=191), lambda: vehicle.time_s)
    monitor = LinkLossMonitor(LinkLossConfig(), PX4, send_probe=link.send_timesync_request)
    sent = []
    link.conn.mav.set_send_callback(lambda msg: sent.append(msg))
    for step in range(400):  # 2 s answered, then 2 s with everything the runner sends dropped
        if step == 200:
            client_end.send = lambda data: None
        vehicle.step()
        link.tick()
        monitor.observe(vehicle.time_s, link.last_vehicle_message_s, [], link.take_timesync_replies(), probing=True)
    requests = [m for m in sent if m.get_type() == "TIMESYNC"]
    assert len(requests) == pytest.approx(40, abs=1) and {m.tc1 for m in requests} == {0}
    assert monitor.probe.answered == pytest.approx(20, abs=1)
    (deaf,) = monitor.deaf
    assert deaf.start_s == pytest.approx(2.0, abs=0.11) and deaf.end_s is None


@dataclass
class StillLink:
    """What judge_search reads from a link: telemetry flowing, armed, in ``flight_mode``."""

    flight_mode: str
    last_vehicle_message_s: float = 0.0
    armed: bool = True
    params: dict = field(default_factory=dict)

    def battery_percent(self) -> float | None:
        return 80.0


def judge(now: float, link: StillLink, monitor: LinkLossMonitor, texts=()):
    link.last_vehicle_message_s = now
    monitor.observe(now, now, list(texts))
    return judge_search(now, link, RunnerConfig(), PX4, monitor, BootTimeMap(RunnerConfig().boot_time), now)


@pytest.mark.parametrize("late_text", [None, "Geofence: exceeding maximum distance to Home"])
def test_a_mode_change_is_judged_after_settling_so_a_late_safety_text_still_vetoes(late_text):
    """A 2 s silence ended at 10 s (link-loss evidence); at 10.5 s the vehicle is seen in LOITER. PX4 reports its
    health (the geofence text) at most every 2 s, so the text may come after the switch: the runner holds
    ``settle_s`` (2.5 s) before judging, and a text in that time ends the search instead of resuming it."""
    monitor, link = LinkLossMonitor(LinkLossConfig(), PX4), StillLink("OFFBOARD")
    monitor.observe(10.0, 8.0, [])  # the silence from 8 s
    assert judge(10.2, link, monitor) is None
    link.flight_mode = "LOITER"
    waiting = judge(10.5, link, monitor)
    assert waiting.action == "wait" and waiting.mode == "LOITER" and monitor.left_companion_s == 10.5
    verdict = judge(12.0, link, monitor, [(12.0, late_text)] if late_text else [])
    if late_text:  # 1.5 s after the switch: the search ends at once
        assert verdict.action == "end" and verdict.message.endswith(f"the autopilot's own failsafe ({late_text!r})")
    else:
        assert verdict.action == "wait"
        verdict = judge(13.0, link, monitor)  # settled: resumed
        assert verdict.action == "resume" and verdict.evidence == "the link was lost for 2.2 s from 8.0 s"
    assert monitor.left_companion_s is None


def test_a_vehicle_back_in_offboard_while_settling_is_flown_on():
    """PX4 leaves its offboard-loss fallback by itself once setpoints flow again (the user's intended mode is still
    OFFBOARD): the runner stops holding and searches on, without counting a resumption."""
    monitor, link = LinkLossMonitor(LinkLossConfig(), PX4), StillLink("POSCTL")
    monitor.observe(10.0, 8.0, [])
    assert judge(10.5, link, monitor).action == "wait" and monitor.left_companion_s == 10.5
    link.flight_mode = "OFFBOARD"
    assert judge(11.0, link, monitor) is None and monitor.left_companion_s is None and monitor.resumptions == 0
