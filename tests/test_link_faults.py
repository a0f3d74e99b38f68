"""Link fault injection (``sitl_bridge.faults``) and mission outcomes under faults.

The fault model's statistics are checked on seeded packet streams through real links (the in-memory pair and real
UDP sockets) driven by a hand-stepped clock; the missions are whole lockstep replays (real MAVLink bytes, the real
runner and the simulated PX4-like vehicle) with the faults on the vehicle's end of the link, judged from the
simulator's ground truth by ``simulation.flight_outcome``.
"""
from __future__ import annotations

import dataclasses
import json
import re
import math
import time

import numpy as np
import pytest
from conftest import free_udp_ports
from pymavlink.dialects.v20 import common as mavlink
from runner_helpers import searched_to_its_own_end, small_mission

import hrlsac_cli
from autonomy.autopilots import ARDUPILOT_COPTER, PX4
from autonomy.link_loss import LinkLossConfig, LinkLossMonitor
from autonomy.policy import Policy, load_policy
from autonomy.runner import RunnerConfig
from missions.mission_writer import save_mission
from simulation import mission_replay as replay_module
from simulation.flight_outcome import FlyawayLimits
from simulation.mission_replay import airframe_for, replay_mission, start_point
from sitl_bridge import cli as sitl_cli
from sitl_bridge.faults import FaultModel, FaultyLink, LinkFaults, Outage, parse_link_faults
from sitl_bridge.link import UdpLink, memory_link_pair
from sitl_bridge.server import UdpPorts, VehicleServer
from sitl_bridge.vehicle import VehicleConfig

PRETRAINED = "policies/pretrained/hrl-sac.pt"
TICK_S = 0.01
SEARCH_START_S = 16.75  # the small mission's SEARCH begins here for seed 5 (tests below check it)
LONGEST_OUTAGE_END_S = 25.0 + 10.0  # the outages below start 25 s into the flight and last up to 10 s


class StepClock:
    """A clock the test moves by hand (the simulated clock of a lockstep run)."""

    def __init__(self) -> None:
        self.time_s = 0.0

    def __call__(self) -> float:
        return self.time_s


def send_stream(faults: LinkFaults, count: int, seed: int = 0, spacing_s: float = TICK_S,
                drain_s: float = 5.0) -> list[tuple[float, int]]:
    """``count`` numbered packets sent by the vehicle's end (through the ``down`` faults), one per ``spacing_s``;
    returns what the client end received as (receive time, packet number), in order."""
    vehicle_end, client_end = memory_link_pair("test")
    clock = StepClock()
    link = FaultyLink(vehicle_end, faults, clock, seed)
    received = []
    ticks = int(round((count * spacing_s + drain_s) / TICK_S))
    for tick in range(ticks):
        clock.time_s = tick * TICK_S
        if tick * TICK_S < count * spacing_s - 1e-9 and tick % round(spacing_s / TICK_S) == 0:
            link.send(int(tick * TICK_S / spacing_s + 0.5).to_bytes(4, "big"))
        link.receive()  # the vehicle uses its link every tick: due packets go out
        received += [(clock.time_s, int.from_bytes(data, "big")) for data in client_end.receive()]
    return received


def down(**fields) -> LinkFaults:
    return LinkFaults(down=FaultModel(**fields))


def within_binomial(observed: int, n: int, p: float, sigmas: float = 5.0) -> bool:
    return abs(observed - n * p) <= sigmas * math.sqrt(n * p * (1 - p))


# ------------------------------------------------------------------------------------ the fault model's statistics
@pytest.mark.parametrize("loss", [0.1, 0.3])
def test_independent_loss_share_is_within_the_binomial_bound(loss):
    n = 20_000
    received = send_stream(down(loss=loss), n, spacing_s=0.01, drain_s=0.1)
    numbers = [number for _, number in received]
    assert numbers == sorted(set(numbers))  # loss only: no duplicate, no reordering
    assert within_binomial(n - len(numbers), n, loss)


