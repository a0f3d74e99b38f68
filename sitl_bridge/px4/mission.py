"""PX4's Mission mode (AUTO.MISSION) for a multirotor: the feasibility check, and flying the items one by one.

A mixin of :class:`sitl_bridge.px4.autopilot.Px4Autopilot`. Read in PX4-Autopilot main at 02e73e3 (docs/sitl.md, "PX4
missions", has the line references):

* **feasibility** (``navigator/MissionFeasibility/FeasibilityChecker.cpp``, ``mission_feasibility_checker.cpp``):
  run when a mission arrives and again when it starts. A failure does not refuse the upload (that was ACKed
  already); it marks the mission invalid, so Mission mode cannot be entered armed, arming in it is refused, and
  MAV_CMD_MISSION_START is DENIED. Checked here: a position fix (home), a takeoff above home and before any other
  position item, no landing as the first item while landed, every position item inside the geofence
  (GF_MAX_HOR_DIST / GF_MAX_VER_DIST and the uploaded areas, whatever GF_ACTION says). A first waypoint further
  than MIS_DIST_1WP from home only warns.
* **flying it** (``mission_base.cpp``, ``mission.cpp``, ``mission_block.cpp``): starting below the next position
  item's altitude, PX4 first climbs straight up to it (a takeoff when landed; no MISSION_ITEM_REACHED for that
  climb), then flies each item: a position item is reached within its param2 (else NAV_ACC_RAD) horizontally and
  NAV_MC_ALT_RAD vertically, facing param4 within MIS_YAW_ERR when param4 is set, then held for param1 s
  (WAYPOINT, LOITER_TIME); LOITER_UNLIM holds for ever; LAND flies to the point at its altitude, then lands, and is
  reached on the ground; DO_CHANGE_SPEED (param2 > 0 sets the cruising speed, else the default) completes at once;
  RETURN_TO_LAUNCH completes at once and switches to RTL; NAV_DELAY holds for param1 s. After the last item
  "Mission finished, loitering" (or "..., landed"): the vehicle holds in Mission mode. Entering Mission mode
  resets the cruising speed and replays the last DO_CHANGE_SPEED before the current item; a finished mission
  starts again at its first item once the vehicle has been disarmed.
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.autopilot_base import ACCEPTED, DENIED, TEMPORARILY_REJECTED
from sitl_bridge.dynamics import velocity_toward
from sitl_bridge.mission_items import MissionItem
from sitl_bridge.multirotor import VehicleState, VelocityCommand
from sitl_bridge.px4.modes import FlightMode

ACTIVE_MODES = (FlightMode.MISSION, FlightMode.TAKEOFF, FlightMode.LAND)  # update_mission_state's "active"
HELD_COMMANDS = (mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_LOITER_TIME)  # param1 is a hold time
# MISSION_CURRENT.mission_mode (a plain uint8 in common.xml: 1 in a mode that flies the mission, 2 suspended)
IN_MISSION_MODE, SUSPENDED = 1, 2
INSTANT_COMMANDS = (mavlink.MAV_CMD_DO_CHANGE_SPEED, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)


def seconds(param: float) -> float:
    """A hold time or delay parameter: at least 0 (get_time_inside's clamp), NaN as 0."""
    return param if math.isfinite(param) and param > 0.0 else 0.0


class Px4MissionMode:
    """The stored mission and where Mission mode is in it; ``mission_*`` attributes are read by the telemetry."""

    mission_items: list[MissionItem] = []
    mission_valid = False
    mission_current = 0  # the item being flown (MISSION_CURRENT.seq)
    mission_reached = -1  # the last item reached; -1: none since Mission mode began (MISSION_CURRENT's state)
    mission_reached_news: list[int]  # items reached since the vehicle last sent MISSION_ITEM_REACHED
    mission_finished = False
    _climb: tuple[float, float, float] | None = None  # the inserted climb's target (NED), while climbing
    _climb_is_takeoff = False  # the climb began on the ground (a TAKEOFF setpoint)
    _item_reached_s: float | None = None  # when the current position item was reached (its hold time runs)
    _item_started_s: float | None = None  # when the current item became the one flown (NAV_DELAY's clock)
    _landing = False  # the LAND item's descent has begun
    _disarmed_since_start = True

    # ------------------------------------------------------------------ the stored mission
    def load_mission(self, items: list[MissionItem], current_seq: int, now: float, state: VehicleState) -> None:
        """A mission arrived (an upload or a clear); ``current_seq`` -1: keep the current index, clamped."""
        self.mission_items = list(items)
        last = max(len(items) - 1, 0)
        self.mission_current = current_seq if current_seq >= 0 else min(max(self.mission_current, 0), last)
        self.mission_reached, self.mission_finished = -1, False
        self.check_mission(now, state)
        if self.mode is FlightMode.MISSION and self.armed:
            if self.mission_valid:
                self._start_mission(now, state)  # PX4 flies the new mission at once
            else:  # Commander's fallback for a Mission mode that can no longer run
                self._event(now, "No valid mission available, loitering\t", mavlink.MAV_SEVERITY_CRITICAL)
                self.set_mode(FlightMode.RTL, now, state, "the mission is no longer valid")

    def set_mission_current(self, seq: int, now: float, state: VehicleState) -> None:
        """MISSION_SET_CURRENT (or MISSION_START's param1): fly ``seq`` next; in Mission mode at once."""
        self.mission_current, self.mission_finished = seq, False
        self._begin_item(now, state)
        if self.mode is FlightMode.MISSION and self.armed:
            self._climb = self._climb_needed(state)

    def check_mission(self, now: float, state: VehicleState, announce: bool = True) -> bool:
        """MissionFeasibilityChecker::checkMissionFeasible (kept as ``mission_valid``); the reasons go out as PX4's
        texts when ``announce``."""
        failures = self._infeasible(state) if self.mission_items else ["no mission"]
        self.mission_valid = not failures
        if not self.mission_items:
            return False
        if announce:
            for text in failures:  # all mavlink_log_critical but the position lock's (info)
                self._event(now, text, mavlink.MAV_SEVERITY_INFO if "position lock" in text
                            else mavlink.MAV_SEVERITY_CRITICAL)
            far = self._first_waypoint_distance_m()
            if not failures and far is not None and 0.0 < self.params["MIS_DIST_1WP"] < far:
                self._event(now, f"First waypoint far away from home: {int(far)}m. Correct mission loaded?\t",
                            mavlink.MAV_SEVERITY_CRITICAL)
        return not failures

    def _infeasible(self, state: VehicleState) -> list[str]:
        if not self.gps_ok:
            return ["Not yet ready for mission, no position lock.\t"]
        seen_position = False
        for index, item in enumerate(self.mission_items):
            if index == 0 and item.command == mavlink.MAV_CMD_NAV_LAND and state.on_ground:
                return ["Mission rejected: starts with landing\t"]
            if item.command == mavlink.MAV_CMD_NAV_TAKEOFF:
                if seen_position:
                    return ["Mission rejected: takeoff not first waypoint item\t"]
                if self._item_ned(item)[2] >= self.home_ned[2]:
                    return ["Mission rejected: Takeoff altitude below home altitude!\t"]
            seen_position = seen_position or item.positional
        for index, item in enumerate(self.mission_items):
            if item.positional and self.outside_fence(*self._item_ned(item)):  # whatever GF_ACTION says
                return [f"Geofence violation for waypoint {index + 1}\t"]  # counted from 1
        return []

    def _first_waypoint_distance_m(self) -> float | None:
        item = next((i for i in self.mission_items if i.positional), None)
        if item is None:
            return None
        north, east, _ = self._item_ned(item)
        return math.hypot(north - self.home_ned[0], east - self.home_ned[1])

    def _item_ned(self, item: MissionItem) -> tuple[float, float, float]:
        north, east = self.ned_of(item.x, item.y)
        return north, east, self.home_ned[2] - item.z if item.relative else self.down_of(item.z)

    def _mission_start(self, first: float, now: float, state: VehicleState, source_component: int) -> int:
        """MAV_CMD_MISSION_START as Commander takes it: a valid mission, param1 the first item (-1: the current
        one); Mission mode and arming, TEMPORARILY_REJECTED if either fails."""
        if not self.check_mission(now, state, announce=False):
            self._event(now, "Mission start denied! No valid mission\t", mavlink.MAV_SEVERITY_CRITICAL)
            return DENIED
        if not (math.isfinite(first) and -1 <= first < len(self.mission_items)):
            return DENIED
        if first >= 0:
            self.set_mission_current(int(first), now, state)
        if self.set_mode(FlightMode.MISSION, now, state, "MISSION_START", source_component) != ACCEPTED:
            return TEMPORARILY_REJECTED
        return self.arm(now, state, force=False)

    # ------------------------------------------------------------------ what MISSION_CURRENT says
    def mission_state(self, previous: int) -> tuple[int, int]:
        """(mission_state, mission_mode) as mavlink_mission.cpp's update_mission_state derives them."""
        active = self.mode in ACTIVE_MODES
        mode = IN_MISSION_MODE if active else SUSPENDED
        if not self.mission_items or not self.mission_valid:
            return mavlink.MISSION_STATE_NO_MISSION, mode
        if self.mission_finished:
            return mavlink.MISSION_STATE_COMPLETE, mode
        if active:
            return mavlink.MISSION_STATE_ACTIVE, mode
        if self.mission_reached >= 0:
            return mavlink.MISSION_STATE_PAUSED, mode
        if self.mission_current < 1:
            return mavlink.MISSION_STATE_NOT_STARTED, mode
        return previous, mode

    @property
    def mission_setpoint(self) -> str:
        """What Mission mode is doing now: "takeoff" (climbing from the ground), "land" (a LAND item's descent)
        or "position" (EXTENDED_SYS_STATE reads the first two as TAKEOFF and LANDING)."""
        if self._climb is not None and self._climb_is_takeoff:
            return "takeoff"
        return "land" if self._landing else "position"

    # ------------------------------------------------------------------ flying it
    def _start_mission(self, now: float, state: VehicleState) -> None:
        """MissionBase::on_activation: armed and in Mission mode with a valid mission."""
        if self.mission_finished and self._disarmed_since_start:  # checkMissionRestart
            self.mission_current, self.mission_finished = 0, False
        self._disarmed_since_start = False
        self.mission_reached = -1
        self.cruise_speed_mps = None
        for item in self.mission_items[:self.mission_current]:  # replayCachedSpeedChangeItems
            if item.command == mavlink.MAV_CMD_DO_CHANGE_SPEED:
                self.cruise_speed_mps = item.params[1] if item.params[1] > 0.0 else None
        self._begin_item(now, state)
        self._climb, self._climb_is_takeoff = self._climb_needed(state), state.on_ground
        if self._climb is not None:
            self._event(now, f"Climb to {self.home_ned[2] - self._climb[2]:.1f} meters above home\t")

    def _climb_needed(self, state: VehicleState) -> tuple[float, float, float] | None:
        """checkClimbRequired: the next position item more than NAV_MC_ALT_RAD above: climb where we are."""
        item = next((i for i in self.mission_items[self.mission_current:] if i.positional), None)
        if item is None or self.mission_finished:
            return None
        down = self._item_ned(item)[2]
        if state.down_m - down <= self.params["NAV_MC_ALT_RAD"]:
            return None
        return state.north_m, state.east_m, down

    def _begin_item(self, now: float, state: VehicleState) -> None:
        self._item_reached_s, self._item_started_s, self._landing = None, now, False
        self.hold_target = (state.north_m, state.east_m, 0.0 if state.on_ground else state.down_m)

    def _mission_command(self, now: float, state: VehicleState) -> VelocityCommand:
        """This tick's command in Mission mode (armed)."""
        if self._climb is not None:
            north, east, down = self._climb
            height = self.home_ned[2] - down
            margin = min(self.params["NAV_MC_ALT_RAD"], height / 2.0) if height > 0.0 else 0.0
            if state.down_m > down + margin:
                return velocity_toward(state, north, east, down, self.airframe, speed_xy_mps=0.0,
                                       speed_z_mps=self.params["MPC_TKO_SPEED"])
            self._climb = None
        for _ in range(len(self.mission_items) + 1):  # items that complete at once, then the one to fly
            if self.mission_finished or self.mode is not FlightMode.MISSION:
                return self._hold_command(state)
            item = self.mission_items[self.mission_current]
            if not item.positional and item.command != mavlink.MAV_CMD_NAV_DELAY:
                self._instant_item(item, now, state)
                continue
            command = self._fly_item(item, now, state)
            if command is not None:
                return command
        return self._hold_command(state)

    def _instant_item(self, item: MissionItem, now: float, state: VehicleState) -> None:
        if item.command == mavlink.MAV_CMD_DO_CHANGE_SPEED:  # Navigator: param2 > 0 sets, anything else resets
            self.cruise_speed_mps = item.params[1] if item.params[1] > 0.0 else None
        elif item.command not in INSTANT_COMMANDS:
            self._event(now, f"mission item {self.mission_current}: command {item.command} passed over "
                             f"(no camera or gimbal simulated)", broadcast=False)
        returning = item.command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
        self._item_done(now, state)
        if returning:  # Commander: "switch to RTL which ends the mission"
            self._event(now, "Returning to launch\t")
            self.set_mode(FlightMode.RTL, now, state, "mission item RETURN_TO_LAUNCH")

    def _fly_item(self, item: MissionItem, now: float, state: VehicleState) -> VelocityCommand | None:
        """The command towards a position item (or NAV_DELAY's hold); None once it is done."""
        if item.command == mavlink.MAV_CMD_NAV_DELAY:
            if now - (self._item_started_s or now) >= seconds(item.params[0]):
                self._item_done(now, state)
                return None
            return self._hold_command(state)
        north, east, down = self._item_ned(item)
        speed = min(self.cruise_speed_mps or self.params["MPC_XY_CRUISE"], self.params["MPC_XY_VEL_MAX"])
        if item.command == mavlink.MAV_CMD_NAV_LAND:
            return self._land_item(north, east, now, state, speed)
        radius = item.params[1] if math.isfinite(item.params[1]) and item.params[1] > 0.0 else \
            self.params["NAV_ACC_RAD"]
        yaw = math.radians(item.params[3]) if math.isfinite(item.params[3]) else None
        distance = math.hypot(north - state.north_m, east - state.east_m)
        if self._item_reached_s is None and not state.on_ground and distance <= radius \
                and abs(down - state.down_m) <= self.params["NAV_MC_ALT_RAD"] \
                and (yaw is None or abs(math.remainder(yaw - state.yaw_rad, math.tau))
                     <= math.radians(self.params["MIS_YAW_ERR"])):
            self._item_reached_s = now
        if self._item_reached_s is not None:
            hold_s = seconds(item.params[0]) if item.command in HELD_COMMANDS else 0.0
            if item.command != mavlink.MAV_CMD_NAV_LOITER_UNLIM and now - self._item_reached_s >= hold_s:
                self._item_done(now, state)
                return None
        if yaw is None and distance > radius:  # PX4's multirotor faces the waypoint it flies to
            yaw = math.atan2(east - state.east_m, north - state.north_m)
        command = velocity_toward(state, north, east, down, self.airframe, speed_xy_mps=speed)
        return VelocityCommand(command.north_mps, command.east_mps, command.down_mps, yaw)

    def _land_item(self, north: float, east: float, now: float, state: VehicleState,
                   speed: float) -> VelocityCommand | None:
        """handleLanding: further than NAV_ACC_RAD, first to the point at the current altitude; then land."""
        if state.on_ground and self._landing:
            self._item_done(now, state)
            return None
        if not self._landing:
            if math.hypot(north - state.north_m, east - state.east_m) > self.params["NAV_ACC_RAD"]:
                return velocity_toward(state, north, east, state.down_m, self.airframe, speed_xy_mps=speed)
            self._landing = True
        return self._landing_command(state, north, east)

    def _item_done(self, now: float, state: VehicleState) -> None:
        """set_mission_item_reached, then advance_mission (or the end of the mission)."""
        self.mission_reached = self.mission_current
        self.mission_reached_news.append(self.mission_current)
        if self.mission_current + 1 < len(self.mission_items):
            self.mission_current += 1
            self._begin_item(now, state)
            return
        self.mission_finished = True
        self._event(now, "Mission finished, landed\t" if state.on_ground else "Mission finished, loitering\t")
        self.hold_target = (state.north_m, state.east_m, 0.0 if state.on_ground else state.down_m)
