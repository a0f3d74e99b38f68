"""PX4's failsafe reaction and its battery failsafe, as the simulated PX4 runs them (a mixin of ``Px4Autopilot``).

Read in PX4/PX4-Autopilot, ``src/modules/commander``:

* ``failsafe/framework.cpp``: ``FailsafeBase::notifyUser`` (the one STATUSTEXT, "Failsafe activated\\t", CRITICAL;
  the cause and the action go out as events), ``checkFailsafe`` and ``getSelectedAction`` (**COM_FAIL_ACT_T**,
  default 5 s: an action whose user-takeover setting is "auto" first holds for that long, saying "Failsafe
  activated, entering Hold for 5 seconds\\t"; a mode switch meanwhile is a user takeover and the action is not
  taken), ``clearDelayIfNeeded`` (no delay once a failsafe worse than Hold is under way).
* ``failsafe/failsafe.cpp``: which actions are "auto" (``ActionOptions``'s default: the geofence's Return and Land,
  the battery's; not the geofence's Hold, "AlwaysModeSwitchOnly", nor the offboard-loss fallback, "Always"),
  ``fromBatteryWarningActParam`` (**COM_LOW_BAT_ACT**, default 0 = warning only; 2 Land; 3 Return at critical,
  Land at emergency) and the rule that a vehicle already landing is not sent into Return.
* ``HealthAndArmingChecks/checks/batteryCheck.cpp``: "Low battery\\t" and "Critical battery\\t" (CRITICAL),
  "Emergency battery level\\t" (EMERGENCY); ``lib/battery/battery.cpp`` ``determineWarning``: below (``<``)
  BAT_LOW_THR, BAT_CRIT_THR, BAT_EMERGEN_THR; while armed the warning only gets worse.

Not emulated: COM_FAIL_ACT_T's shortening after repeated failsafes (``updateStartDelay``), stick takeover (no RC
here), the remaining-flight-time failsafe (COM_FLTT_LOW_ACT) and battery faults.
"""
from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.multirotor import VehicleState
from sitl_bridge.px4.modes import FlightMode

NONE, LOW, CRITICAL, EMERGENCY = 0, 1, 2, 3  # battery_status_s::WARNING_*
BATTERY_TEXTS = {LOW: ("Low battery\t", mavlink.MAV_SEVERITY_CRITICAL),
                 CRITICAL: ("Critical battery\t", mavlink.MAV_SEVERITY_CRITICAL),
                 EMERGENCY: ("Emergency battery level\t", mavlink.MAV_SEVERITY_EMERGENCY)}
BATTERY_ACTIONS = {0: {}, 2: {CRITICAL: FlightMode.LAND, EMERGENCY: FlightMode.LAND},
                   3: {CRITICAL: FlightMode.RTL, EMERGENCY: FlightMode.LAND}}
"""COM_LOW_BAT_ACT -> the mode each warning level switches to (absent: warning only)."""
CHARGE_STATES = {NONE: mavlink.MAV_BATTERY_CHARGE_STATE_OK, LOW: mavlink.MAV_BATTERY_CHARGE_STATE_LOW,
                 CRITICAL: mavlink.MAV_BATTERY_CHARGE_STATE_CRITICAL,
                 EMERGENCY: mavlink.MAV_BATTERY_CHARGE_STATE_EMERGENCY}
SEVERITY = {FlightMode.POSCTL: 0, FlightMode.HOLD: 1, FlightMode.RTL: 2, FlightMode.LAND: 3}
"""FailsafeBase::Action's order (FallbackPosCtrl < Hold < RTL < Land): the worst selected action wins."""
MIN_DELAY_S = 0.1  # checkFailsafe: COM_FAIL_ACT_T above this turns an "auto" action into a delayed one


def battery_warning_level(fraction: float, params) -> int:
    """battery.cpp ``determineWarning``: the level the charge ``fraction`` is below."""
    for level, name in ((EMERGENCY, "BAT_EMERGEN_THR"), (CRITICAL, "BAT_CRIT_THR"), (LOW, "BAT_LOW_THR")):
        if fraction < params[name]:
            return level
    return NONE


