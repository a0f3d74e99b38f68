"""The mission runner on whole replayed missions: the captured MAVLink bytes (tlog) of the setpoint stream and the
companion heartbeat, the state machine, failsafes (slow, stalled and NaN policies, the geofence), determinism,
and the ``hrlsac mission replay`` command (its summary, progress, dated tlog and one-line errors; ``mission run``'s
refusal of a bad connection URL).

Every mission here is flown by the real runner against the simulated vehicle over the in-memory MAVLink link, in
lockstep; the tlog is read back with pymavlink. Policies are real exported artifacts of a short training run
(runner_helpers.trained_policy); where a test needs a misbehaving policy it wraps the artifact's entry points (a
fault injected into a real policy). The real-UDP flights are in test_runner_udp.py.
"""
from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
import torch
from pymavlink.dialects.v20 import common as mavlink
from cli_harness import run_cli
from runner_helpers import ALL_STATES, FLIGHT, HRLSAC, ours, read_tlog, small_mission, trained_policy, with_actions

from autonomy.policy import Policy
from missions.mission_writer import save_mission
from simulation.mission_replay import DEFAULT_START_TIME, replay_mission


STREAM_PERIOD_US = 50_000  # 20 Hz


@pytest.fixture(scope="module")
def policy(tmp_path_factory) -> Policy:
    """The short-trained HRL-SAC artifact the runner's test files share (runner_helpers.trained_policy)."""
    return trained_policy(tmp_path_factory)


def micros(msg) -> int:
    return int(round(msg._timestamp * 1e6))


@pytest.fixture(scope="module")
def flown(policy, tmp_path_factory) -> tuple[dict, list, Path]:
    out = tmp_path_factory.mktemp("flight")
    report = replay_mission(small_mission(), policy, seed=5, out=out, video=True)
    return report, read_tlog(out / "flight.tlog"), out


# ---------------------------------------------------------------------------------------- the setpoint stream
def test_the_mission_goes_through_every_state_with_reasons(flown):
    report, _, out = flown
    assert [t["to"] for t in report["transitions"]] == ALL_STATES
    assert all(t["reason"] for t in report["transitions"])
    assert report["search_end"] in ("victim reached", "step limit", "return to base")
    assert 1 <= report["steps"] <= FLIGHT.max_steps
    assert json.loads((out / "report.json").read_text()) == json.loads(json.dumps(report))
    assert (out / "trajectory.png").stat().st_size > 1000 and (out / "replay.mp4").stat().st_size > 1000


def test_every_setpoint_is_a_velocity_setpoint_for_the_vehicle_within_limits(flown):
    _, messages, _ = flown
    setpoints = ours(messages, "SET_POSITION_TARGET_LOCAL_NED")
    assert len(setpoints) > 20 * 30  # at least the 40-step search at 20 Hz
    for sp in setpoints:
        assert (sp.target_system, sp.target_component) == (1, 1)
        assert sp.coordinate_frame == mavlink.MAV_FRAME_LOCAL_NED and sp.type_mask == 3527
        assert math.hypot(sp.vx, sp.vy) <= FLIGHT.max_speed_mps + 1e-4 and abs(sp.vz) <= 2.0 + 1e-6
        assert all(math.isfinite(v) for v in (sp.vx, sp.vy, sp.vz))


