"""How the runner ends a flight: RTL -> LAND -> DONE, or DONE at once when there is nothing left to fly home.

After the search (whatever ended it) and after a failed state while airborne, the runner asks for the autopilot's
own return to launch (RTL itself, not LAND: a vehicle that a failsafe put into LAND out over the water would ditch
there), keeps asking until the link is back (``link_recovery_s``), stops the setpoint stream and waits for the
vehicle to land and disarm. A vehicle disarmed in flight (a reboot, a crash) is not commanded any more.
"""
from __future__ import annotations

import math
from typing import Iterator

from pymavlink.dialects.v20 import common as mavlink

from autonomy.mission_state import AIRBORNE_STATES, MissionState
from autonomy.runner_core import MissionAborted, RunnerCore


class ReturnAndLand(RunnerCore):
    """The end of a flight; see the module docstring."""

    def _return_and_land(self, reason: str) -> Iterator[None]:
        if not self.link.armed and self.search_end == "vehicle disarmed":
            self._record(MissionState.DONE, f"{reason}: nothing left to fly home")
            self.streamer.stop()
            return
        self._record(MissionState.RTL, reason)
        # The one command that must get through: keep asking until the link is back (or link_recovery_s is over).
        config = self.config
        attempts = max(config.command_retries, math.ceil(config.link_recovery_s / config.command_timeout_s))
        # RTL itself, not LAND: a vehicle that a failsafe put into LAND out over the water would ditch there.
        yield from self.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, what="return to launch", attempts=attempts,
                                took_effect=lambda: self.link.flight_mode == "RTL")
        self.streamer.stop()
        yield from self.wait_until(lambda: self.link.flight_mode == "RTL", 5.0, "RTL in the heartbeat")
        self._record(MissionState.LAND, "returning")
        yield from self.wait_until(lambda: not self.link.armed, self.config.land_timeout_s, "landing and disarm")
        self._record(MissionState.DONE, "landed and disarmed")

    def _abort(self, reason: str) -> Iterator[None]:
        """After a failed state: return home if flying, else stop. From TAKEOFF too: a takeoff whose ACKs were
        all lost may still have flown (the vehicle then hovers where it climbed to)."""
        airborne = self._height_m() > 1.0  # on the ground the vehicle disarms itself (COM_DISARM_PRFLT)
        if self.state in AIRBORNE_STATES and self.link.armed and airborne:
            try:
                yield from self._return_and_land(f"abort: {reason}")
            except MissionAborted as exc:
                self._event("abort", str(exc))
