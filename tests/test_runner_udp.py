"""The mission runner over real UDP in real time: ``hrlsac mission run`` flies ``hrlsac sitl`` (its own process,
with PX4's or ArduPilot's default stream rates and a clock far ahead of the runner's) with the pymavlink and the
MAVSDK backend, and both backends implement the vehicle connection the runner is typed with.

The policy is the short-trained HRL-SAC artifact the runner's test files share (runner_helpers.trained_policy);
the replayed missions are in test_runner_replay.py.
"""
from __future__ import annotations

import ast
import dataclasses
import inspect
import textwrap
import time
from datetime import datetime, timezone

import pytest
from runner_helpers import ALL_STATES, VEHICLE_UP_FIRST_S, fly_against_sitl_process, ours, read_tlog, trained_policy

from autonomy.policy import Policy


@pytest.fixture(scope="module")
def policy(tmp_path_factory) -> Policy:
    """The short-trained HRL-SAC artifact the runner's test files share (runner_helpers.trained_policy)."""
    return trained_policy(tmp_path_factory)


@pytest.mark.slow
@pytest.mark.parametrize("autopilot, pilot", [("px4", None), ("ardupilot", None), ("px4", "lookahead_bayes")])
def test_mission_run_flies_hrlsac_sitl_over_real_udp_in_real_time(policy, tmp_path, autopilot, pilot):
    """The policy artifact on both autopilots, and the best scripted searcher (``--pilot``) on PX4."""
    started = time.time()
    _, _, report = fly_against_sitl_process(policy, tmp_path, autopilot=autopilot, pilot=pilot)
    assert [t["to"] for t in report["transitions"]] == ALL_STATES
    assert report["pilot"] == (pilot or "hrl-sac")
    assert report["autopilot"] == {"px4": "PX4", "ardupilot": "ArduPilot Copter"}[autopilot]
    assert report["clock"] == "wall" and report["estimator"]["accepted"] > 100
    # The vehicle's clock is 600 s plus the head start ahead of the runner's: one time base all the same.
    assert report["vehicle_time"]["offset_s"] < -600.0 - VEHICLE_UP_FIRST_S + 1.0
    assert report["vehicle_time"]["timeline_changes"] == 0 and report["estimator"]["reinitialisations"] == 0
    messages = read_tlog(tmp_path / "out" / "flight.tlog", datetime.fromtimestamp(0, timezone.utc))
    setpoints = ours(messages, "SET_POSITION_TARGET_LOCAL_NED")
    assert len(setpoints) >= 20 and {sp.type_mask for sp in setpoints} == {3527}
    # A real flight's tlog is stamped with the wall clock (mavtogpx and log viewers date its points by it).
    assert started - 1.0 < messages[0]._timestamp < messages[-1]._timestamp < time.time()


@pytest.mark.slow
@pytest.mark.mavsdk
def test_mission_run_flies_the_same_mission_through_the_mavsdk_backend(policy, tmp_path):
    """The same short mission, with MAVSDK (Action, Offboard.set_velocity_ned, Telemetry) as the client."""
    pytest.importorskip("mavsdk.asyncio")
    result, vehicle_log, report = fly_against_sitl_process(policy, tmp_path, "--backend", "mavsdk")
    assert [t["to"] for t in report["transitions"]] == ALL_STATES and report["backend"] == "mavsdk"
    assert report["estimator"]["accepted"] > 100 and report["setpoints_sent"] >= 20  # at least the 1.2 s lead
    assert "mode OFFBOARD" in vehicle_log and "Task was destroyed" not in result.stderr
    # the autopilot's fence parameters, read through MAVSDK's Param plugin (GF_ACTION an INT32, the others floats)
    assert report["autopilot_fence"] == {"checked": True, "acts": False,
                                         "description": "no limit set, on a breach: Hold"}


def _assigned_attributes(cls) -> set[str]:
    """The names a class assigns as ``self.NAME`` anywhere in its source."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    return {node.attr for node in ast.walk(tree) if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
            and node.value.id == "self" and isinstance(node.ctx, ast.Store)}


@pytest.mark.parametrize("backend", ["autonomy.vehicle_link.VehicleLink", "autonomy.mavsdk_link.MavsdkLink"])
def test_both_backends_implement_the_vehicle_connection_the_runner_is_typed_with(backend):
    """Every member of ``VehicleConnection`` is defined by the pymavlink and the MAVSDK client, each method taking
    the protocol's parameters: the runner never asks which client it has."""
    import importlib

    from autonomy.vehicle_connection import VehicleConnection

    module, name = backend.rsplit(".", 1)
    cls = getattr(importlib.import_module(module), name)
    members = {name for name in vars(VehicleConnection) if not name.startswith("_")}
    defined = set(dir(cls)) | _assigned_attributes(cls)
    if dataclasses.is_dataclass(cls):
        defined |= {f.name for f in dataclasses.fields(cls)}
    assert members - defined == set()
    for member in members:
        wanted = getattr(VehicleConnection, member)
        if inspect.isfunction(wanted):
            ours = list(inspect.signature(getattr(cls, member)).parameters)
            assert list(inspect.signature(wanted).parameters) == ours[:len(inspect.signature(wanted).parameters)], \
                member