def test_bursts_lose_the_configured_share_in_runs_of_the_configured_mean_length():
    n = 50_000
    numbers = {number for _, number in send_stream(down(loss=0.2, burst_length=5.0), n, drain_s=0.1)}
    lost = np.array([i not in numbers for i in range(n)])
    assert abs(lost.mean() - 0.2) < 0.02  # bursts correlate losses: a looser bound than the binomial one
    edges = np.flatnonzero(np.diff(np.concatenate([[0], lost.astype(int), [0]])))
    runs = edges[1::2] - edges[::2]
    assert abs(runs.mean() - 5.0) < 0.5
    independent = {number for _, number in send_stream(down(loss=0.2), n, drain_s=0.1)}
    lost_independent = np.array([i not in independent for i in range(n)])
    # P(lost | previous lost): 1 - 1/5 in bursts, the plain loss share without
    assert lost[1:][lost[:-1]].mean() > 0.7 and abs(lost_independent[1:][lost_independent[:-1]].mean() - 0.2) < 0.03


def test_duplicates_arrive_right_after_the_original_at_the_configured_rate():
    n = 10_000
    numbers = [number for _, number in send_stream(down(duplicate=0.2), n, drain_s=0.1)]
    assert sorted(set(numbers)) == list(range(n))
    assert numbers == sorted(numbers)  # a copy comes right after its original
    assert within_binomial(len(numbers) - n, n, 0.2)


def test_reordered_packets_are_overtaken_and_none_is_lost():
    n = 5_000
    received = send_stream(down(reorder=0.05, reorder_delay_ms=100.0), n)
    numbers = [number for _, number in received]
    assert sorted(numbers) == list(range(n))
    overtaken = sum(1 for i in range(1, len(numbers)) if numbers[i] < numbers[i - 1])
    assert overtaken > 0 and within_binomial(overtaken, n, 0.05)
    # a held-back packet arrives 100 ms late, i.e. after the 10 packets sent during that time
    late = {number: time_s for time_s, number in received}
    assert any(abs(late[k] - (k * TICK_S + 0.1)) < 1e-6 for k in range(n))


def test_an_outage_drops_exactly_the_packets_sent_in_its_window():
    n = 1_000  # 10 s of packets, one per 10 ms
    faults = down(outages=(Outage(2.0, 0.5), Outage(6.0, 1.25)))
    numbers = {number for _, number in send_stream(faults, n)}
    dropped = sorted(set(range(n)) - numbers)
    assert dropped == list(range(200, 250)) + list(range(600, 725))


def test_latency_and_jitter_are_applied_on_the_run_clock_and_keep_the_order():
    n = 2_000
    received = send_stream(down(latency_ms=50.0), n)
    assert [round(t - number * TICK_S, 6) for t, number in received] == [0.05] * n
    jittered = send_stream(down(latency_ms=200.0, jitter_ms=100.0), n)
    numbers = [number for _, number in jittered]
    assert numbers == list(range(n))  # jitter never reorders
    delays = np.array([t - number * TICK_S for t, number in jittered])
    assert delays.min() >= 0.1 - 1e-9 and delays.max() <= 0.3 + TICK_S + 1e-9 and delays.std() > 0.01
    # Packets further apart than the jitter's spread never wait for an earlier one: their delays are uniform
    # in [latency - jitter, latency + jitter], rounded up to the next tick (+5 ms on average).
    sparse = send_stream(down(latency_ms=200.0, jitter_ms=100.0), 500, spacing_s=0.5)
    delays = np.array([t - number * 0.5 for t, number in sparse])
    assert delays.min() >= 0.1 - 1e-9 and delays.max() <= 0.3 + TICK_S + 1e-9
    assert abs(delays.mean() - 0.205) < 0.01 and abs(delays.std() - 0.2 / math.sqrt(12)) < 0.01


def test_the_uplink_faults_apply_to_what_the_vehicle_receives():
    vehicle_end, client_end = memory_link_pair("test")
    clock = StepClock()
    link = FaultyLink(vehicle_end, LinkFaults(up=FaultModel(latency_ms=30.0, outages=(Outage(0.0, 0.05),))), clock)
    got = []
    for tick in range(20):
        clock.time_s = tick * TICK_S
        client_end.send(bytes([tick]))
        got += [(tick, data[0]) for data in link.receive()]
    assert got == [(tick, tick - 3) for tick in range(8, 20)]  # 0..4 sent in the outage, the rest 30 ms late
    assert link.counts()["up"]["outage"] == 5 and link.counts()["down"]["sent"] == 0


