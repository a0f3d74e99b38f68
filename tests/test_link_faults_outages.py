"""Mission outcomes under link faults: packet loss, bursts and outages of 0.5, 2 and 10 s during the search end
completed or safe, never in a flyaway; the runner waits an outage out and searches on (or, without resumption, returns),
gives up on a return or a link that never comes back, resumes a bounded number of times; a faulty replay is
bit-reproducible, and ``hrlsac mission replay --link-faults`` prints and records the outcome.

The missions are whole lockstep replays (real MAVLink bytes, the real runner and the simulated PX4-like vehicle) with
the faults on the vehicle's end of the link, judged from the simulator's ground truth by ``simulation.flight_outcome``;
the policy is the shipped HRL-SAC artifact (the ``policy`` fixture of conftest.py).
"""
from __future__ import annotations

import json
import re

import pytest
from link_faults_helpers import PRETRAINED, back_by_itself, fly, resumed, states
from runner_helpers import searched_to_its_own_end, small_mission

import hrlsac_cli
from autonomy.link_loss import LinkLossConfig
from autonomy.runner import RunnerConfig
from missions.mission_writer import save_mission


SEARCH_START_S = 16.75  # the small mission's SEARCH begins here for seed 5 (tests below check it)
LONGEST_OUTAGE_END_S = 25.0 + 10.0  # the outages below start 25 s into the flight and last up to 10 s


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
