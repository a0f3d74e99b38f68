"""What the link-fault tests share (tests/test_link_faults_*.py, test_runner_autopilots.py, test_kill_record.py): the
shipped policy's path, the small mission flown under a fault spec and what its report says (states, resumptions, the
vehicle back in OFFBOARD by itself), and a ground station whose pilot takes over. Not a test module (pytest does not
collect it)."""
from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink
from runner_helpers import small_mission

from autonomy.policy import Policy
from autonomy.runner import RunnerConfig
from simulation.flight_outcome import FlyawayLimits
from simulation.mission_replay import airframe_for, replay_mission, start_point
from sitl_bridge.faults import parse_link_faults
from sitl_bridge.vehicle import VehicleConfig


PRETRAINED = "policies/pretrained/hrl-sac.pt"


def fly(policy: Policy, spec: str, seed: int = 5, vehicle_params: dict | None = None, tmp_path=None,
        limits: FlyawayLimits = FlyawayLimits(), runner: RunnerConfig = RunnerConfig()) -> dict:
    mission = small_mission()
    config = VehicleConfig(home=start_point(mission), seed=seed, airframe=airframe_for(mission),
                           params=vehicle_params or {})
    return replay_mission(mission, policy, seed=seed, out=tmp_path, video=False, vehicle_config=config,
                          link_faults=parse_link_faults(spec), limits=limits, config=runner)


def states(report: dict) -> list[str]:
    return [t["to"] for t in report["transitions"]]


def resumed(report: dict) -> list[str]:
    return [e["reason"] for e in report["events"] if e["event"] == "resume"]


def back_by_itself(report: dict) -> list[float]:
    return [e["time_s"] for e in report["events"]
            if e["event"] == "link" and e["reason"] == "the vehicle is back in OFFBOARD by itself: searching on"]


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