def test_the_same_seed_delivers_the_same_sequence_and_another_seed_does_not():
    faults = down(loss=0.2, burst_length=3.0, latency_ms=40.0, jitter_ms=30.0, duplicate=0.1, reorder=0.1,
                  outages=(Outage(3.0, 1.0),))
    first, again, other = (send_stream(faults, 1_000, seed=seed) for seed in (7, 7, 8))
    assert first == again and first != other
    assert send_stream(dataclasses.replace(faults, seed=7), 1_000, seed=123) == first  # the faults' own seed wins


def test_faults_over_real_udp_sockets_lose_the_same_packets_as_over_memory():
    """The fault model does not care what it wraps: the seeded fates are the same over a real UDP socket."""
    vehicle_port, client_port = free_udp_ports(2)
    vehicle_udp = UdpLink("vehicle", ("127.0.0.1", vehicle_port), ("127.0.0.1", client_port))
    client_udp = UdpLink("client", ("127.0.0.1", client_port), None)
    faults = down(loss=0.3)
    clock = StepClock()
    link = FaultyLink(vehicle_udp, faults, clock, seed=4)
    try:
        for number in range(300):
            clock.time_s = number * TICK_S
            link.send(number.to_bytes(4, "big"))
        received: list[int] = []
        for _ in range(300):  # bounded: at most 300 polls 10 ms apart
            received += [int.from_bytes(d, "big") for d in client_udp.receive()]
            if len(received) >= link.counts()["down"]["delivered"]:
                break
            time.sleep(0.01)
    finally:
        vehicle_udp.close()
        client_udp.close()
    assert received == [number for _, number in send_stream(faults, 300, seed=4, drain_s=0.1)]


def test_the_sitl_server_wraps_every_udp_link_in_the_faults():
    api_port, api_remote, gcs_port, gcs_remote = free_udp_ports(4)
    faults = parse_link_faults("outage=0:1000")
    server = VehicleServer(VehicleConfig(seed=3), UdpPorts("127.0.0.1", api_port, api_remote, gcs_port, gcs_remote),
                           link_faults=faults)
    try:
        assert [endpoint.link for endpoint in server.vehicle.endpoints] == server.faulty_links
        assert [link.link for link in server.faulty_links] == server.links  # the api and gcs UDP links
        server.vehicle.run(2.0)  # the vehicle's heartbeats and telemetry all fall into the outage
        counts = server.faulty_links[0].counts()["down"]
        assert counts["sent"] > 10 and counts["outage"] == counts["sent"] and counts["delivered"] == 0
    finally:
        for link in server.links:
            link.close()


# ------------------------------------------------------------------------------------ the command-line spec
def test_the_spec_sets_both_directions_or_one():
    faults = parse_link_faults("loss=0.1,latency_ms=50,jitter_ms=20,outage=30:2,down.dup=0.05,up.outage=60:1,seed=9")
    assert faults.seed == 9
    assert faults.up == FaultModel(loss=0.1, latency_ms=50, jitter_ms=20, outages=(Outage(30, 2), Outage(60, 1)))
    assert faults.down == FaultModel(loss=0.1, latency_ms=50, jitter_ms=20, duplicate=0.05, outages=(Outage(30, 2),))
    assert parse_link_faults(faults.down.describe()).down == faults.down  # describe() writes the spec back
    assert parse_link_faults("").perfect and FaultModel().describe() == "none"


