"""The mission report: what a flight did, as ``hrlsac mission run`` and ``mission replay`` write it to report.json.

One dict of plain values: how the search ended and what it found (the pilot's summary), the path, the setpoints and
heartbeats sent, every state transition, failsafe and event with its time and reason, the autopilot, the link-loss
resumptions, the estimator's counters and the vehicle-time mapping.
"""
from __future__ import annotations

import numpy as np

from autonomy.runner_core import RunnerCore


def mission_report(runner: RunnerCore) -> dict:
    """The report of ``runner``'s mission so far (an ``autonomy.runner.MissionRunner``; complete once ``run()`` has
    returned)."""
    search = runner.pilot.summary(runner.fleet.row if runner.fleet is not None else 0)
    path = np.array([(n, e) for _, n, e in runner.trajectory]) if runner.trajectory else np.zeros((0, 2))
    return {
        "mission": runner.mission.name,
        "success": runner.search_end == "victim reached",
        "search_end": runner.search_end,
        **search,
        "path_length_m": float(np.hypot(*np.diff(path, axis=0).T).sum()) if len(path) > 1 else 0.0,
        "trajectory": [[t, round(n, 2), round(e, 2)] for t, n, e in runner.trajectory],
        "flight_time_s": round(runner.clock.now(), 3),
        "setpoints_sent": runner.streamer.sent,
        "companion_heartbeats": runner.link.sent_heartbeats,
        "transitions": runner.transitions,
        "failsafes": [e for e in runner.events if e["event"] == "failsafe"],
        "events": runner.events,
        "autopilot": runner.flavour.name,
        "autopilot_fence": runner.autopilot_fence,
        "companion_loss": runner.companion_loss,
        "resumptions": runner.link_loss.resumptions,
        "estimator": runner.estimator.counters(),
        "vehicle_time": {"offset_s": runner.boot_time.offset_s, "timeline_changes": runner.boot_time.timeline_changes,
                         "last_change": runner.boot_time.last_change, "ignored": runner.boot_time.ignored},
    }
