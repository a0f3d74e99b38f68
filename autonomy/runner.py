"""The mission runner: a state machine that flies a search with a policy (or a scripted searcher) over MAVLink;
one per drone in a fleet (``autonomy.fleet_runner``).

    CONNECT -> PREFLIGHT -> ARM -> TAKEOFF -> OFFBOARD -> SEARCH -> RTL -> LAND -> DONE
                                                     (any failure or failsafe -> RTL, or DONE with the reason)
                                      SEARCH -> OFFBOARD -> SEARCH   (resumed after the vehicle's link-loss failsafe)

The states (:class:`autonomy.mission_state.MissionState`) are flown by one class built in layers, each in its own
module:

* :mod:`autonomy.runner_core`: the clock and the control tick, waits, commands with retries, the record of
  transitions and events;
* :mod:`autonomy.takeoff_sequence`: CONNECT to OFFBOARD (discovery, preflight checks, arming, take-off, the
  setpoint lead before the companion mode);
* :mod:`autonomy.search_loop`: SEARCH (policy decisions, the geofence guard, failsafes, link-loss resumption);
* :mod:`autonomy.return_and_land`: RTL, LAND, DONE.

The autopilot is PX4 or ArduPilot Copter, told by the vehicle's HEARTBEAT (:mod:`autonomy.autopilots`), and the
link to it any :class:`autonomy.vehicle_connection.VehicleConnection` (pymavlink or MAVSDK). Every transition and
failsafe is recorded with its reason; :meth:`MissionRunner.run` returns the mission report.
"""
from __future__ import annotations

from typing import Iterator

from autonomy.clocks import Clock, WallClock
from autonomy.mission_report import mission_report
from autonomy.mission_state import MissionState
from autonomy.return_and_land import ReturnAndLand
from autonomy.runner_config import RunnerConfig
from autonomy.runner_core import MissionAborted
from autonomy.search_loop import SearchLoop

__all__ = ["Clock", "MissionAborted", "MissionRunner", "RunnerConfig", "WallClock"]


class MissionRunner(SearchLoop, ReturnAndLand):
    """Flies one mission; see the module docstring. ``run()`` returns the mission report (a dict)."""

    def run(self) -> dict:
        """Fly the mission on this runner's clock; returns the report."""
        for _ in self.flight():
            self.clock.advance()
        return self.report()

    def flight(self) -> Iterator[None]:
        """The whole mission, yielding at every control tick: the driver moves the clock on in between (``run``,
        or a loop that steps several runners on one clock)."""
        try:
            yield from self._connect()
            yield from self._preflight()
            yield from self._arm_and_take_off()
            yield from self._offboard()
            yield from self._search()
            yield from self._return_and_land("search ended: " + (self.search_end or "?"))
        except MissionAborted as exc:
            self._event("abort", str(exc))
            yield from self._abort(str(exc))
        self.streamer.stop()
        if self.state != MissionState.DONE:
            self._record(MissionState.DONE, "mission over")

    def report(self) -> dict:
        """The mission report (``autonomy.mission_report``): also what a killed run leaves behind."""
        return mission_report(self)
