"""The autopilots' own geofences: PX4's failsafe geofence and ArduCopter's circle and altitude fences.

The runner's guard (``autonomy/geofence.py``) lives in the companion computer's software; the autopilot's fence is
the layer beneath it, and what stops the drone when that software misbehaves. Both are parameter-only fences around
home, and PX4 also takes a fence uploaded with the mission protocol (``sitl_bridge.mission_protocol``: polygons and
circles). Mixins of the two personalities, read in:

* PX4-Autopilot: ``src/modules/navigator/geofence_params.yaml`` (GF_ACTION 2 = Hold, GF_MAX_HOR_DIST and
  GF_MAX_VER_DIST 0 = off), ``Navigator::geofence_breach_check`` (every 200 ms while GF_ACTION is not None; with
  GF_PREDICT at its default 0 the test point is the position itself), ``Geofence::isCloserThanMaxDistToHome`` /
  ``isBelowMaxAltitude`` (outside from ``>=`` the limit), ``checkPointAgainstAllGeofences`` (the cylinder AND the
  uploaded areas: inside every inclusion polygon or circle and outside every exclusion, since f2aabe968e8, 2023-11;
  a circle is ``d² < r²``, a polygon Franklin's PNPOLY), ``_updateFence`` (an area that does not contain home, or,
  flying with GF_ACTION set, the vehicle, is dropped with a text; no areas: no uploaded fence), commander ``HealthAndArmingChecks/checks/geofenceCheck.cpp``
  (the texts; arming refused while breached) and ``failsafe/failsafe.cpp`` ``fromGfActParam`` (the action; a Hold
  is left by any mode switch and cleared by it, so it acts again only on a new breach).
* ArduPilot: ``libraries/AC_Fence/AC_Fence.cpp`` (FENCE_* parameters and defaults, ``check``, the backup fences 20 m
  further out, the floor enabled once above FENCE_ALT_MIN + FENCE_MARGIN and off while landing or landed,
  ``pre_arm_check`` texts, ``print_fence_message``) and ``ArduCopter/fence.cpp`` ``Copter::fence_check`` (the action
  on a new breach; landed: disarm; more than 100 m out: LAND), ``Copter::set_mode`` (a mode change during a breach
  starts the 10 s manual recovery: ``AC_Fence::check`` still tracks breaches, done last "so that _breached_fences is
  correct", but returns no new one, so nothing acts).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot_modes import CopterMode
from sitl_bridge.mission_protocol import MissionItem
from sitl_bridge.multirotor import VehicleState
from sitl_bridge.px4_modes import FlightMode

# ----------------------------------------------------------------- PX4
PX4_CHECK_INTERVAL_S = 0.2  # Navigator's GEOFENCE_CHECK_INTERVAL_US
PX4_ACTIONS = {2: FlightMode.HOLD, 3: FlightMode.RTL, 5: FlightMode.LAND}  # GF_ACTION; 1 warns only


@dataclass(frozen=True)
class FenceArea:
    """One uploaded area: a polygon (vertices, north/east m) or a circle (centre and radius), to stay in or out of."""

    inclusion: bool
    vertices: tuple[tuple[float, float], ...] = ()
    centre: tuple[float, float] | None = None
    radius_m: float = 0.0

    def contains(self, north: float, east: float) -> bool:
        if self.centre is not None:  # Geofence::insideCircle
            return (north - self.centre[0]) ** 2 + (east - self.centre[1]) ** 2 < self.radius_m ** 2
        inside, j = False, len(self.vertices) - 1  # Geofence::insidePolygon (PNPOLY; north as lat, east as lon)
        for i, (n_i, e_i) in enumerate(self.vertices):
            n_j, e_j = self.vertices[j]
            if (e_i >= east) != (e_j >= east) and north <= (n_j - n_i) * (east - e_i) / (e_j - e_i) + n_i:
                inside = not inside
            j = i
        return inside

    def passes(self, north: float, east: float) -> bool:
        """checkPointAgainstPolygonCircle: inside an inclusion, outside an exclusion."""
        return self.contains(north, east) == self.inclusion


class Px4Geofence:
    """PX4's failsafe geofence: a cylinder around home of GF_MAX_HOR_DIST and GF_MAX_VER_DIST, and the uploaded
    areas."""

    geofence_breached = False  # geofence_result's triggers, as Commander last read them
    _geofence_checked_s = -math.inf
    fence_areas: tuple[FenceArea, ...] = ()

    def load_fence(self, items: list[MissionItem], now: float, state: VehicleState) -> None:
        """Geofence::_updateFence: the uploaded items as areas, each kept only if home (when known) passes it and,
        flying with GF_ACTION set, the vehicle does too."""
        areas, index = [], 0
        while index < len(items):
            item = items[index]
            inclusion = item.command in (mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                                         mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION)
            if item.command in (mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION):
                area, index = FenceArea(inclusion, centre=self.ned_of(item.x, item.y), radius_m=item.params[0]), index + 1
            elif item.command == mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT:
                index += 1
                continue
            else:
                count = int(item.params[0] + 0.5)
                corners = items[index:index + count]
                area, index = FenceArea(inclusion, vertices=tuple(self.ned_of(c.x, c.y) for c in corners)), index + count
            if self.gps_ok and not area.passes(*self.home_ned[:2]):
                self._event(now, "Geofence invalid, doesn't contain Home position\t", mavlink.MAV_SEVERITY_CRITICAL)
            elif int(self.params["GF_ACTION"]) and not state.on_ground and not area.passes(state.north_m, state.east_m):
                self._event(now, "Geofence invalid, doesn't contain current vehicle position\t",
                            mavlink.MAV_SEVERITY_CRITICAL)
            else:
                areas.append(area)
        self.fence_areas = tuple(areas)

    def outside_fence(self, north: float, east: float, down: float) -> list[str]:
        """checkPointAgainstAllGeofences, whatever GF_ACTION says: the limits a point breaks, in the texts
        geofenceCheck.cpp sends (empty: inside)."""
        home_n, home_e, home_d = self.home_ned
        max_hor, max_ver = self.params["GF_MAX_HOR_DIST"], self.params["GF_MAX_VER_DIST"]
        broken = []
        if max_hor > 0 and math.hypot(north - home_n, east - home_e) >= max_hor:
            broken.append("Geofence: exceeding maximum distance to Home")
        if max_ver > 0 and home_d - down >= max_ver:
            broken.append("Geofence: exceeding maximum altitude above Home")
        if not all(area.passes(north, east) for area in self.fence_areas):
            broken.append("Geofence: approaching or outside geofence")
        return broken

    def geofence_violations(self, state: VehicleState) -> list[str]:
        """What the position breaches, in the texts geofenceCheck.cpp sends as STATUSTEXT (its legacy mavlink_log
        path; "Geofence violation: ..." is the events-protocol wording), empty when inside or the fence is off."""
        if not int(self.params["GF_ACTION"]):
            return []
        return self.outside_fence(state.north_m, state.east_m, state.down_m)

    def _check_geofence(self, now: float, state: VehicleState) -> None:
        """Navigator's check and Commander's failsafe; called every tick while armed."""
        action = int(self.params["GF_ACTION"])
        if not action:
            self.geofence_breached = False
            return
        if now - self._geofence_checked_s < PX4_CHECK_INTERVAL_S - 1e-9:
            return
        self._geofence_checked_s = now
        violations = self.geofence_violations(state)
        if violations and not self.geofence_breached:
            for text in violations:
                self._event(now, text, mavlink.MAV_SEVERITY_CRITICAL)
            self._failsafe(now, state, PX4_ACTIONS.get(action), "geofence breached", delayable=True)
            if PX4_ACTIONS.get(action) is FlightMode.HOLD and self.mode is FlightMode.HOLD:
                # Navigator::geofence_breach_check repositions to where the vehicle is: already in Hold (flying to
                # a DO_REPOSITION target, MAVSDK's goto_location) it stops there too, not only on a mode change
                self.hold_target = (state.north_m, state.east_m, state.down_m)
        self.geofence_breached = bool(violations)


# ----------------------------------------------------------------- ArduCopter
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


class CopterFence:
    """ArduCopter's circle (FENCE_RADIUS), ceiling (FENCE_ALT_MAX) and floor (FENCE_ALT_MIN) fences."""

    fence_breaches = 0  # AC_Fence::_breached_fences
    _fence_floor_enabled = False
    _fence_backups: dict[int, float] = {}  # per fence: the distance past the fence that is a new breach
    _fence_recovery_until_s = -math.inf
    _fence_checked_s = -math.inf

    def _fence_configured(self) -> int:
        """FENCE_TYPE's fences that are present (AC_Fence::present: a polygon needs an upload, never made here)."""
        return int(self.params["FENCE_TYPE"]) & (ALT_MAX | CIRCLE | ALT_MIN) if self.params["FENCE_ENABLE"] else 0

    def _fence_distances(self, state: VehicleState) -> dict[int, float]:
        """How far past each fence the vehicle is (negative: inside)."""
        home_n, home_e, home_d = self.home_ned
        altitude = home_d - state.down_m
        return {ALT_MAX: altitude - self.params["FENCE_ALT_MAX"], ALT_MIN: self.params["FENCE_ALT_MIN"] - altitude,
                CIRCLE: math.hypot(state.north_m - home_n, state.east_m - home_e) - self.params["FENCE_RADIUS"]}

    def fence_prearm_failure(self) -> str | None:
        """AC_Fence::pre_arm_check, the parts that apply to parameter fences."""
        if not self.params["FENCE_ENABLE"]:
            return None
        if not self._fence_configured():
            return "Fences enabled, but none selected"
        if self._fence_configured() & CIRCLE and not self.gps_ok:
            return "Fence requires position"
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
            if past < 0:
                self.fence_breaches &= ~fence
                continue
            if not self.fence_breaches & fence or past >= self._fence_backups.get(fence, math.inf):
                new |= fence
                self.fence_breaches |= fence
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
