"""Link fault injection (``sitl_bridge.faults``): the fault model's statistics and its command-line spec.

The statistics are checked on seeded packet streams through real links (the in-memory pair and real UDP sockets) driven
by a hand-stepped clock; a bad spec is one line naming the problem, from ``hrlsac mission replay`` and ``hrlsac sitl``
alike. The missions flown under faults are in test_link_faults_outages.py and test_link_faults_failsafes.py.
"""
from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest
from conftest import free_udp_ports
from link_faults_helpers import PRETRAINED
from runner_helpers import small_mission

import hrlsac_cli
from missions.mission_writer import save_mission
from sitl_bridge import cli as sitl_cli
from sitl_bridge.faults import FaultModel, FaultyLink, LinkFaults, Outage, parse_link_faults
from sitl_bridge.link import UdpLink, memory_link_pair
from sitl_bridge.server import UdpPorts, VehicleServer
from sitl_bridge.vehicle import VehicleConfig


TICK_S = 0.01


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