@pytest.mark.parametrize("spec, message", [
    ("los=0.1", "unknown key 'los' in 'los=0.1'; known keys: loss, burst, latency_ms"),
    ("loss", "expected KEY=VALUE, got 'loss'"),
    ("loss=lots", "'lots' in 'loss=lots' is not a number"),
    ("loss=1.5", "FaultModel.loss must be a number in [0, 0.99], got 1.5"),
    ("outage=30", "outage needs START_S:LENGTH_S (e.g. outage=30:2), got 'outage=30'"),
    ("outage=30:-2", "Outage.duration_s must be a number in [0, 1e+06], got -2.0"),
    ("loss=0.9,burst=1.5", "FaultModel.loss 0.9 cannot be reached with burst_length 1.5"),
    ("seed=1.5", "'1.5' in 'seed=1.5' is not an integer"),
])
def test_a_bad_spec_is_one_line_naming_the_problem(spec, message, capsys, tmp_path):
    with pytest.raises(ValueError) as error:
        parse_link_faults(spec)
    assert str(error.value).startswith("--link-faults: ") and message in str(error.value)
    mission = tmp_path / "small.yaml"
    save_mission(small_mission(), mission)
    assert hrlsac_cli.main(["mission", "replay", str(mission), "--policy", PRETRAINED, "--link-faults", spec]) == 2
    assert sitl_cli.main(["--link-faults", spec, "--api-port", "0", "--gcs-remote", "0"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 2 and message in lines[0] and message in lines[1]
    assert lines[0].startswith("hrlsac mission replay: error: --link-faults: ")
    assert lines[1].startswith("hrlsac sitl: error: --link-faults: ")


# ------------------------------------------------------------------------------------ missions under faults
@pytest.fixture(scope="module")
def policy() -> Policy:
    return load_policy(PRETRAINED)


def fly(policy: Policy, spec: str, seed: int = 5, vehicle_params: dict | None = None, tmp_path=None,
        limits: FlyawayLimits = FlyawayLimits(), runner: RunnerConfig = RunnerConfig()) -> dict:
    mission = small_mission()
    config = VehicleConfig(home=start_point(mission), seed=seed, airframe=airframe_for(mission),
                           params=vehicle_params or {})
    return replay_mission(mission, policy, seed=seed, out=tmp_path, video=False, vehicle_config=config,
                          link_faults=parse_link_faults(spec), limits=limits, config=runner)


def states(report: dict) -> list[str]:
    return [t["to"] for t in report["transitions"]]


def test_the_clean_mission_completes_and_the_outages_below_fall_in_its_search(policy):
    report = fly(policy, "")
    assert report["outcome"]["outcome"] == "completed" and report["outcome"]["vehicle_end"] == "landed and disarmed"
    search = next(t["time_s"] for t in report["transitions"] if t["to"] == "SEARCH")
    rtl = next(t["time_s"] for t in report["transitions"] if t["to"] == "RTL")
    assert search == SEARCH_START_S and rtl > LONGEST_OUTAGE_END_S  # every outage tested here hits the search
    assert report["link_faults"] == "none" and report["complete"] is True


@pytest.mark.parametrize("spec", ["loss=0", "loss=0.1", "loss=0.3", "outage=25:0.5", "outage=25:2",
                                  "outage=25:10", "loss=0.3,burst=4,latency_ms=80,jitter_ms=40,dup=0.05,reorder=0.05"])
@pytest.mark.parametrize("seed", [5, 6])
def test_under_faults_the_mission_completes_or_ends_safely_never_a_flyaway(policy, spec, seed):
    report = fly(policy, spec, seed=seed)
    outcome = report["outcome"]
    assert outcome["outcome"] in ("completed", "safe"), outcome
    assert outcome["max_fence_excursion_m"] == 0.0 and outcome["longest_offboard_setpoint_gap_s"] <= 1.05
    assert outcome["reason"]
    assert outcome["vehicle_end"] == "landed and disarmed" or outcome["vehicle_end"].startswith(
        ("flying in POSCTL", "flying in HOLD", "flying in RTL", "flying in LAND"))
    if outcome["outcome"] == "safe":  # the reason is the first thing that went wrong, recorded with its cause
        assert outcome["reason"].startswith(("failsafe: ", "abort: ", "vehicle: Failsafe"))
    assert states(report)[-1] == "DONE"
    if spec != "loss=0":
        assert report["link_packets"]["down"]["sent"] > report["link_packets"]["down"]["delivered"]


def test_a_half_second_outage_is_ridden_through(policy):
    report = fly(policy, "outage=25:0.5")
    assert report["outcome"]["outcome"] == "completed" and report["failsafes"] == []
    assert 0.5 <= report["outcome"]["longest_offboard_setpoint_gap_s"] < 1.0  # under PX4's 1 s COM_OF_LOSS_T


def resumed(report: dict) -> list[str]:
    return [e["reason"] for e in report["events"] if e["event"] == "resume"]


def back_by_itself(report: dict) -> list[float]:
    return [e["time_s"] for e in report["events"]
            if e["event"] == "link" and e["reason"] == "the vehicle is back in OFFBOARD by itself: searching on"]


def test_a_two_second_outage_trips_the_vehicles_failsafe_and_px4_returns_to_offboard_by_itself(policy):
    """PX4's offboard-loss fallback clears once setpoints flow again (the user's intended mode is still OFFBOARD):
    the runner, settling the switch it saw when the link came back, finds the vehicle in OFFBOARD and searches on."""
    report = fly(policy, "outage=25:2")
    outcome = report["outcome"]
    assert [f["reason"] for f in outcome["vehicle_failsafes"]] == [
        "Failsafe: offboard setpoints lost for 1.0 s, switching to POSCTL"]
    assert resumed(report) == [] and report["resumptions"] == 0
    assert back_by_itself(report) == [pytest.approx(27.0, abs=0.15)]
    assert states(report) == ["CONNECT", "PREFLIGHT", "ARM", "TAKEOFF", "OFFBOARD", "SEARCH", "RTL", "LAND", "DONE"]
    assert report["failsafes"] == [] and searched_to_its_own_end(report)
    assert outcome["outcome"] == "completed" and outcome["vehicle_end"] == "landed and disarmed"


def test_a_ten_second_outage_is_waited_out_and_the_search_goes_on_once_the_link_is_back(policy):
    report = fly(policy, "outage=25:10")
    outcome = report["outcome"]
    assert outcome["vehicle_failsafes"][0]["time_s"] == pytest.approx(25.0 + 1.0, abs=0.06)  # COM_OF_LOSS_T
    links = [(e["time_s"], e["reason"]) for e in report["events"] if e["event"] == "link"]
    assert links == [(pytest.approx(25.9, abs=0.1), "no telemetry for 1 s: holding position"),
                     (pytest.approx(27.9, abs=0.1), "telemetry lost for 3.0 s: waiting up to 60 s for it to come back"),
                     (pytest.approx(35.0, abs=0.1), "the vehicle left OFFBOARD (now POSCTL): holding 2.5 s for what "
                                                    "the autopilot says before judging it"),
                     (pytest.approx(35.0, abs=0.2), "the vehicle is back in OFFBOARD by itself: searching on")]
    assert resumed(report) == [] and report["failsafes"] == []
    assert not [e for e in report["events"] if e["event"] == "abort"]
    assert outcome["outcome"] == "completed" and searched_to_its_own_end(report)


def test_without_resumption_an_outage_ends_the_search_and_the_return_goes_through_once_the_link_is_back(policy):
    report = fly(policy, "outage=25:10", runner=RunnerConfig(link_loss=LinkLossConfig(resume=False)))
    outcome = report["outcome"]
    assert outcome["outcome"] == "safe" and outcome["vehicle_end"] == "landed and disarmed"
    assert [f["reason"] for f in report["failsafes"]] == ["telemetry lost for 3.0 s"]
    # the return command is re-sent through the outage (link_recovery_s) and accepted after it ends at 35 s
    rtl, land = (next(t for t in report["transitions"] if t["to"] == state) for state in ("RTL", "LAND"))
    assert rtl["time_s"] == pytest.approx(28.0, abs=0.1) and 35.0 <= land["time_s"] <= 36.6
    assert states(report)[-3:] == ["RTL", "LAND", "DONE"] and resumed(report) == []


def test_the_runner_gives_up_on_the_return_after_link_recovery_s_and_the_vehicle_holds(policy):
    report = fly(policy, "outage=25:10", runner=RunnerConfig(link_recovery_s=3.0,
                                                            link_loss=LinkLossConfig(resume=False)))
    assert report["outcome"]["vehicle_end"] == "flying in POSCTL at 20 m"
    aborts = [e["reason"] for e in report["events"] if e["event"] == "abort"]
    assert aborts == ["return to launch: no COMMAND_ACK for MAV_CMD_NAV_RETURN_TO_LAUNCH after 5 attempts"]


def test_a_link_that_never_comes_back_ends_the_search_after_the_wait(policy):
    report = fly(policy, "outage=25:200", runner=RunnerConfig(link_recovery_s=3.0,
                                                             link_loss=LinkLossConfig(wait_s=20.0)))
    assert [f["reason"] for f in report["failsafes"]] == ["telemetry lost for 20.0 s"]
    assert report["search_end"] == "telemetry lost" and resumed(report) == []


def test_resumptions_are_bounded(policy):
    """Setpoints cut for 5 s, three times: PX4 cannot return to OFFBOARD while they are cut, so after settling the
    runner resumes on its probe's evidence, twice; the third time no resumption is left."""
    report = fly(policy, "up.outage=20:5,up.outage=28:5,up.outage=36:5",
                 runner=RunnerConfig(link_loss=LinkLossConfig(max_resumptions=2)))
    assert len(resumed(report)) == 2 and report["resumptions"] == 2
    (last,) = [f["reason"] for f in report["failsafes"]]
    deaf = re.fullmatch(r"the vehicle left OFFBOARD \(now POSCTL\); the vehicle stopped answering the runner \(its "
                        r"uplink was lost\) for ([0-9.]+) s from ([0-9.]+) s, but no resumption is left", last)
    # judged at once (nothing to resume, nothing to settle), 1 s into the third cut: the evidence is the second's
    assert deaf and float(deaf[2]) == pytest.approx(28.0, abs=0.15), last
    assert report["search_end"] == "vehicle switched to POSCTL" and report["outcome"]["outcome"] == "safe"


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


def switch_to_posctl(gcs: mavlink.MAVLink):
    return gcs.command_long_encode(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                   3, 0, 0, 0, 0, 0)


class PilotAtTheGroundStation:
    """The vehicle's end of the link, plus a ground station (system 255) that sends one message at ``at_s`` (by
    default: switch the vehicle to POSCTL, a pilot taking over while the companion's link is fine). Real MAVLink
    bytes."""

    def __init__(self, link, clock, at_s: float, encode=switch_to_posctl):
        self.link, self.clock, self.at_s, self.sent, self.name = link, clock, at_s, False, link.name
        self.encode = encode
        self.gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=mavlink.MAV_COMP_ID_MISSIONPLANNER)

    def send(self, data: bytes) -> None:
        self.link.send(data)

    def receive(self) -> list[bytes]:
        received = self.link.receive()
        if not self.sent and self.clock() >= self.at_s:
            self.sent = True
            received.append(bytes(self.encode(self.gcs).pack(self.gcs)))
        return received

    def counts(self) -> dict:
        return {"pilot_commands": int(self.sent)}


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


def test_a_faulty_replay_is_bit_reproducible(policy, tmp_path):
    spec = "loss=0.2,burst=3,latency_ms=60,jitter_ms=30,dup=0.05,reorder=0.05,outage=30:2"
    first = fly(policy, spec, tmp_path=tmp_path / "a")
    again = fly(policy, spec, tmp_path=tmp_path / "b")
    assert (tmp_path / "a" / "flight.tlog").read_bytes() == (tmp_path / "b" / "flight.tlog").read_bytes()
    assert (tmp_path / "a" / "report.json").read_bytes() == (tmp_path / "b" / "report.json").read_bytes()
    assert first == again
    other = fly(policy, spec + ",seed=99", tmp_path=tmp_path / "c")
    assert (tmp_path / "c" / "flight.tlog").read_bytes() != (tmp_path / "a" / "flight.tlog").read_bytes()
    assert other["link_faults"].endswith("; seed 99")


def test_mission_replay_with_link_faults_prints_and_records_the_outcome(policy, tmp_path, capsys):
    mission = tmp_path / "small.yaml"
    save_mission(small_mission(), mission)
    code = hrlsac_cli.main(["mission", "replay", str(mission), "--policy", PRETRAINED, "--seed", "5", "--no-video",
                             "--out", str(tmp_path / "out"), "--link-faults", "outage=25:2",
                             "--accept-flight-mismatch"])
    assert code == 0
    out = capsys.readouterr().out
    assert "  outcome: completed (search ended: step limit); vehicle landed and disarmed" in out
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["link_faults"] == "both ways outage=25:2" and report["complete"] is True
    assert report["outcome"]["outcome"] == "completed" and report["resumptions"] == 0  # PX4 went back itself


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
