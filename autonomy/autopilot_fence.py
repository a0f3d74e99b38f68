"""Before arming: does the autopilot's own geofence fit the mission?

The runner's guard (:mod:`autonomy.geofence`) is software on the companion computer; the autopilot's parameter fence
is the layer beneath it (PX4: GF_MAX_HOR_DIST / GF_MAX_VER_DIST around home, GF_ACTION; ArduCopter: FENCE_ENABLE,
FENCE_TYPE, FENCE_RADIUS / FENCE_ALT_MAX / FENCE_ALT_MIN around home, FENCE_ACTION; docs/sitl.md cites both
autopilots' sources). The runner reads those parameters while it waits for its pose estimate and judges them:

* a fence that acts (PX4 Hold/Return/Land, ArduPilot RTL/Land/Brake) and that the search would cross (the radius
  short of where the guard lets the drone go, the ceiling at or below the search altitude, the floor at or above
  the lowest altitude a close look descends to) would end the search mid-way: the mission is refused before
  arming, with the value that would fit;
* no fence that acts: the flight goes ahead with a warning naming the setting that would enclose the mission;
* otherwise the fence is recorded in the mission report.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from missions.search_state_v1 import CLOSE_LOOK_ALTITUDE_M
from missions.geodesy import GeoPoint, LocalFrame
from missions.mission import Mission

PX4_PARAMS = ("GF_ACTION", "GF_MAX_HOR_DIST", "GF_MAX_VER_DIST")
ARDUPILOT_PARAMS = ("FENCE_ENABLE", "FENCE_TYPE", "FENCE_ACTION", "FENCE_RADIUS", "FENCE_ALT_MAX", "FENCE_ALT_MIN")
PX4_ACTIONS = {0: "none", 1: "warning", 2: "Hold", 3: "Return", 4: "Terminate", 5: "Land"}
ARDUPILOT_ACTIONS = {0: "report only", 1: "RTL or Land", 2: "Land", 3: "SmartRTL, RTL or Land",
                     4: "Brake or Land", 5: "SmartRTL or Land"}
ALT_MAX, CIRCLE, ALT_MIN = 1, 2, 8  # FENCE_TYPE bits
CEILING_ROOM_M = 5.0  # the altitude hold's overshoot a ceiling must leave room for
FLOOR_ROOM_M = 5.0
REACHED_RADIUS_M = 5.0  # closer than this to an acting fence's radius counts as at it (fence_reached) ...
REACHED_HEIGHT_M = 2.0  # ... and to its ceiling or floor (inside the 5 m the preflight check leaves free)


def fence_params(autopilot: str) -> tuple[str, ...]:
    """The parameters to read for an autopilot flavour's name ("PX4" or "ArduPilot Copter")."""
    return PX4_PARAMS if autopilot == "PX4" else ARDUPILOT_PARAMS


@dataclass(frozen=True)
class AutopilotFence:
    """The autopilot's fence around home, in the runner's terms (None: that limit is off)."""

    radius_m: float | None
    ceiling_m: float | None
    floor_m: float | None
    action: str
    """What a breach makes the autopilot do, in its own words."""
    action_changes_flight: bool
    """A breach changes the flight (not only a warning or a report)."""
    names: tuple[str, str, str]
    """The parameters behind radius, ceiling and floor (for messages)."""

    @property
    def acts(self) -> bool:
        """There is a limit, and breaching it changes the flight."""
        return self.action_changes_flight and any(v is not None for v in (self.radius_m, self.ceiling_m, self.floor_m))

    def describe(self) -> str:
        limits = [f"{name} {value:g} m" for name, value in zip(self.names, (self.radius_m, self.ceiling_m,
                                                                            self.floor_m)) if value is not None]
        return f"{', '.join(limits) or 'no limit set'}, on a breach: {self.action}"


def read_fence(autopilot: str, values: dict[str, float]) -> AutopilotFence:
    """The fence the parameter ``values`` (decoded numbers, by name) describe."""
    if autopilot == "PX4":
        action = int(values["GF_ACTION"])
        radius, ceiling = values["GF_MAX_HOR_DIST"], values["GF_MAX_VER_DIST"]
        return AutopilotFence(radius if radius > 0 else None, ceiling if ceiling > 0 else None, None,
                              PX4_ACTIONS.get(action, f"GF_ACTION {action}"), action >= 2,
                              ("GF_MAX_HOR_DIST", "GF_MAX_VER_DIST", ""))
    enabled, types, action = int(values["FENCE_ENABLE"]) == 1, int(values["FENCE_TYPE"]), int(values["FENCE_ACTION"])

    def on(bit: int) -> bool:
        return enabled and bool(types & bit)

    return AutopilotFence(values["FENCE_RADIUS"] if on(CIRCLE) else None,
                          values["FENCE_ALT_MAX"] if on(ALT_MAX) else None,
                          values["FENCE_ALT_MIN"] if on(ALT_MIN) else None,
                          ARDUPILOT_ACTIONS.get(action, f"FENCE_ACTION {action}"), enabled and action != 0,
                          ("FENCE_RADIUS", "FENCE_ALT_MAX", "FENCE_ALT_MIN"))


def home_offset_ne(mission: Mission, vehicle_home: GeoPoint) -> tuple[float, float]:
    """Where the vehicle's home is in the mission's frame (north, east from the mission's home, m)."""
    north, east, _ = LocalFrame(mission.scenario.home).to_ned(vehicle_home.lat_deg, vehicle_home.lon_deg,
                                                              vehicle_home.alt_m)
    return north, east


