"""ArduCopter's fences: the circle (FENCE_RADIUS), the ceiling (FENCE_ALT_MAX), the floor (FENCE_ALT_MIN) and the
uploaded polygons and circles (``sitl_bridge.ardupilot.polyfence``), each when FENCE_TYPE has its bit.

The runner's guard (``autonomy/geofence.py``) lives in the companion computer's software; the autopilot's fence is
the layer beneath it, and what stops the drone when that software misbehaves. A mixin of the ArduCopter
personality (:class:`sitl_bridge.ardupilot.autopilot.ArduCopter`). Read in

* ArduPilot: ``libraries/AC_Fence/AC_Fence.cpp`` (FENCE_* parameters and defaults, ``check``, the backup fences 20 m
  further out, the floor enabled once above FENCE_ALT_MIN + FENCE_MARGIN and off while landing or landed,
  ``pre_arm_check`` texts, ``print_fence_message``) and ``ArduCopter/fence.cpp`` ``Copter::fence_check`` (the action
  on a new breach; landed: disarm; more than 100 m out: LAND), ``Copter::set_mode`` (a mode change during a breach
  starts the 10 s manual recovery: ``AC_Fence::check`` still tracks breaches, done last "so that _breached_fences is
  correct", but returns no new one, so nothing acts); ``AC_Fence::present`` (the polygon bit counts only with an
  uploaded fence loaded), ``check_fence_polygon`` (a new breach only when not breached already: no backup fence),
  ``get_breach_distance``.
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.ardupilot.polyfence import CopterPolyFence
from sitl_bridge.multirotor import VehicleState

ALT_MAX, CIRCLE, POLYGON, ALT_MIN = 1, 2, 4, 8  # AC_FENCE_TYPE_* bits of FENCE_TYPE
FENCE_NAMES = ("Max Alt", "Circle", "Polygon", "Min Alt")
CHECK_INTERVAL_S = 0.04  # Copter::fence_checks_async: 25 Hz
BACKUP_DISTANCE_M = 20.0  # AC_FENCE_*_BACKUP_DISTANCE: a new breach this much further out
GIVE_UP_DISTANCE_M = 100.0  # AC_FENCE_GIVE_UP_DISTANCE: further out than this, LAND whatever FENCE_ACTION says
MANUAL_RECOVERY_S = 10.0  # AC_FENCE_MANUAL_RECOVERY_TIME_MIN


def fence_names(fences: int) -> str:
    """AC_Fence::get_fence_names: ``Circle fence``, ``Max Alt and Circle fences``."""
    names = [name for bit, name in enumerate(FENCE_NAMES) if fences & (1 << bit)]
    listed = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
    return f"{listed} fence" + ("s" if len(names) > 1 else "")


class CopterFence(CopterPolyFence):
    """ArduCopter's circle (FENCE_RADIUS), ceiling (FENCE_ALT_MAX), floor (FENCE_ALT_MIN) and uploaded fences."""

    fence_breaches = 0  # AC_Fence::_breached_fences
    _fence_floor_enabled = False
    _fence_backups: dict[int, float] = {}  # per fence: the distance past the fence that is a new breach
    _fence_recovery_until_s = -math.inf
    _fence_checked_s = -math.inf
    _polygon_outside = False  # AC_PolyFence_loader::breached at the last check

    def _fence_configured(self) -> int:
        """FENCE_TYPE's fences that are present, when the fence is enabled (AC_Fence::present: the polygon bit only
        with uploaded areas loaded)."""
        if not self.params["FENCE_ENABLE"]:
            return 0
        present = ALT_MAX | CIRCLE | ALT_MIN | (POLYGON if self.polyfence_areas else 0)
        return int(self.params["FENCE_TYPE"]) & present

    def _fence_distances(self, state: VehicleState) -> dict[int, float]:
        """How far past each fence the vehicle is (negative: inside); the uploaded fence's only when present."""
        home_n, home_e, home_d = self.home_ned
        altitude = home_d - state.down_m
        distances = {ALT_MAX: altitude - self.params["FENCE_ALT_MAX"],
                     ALT_MIN: self.params["FENCE_ALT_MIN"] - altitude,
                     CIRCLE: math.hypot(state.north_m - home_n, state.east_m - home_e) - self.params["FENCE_RADIUS"]}
        if self.polyfence_areas:
            self._polygon_outside, distances[POLYGON] = self.polyfence_breach(state.north_m, state.east_m)
        return distances

    def fence_prearm_failure(self) -> str | None:
        """AC_Fence::pre_arm_check, the parts that apply to the emulated fences."""
        if not self.params["FENCE_ENABLE"]:
            return None
        if not self._fence_configured():
            return "Fences enabled, but none selected"
        fence_type = int(self.params["FENCE_TYPE"])
        if fence_type & (CIRCLE | POLYGON) and not self.gps_ok:
            return "Fence requires position"
        polygon_failure = self.polyfence_prearm_failure() if fence_type & POLYGON else None
        if polygon_failure:
            return polygon_failure
        margin, alt_max, alt_min = (self.params[name] for name in ("FENCE_MARGIN", "FENCE_ALT_MAX", "FENCE_ALT_MIN"))
        if self.params["FENCE_RADIUS"] < margin:
            return "Circle FENCE_MARGIN is greater than FENCE_RADIUS"
        if self.fence_breaches:
            return f"Vehicle breaching {fence_names(self.fence_breaches)}"
        if alt_max < alt_min:
            return "FENCE_ALT_MAX < FENCE_ALT_MIN"
        if alt_max - alt_min <= 2 * margin:
            return "FENCE_MARGIN too big"
        return None

    def _fence_recovery_start(self, now: float) -> None:
        """Copter::set_mode → AC_Fence::manual_recovery_start: a mode change during a breach is a pilot recovering;
        for a while breaches are still tracked but start no action."""
        if self.fence_breaches and int(self.params["FENCE_ACTION"]):
            self._fence_recovery_until_s = now + MANUAL_RECOVERY_S
            self._event(now, "Manual recovery started")

    def _check_fence(self, now: float, state: VehicleState, landing_or_landed: bool) -> None:
        """Copter::fence_checks_async + fence_check; called every tick, armed or not."""
        if now - self._fence_checked_s < CHECK_INTERVAL_S - 1e-9:
            return
        self._fence_checked_s = now
        configured = self._fence_configured()
        was_breached = self.fence_breaches
        self.fence_breaches &= configured
        if landing_or_landed and self._fence_floor_enabled:  # the floor is off while landing or landed
            self._fence_floor_enabled = False
            self.fence_breaches &= ~ALT_MIN
            self._event(now, "Min Alt fence auto-disabled", mavlink.MAV_SEVERITY_NOTICE)
        if not configured:
            return
        distances = self._fence_distances(state)
        new = 0
        for fence, past in distances.items():
            if not configured & fence or (fence == ALT_MIN and not self._fence_floor_enabled):
                continue
            if not (self._polygon_outside if fence == POLYGON else past >= 0):
                self.fence_breaches &= ~fence
                continue
            if not self.fence_breaches & fence or past >= self._fence_backups.get(fence, math.inf):
                new |= fence
                self.fence_breaches |= fence
                if fence != POLYGON:  # check_fence_polygon keeps no backup fence
                    self._fence_backups = {**self._fence_backups, fence: past + BACKUP_DISTANCE_M}
        if (configured & ALT_MIN and not self._fence_floor_enabled and not landing_or_landed
                and -distances[ALT_MIN] >= self.params["FENCE_MARGIN"]):  # AC_Fence::auto_enable_fence_floor
            self._fence_floor_enabled = True
            self._event(now, "Min Alt fence enabled (auto enable)", mavlink.MAV_SEVERITY_NOTICE)
        if was_breached and not self.fence_breaches and not self.land_complete:
            self._event(now, "Fence breach cleared", mavlink.MAV_SEVERITY_NOTICE)
        if new and self.armed and now >= self._fence_recovery_until_s:  # check() returns 0 during a recovery
            self._fence_action(new, max(distances[fence] for fence in distances if new & fence), now, state)

    def _fence_action(self, new: int, past_m: float, now: float, state: VehicleState) -> None:
        """Copter::fence_check on a new breach."""
        if not self.land_complete:
            self._event(now, f"{fence_names(new)} breached", mavlink.MAV_SEVERITY_NOTICE)
        action = int(self.params["FENCE_ACTION"])
        if not action:  # report only
            return
        if self.land_complete:
            self._disarm(now, "fence breach")
            return
        first = {1: CopterMode.RTL, 2: CopterMode.LAND, 4: CopterMode.BRAKE}[action]
        if past_m > GIVE_UP_DISTANCE_M:
            first = CopterMode.LAND
        if not self.set_mode(first, now, state, "fence breach"):
            self.set_mode(CopterMode.LAND, now, state, "fence breach")
