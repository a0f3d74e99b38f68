"""ArduCopter's failsafes as far as they matter to a companion computer: GCS (link) loss and the battery.

A mixin of :class:`sitl_bridge.ardupilot.autopilot.ArduCopter` (it uses the autopilot's params, mode and events).
Checked against ArduPilot's ArduCopter/events.cpp (Copter::failsafe_gcs_check, failsafe_gcs_on_event,
handle_battery_failsafe, announce_failsafe, do_failsafe_action, should_disarm_on_failsafe),
libraries/GCS_MAVLink (GCS_MAVLINK::handle_heartbeat: only SYSID_MYGCS counts) and
libraries/AP_BattMonitor/AP_BattMonitor.cpp (check_failsafes and its "Battery 1 is low ..." text).
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.autopilot_base import battery_voltage_v, consumed_mah
from sitl_bridge.multirotor import VehicleState

FS_OPTION_CONTINUE_IF_LANDING = 8
FS_OPTION_GCS_CONTINUE_IF_PILOT_CONTROL = 16
GCS_ACTIONS = {1: CopterMode.RTL, 2: CopterMode.RTL, 5: CopterMode.LAND, 7: CopterMode.BRAKE}  # FS_GCS_ENABLE
BATTERY_ACTIONS = {1: CopterMode.LAND, 2: CopterMode.RTL, 7: CopterMode.BRAKE}  # BATT_FS_*_ACT (0: warn only)


class CopterFailsafes:
    """GCS and battery failsafe state and checks; ``guidance`` calls them every tick."""

    gcs_last_seen_s: float | None = None
    gcs_failsafe = False
    battery_failsafe = 0  # 0 none, 1 low, 2 critical

    def on_heartbeat(self, system_id: int, now: float) -> None:
        """GCS_MAVLINK::handle_heartbeat: only our ground station's heartbeats count for the GCS failsafe."""
        if system_id == int(self.params["SYSID_MYGCS"]):
            self.gcs_last_seen_s = now

    def _check_gcs_failsafe(self, now: float, state: VehicleState) -> None:
        action = int(self.params["FS_GCS_ENABLE"])
        if action and self.gcs_last_seen_s is not None:  # Copter::failsafe_gcs_check
            lost = now - self.gcs_last_seen_s > self.params["FS_GCS_TIMEOUT"]
            if lost and not self.gcs_failsafe:
                self.gcs_failsafe = True
                self._failsafe("GCS", GCS_ACTIONS[action], now, state, gcs=True)
            elif not lost and self.gcs_failsafe:
                self.gcs_failsafe = False
                self._event(now, "GCS Failsafe Cleared", mavlink.MAV_SEVERITY_WARNING)

    def _check_battery(self, now: float, state: VehicleState) -> None:
        """AP_BattMonitor::check_failsafes: voltage below for BATT_LOW_TIMER, or remaining mAh below; nothing
        without a monitor (BATT_MONITOR 0)."""
        if not self.battery_monitored:
            return
        fraction = self.battery_fraction(state)
        volts = battery_voltage_v(fraction)
        remaining_mah = consumed_mah(state.battery_wh)
        for level, volt_name, mah_name in ((2, "BATT_CRT_VOLT", "BATT_CRT_MAH"), (1, "BATT_LOW_VOLT", "BATT_LOW_MAH")):
            if level <= self.battery_failsafe:
                return
            threshold = self.params[volt_name]
            if threshold > 0 and volts < threshold:
                self._battery_low_since_s.setdefault(level, now)
            else:
                self._battery_low_since_s.pop(level, None)
            timed = now - self._battery_low_since_s.get(level, math.inf) >= self.params["BATT_LOW_TIMER"]
            if timed or 0 < remaining_mah < self.params[mah_name]:
                self.battery_failsafe = level
                used = consumed_mah(self.airframe.battery_capacity_wh - state.battery_wh)
                self._event(now, f"Battery 1 is {('low', 'critical')[level - 1]} {volts:.2f}V used {used:.0f} mAh",
                            mavlink.MAV_SEVERITY_WARNING)
                action = int(self.params["BATT_FS_CRT_ACT" if level == 2 else "BATT_FS_LOW_ACT"])
                self._failsafe("Battery", BATTERY_ACTIONS.get(action), now, state)
                return

    def _failsafe(self, kind: str, mode: CopterMode | None, now: float, state: VehicleState, gcs: bool = False) -> None:
        """Copter::failsafe_gcs_on_event / handle_battery_failsafe + do_failsafe_action."""
        options = int(self.params["FS_OPTIONS"])
        landing = self.is_landing
        if not self.armed:
            self._event(now, f"{kind} Failsafe", mavlink.MAV_SEVERITY_WARNING)
            return
        if self.land_complete:  # should_disarm_on_failsafe()
            self._event(now, f"{kind} Failsafe - Disarming", mavlink.MAV_SEVERITY_WARNING)
            self._disarm(now, f"{kind.lower()} failsafe")
            return
        if landing and options & FS_OPTION_CONTINUE_IF_LANDING:
            self._event(now, f"{kind} Failsafe - Continuing Landing", mavlink.MAV_SEVERITY_WARNING)
            return
        if gcs and options & FS_OPTION_GCS_CONTINUE_IF_PILOT_CONTROL and not self.mode.is_autopilot:
            self._event(now, f"{kind} Failsafe - Continuing Pilot Control", mavlink.MAV_SEVERITY_WARNING)
            return
        self._event(now, f"{kind} Failsafe", mavlink.MAV_SEVERITY_WARNING)
        if mode is CopterMode.BRAKE and not self.set_mode(mode, now, state, f"{kind} failsafe"):
            mode = CopterMode.LAND  # set_mode_brake_or_land_with_pause
        if mode is CopterMode.RTL and not self.set_mode(mode, now, state, f"{kind} failsafe"):
            mode = CopterMode.LAND  # set_mode_RTL_or_land_with_pause
        if mode is CopterMode.LAND:
            self.set_mode(mode, now, state, f"{kind} failsafe")
