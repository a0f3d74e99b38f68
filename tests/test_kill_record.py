"""Nothing lost on a kill: a mission replay killed at any point leaves a readable tlog and a valid partial report.

The tlog is written unbuffered, one ``write`` per timestamped message, so pymavlink reads every message up to the
kill; the report is rewritten atomically (temporary file + rename) while the run goes, marked
``"complete": false`` until the end.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from link_faults_helpers import PRETRAINED
from pymavlink import mavutil
from runner_helpers import small_mission

from autonomy.policy import load_policy
from autonomy.recorder import PartialReport
from missions.mission_writer import save_mission
from simulation.mission_replay import DEFAULT_START_TIME, replay_mission, unix_microseconds

HRLSAC = [sys.executable, "-m", "hrlsac_cli"]


def tlog_messages(path: Path) -> list:
    """Every complete message of a tlog (pymavlink's reader), BAD_DATA left out."""
    log = mavutil.mavlink_connection(str(path), dialect="common")
    try:
        messages = []
        while (msg := log.recv_match()) is not None:
            if msg.get_type() != "BAD_DATA":
                messages.append(msg)
        return messages
    finally:
        log.close()


@pytest.fixture(scope="module")
def clean_tlog(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("clean")
    replay_mission(small_mission(max_steps=10), load_policy(PRETRAINED), seed=1, out=out, video=False)
    return out / "flight.tlog"


def test_a_torn_last_record_is_skipped_by_the_reader_and_everything_before_it_is_read(clean_tlog, tmp_path):
    data = clean_tlog.read_bytes()
    complete = tlog_messages(clean_tlog)
    # Cut the file in the middle of the last message (8-byte timestamp + frame): a write torn by a power cut.
    last_frame = len(complete[-1].get_msgbuf())
    for cut in (3, 8 + 5, 8 + last_frame - 1):
        torn = tmp_path / f"torn-{cut}.tlog"
        torn.write_bytes(data[: len(data) - 8 - last_frame + cut])
        messages = tlog_messages(torn)
        assert len(messages) == len(complete) - 1
        assert [m.get_msgbuf() for m in messages] == [m.get_msgbuf() for m in complete[:-1]]


def test_the_report_is_partial_while_flying_and_complete_at_the_end(tmp_path):
    seen = []

    def look(text: str) -> None:
        if (tmp_path / "report.json").exists():
            seen.append(json.loads((tmp_path / "report.json").read_text()))

    report = replay_mission(small_mission(max_steps=10), load_policy(PRETRAINED), seed=1, out=tmp_path,
                            video=False, say=look)
    assert seen and all(partial["complete"] is False for partial in seen)
    assert seen[0]["transitions"][0]["to"] == "CONNECT" and seen[0]["tlog_messages"] >= 0
    final = json.loads((tmp_path / "report.json").read_text())
    assert final["complete"] is True and final == json.loads(json.dumps(report))
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


def test_partial_reports_are_rate_limited_and_atomic(tmp_path):
    state = {"n": 0}
    partial = PartialReport(tmp_path / "r.json", lambda: {"n": state["n"]}, min_interval_s=3600.0)
    partial.update(force=True)  # before start(): the run is being set up, nothing to write yet
    assert partial.writes == 0 and not (tmp_path / "r.json").exists()
    partial.start()
    for state["n"] in range(1, 50):
        partial.update()  # within the hour: not written again
    assert partial.writes == 1 and json.loads((tmp_path / "r.json").read_text()) == {"n": 0, "complete": False}
    partial.finish({"n": 99})
    assert json.loads((tmp_path / "r.json").read_text()) == {"n": 99, "complete": True}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]


@pytest.mark.slow
def test_sigkill_mid_replay_leaves_a_readable_tlog_and_a_partial_report(tmp_path):
    mission = tmp_path / "long.yaml"
    save_mission(small_mission(max_steps=3000), mission)  # far longer than the test waits
    out = tmp_path / "out"
    process = subprocess.Popen([*HRLSAC, "mission", "replay", str(mission), "--policy", PRETRAINED, "--out", str(out),
                                "--no-video", "--quiet", "--accept-flight-mismatch"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    tlog, report = out / "flight.tlog", out / "report.json"
    try:
        deadline = time.monotonic() + 120.0  # bounded: imports, then a few seconds of flying
        while time.monotonic() < deadline and process.poll() is None:
            if tlog.exists() and tlog.stat().st_size > 200_000 and report.exists():
                break
            time.sleep(0.05)
        assert process.poll() is None, f"the replay ended before the kill: {process.stderr.read().decode()}"
        assert tlog.stat().st_size > 200_000, "the replay wrote too little within 120 s"
        os.kill(process.pid, signal.SIGKILL)
    finally:
        if process.poll() is None:
            process.kill()
        process.wait(timeout=30)
    assert process.returncode == -signal.SIGKILL
    messages = tlog_messages(tlog)
    assert len(messages) > 1000
    # the run's clock from the replay's start time, monotonic up to the kill
    stamps = np.array([m._timestamp for m in messages]) - unix_microseconds(DEFAULT_START_TIME) / 1e6
    assert np.all(np.diff(stamps) >= 0) and stamps[0] >= 0
    assert {"HEARTBEAT", "GLOBAL_POSITION_INT", "COMMAND_LONG"} <= {m.get_type() for m in messages}
    partial = json.loads(report.read_text())  # valid JSON: written by rename, never torn
    assert partial["complete"] is False and partial["transitions"][0]["to"] == "CONNECT"
    assert partial["flight_time_s"] <= stamps[-1] + 1e-6  # the partial report is of a moment before the kill
