"""The vehicle's failsafes and the runner's link-loss judgement under one-sided faults: commands whose acks are all
lost, setpoints cut (the silence to the runner's probe lets it resume), telemetry cut (the runner holds), a pilot's mode
change, a vehicle without a working failsafe (a flyaway), a 3 s COM_OF_LOSS_T, and only link loss resumed from, never
the autopilots' safety failsafes.

The missions are whole lockstep replays (real MAVLink bytes, the real runner and the simulated PX4-like vehicle) with
the faults on the vehicle's end of the link, judged from the simulator's ground truth by ``simulation.flight_outcome``;
the policy is the shipped HRL-SAC artifact (the ``policy`` fixture of conftest.py).
"""
from __future__ import annotations

import re

import pytest
from link_faults_helpers import PilotAtTheGroundStation, back_by_itself, fly, resumed, states
from pymavlink.dialects.v20 import common as mavlink
from runner_helpers import searched_to_its_own_end

from autonomy.autopilots import ARDUPILOT_COPTER, PX4
from autonomy.link_loss import LinkLossConfig, LinkLossMonitor
from simulation import mission_replay as replay_module


class AckSwallowingLink:
    """The vehicle's end of the link with every COMMAND_ACK it sends lost: a lossy downlink at its worst for
    commands (they arrive and are carried out; their answers never do)."""

    def __init__(self, link):
        self.link, self.swallowed, self.name = link, 0, link.name

    def send(self, data: bytes) -> None:
        if data[:1] == b"\xfd" and int.from_bytes(data[7:10], "little") == mavlink.MAVLINK_MSG_ID_COMMAND_ACK:
            self.swallowed += 1
            return
        self.link.send(data)

    def receive(self) -> list[bytes]:
        return self.link.receive()

    def counts(self) -> dict:
        return {"acks_swallowed": self.swallowed}


def test_commands_whose_acks_are_all_lost_count_as_done_once_the_heartbeat_shows_them(policy, monkeypatch):
    monkeypatch.setattr(replay_module, "apply_faults", lambda links, faults, clock, seed: [AckSwallowingLink(links[0])])
    report = fly(policy, "")
    assert report["outcome"]["outcome"] == "completed" and report["outcome"]["vehicle_end"] == "landed and disarmed"
    assert states(report) == ["CONNECT", "PREFLIGHT", "ARM", "TAKEOFF", "OFFBOARD", "SEARCH", "RTL", "LAND", "DONE"]
    assert report["link_packets"]["acks_swallowed"] >= 4  # arm, takeoff, offboard, RTL (and any zoom commands)


@pytest.mark.parametrize("action, mode", [(0, "POSCTL"), (3, "RTL"), (4, "LAND")])
def test_when_only_the_setpoints_are_cut_the_vehicles_silence_to_the_runners_probe_lets_it_resume(policy, action,
                                                                                                    mode):
    """Telemetry keeps flowing, so the runner sees no silence, and PX4 says only "Failsafe activated": what tells the
    runner is that the vehicle stopped answering its TIMESYNC requests (autonomy.uplink_probe). The cut outlasts
    the settle, so the vehicle cannot go back to OFFBOARD by itself first."""
    report = fly(policy, "up.outage=25:6", vehicle_params={"COM_OBL_RC_ACT": action})
    outcome = report["outcome"]
    text = f"Failsafe: offboard setpoints lost for 1.0 s, switching to {mode}"  # the vehicle's own log
    assert [f["reason"] for f in outcome["vehicle_failsafes"]] == [text]
    assert outcome["vehicle_failsafes"][0]["time_s"] == pytest.approx(25.0 + 1.0, abs=0.05)
    (resume,) = resumed(report)
    deaf = re.search(r"the vehicle stopped answering the runner \(its uplink was lost\) for ([0-9.]+) s from "
                     r"([0-9.]+) s", resume)
    assert resume.startswith(f"the vehicle's link-loss failsafe switched it to {mode} (") and deaf, resume
    assert float(deaf[2]) == pytest.approx(25.0, abs=0.15) and float(deaf[1]) == pytest.approx(3.5, abs=0.3)
    assert resume.endswith("): resuming the search (1 of 3)")
    assert report["link_packets"]["down"]["outage"] == 0  # telemetry kept flowing: only the vehicle's failsafe
    assert outcome["outcome"] == "completed" and outcome["vehicle_end"] == "landed and disarmed"