def test_setpoints_stream_at_exactly_20_hz_without_a_gap_until_rtl(flown):
    _, messages, _ = flown
    times = np.array([micros(sp) for sp in ours(messages, "SET_POSITION_TARGET_LOCAL_NED")])
    assert set(np.diff(times).tolist()) == {STREAM_PERIOD_US}
    rtl = next(m for m in ours(messages, "COMMAND_LONG") if m.command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    assert times[-1] <= micros(rtl) < times[-1] + STREAM_PERIOD_US  # the stream ran until RTL was requested


def test_at_least_one_second_of_setpoints_precedes_the_offboard_request(flown):
    _, messages, _ = flown
    request = next(m for m in ours(messages, "COMMAND_LONG")
                   if m.command == mavlink.MAV_CMD_DO_SET_MODE and int(m.param2) == 6)
    before = [sp for sp in ours(messages, "SET_POSITION_TARGET_LOCAL_NED") if micros(sp) < micros(request)]
    assert micros(request) - micros(before[0]) >= 1_000_000 and len(before) >= 20
    assert all((sp.vx, sp.vy) == (0.0, 0.0) for sp in before)  # hold while waiting for OFFBOARD
    ack = next(m for m in messages if m.get_type() == "COMMAND_ACK" and m.command == mavlink.MAV_CMD_DO_SET_MODE)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED


def test_companion_heartbeat_at_1_hz_as_an_onboard_controller(flown):
    report, messages, _ = flown
    beats = ours(messages, "HEARTBEAT")
    assert len(beats) == report["companion_heartbeats"] >= 30
    assert {b.type for b in beats} == {mavlink.MAV_TYPE_ONBOARD_CONTROLLER}
    assert {b.autopilot for b in beats} == {mavlink.MAV_AUTOPILOT_INVALID}
    assert set(np.diff([micros(b) for b in beats]).tolist()) == {1_000_000}


def test_replays_of_the_same_mission_and_seed_are_byte_identical(policy, flown, tmp_path):
    _, _, first = flown
    replay_mission(small_mission(), policy, seed=5, out=tmp_path, video=False)
    assert (tmp_path / "flight.tlog").read_bytes() == (first / "flight.tlog").read_bytes()
    assert (tmp_path / "report.json").read_bytes() == (first / "report.json").read_bytes()
    other = replay_mission(small_mission(), policy, seed=6, out=tmp_path / "other", video=False)
    assert (tmp_path / "other" / "flight.tlog").read_bytes() != (first / "flight.tlog").read_bytes()
    assert other["transitions"][-1]["to"] == "DONE"


def test_a_replay_without_video_still_draws_its_trajectory(policy, flown, tmp_path):
    """``video=False`` (``--no-video``) skips replay.mp4 only: trajectory.png is the video's last frame all the same."""
    _, _, first = flown
    replay_mission(small_mission(), policy, seed=5, out=tmp_path, video=False)
    assert (first / "replay.mp4").exists() and not (tmp_path / "replay.mp4").exists()
    assert (tmp_path / "trajectory.png").read_bytes() == (first / "trajectory.png").read_bytes()


# ---------------------------------------------------------------------------------------- slow and broken policies
def setpoints_during_search(report: dict, messages: list) -> list:
    start = next(t["time_s"] for t in report["transitions"] if t["to"] == "SEARCH")
    return [sp for sp in ours(messages, "SET_POSITION_TARGET_LOCAL_NED") if sp._timestamp >= start]


def test_the_stream_keeps_its_rate_while_a_slow_policy_computes(policy, tmp_path):
    # Each decision takes 0.8 s of simulated time: decisions arrive late, setpoints never do.
    report = replay_mission(small_mission(), policy, seed=5, out=tmp_path, video=False, simulated_policy_s=0.8)
    messages = read_tlog(tmp_path / "flight.tlog")
    times = [micros(sp) for sp in ours(messages, "SET_POSITION_TARGET_LOCAL_NED")]
    assert set(np.diff(times).tolist()) == {STREAM_PERIOD_US}
    assert report["failsafes"] == [] and report["transitions"][-1]["to"] == "DONE"


def test_decisions_late_by_more_than_a_period_skip_the_missed_steps(policy, tmp_path):
    # 1.5 s per decision with a 1 s step: one decision every 2 s (no catch-up burst), 40 steps over ~80 s.
    report = replay_mission(small_mission(), policy, seed=5, out=tmp_path, video=False, simulated_policy_s=1.5)
    times = np.array([t for t, _, _ in report["trajectory"]])
    assert np.all(np.diff(times) >= 1.5 - 1e-6)
    assert report["search_end"] == "step limit" and report["steps"] == FLIGHT.max_steps


def test_a_stalled_policy_gets_zero_velocity_then_rtl(policy, tmp_path):
    report = replay_mission(small_mission(), policy, seed=5, out=tmp_path, video=False, simulated_policy_s=30.0)
    assert report["search_end"] == "policy stalled"
    assert [f["reason"] for f in report["failsafes"]] == ["no policy decision for 5 s: RTL"]
    assert [t["to"] for t in report["transitions"]][-3:] == ["RTL", "LAND", "DONE"]
    search = setpoints_during_search(report, read_tlog(tmp_path / "flight.tlog"))
    assert len(search) >= 5 * 20 - 1 and all((sp.vx, sp.vy) == (0.0, 0.0) for sp in search)


def test_a_nan_action_gets_zero_velocity_then_rtl(policy, tmp_path):
    calls = {"n": 0}

    def act(obs):
        calls["n"] += 1
        out = policy._act(obs)
        return torch.full_like(out, float("nan")) if calls["n"] > 4 else out  # the self-test and 3 steps are fine

    report = replay_mission(small_mission(), with_actions(policy, act), seed=5, out=tmp_path, video=False)
    assert report["search_end"] == "policy returned NaN"
    assert report["failsafes"][0]["reason"].startswith("policy returned a non-finite action")
    nan_at = report["failsafes"][0]["time_s"]
    after = [sp for sp in setpoints_during_search(report, read_tlog(tmp_path / "flight.tlog"))
             if sp._timestamp > nan_at]
    assert len(after) >= 20 and all((sp.vx, sp.vy) == (0.0, 0.0) for sp in after)  # 1 s of hold, then RTL
    rtl = next(t["time_s"] for t in report["transitions"] if t["to"] == "RTL")
    assert rtl >= nan_at + 1.0
    assert [t["to"] for t in report["transitions"]][-3:] == ["RTL", "LAND", "DONE"]


@pytest.mark.parametrize("layers", ["shield and guard", "guard alone"])
def test_the_geofence_guard_turns_back_a_policy_flying_out_of_the_area(policy, tmp_path, monkeypatch, layers):
    """Two layers keep a policy inside the fence: the pilot's safety shield (missions.shield, as in training) and
    the runner's geofence guard on the 20 Hz filtered pose. With the shield switched off the guard alone must hold
    (a pilot or artifact that does not shield its commands); with both, the shield acts first."""
    if layers == "guard alone":
        monkeypatch.setattr("autonomy.search_pilot.shield_velocity", lambda position, velocity, *zones: velocity)

    def east_at_full_speed(obs):
        return torch.tensor([[0.0, 1.0, 1.0, 0.0]]).expand(obs.shape[0], 4).contiguous()

    mission = small_mission(max_steps=120)  # 120 s east at 8 m/s would end 960 m east of a fence at 300 m
    report = replay_mission(mission, with_actions(policy, east_at_full_speed), seed=5, out=tmp_path, video=False)
    assert report["search_end"] == "step limit"  # never left the geofence
    guard_acted = any(e["event"] == "geofence" for e in report["events"])
    assert guard_acted == (layers == "guard alone")
    east = np.array([e for _, _, e in report["trajectory"]])
    assert east.max() < mission.fence.east_max_m and east[-1] > mission.fence.east_max_m - 60.0


# ---------------------------------------------------------------------------------------- the command
@pytest.fixture(scope="module")
def mission_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("missions") / "small.yaml"
    save_mission(small_mission(), path)
    return path


def test_mission_replay_command_prints_a_summary_and_writes_the_report(policy, mission_file, tmp_path):
    result = subprocess.run([*HRLSAC, "mission", "replay", str(mission_file), "--policy", str(policy.path),
                             "--out", str(tmp_path), "--seed", "2", "--no-video"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    report = json.loads((tmp_path / "report.json").read_text())
    assert [t["to"] for t in report["transitions"]][-1] == "DONE" and report["seed"] == 2
    assert f"small (hrl-sac): {int(report['success'])}/1 searches found the victim" in result.stdout
    assert f"report: {tmp_path / 'report.json'}" in result.stdout
    assert "SEARCH -> RTL" in result.stdout  # the transitions, with their reasons
    assert result.stdout.splitlines()[0] == "[    0.00 s] -> CONNECT: start" and "None" not in result.stdout


def test_replays_of_many_episodes_show_their_progress_on_stderr_unless_quiet(policy, mission_file, tmp_path, capsys,
                                                                            monkeypatch):
    """Progress (tqdm: episodes done, rate, time left) goes to stderr; stderr is not a terminal here, so each update
    is a line of its own. --quiet prints none, and the episodes' files are the same either way."""
    import hrlsac_cli
    from hrlsac_cli import progress

    monkeypatch.setattr(progress, "LOG_EVERY_S", 0.0)  # not a terminal: a line at every update, from the first

    def replay(out: Path, *extra: str) -> str:
        assert hrlsac_cli.main(["mission", "replay", str(mission_file), "--policy", str(policy.path), "--out",
                                str(out), "--episodes", "2", "--no-video", *extra]) == 0
        return capsys.readouterr().err

    shown, quiet = replay(tmp_path / "shown"), replay(tmp_path / "quiet", "--quiet")
    lines = [line for line in shown.splitlines() if line.startswith("episodes:")]
    assert "\r" not in shown and lines[0].startswith("episodes:   0%") and "0/2" in lines[0]
    assert lines[-1].startswith("episodes: 100%") and "2/2 [" in lines[-1] and "success" in lines[-1]
    assert re.search(r"[0-9.]+(s/episode|episode/s)", lines[-1]) and quiet == ""
    for name in ("seed-00000/report.json", "seed-00001/flight.tlog"):
        assert (tmp_path / "shown" / name).read_bytes() == (tmp_path / "quiet" / name).read_bytes()


def gpx_times(tlog: Path) -> list[datetime]:
    """The times of the track points pymavlink's mavtogpx.py writes for a tlog (it formats them in local time)."""
    subprocess.run([sys.executable, str(Path(sys.executable).parent / "mavtogpx.py"), str(tlog)], check=True,
                   capture_output=True, env={**os.environ, "TZ": "UTC"}, timeout=120)
    text = Path(f"{tlog}.gpx").read_text()
    return [datetime.fromisoformat(t) for t in re.findall(r"<time>([^<]+)</time>", text)]


@pytest.mark.parametrize("start", [None, "2026-03-14T09:26:53Z"])
def test_a_replay_tlog_is_dated_from_its_start_time(policy, mission_file, tmp_path, start):
    """``--start-time`` (default: the fixed DEFAULT_START_TIME, so that replays stay byte-identical) is the moment
    the tlog's simulated time 0 stands for: the GPX track of the flight carries that date."""
    given = ["--start-time", start] if start else []
    result = subprocess.run([*HRLSAC, "mission", "replay", str(mission_file), "--policy", str(policy.path),
                             "--out", str(tmp_path), "--no-video", "--quiet", *given],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    begins = datetime.fromisoformat(start) if start else DEFAULT_START_TIME
    flight_time_s = json.loads((tmp_path / "report.json").read_text())["flight_time_s"]
    times = gpx_times(tmp_path / "flight.tlog")
    assert len(times) > 100 and times == sorted(times)
    assert begins <= times[0] and (times[-1] - begins).total_seconds() <= flight_time_s


@pytest.mark.parametrize("change, message", [
    (("--policy", "missing.pt"), "missing.pt: no such file"),
    (("--episodes", "0"), "--episodes must be in [1, 100000], got 0"),
    (("--start-time", "yesterday"), "--start-time must be an ISO 8601 date and time from 1970 on, as "
                                    "YYYY-MM-DDTHH:MM:SSZ, got 'yesterday'"),
])
def test_mission_command_turns_bad_input_into_one_line(policy, mission_file, change, message):
    args = {"--policy": str(policy.path), "--episodes": "1"}
    args[change[0]] = change[1]
    result = run_cli("mission", "replay", str(mission_file), *sum(args.items(), ()))
    assert result.code == 2
    lines = result.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hrlsac mission replay: error: ") and lines[0].endswith(message)


def test_mission_run_refuses_a_bad_connection_url(policy, mission_file):
    result = run_cli("mission", "run", str(mission_file), "--policy", str(policy.path), "--connect", "udp:nowhere")
    assert result.code == 2
    assert "cannot use connection 'udp:nowhere': write udpin:HOST:PORT" in result.err