def fence_reached(autopilot: str, values: dict[str, float], north_m: float, east_m: float,
                  height_m: float) -> str | None:
    """Whether the drone, ``north_m``/``east_m`` from the vehicle's home at ``height_m`` above it, is at the
    autopilot's acting fence (read from the parameter ``values``, the latest the link heard), within the distance
    the autopilot's own check can lag (PX4 checks every 200 ms; GPS error): then a mode change there is the
    autopilot's geofence failsafe, announced or not (its text may be lost in an outage). None: not at it."""
    names = fence_params(autopilot)
    if not all(name in values for name in names):
        return None
    fence = read_fence(autopilot, values)
    if not fence.acts:
        return None
    distance = math.hypot(north_m, east_m)
    radius_name, ceiling_name, floor_name = fence.names
    if fence.radius_m is not None and distance >= fence.radius_m - REACHED_RADIUS_M:
        return f"{radius_name} {fence.radius_m:g} m reached: {distance:.0f} m from home"
    if fence.ceiling_m is not None and height_m >= fence.ceiling_m - REACHED_HEIGHT_M:
        return f"{ceiling_name} {fence.ceiling_m:g} m reached: {height_m:.0f} m above home"
    if fence.floor_m is not None and height_m <= fence.floor_m + REACHED_HEIGHT_M:
        return f"{floor_name} {fence.floor_m:g} m reached: {height_m:.0f} m above home"
    return None


def mission_reach_m(mission: Mission, vehicle_home: GeoPoint, guard_margin_m: float) -> tuple[float, float]:
    """(how far from the vehicle's home the runner's guard lets the drone go, how far the mission's fence reaches):
    the farthest corner of the mission's geofence, drawn in by the guard's margin for the first."""
    home_n, home_e = home_offset_ne(mission, vehicle_home)
    fence = mission.fence

    def farthest(inset: float) -> float:
        return max(math.hypot(n - home_n, e - home_e) for n in (fence.north_min_m + inset, fence.north_max_m - inset)
                   for e in (fence.east_min_m + inset, fence.east_max_m - inset))
    return farthest(guard_margin_m), farthest(0.0)


def fence_conflicts(fence: AutopilotFence, mission: Mission, vehicle_home: GeoPoint,
                    guard_margin_m: float) -> list[str]:
    """Where an acting autopilot fence would stop the search, one sentence each with the value that fits."""
    if not fence.acts:
        return []
    reach, extent = mission_reach_m(mission, vehicle_home, guard_margin_m)
    altitude = mission.flight.altitude_m
    lowest = min(altitude, CLOSE_LOOK_ALTITUDE_M)
    radius_name, ceiling_name, floor_name = fence.names
    problems = []
    if fence.radius_m is not None and fence.radius_m <= reach:
        problems.append(f"{radius_name} {fence.radius_m:g} m is short of the search: the drone may fly {reach:.0f} m "
                        f"from home; set it to at least {math.ceil(extent / 10) * 10:.0f} m (the mission's geofence)")
    if fence.ceiling_m is not None and fence.ceiling_m < altitude + CEILING_ROOM_M:
        problems.append(f"{ceiling_name} {fence.ceiling_m:g} m is too low for the search altitude {altitude:g} m; set "
                        f"it to at least {altitude + CEILING_ROOM_M:g} m")
    if fence.floor_m is not None and fence.floor_m > lowest - FLOOR_ROOM_M:
        problems.append(f"{floor_name} {fence.floor_m:g} m is too high for the close looks down to {lowest:g} m; set "
                        f"it to at most {lowest - FLOOR_ROOM_M:g} m")
    return problems


def missing_fence_warning(autopilot: str, fence: AutopilotFence, mission: Mission, vehicle_home: GeoPoint) -> str:
    """Why only the runner's guard keeps the drone inside, and the setting that would add the autopilot's fence."""
    _, extent = mission_reach_m(mission, vehicle_home, 0.0)
    radius = math.ceil(extent / 10) * 10
    fix = f"GF_MAX_HOR_DIST={radius} (GF_ACTION 2: Hold)" if autopilot == "PX4" else \
        f"FENCE_ENABLE=1, FENCE_RADIUS={radius} (FENCE_ACTION 1: RTL)"
    return (f"the autopilot's own geofence does not act ({fence.describe()}): only the runner's guard keeps the drone "
            f"in the mission's area; {fix} would add the autopilot's fence around it")


def judge_autopilot_fence(autopilot: str, values: dict[str, float], mission: Mission, vehicle_home: GeoPoint,
                          guard_margin_m: float) -> tuple[dict, str | None, str]:
    """(the mission report's record, why the mission must not be flown or None, the event log's line) for the
    fence parameter ``values`` of an ``autopilot`` ("PX4" or "ArduPilot Copter")."""
    fence = read_fence(autopilot, values)
    record = {"checked": True, "acts": fence.acts, "description": fence.describe()}
    problems = fence_conflicts(fence, mission, vehicle_home, guard_margin_m)
    refusal = "the autopilot's own geofence would stop the search: " + "; ".join(problems) if problems else None
    note = fence.describe() if fence.acts else missing_fence_warning(autopilot, fence, mission, vehicle_home)
    return record, refusal, note