def test_when_only_the_telemetry_is_cut_the_runner_holds_then_carries_on(policy):
    report = fly(policy, "down.outage=25:5")
    outcome = report["outcome"]
    links = [e["reason"] for e in report["events"] if e["event"] == "link"]
    assert links == ["no telemetry for 1 s: holding position",
                     "telemetry lost for 3.0 s: waiting up to 60 s for it to come back"]
    assert outcome["vehicle_failsafes"] == [] and report["failsafes"] == []  # the hold setpoints kept flowing
    assert resumed(report) == [] and searched_to_its_own_end(report)
    assert outcome["outcome"] == "completed" and outcome["vehicle_end"] == "landed and disarmed"


def test_a_pilots_mode_change_ends_the_search_even_with_resumption_on(policy, monkeypatch):
    monkeypatch.setattr(replay_module, "apply_faults",
                        lambda links, faults, clock, seed: [PilotAtTheGroundStation(links[0], clock, 30.0)])
    report = fly(policy, "")
    assert resumed(report) == [] and report["link_packets"] == {"pilot_commands": 1}
    assert [f["reason"] for f in report["failsafes"]] == ["the vehicle left OFFBOARD (now POSCTL)"]
    assert report["search_end"] == "vehicle switched to POSCTL" and states(report)[-3:] == ["RTL", "LAND", "DONE"]


def test_a_vehicle_without_a_working_failsafe_is_caught_as_a_flyaway(policy):
    """The watch does not trust the autopilot: with COM_OF_LOSS_T at 60 s the vehicle flies on without setpoints."""
    report = fly(policy, "up.outage=25:10", vehicle_params={"COM_OF_LOSS_T": 60.0})
    outcome = report["outcome"]
    assert outcome["outcome"] == "flyaway"
    assert outcome["reason"].startswith("flying OFFBOARD with no setpoint for 5.5")  # slowest_failsafe_s + 0.5
    assert outcome["vehicle_failsafes"] == [] and outcome["longest_offboard_setpoint_gap_s"] > 5.5


def test_a_three_second_com_of_loss_t_is_flown_as_configured_and_the_search_goes_on(policy):
    """PX4 with COM_OF_LOSS_T = 3 s: through a 10 s outage the vehicle flies its last setpoint for 3 s (configured,
    not a flyaway), then its failsafe switches it to POSCTL, and it is back in OFFBOARD once the link is."""
    report = fly(policy, "outage=25:10", vehicle_params={"COM_OF_LOSS_T": 3.0})
    outcome = report["outcome"]
    assert [f["reason"] for f in outcome["vehicle_failsafes"]] == [
        "Failsafe: offboard setpoints lost for 3.0 s, switching to POSCTL"]
    assert outcome["vehicle_failsafes"][0]["time_s"] == pytest.approx(25.0 + 3.0, abs=0.06)
    assert 2.9 <= outcome["longest_offboard_setpoint_gap_s"] <= 3.5
    assert back_by_itself(report) == [pytest.approx(35.0, abs=0.2)] and resumed(report) == []
    assert outcome["outcome"] == "completed" and searched_to_its_own_end(report)


@pytest.mark.parametrize("flavour, link_loss_text, safety_texts", [
    (PX4, None,  # PX4 names no cause in STATUSTEXT ("Failsafe activated"); its health checks' texts name these:
     ["Geofence: exceeding maximum distance to Home", "Geofence: exceeding maximum altitude above Home",
      "Low battery\t", "Critical battery\t", "Emergency battery level\t",
      "Failsafe activated, entering Hold for 5 seconds\t"]),  # only before a geofence or battery Return / Land
    (ARDUPILOT_COPTER, "GCS Failsafe", ["Circle fence breached", "Battery Failsafe", "EKF Failsafe"])])
def test_only_link_loss_is_resumed_from_never_the_autopilots_safety_failsafes(flavour, link_loss_text, safety_texts):
    """Any STATUSTEXT with "failsafe" in it used to count as link-loss evidence: a geofence or battery RTL would
    have been flown back into OFFBOARD / GUIDED. A safety text in the window vetoes even a silence's evidence."""
    mode = "RTL"
    announced = LinkLossMonitor(LinkLossConfig(), flavour)
    announced.observe(10.0, 10.0, [(10.0, link_loss_text or "Failsafe activated\t"), (11.0, "GCS Failsafe Cleared")])
    assert announced.failsafe_evidence(12.0, mode) == (
        f"the vehicle announced it: {link_loss_text!r}" if link_loss_text else None)
    for text in safety_texts:
        silent = LinkLossMonitor(LinkLossConfig(), flavour)
        silent.observe(10.0, 8.0, [])  # a 2 s silence: link-loss evidence on its own...
        silent.observe(10.5, 10.5, [(10.5, text)])
        assert silent.safety_failsafe(12.0) == text and silent.failsafe_evidence(12.0, mode) is None
        assert silent.failsafe_evidence(12.0 + LinkLossConfig().evidence_window_s, mode) is None  # both expired
