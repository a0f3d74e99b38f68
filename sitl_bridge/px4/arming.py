"""PX4's arming and disarming: Commander's pre-arm checks, their texts, and the auto-disarm on the ground.

A mixin of :class:`sitl_bridge.px4.autopilot.Px4Autopilot` (it uses the autopilot's mode, params, failsafe state and
``set_mode``). Read in PX4-Autopilot's commander: ``Commander::arm`` / ``disarm`` (the texts, the reasons of
``arm_disarm_reason_str``), ``HealthAndArmingChecks`` (``batteryCheck.cpp``, ``geofenceCheck.cpp``, ``modeCheck.cpp``:
which failure has a legacy STATUSTEXT of its own) and the land detector's auto-disarm (COM_DISARM_LAND after a
landing, COM_DISARM_PRFLT when the vehicle never took off).
"""
from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.autopilot_base import ACCEPTED, TEMPORARILY_REJECTED
from sitl_bridge.multirotor import VehicleState
from sitl_bridge.px4.failsafes import BATTERY_TEXTS, CRITICAL, EMERGENCY, NONE, battery_warning_level
from sitl_bridge.px4.modes import FlightMode

BATTERY_FAILURES = {CRITICAL: "battery below BAT_CRIT_THR", EMERGENCY: "battery below BAT_EMERGEN_THR"}


class Px4Arming:
    """Arming (with the pre-arm checks), disarming and the auto-disarm of a landed vehicle."""

    def prearm_failure(self, state: VehicleState) -> str | None:
        """Why arming is refused, or None when the pre-arm checks pass."""
        if not self.gps_ok:
            return "no GPS fix"
        level = battery_warning_level(self.battery_fraction(state), self.params)
        if level in BATTERY_FAILURES:  # batteryCheck.cpp: critical or worse affects every mode
            return BATTERY_FAILURES[level]
        if self.mode is FlightMode.MISSION and not self.check_mission(0.0, state, announce=False):
            return "No valid mission available"  # modeCheck.cpp: an event only, as "No valid global position"
        return next(iter(self.geofence_violations(state)), None)


    def arm(self, now: float, state: VehicleState, force: bool) -> int:
        if self.armed:
            return ACCEPTED
        failure = None if force else self.prearm_failure(state)
        if failure:
            self._refuse_arming(now, state, failure)
            return TEMPORARILY_REJECTED
        self.armed, self.state_changed = True, True
        self.armed_at_s, self.has_flown, self.ground_since_s = now, False, None
        self.battery_warning = NONE
        self._forget_failsafe_actions()
        if self.mode in (FlightMode.HOLD, FlightMode.POSCTL):
            self.hold_target = (state.north_m, state.east_m, 0.0 if state.on_ground else state.down_m)
        self._event(now, "Armed by external command\t")  # Commander::arm; forced or not, the same text
        if self.mode is FlightMode.MISSION:  # Navigator runs a mode only while armed: the mission starts now
            self._start_mission(now, state)
        if force:
            self._event(now, "forced: pre-arm checks skipped", broadcast=False)
        return ACCEPTED

    def _refuse_arming(self, now: float, state: VehicleState, failure: str) -> None:
        """Commander::arm: "Arming denied: Resolve system health failures first". The reason goes out as a
        STATUSTEXT only where its health check has a legacy mavlink_log text (geofenceCheck.cpp, batteryCheck.cpp);
        modeCheck.cpp's "No valid global position estimate" is an event only. The vehicle's log names it."""
        if failure.startswith("Geofence: "):
            self._event(now, failure, mavlink.MAV_SEVERITY_CRITICAL)
        elif failure in BATTERY_FAILURES.values():
            self._event(now, *BATTERY_TEXTS[battery_warning_level(self.battery_fraction(state), self.params)])
        self._event(now, f"arming refused: {failure}", broadcast=False)
        self._event(now, "Arming denied: Resolve system health failures first\t", mavlink.MAV_SEVERITY_CRITICAL)

    def disarm(self, now: float, state: VehicleState, force: bool, reason: str) -> int:
        if not self.armed:
            return ACCEPTED
        if not state.on_ground and not force:
            self._event(now, "Disarming denied: not landed", mavlink.MAV_SEVERITY_CRITICAL)
            return TEMPORARILY_REJECTED
        self.armed, self.state_changed, self.offboard_fallback = False, True, False
        self._disarmed_since_start = True
        self._forget_failsafe_actions()
        self._event(now, f"Disarmed by {reason}\t")  # Commander::disarm, arm_disarm_reason_str
        if self.mode is not FlightMode.HOLD and state.on_ground:
            self.set_mode(FlightMode.HOLD, now, state, "disarmed on the ground")
        return ACCEPTED

    def _auto_disarm(self, now: float, state: VehicleState) -> None:
        if not state.on_ground:
            self.has_flown, self.ground_since_s = True, None
            return
        if self.ground_since_s is None:
            self.ground_since_s = now
        if self.has_flown:
            delay, why = self.params["COM_DISARM_LAND"], "landing"
        else:
            delay, why = self.params["COM_DISARM_PRFLT"], "auto preflight disarming"
        if delay >= 0 and now - self.ground_since_s >= delay and now - self.armed_at_s >= delay:
            self.disarm(now, state, force=False, reason=why)
