"""A fleet flown over real UDP in real time: ``hrlsac sitl --count 2`` (two PX4 instances in one process, system ids
1 and 2, offboard ports one apart, both ground-station links to one port) and ``hrlsac mission run FLEET.yaml`` as
separate processes, with ``--connect`` once per drone on the offboard ports, or once on the ground-station port that
carries both (``autonomy.shared_port``). Both drones search on their layers, return and land at home; each drone's
tlog holds its own system's traffic only."""
from __future__ import annotations

import concurrent.futures
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import free_udp_ports
from pymavlink import mavutil

from test_fleet_replay import SMALL_FLEET

HRLSAC = [sys.executable, "-m", "hrlsac_cli"]
UDP_FLEET = (SMALL_FLEET.replace("name: small-fleet", "name: udp-fleet").replace("altitude_m: 20", "altitude_m: 10")
             .replace("max_steps: 300", "max_steps: 10").replace("altitude_layer_m: 10", "altitude_layer_m: 5"))


def fly_fleet(folder: Path, ground_station_port: bool) -> tuple[subprocess.CompletedProcess, str]:
    """``hrlsac sitl --count 2`` and ``hrlsac mission run`` over UDP, one connection per drone on the offboard
    ports or (``ground_station_port``) one for both on the ground-station port; the run and the vehicles' log."""
    folder.mkdir()
    path = folder / "udp-fleet.yaml"
    path.write_text(UDP_FLEET)
    api_port, api_remote, gcs_port, gcs_remote = free_udp_ports(4)
    # vehicle 2 takes the port above each (PX4's numbering); both send their ground-station links to gcs_remote
    api_port, api_remote, gcs_port = api_port + 100, api_remote + 200, gcs_port + 300
    sitl = subprocess.Popen([*HRLSAC, "sitl", "--count", "2", "--offset-line", "90,40", "--api-port", str(api_port),
                             "--api-remote", str(api_remote), "--gcs-port", str(gcs_port),
                             "--gcs-remote", str(gcs_remote) if ground_station_port else "0",
                             "--param", "RTL_RETURN_ALT=12", "--param", "MPC_TKO_SPEED=3", "--param",
                             "MPC_LAND_SPEED=2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    connects = (["--connect", f"udpin:127.0.0.1:{gcs_remote}"] if ground_station_port else
                ["--connect", f"udpin:127.0.0.1:{api_remote}", "--connect", f"udpin:127.0.0.1:{api_remote + 1}"])
    try:
        time.sleep(3.0)
        assert sitl.poll() is None, sitl.communicate()
        result = subprocess.run([*HRLSAC, "mission", "run", str(path), "--pilot", "greedy_bayes", *connects,
                                 "--out", str(folder / "out")], capture_output=True, text=True, timeout=240)
    finally:
        sitl.send_signal(signal.SIGINT)
        vehicle_log, _ = sitl.communicate(timeout=10)
    return result, vehicle_log


@pytest.fixture(scope="module")
def flights(tmp_path_factory) -> dict[bool, tuple[Path, subprocess.CompletedProcess, str]]:
    """Both fleets flown at once (each flight waits on real time, not on the CPU): by ``ground_station_port``, the
    folder, the run and the vehicles' log."""
    folders = {port: tmp_path_factory.mktemp("fleet-udp") / "fleet" for port in (False, True)}
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as pool:
        runs = {port: pool.submit(fly_fleet, folder, port) for port, folder in folders.items()}
        return {port: (folders[port], *run.result()) for port, run in runs.items()}


@pytest.mark.parametrize("ground_station_port", [False, True], ids=["a port per drone", "one ground-station port"])
def test_a_fleet_flies_over_real_udp_against_hrlsac_sitl_count_2(flights, ground_station_port):
    folder, result, vehicle_log = flights[ground_station_port]
    assert result.returncode == 0, result.stdout + result.stderr
    assert "udp-fleet (greedy_bayes, 2 drones): victim not found; 2 of 2 landed and disarmed; separation kept" \
        in result.stdout
    assert "vehicle 2 of 2: Simulated PX4 multirotor (sysid 2)" in vehicle_log
    report = json.loads((folder / "out" / "report.json").read_text())
    assert report["complete"] and report["clock"] == "wall" and report["all_landed"]
    assert not report["separation"]["breached"]
    for system_id, drone in enumerate(report["vehicles"], start=1):
        assert drone["system_id"] == system_id
        assert drone["search_end"] == "step limit"
        to_search = next(t for t in drone["transitions"] if t["to"] == "OFFBOARD")
        assert float(to_search["reason"].split()[1]) >= [9.0, 14.0][system_id - 1]  # its own layer: 10 or 15 m
        log = mavutil.mavlink_connection(str(folder / "out" / drone["name"] / "flight.tlog"), dialect="common")
        targets, sources = set(), set()
        while (msg := log.recv_match()) is not None:
            sources.add(msg.get_srcSystem())
            if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
                targets.add(msg.target_system)
        assert targets == {system_id} and sources == {system_id}  # its own vehicle's traffic, and its own