class Px4Failsafes:
    """The reaction to a failsafe (``_failsafe``), COM_FAIL_ACT_T's Hold first, and the battery failsafe."""

    battery_warning = NONE  # the worst level seen since arming
    delayed_action: FlightMode | None = None  # taken at delayed_until_s unless the user switches mode first
    delayed_until_s = 0.0
    failsafe_mode: FlightMode | None = None  # the Return or Land a failsafe is flying (None: none, or taken over)

    def battery_charge_state(self, fraction: float) -> int:
        """BATTERY_STATUS.charge_state: the warning level (batteryCheck.cpp: armed, it only rises)."""
        level = battery_warning_level(fraction, self.params)
        return CHARGE_STATES[max(self.battery_warning, level) if self.armed else level]

    def _check_battery(self, now: float, state: VehicleState) -> None:
        fraction = self.battery_fraction(state)
        level = battery_warning_level(fraction, self.params)
        if level <= self.battery_warning:
            return
        self.battery_warning = level
        self._event(now, *BATTERY_TEXTS[level])
        action = BATTERY_ACTIONS.get(int(self.params["COM_LOW_BAT_ACT"]), {}).get(level)
        self._failsafe(now, state, action, f"battery {fraction:.1%}", delayable=True)

    def _failsafe(self, now: float, state: VehicleState, action: FlightMode | None, why: str,
                  delayable: bool = False) -> None:
        """Commander's reaction: switch to ``action`` (None: warn only). ``delayable``: the action's user-takeover
        setting is "auto", so a Return or Land holds for COM_FAIL_ACT_T first. The cause and the action are kept
        in the vehicle's own log only: PX4 sends them as events, which STATUSTEXT readers do not see."""
        if action is FlightMode.RTL and self.mode is FlightMode.LAND:
            action = None  # getSelectedAction: "If already landing, do not go into RTL"
        under_way = self.failsafe_mode or self.delayed_action
        if action is not None and under_way is not None and SEVERITY[action] <= SEVERITY[under_way]:
            # getSelectedAction keeps the worst action: nothing changes and notifyUser says nothing
            self._event(now, f"Failsafe: {why}, {under_way.name} already under way", broadcast=False)
            return
        delay_s = self.params["COM_FAIL_ACT_T"]
        if (delayable and action in (FlightMode.RTL, FlightMode.LAND) and delay_s > MIN_DELAY_S
                and self.failsafe_mode is None):
            if self.delayed_action is not None:  # a worse action during the Hold: same deadline, no new text
                self.delayed_action = action
                return
            seconds = int(delay_s + 0.5)
            self._event(now, f"Failsafe activated, entering Hold for {seconds} seconds\t",
                        mavlink.MAV_SEVERITY_CRITICAL)
            self._event(now, f"Failsafe: {why}, holding {delay_s:g} s before {action.name}",
                        mavlink.MAV_SEVERITY_CRITICAL, broadcast=False)
            self.set_mode(FlightMode.HOLD, now, state, "failsafe delay (COM_FAIL_ACT_T)")
            self.delayed_action, self.delayed_until_s = action, now + delay_s
            return
        self._event(now, "Failsafe activated\t", mavlink.MAV_SEVERITY_CRITICAL)
        self._event(now, f"Failsafe: {why}, " + (f"switching to {action.name}" if action else "warning only"),
                    mavlink.MAV_SEVERITY_CRITICAL, broadcast=False)
        if action is not None:
            self._take_failsafe_action(action, now, state)

    def _run_delayed_failsafe(self, now: float, state: VehicleState) -> None:
        """After COM_FAIL_ACT_T in Hold the action is taken; notifyUser says "Failsafe activated" again (the action
        got worse than Hold)."""
        if self.delayed_action is None or now < self.delayed_until_s - 1e-9:
            return
        action, self.delayed_action = self.delayed_action, None
        self._event(now, "Failsafe activated\t", mavlink.MAV_SEVERITY_CRITICAL)
        self._event(now, f"Failsafe: hold over, switching to {action.name}", mavlink.MAV_SEVERITY_CRITICAL,
                    broadcast=False)
        self._take_failsafe_action(action, now, state)

    def _take_failsafe_action(self, action: FlightMode, now: float, state: VehicleState) -> None:
        self.set_mode(action, now, state, "failsafe")
        if action in (FlightMode.RTL, FlightMode.LAND):
            self.failsafe_mode = action

    def _forget_failsafe_actions(self) -> None:
        """A mode switch (the user taking over), arming or disarming: no pending or running failsafe action."""
        self.delayed_action = self.failsafe_mode = None
