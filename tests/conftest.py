"""Shared fixtures: free UDP ports and a simulated vehicle served over real UDP."""
from __future__ import annotations

import itertools
import os
import socket

# pymavlink clients in the tests speak MAVLink 2 from the first byte (set before mavutil is imported).
os.environ.setdefault("MAVLINK20", "1")
if os.environ.get("PYTEST_XDIST_WORKER"):
    # make test runs one worker per core: a torch spreading its work over every core in each worker would
    # oversubscribe them (the Stable-Baselines3 test took 286 s beside two training processes with torch's
    # default threads, 11 s with one). Subprocesses inherit the variable.
    os.environ["OMP_NUM_THREADS"] = "1"
    import torch

    torch.set_num_threads(1)

import pytest  # noqa: E402

LONGEST_FIRST = ("test_runner_udp.py", "test_learning_sac.py", "test_mavproxy_flight.py", "test_learning.py",
                 "test_fleet_udp.py", "test_onboard_install.py", "test_scaling.py", "test_fleet_replay.py",
                 "test_mavsdk_mission.py", "test_runner_replay.py",
                 "test_mavsdk_offboard.py", "test_training_evaluation.py", "test_link_faults_outages.py",
                 "test_mavsdk_actions.py", "test_compare.py", "test_pymavlink_udp_flight.py",
                 "test_runner_autopilots.py", "test_training_resume.py", "test_decision_ceiling.py",
                 "test_bad_missions.py", "test_training_meta.py", "test_link_faults_failsafes.py",
                 "test_export_parity.py", "test_belief_calibration.py", "test_env.py", "test_signing.py",
                 "test_fuzz_mavlink.py", "test_link_faults_model.py", "test_mavsdk_runner_link.py")
"""The test files that take longest, roughly longest first (from ``pytest --durations=0``), those that wait on real
time (UDP flights at 1x) interleaved with those that keep a core busy (training). ``make test`` hands whole files to
its workers in collection order (``--dist loadfile --no-loadscope-reorder``): started first, the long files run
beside the many short ones instead of after them, where one worker would be left running a training alone."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    rank = {name: index for index, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: each file keeps its own order

PORT_RANGE = (20_000, 60_000)
"""UDP ports the tests take theirs from, split between the pytest-xdist workers."""
_ports_handed_out = itertools.count()


def free_udp_ports(count: int) -> list[int]:
    """Ports free right now, from this pytest-xdist worker's own share of ``PORT_RANGE``.

    Asking the OS for a free port (bind to port 0, release) leaves a moment in which another worker can be handed
    the same one before either test binds it; with a share per worker that cannot happen, and within a worker the
    ports go round the share, so a port comes back only after all the others."""
    worker = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw") or 0)
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    share = (PORT_RANGE[1] - PORT_RANGE[0]) // max(workers, 1)
    first = PORT_RANGE[0] + worker * share
    ports: list[int] = []
    for _ in range(share):
        port = first + next(_ports_handed_out) % share
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:  # in use by something else on the machine: the next one
                continue
        ports.append(port)
        if len(ports) == count:
            return ports
    raise RuntimeError(f"no {count} free UDP ports in {first}-{first + share - 1}")


@pytest.fixture
def udp_ports() -> list[int]:
    return free_udp_ports(4)


@pytest.fixture(scope="module")
def policy():
    """The shipped HRL-SAC artifact (policies/pretrained/hrl-sac.pt), loaded once per test module. A module that
    flies another policy defines its own ``policy`` fixture, which takes precedence over this one."""
    from autonomy.policy import load_policy

    return load_policy("policies/pretrained/hrl-sac.pt")


@pytest.fixture
def pilot():
    """A lockstep pymavlink client of a simulated PX4 (seed 1) that has its GPS fix (sitl_bridge.scripted_flight)."""
    from sitl_bridge.scripted_flight import LockstepPilot
    from sitl_bridge.vehicle import VehicleConfig

    p = LockstepPilot.create(VehicleConfig(seed=1))
    p.wait_for(lambda: p.vehicle.autopilot.gps_ok, 2.0, "GPS")
    return p


class UdpClient:
    """A plain pymavlink client that streams setpoints and records what it hears, all from one thread."""

    def __init__(self, url: str):
        from pymavlink import mavutil

        self.conn = mavutil.mavlink_connection(url, source_system=255, source_component=190)
        self.latest: dict[str, object] = {}
        self.received: list[object] = []
        self.stream: tuple[float, float, float] | None = None  # NED velocity re-sent at 20 Hz
        self.stream_frame = 1  # MAV_FRAME_LOCAL_NED
        self.target_system = 1  # the vehicle commands and setpoints go to (a fleet has several)
        self._next_send = 0.0

    def pump(self, seconds: float) -> None:
        """Receive (and stream) for ``seconds`` of wall time."""
        import time

        end = time.monotonic() + seconds
        while True:
            now = time.monotonic()
            if self.stream is not None and now >= self._next_send:
                vn, ve, vd = self.stream
                self.conn.mav.set_position_target_local_ned_send(0, self.target_system, 1, self.stream_frame, 3527,
                                                                 0, 0, 0, vn, ve, vd, 0, 0, 0, 0, 0)
                self._next_send = now + 0.05
            if now >= end:
                return
            msg = self.conn.recv_match(blocking=True, timeout=min(0.01, end - now))
            while msg is not None:
                if msg.get_type() != "BAD_DATA":
                    self.latest[msg.get_type()] = msg
                    self.received.append(msg)
                msg = self.conn.recv_match(blocking=False)

    def wait(self, predicate, timeout_s: float, what: str):
        import time

        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            value = predicate()
            if value:
                return value
            self.pump(0.02)
        raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")

    def wait_message(self, msg_type: str, timeout_s: float = 3.0, match=lambda m: True, since: int | None = None):
        """The first ``msg_type`` message received after index ``since`` (default: from now on)."""
        seen = len(self.received) if since is None else since
        return self.wait(lambda: next((m for m in self.received[seen:]
                                       if m.get_type() == msg_type and match(m)), None), timeout_s, msg_type)

    def command(self, command: int, *params: float, timeout_s: float = 3.0, target_component: int = 1):
        """COMMAND_LONG; returns the matching COMMAND_ACK."""
        p = list(params) + [0.0] * (7 - len(params))
        self.conn.mav.command_long_send(self.target_system, target_component, command, 0, *p)
        return self.wait_message("COMMAND_ACK", timeout_s, lambda m: m.command == command)

    def close(self) -> None:
        self.conn.close()


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The export tests' short training run of each algorithm (export_helpers.trained_runs, one per process)."""
    from export_helpers import trained_runs

    return trained_runs(tmp_path_factory)


@pytest.fixture(scope="module")
def artifacts(runs, tmp_path_factory):
    """Those runs exported in every format and precision (export_helpers.exported_artifacts)."""
    from export_helpers import exported_artifacts

    return exported_artifacts(runs, tmp_path_factory)
