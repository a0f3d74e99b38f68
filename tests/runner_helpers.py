"""What the mission runner's tests share (tests/test_runner_replay.py, test_runner_udp.py and the other test files
that fly the small mission): the small mission, the short-trained HRL-SAC artifact, reading a tlog back, and a
mission flown by ``hrlsac mission run`` against ``hrlsac sitl`` over real UDP. Not a test module (pytest does not
collect it).
"""
from __future__ import annotations

import dataclasses
import json
import signal
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import pytest
import torch
from conftest import free_udp_ports
from pymavlink import mavutil

from autonomy.policy import Policy, load_policy
from autonomy.vehicle_link import COMPANION_COMPONENT
from missions.mission import FlightSettings, Mission
from missions.mission_writer import save_mission
from missions.scenario import Scenario, SearchArea, Target
from policies.config import NetworkConfig, TrainConfig
from policies.export.artifact import export_policy
from policies.training.trainer import Trainer
from simulation.mission_replay import DEFAULT_START_TIME, unix_microseconds


FLIGHT = FlightSettings(altitude_m=20.0, max_speed_mps=8.0, max_steps=40, subgoal_interval=10)
NET = NetworkConfig(hidden=(32, 32))


ALL_STATES = ["CONNECT", "PREFLIGHT", "ARM", "TAKEOFF", "OFFBOARD", "SEARCH", "RTL", "LAND", "DONE"]


def small_mission(**flight) -> Mission:
    scenario = Scenario(area=SearchArea(-100.0, 500.0, -300.0, 300.0), datum_north_m=250.0, datum_east_m=0.0,
                        datum_sigma_m=60.0, targets=(Target("person", 420.0, 150.0, primary=True),), name="small")
    return Mission(scenario=scenario, flight=dataclasses.replace(FLIGHT, **flight), name="small")


_TRAINED: dict[str, Policy] = {}


def trained_policy(tmp_path_factory) -> Policy:
    """An HRL-SAC artifact from a few hundred training steps (the runner needs a real artifact, not a good one),
    trained once per test process: the test files of the runner share it. No test changes it (a test that needs a
    misbehaving policy wraps it with ``with_actions``, a copy)."""
    if "policy" not in _TRAINED:
        run = tmp_path_factory.mktemp("run")
        config = TrainConfig.from_preset("default", algo="hrl-sac", seed=3, total_steps=300, num_envs=2,
                                         warmup_steps=100, batch_size=32, meta_batch_size=8, buffer_size=1_000,
                                         meta_buffer_size=200, checkpoint_every=10**6, log_every=10**6, eval_every=0,
                                         actor=NET, critic=NET, meta_actor=NET, meta_critic=NET, flight=FLIGHT)
        Trainer(config, run).run(progress=False)
        artifact = load_policy(export_policy(run, run / "policy.pt").path)
        # An untrained meta-controller may well choose ReturnToBase at once, which ends the search before these
        # tests see it: the goal is fixed to TrackObject (the policy's own low level still flies every step).
        _TRAINED["policy"] = dataclasses.replace(artifact,
                                                 _select_goal=lambda meta_obs: torch.full((meta_obs.shape[0],), 2))
    return _TRAINED["policy"]


@pytest.fixture(scope="module")
def policy(tmp_path_factory) -> Policy:
    """The short-trained HRL-SAC artifact (``trained_policy``), for a test module that imports this fixture."""
    return trained_policy(tmp_path_factory)


def with_actions(policy: Policy, act) -> Policy:
    """The same artifact whose every-step entry point is replaced by ``act(obs_tensor) -> tensor``."""
    return dataclasses.replace(policy, _act=act)


LINK_OR_VEHICLE_ENDS = ("vehicle switched to", "telemetry lost", "vehicle disarmed", "policy stalled", "low battery")


def searched_to_its_own_end(report: dict) -> bool:
    """The search ended by its own logic (victim, step limit, back home...), not because of the link or the vehicle:
    which of those depends on the policy, so tests of the flight side do not name it."""
    return report["search_end"] is not None and not report["search_end"].startswith(LINK_OR_VEHICLE_ENDS)


def read_tlog(path: Path, start_time: datetime = DEFAULT_START_TIME) -> list:
    """Every message of a tlog, with ``_timestamp`` in seconds of the runner's clock (the tlog's stamps count from
    the replay's ``start_time``)."""
    log = mavutil.mavlink_connection(str(path), dialect="common")
    start_s = unix_microseconds(start_time) / 1e6
    messages = []
    while (msg := log.recv_match()) is not None:
        if msg.get_type() != "BAD_DATA":
            msg._timestamp -= start_s
            messages.append(msg)
    return messages


def ours(messages: list, kind: str) -> list:
    return [m for m in messages if m.get_type() == kind and m.get_srcComponent() == COMPANION_COMPONENT]


HRLSAC = [sys.executable, "-m", "hrlsac_cli"]


VEHICLE_UP_FIRST_S = 5.0
"""The real-UDP flights start the vehicle this long before the runner (and it says it booted 10 minutes earlier):
the runner meets an autopilot whose clock is far ahead of its own, as on a real vehicle."""


def fly_against_sitl_process(policy, tmp_path: Path, *extra: str, autopilot: str = "px4", runner: list | None = None,
                             pilot: str | None = None) -> tuple[subprocess.CompletedProcess, str, dict]:
    """A short mission flown by ``hrlsac mission run`` against ``hrlsac sitl`` as its own process (started
    VEHICLE_UP_FIRST_S earlier, with PX4's or ArduPilot's own default stream rates), over real UDP in real time;
    returns the command's result, the vehicle's log and the mission report. ``runner``: the ``hrlsac`` command
    that flies (default: this checkout's); ``pilot``: a scripted searcher flies instead of ``policy``."""
    mission = small_mission(altitude_m=10.0, max_steps=10)
    path = tmp_path / "short.yaml"
    save_mission(mission, path)
    home = mission.scenario.home
    api_port, api_remote = free_udp_ports(2)
    personality = {"ardupilot": ["--autopilot", "ardupilot", "--tcp-port", "0", "--param", "RTL_ALT=1200"],
                   "px4": ["--telemetry-profile", "px4", "--param", "RTL_RETURN_ALT=12"]}[autopilot]
    sitl = subprocess.Popen([*HRLSAC, "sitl", "--api-port", str(api_port), "--api-remote", str(api_remote),
                             "--gcs-remote", "0", "--home", f"{home.lat_deg},{home.lon_deg},{home.alt_m}",
                             "--boot-time", "600", *personality],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(VEHICLE_UP_FIRST_S)
        assert sitl.poll() is None, sitl.communicate()
        flown = ["--pilot", pilot] if pilot else ["--policy", str(policy.path)]
        result = subprocess.run([*(runner or HRLSAC), "mission", "run", str(path), *flown,
                                 "--connect", f"udpin:127.0.0.1:{api_remote}", "--out", str(tmp_path / "out"),
                                 "--accept-flight-mismatch", *extra], capture_output=True, text=True, timeout=240)
    finally:
        sitl.send_signal(signal.SIGINT)
        vehicle_log, _ = sitl.communicate(timeout=10)
    assert result.returncode == 0, result.stdout + result.stderr
    return result, vehicle_log, json.loads((tmp_path / "out" / "report.json").read_text())
