"""PX4's failsafe geofence: the GF_* cylinder around home and the fence uploaded with the mission protocol.

The runner's guard (``autonomy/geofence.py``) lives in the companion computer's software; the autopilot's fence is
the layer beneath it, and what stops the drone when that software misbehaves. A mixin of the PX4 personality
(:class:`sitl_bridge.px4.autopilot.Px4Autopilot`); the areas come from ``sitl_bridge.px4.mission_protocol``
(polygons and circles, read by ``sitl_bridge.fence_areas``). Read in

* PX4-Autopilot: ``src/modules/navigator/geofence_params.yaml`` (GF_ACTION 2 = Hold, GF_MAX_HOR_DIST and
  GF_MAX_VER_DIST 0 = off), ``Navigator::geofence_breach_check`` (every 200 ms while GF_ACTION is not None; with
  GF_PREDICT at its default 0 the test point is the position itself), ``Geofence::isCloserThanMaxDistToHome`` /
  ``isBelowMaxAltitude`` (outside from ``>=`` the limit), ``checkPointAgainstAllGeofences`` (the cylinder AND the
  uploaded areas: inside every inclusion polygon or circle and outside every exclusion, since f2aabe968e8; a
  circle is ``d² < r²``, a polygon Franklin's PNPOLY), ``_updateFence`` (an area that does not contain home, or,
  flying with GF_ACTION set, the vehicle, is dropped with a text; no areas: no uploaded fence), commander
  ``HealthAndArmingChecks/checks/geofenceCheck.cpp`` (the texts; arming refused while breached) and
  ``failsafe/failsafe.cpp`` ``fromGfActParam`` (the action; a Hold is left by any mode switch and cleared by it, so
  it acts again only on a new breach).
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.fence_areas import FenceArea, fence_areas
from sitl_bridge.mission_items import MissionItem
from sitl_bridge.multirotor import VehicleState
from sitl_bridge.px4.modes import FlightMode

PX4_CHECK_INTERVAL_S = 0.2  # Navigator's GEOFENCE_CHECK_INTERVAL_US
PX4_ACTIONS = {2: FlightMode.HOLD, 3: FlightMode.RTL, 5: FlightMode.LAND}  # GF_ACTION; 1 warns only


class Px4Geofence:
    """PX4's failsafe geofence: a cylinder around home of GF_MAX_HOR_DIST and GF_MAX_VER_DIST, and the uploaded
    areas."""

    geofence_breached = False  # geofence_result's triggers, as Commander last read them
    _geofence_checked_s = -math.inf
    fence_areas: tuple[FenceArea, ...] = ()

    def load_fence(self, items: list[MissionItem], now: float, state: VehicleState) -> None:
        """Geofence::_updateFence: the uploaded items as areas, each kept only if home (when known) passes it and,
        flying with GF_ACTION set, the vehicle does too."""
        areas = []
        for area in fence_areas(items, self.ned_of):
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
