"""ArduCopter's AUTO mode: flying the uploaded mission command by command.

A mixin of :class:`sitl_bridge.ardupilot.autopilot.ArduCopter`. Read in ArduPilot master at 9070097 (docs/sitl.md,
"ArduPilot missions"): ``ArduCopter/mode_auto.cpp`` (``init``, ``run``, ``exit_mission``, ``do_*`` / ``verify_*``),
``libraries/AP_Mission/AP_Mission.cpp`` (``start_or_resume``, ``set_current_cmd``, ``start_command``'s texts),
``GCS_MAVLink_Copter.cpp`` (MISSION_START, ``mission_state``), ``AP_Arming_Copter.cpp``, ``Parameters.cpp``
(AUTO_OPTIONS):

* entering AUTO disarmed is always allowed; armed it needs a mission, and on the ground one whose next navigation
  command is a takeoff ("Auto: Missing Takeoff Cmd"); leaving AUTO stops the mission, coming back resumes the
  current command (MIS_RESTART 0);
* arming in AUTO is refused ("Arm: Mode not armable") unless AUTO_OPTIONS bit 0; the takeoff then waits for
  the pilot's throttle, which this simulator has none of, so for AUTO_OPTIONS bit 1 or MAV_CMD_MISSION_START (which
  switches to AUTO and lets the takeoff go, but does not arm);
* a command starting says "Mission: N <name>"; the DO commands after a navigation command run as it starts (DO_
  CHANGE_SPEED: param2 > 0 m/s becomes the waypoint speed for this AUTO session); TAKEOFF climbs where the
  vehicle is to its altitude at WPNAV_SPEED_UP; WAYPOINT and LOITER_TIME fly at WPNAV_SPEED, are reached within
  WPNAV_RADIUS, then wait param1 s ("Reached command #N"); LOITER_UNLIM holds; LAND flies to its point (0, 0: here)
  at the current altitude, lands and disarms, the mission staying on it; RETURN_TO_LAUNCH flies RTL inside AUTO
  and, landed, ends the mission; each completed command sends MISSION_ITEM_REACHED (LAND's does not: it disarms
  first);
* the end of the mission: in the air the vehicle holds where it is, still in AUTO; on the ground it disarms.
"""
from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.modes import CopterMode
from sitl_bridge.dynamics import velocity_toward
from sitl_bridge.mission_items import MissionItem
from sitl_bridge.multirotor import HOVER, VehicleState, VelocityCommand

NAMES = {mavlink.MAV_CMD_NAV_WAYPOINT: "WP", mavlink.MAV_CMD_NAV_TAKEOFF: "Takeoff", mavlink.MAV_CMD_NAV_LAND: "Land",
         mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH: "RTL", mavlink.MAV_CMD_NAV_LOITER_TIME: "LoitTime",
         mavlink.MAV_CMD_NAV_LOITER_UNLIM: "LoitUnlim", mavlink.MAV_CMD_DO_CHANGE_SPEED: "ChangeSpeed"}
NAVIGATION = (mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND,
              mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_NAV_LOITER_TIME, mavlink.MAV_CMD_NAV_LOITER_UNLIM)
ALLOW_ARMING, ALLOW_TAKEOFF_WITHOUT_THROTTLE = 1, 2  # AUTO_OPTIONS bits
TAKEOFF_ABOVE_GROUND_M = 1.0  # takeoff_start: at least this far above where a landed vehicle is


class CopterAuto:
    """The uploaded mission (``auto_items``: item 1 first; item 0 is home) and where AUTO is in it."""

    auto_items: list[MissionItem] = []
    mission_state = "stopped"  # AP_Mission: stopped, running or complete
    nav_index: int | None = None  # the navigation command being flown (1: the first item), None: none yet
    auto_submode: str | None = None  # takeoff, wp, land, rtl or loiter (the end of the mission)
    auto_armed = False  # Copter's ap.auto_armed: the takeoff may go
    _auto_target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    _auto_reached_s: float | None = None
    _auto_speed_mps: float | None = None  # DO_CHANGE_SPEED's, for this AUTO session
    _land_descending = False
    _takeoff_started = False
    auto_reached_news: list[int]  # commands completed since the vehicle last sent MISSION_ITEM_REACHED

    # ------------------------------------------------------------------ the mission
    def load_auto_mission(self, items: list[MissionItem], now: float, state: VehicleState) -> None:
        """An upload or a clear (AP_Mission::truncate / clear): the current command is kept if it still exists."""
        self.auto_items = list(items)
        if self.nav_index is not None and self.nav_index > len(items):
            self.nav_index = None
        if not items:
            self.nav_index, self.mission_state = None, "stopped"

    def set_mission_current(self, seq: int, now: float, state: VehicleState) -> bool:
        """AP_Mission::set_current_cmd: item 0 means 1; running, the vehicle goes there at once."""
        if seq >= len(self.auto_items) + 1 or not self.auto_items:
            return False
        seq = max(seq, 1)
        if self.mission_state == "running":
            self._start_command(seq, now, state)
        else:
            self.nav_index, self.mission_state = seq, "stopped"
        return True

    def mission_current_fields(self) -> tuple[int, int, int, int]:
        """MISSION_CURRENT's seq, total (home excluded), mission_state and mission_mode (send_mission_current)."""
        total = len(self.auto_items)
        if total == 0:
            state = mavlink.MISSION_STATE_NO_MISSION
        else:
            state = {"stopped": mavlink.MISSION_STATE_NOT_STARTED, "running": mavlink.MISSION_STATE_ACTIVE,
                     "complete": mavlink.MISSION_STATE_COMPLETE}[self.mission_state]
        return self.nav_index or 0, total, state, int(self.mode is CopterMode.AUTO)

    @property
    def mission_running(self) -> bool:
        return self.armed and self.mission_state == "running"

    def _next_navigation(self, after: int) -> int | None:
        return next((i for i in range(after + 1, len(self.auto_items) + 1)
                     if self.auto_items[i - 1].command in NAVIGATION), None)

    # ------------------------------------------------------------------ entering and leaving AUTO
    def _auto_init(self, now: float, state: VehicleState) -> bool:
        """ModeAuto::init: disarmed anything goes; armed a mission, and landed a takeoff next."""
        if not self.armed:
            return True
        if not self.auto_items:
            return False
        start = self.nav_index if self.nav_index is not None and self.mission_state != "complete" else 0
        first = self._next_navigation(start - 1 if start else 0)
        if self.land_complete and (first is None or self.auto_items[first - 1].command != mavlink.MAV_CMD_NAV_TAKEOFF):
            self._event(now, "Auto: Missing Takeoff Cmd", mavlink.MAV_SEVERITY_CRITICAL)
            return False
        return True

    def _auto_entered(self, now: float, state: VehicleState) -> None:
        """ModeAuto::run's first pass: AP_Mission::start_or_resume (MIS_RESTART 0: resume)."""
        self._auto_speed_mps = None
        if not self.auto_items:
            self.mission_state = "complete"
            return
        if self.mission_state == "complete" or self.nav_index is None:
            first = self._next_navigation(0)
            self.mission_state = "running"
            self._start_command(first or 1, now, state)
        else:  # resume: the current command again, from where the vehicle is
            self.mission_state = "running"
            self._start_command(self.nav_index, now, state)

    def _auto_disarmed(self) -> None:
        """Disarming (AP_Arming_Copter::disarm resets the mission's commands): the takeoff needs letting go again,
        and the mission starts from its first command next time (ArduPilot re-advances to it at once, disarmed,
        saying "Mission: 1 ..."; here that happens when it next starts)."""
        self.auto_armed, self.nav_index = False, None
        if self.mission_state == "running":
            self.mission_state = "stopped"

    def _auto_left(self) -> None:
        """ModeAuto::exit: a running mission stops (its command is kept)."""
        if self.mission_state == "running":
            self.mission_state = "stopped"
        self.auto_submode = None

    def _mission_start(self, p: tuple[float, ...], now: float, state: VehicleState) -> int:
        """GCS_MAVLINK_Copter::handle_MAV_CMD_MISSION_START: no first/last item, AUTO, and the takeoff may go."""
        if p[0] != 0.0 or p[1] != 0.0:
            return mavlink.MAV_RESULT_DENIED
        if not self.set_mode(CopterMode.AUTO, now, state, "MISSION_START"):
            return mavlink.MAV_RESULT_FAILED
        self.auto_armed = True
        if self.mission_state != "running":
            self._auto_entered(now, state)
        return mavlink.MAV_RESULT_ACCEPTED

    # ------------------------------------------------------------------ commands
    def _start_command(self, index: int, now: float, state: VehicleState) -> None:
        """AP_Mission::start_command for the navigation command ``index``, then the DO commands after it."""
        self.nav_index, self._auto_reached_s, self._land_descending = index, None, False
        self._takeoff_started, self.taking_off = False, False
        item = self.auto_items[index - 1]
        self._event(now, f"Mission: {index} {NAMES[item.command]}")
        north, east, down = self._command_place(item, state)
        self._auto_target = (north, east, down)
        if item.command == mavlink.MAV_CMD_NAV_TAKEOFF:
            floor = state.down_m - (TAKEOFF_ABOVE_GROUND_M if self.land_complete else 0.0)
            self._auto_target = (state.north_m, state.east_m, min(down, floor))
            self.auto_submode = "takeoff"
        elif item.command == mavlink.MAV_CMD_NAV_LAND:
            self.auto_submode, self.land_pause_until_s = "land", -math.inf
            self._auto_target = (north, east, state.down_m)
        elif item.command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            self.auto_submode = "rtl"
            self._rtl_start(state)
        else:
            self.auto_submode = "wp"
        after = index
        while after < len(self.auto_items) and self.auto_items[after].command not in NAVIGATION:
            after += 1
            self._do_command(after, now)

    def _command_place(self, item: MissionItem, state: VehicleState) -> tuple[float, float, float]:
        """ModeAuto::loc_from_cmd: latitude and longitude 0 keep the position, altitude 0 the altitude."""
        if item.x == 0.0 and item.y == 0.0:
            north, east = state.north_m, state.east_m
        else:
            north, east = self.ned_of(item.x, item.y)
        if item.z == 0.0:
            down = state.down_m
        else:
            down = self.home_ned[2] - item.z if item.relative else self.down_of(item.z)
        return north, east, down

    def _do_command(self, index: int, now: float) -> None:
        item = self.auto_items[index - 1]
        self._event(now, f"Mission: {index} {NAMES[item.command]}")
        if item.command == mavlink.MAV_CMD_DO_CHANGE_SPEED and item.params[1] > 0.0 and item.params[0] in (0, 1):
            self._auto_speed_mps = item.params[1]
        self.auto_reached_news.append(index)

    def _command_done(self, now: float, state: VehicleState, say: bool = False) -> None:
        """verify_command's true: MISSION_ITEM_REACHED, then the next navigation command or the end."""
        assert self.nav_index is not None
        if say:
            self._event(now, f"Reached command #{self.nav_index}")
        self.auto_reached_news.append(self.nav_index)
        following = self._next_navigation(self.nav_index)
        if following is not None:
            self._start_command(following, now, state)
            return
        self.mission_state = "complete"  # ModeAuto::exit_mission
        if self.land_complete:
            self._disarm(now, "mission complete")
        else:
            self.auto_submode, self._auto_target = "loiter", (state.north_m, state.east_m, state.down_m)

    def _auto_command(self, now: float, state: VehicleState) -> VelocityCommand:
        """This tick's command in AUTO (armed): verify the current command, then fly it."""
        if self.mission_state != "running" and self.auto_submode != "loiter":
            return HOVER if self.land_complete else velocity_toward(state, state.north_m, state.east_m, state.down_m,
                                                                    self.airframe, speed_xy_mps=0.0)
        speed = self._auto_speed_mps or self.params["WPNAV_SPEED"] / 100.0
        north, east, down = self._auto_target
        item = self.auto_items[self.nav_index - 1] if self.nav_index else None
        if self.auto_submode == "takeoff":
            if int(self.params["AUTO_OPTIONS"]) & ALLOW_TAKEOFF_WITHOUT_THROTTLE:
                self.auto_armed = True
            if self.land_complete and not self.auto_armed:
                return HOVER  # ground idle until the throttle (or MISSION_START) lets it go
            if not self._takeoff_started:
                self._takeoff_started, self.hold_target, self.taking_off = True, self._auto_target, True
            if not self.taking_off:  # _takeoff_command found the altitude reached
                self._command_done(now, state)
                return self._auto_command(now, state) if self.armed else HOVER
            return self._takeoff_command(state)
        if self.auto_submode == "rtl":
            if self.rtl_state == "land" and self.land_complete:
                self._command_done(now, state)
                return HOVER
            return self._rtl_command(now, state)
        if self.auto_submode == "land":
            if not self._land_descending:
                if math.hypot(north - state.north_m, east - state.east_m) > self.params["WPNAV_RADIUS"] / 100.0:
                    return velocity_toward(state, north, east, down, self.airframe, speed_xy_mps=speed)
                self._land_descending = True
            if self.land_complete:  # verify_land: disarmed, and the mission stays on the LAND command
                self._disarm(now, "landed")
                return HOVER
            return self._landing_command(now, state, north, east)
        if self.auto_submode == "wp" and item is not None and item.command != mavlink.MAV_CMD_NAV_LOITER_UNLIM:
            radius = self.params["WPNAV_RADIUS"] / 100.0
            if self._auto_reached_s is None and math.dist((north, east, down),
                                                          (state.north_m, state.east_m, state.down_m)) <= radius:
                self._auto_reached_s = now
            if self._auto_reached_s is not None and now - self._auto_reached_s >= max(item.params[0], 0.0):
                self._command_done(now, state, say=True)
                return self._auto_command(now, state) if self.armed else HOVER
        return velocity_toward(state, north, east, down, self.airframe, speed_xy_mps=speed)
