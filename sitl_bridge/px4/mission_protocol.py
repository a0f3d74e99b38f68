"""The vehicle's side of the MAVLink mission protocol, as PX4's MavlinkMissionManager runs it.

Read in PX4-Autopilot ``src/modules/mavlink/mavlink_mission.cpp`` (main at 02e73e3; docs/sitl.md, "PX4 missions",
has the line references and what differs from v1.14):

* **upload**: MISSION_COUNT, then MISSION_REQUEST_INT for seq 0, 1, ... (re-sent after 0.25 s without the item),
  MISSION_ITEM_INT for each, and MISSION_ACK ACCEPTED once the last one is in; only then does the mission replace
  the stored one. A count of 0 clears the mission. An item with the wrong seq is ignored (the retry asks again);
  an item whose frame or command is not supported aborts the transfer with that MAV_MISSION_RESULT; 5 s without
  a message ends it with "Operation timeout" and no ACK. The upload is accepted whatever the mission asks (a
  mission the navigator then finds infeasible is stored but invalid: ``sitl_bridge.px4.mission``), also in flight.
* **download**: MISSION_REQUEST_LIST gives MISSION_COUNT, each MISSION_REQUEST_INT (MISSION_REQUEST) the item as
  MISSION_ITEM_INT (MISSION_ITEM); the client's MISSION_ACK ends it. Positional items come back in a GLOBAL frame
  (relative altitude or not, as uploaded), the others in MAV_FRAME_MISSION.
* **MISSION_CLEAR_ALL** (ACK ACCEPTED) and **MISSION_SET_CURRENT** (no ACK: the next MISSION_CURRENT says it).
* PX4 answers in the ``_INT`` form until a client uses the float messages (a sticky "int mode"), and switches form
  when a client answers a request with MISSION_ACK UNSUPPORTED.

All three types are stored, each in its own storage (dataman's DM_KEY_WAYPOINTS_OFFBOARD, DM_KEY_FENCE_POINTS,
DM_KEY_SAFE_POINTS): a fence holds polygon vertices and circles, inclusion or exclusion, at most 64 items, a polygon
of fewer than 3 vertices being an ERROR (``sitl_bridge.px4.geofence`` flies it); the rally type at most 32 items,
stored whatever they are (``parse_mavlink_mission_item``'s items: handle_mission_item_both checks the command only
for the MISSION type, which refuses fence and rally items with an ERROR), of which RTL uses the rally points
(``sitl_bridge.px4.rally``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.endpoint import Endpoint
from sitl_bridge.fence_areas import POLYGON_VERTICES
from sitl_bridge.mission_items import (
    ABSOLUTE_FRAMES,
    FENCE,
    MISSION,
    RALLY,
    RELATIVE_FRAMES,
    MissionItem,
    item_message,
)

RETRY_S = 0.25  # MAVLINK_MISSION_RETRY_TIMEOUT_DEFAULT: re-request an item after this long without it
TIMEOUT_S = 5.0  # MAVLINK_MISSION_PROTOCOL_TIMEOUT_DEFAULT: a transfer silent this long is abandoned
MAX_ITEMS = 500  # CONFIG_NUM_MISSION_ITMES_SUPPORTED's default (PX4 SITL builds allow 10,000)

CAPACITY = {MISSION: MAX_ITEMS, FENCE: 64, RALLY: 32}  # DM_KEY_FENCE_POINTS_MAX, DM_KEY_SAFE_POINTS_MAX
ACCEPTED = mavlink.MAV_MISSION_ACCEPTED

INT_ONLY_FRAMES = (mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)

# Commands flown by sitl_bridge.px4.mission. PX4 accepts more (LOITER_TO_ALT, ROI, VTOL, gates, DO_JUMP, ...);
# those are refused here with MAV_MISSION_UNSUPPORTED rather than stored and skipped.
POSITION_COMMANDS = (mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND,
                     mavlink.MAV_CMD_NAV_LOITER_TIME, mavlink.MAV_CMD_NAV_LOITER_UNLIM)
NAVIGATION_COMMANDS = (mavlink.MAV_CMD_DO_CHANGE_SPEED, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH,
                       mavlink.MAV_CMD_NAV_DELAY)
FENCE_COMMANDS = (mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT, mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                  mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION, mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
                  mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION)
# Camera and gimbal items (what MAVSDK's MissionItem adds for its camera and gimbal fields): stored, and passed over
# in flight with a log line, since the simulator has no camera triggering or gimbal.
PAYLOAD_COMMANDS = (mavlink.MAV_CMD_IMAGE_START_CAPTURE, mavlink.MAV_CMD_IMAGE_STOP_CAPTURE,
                    mavlink.MAV_CMD_VIDEO_START_CAPTURE, mavlink.MAV_CMD_VIDEO_STOP_CAPTURE,
                    mavlink.MAV_CMD_DO_SET_CAM_TRIGG_DIST, mavlink.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
                    mavlink.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE, mavlink.MAV_CMD_DO_MOUNT_CONTROL,
                    mavlink.MAV_CMD_DO_MOUNT_CONFIGURE)


def parse_item(msg: mavlink.MAVLink_message, mission_type: int = MISSION) -> MissionItem | int:
    """A MISSION_ITEM(_INT) of an upload as PX4's parse_mavlink_mission_item and handle_mission_item_both read it,
    or the MAV_MISSION_RESULT refusing it. A rally point keeps no parameters (format_mavlink_mission_item sends
    param1-4 as 0)."""
    is_int = msg.get_type() == "MISSION_ITEM_INT"
    params = (msg.param1, msg.param2, msg.param3, msg.param4)
    if mission_type == MISSION and msg.command in FENCE_COMMANDS + (mavlink.MAV_CMD_NAV_RALLY_POINT,):
        return mavlink.MAV_MISSION_ERROR  # a fence or rally item in a mission
    if mission_type == FENCE and msg.command not in FENCE_COMMANDS:
        return mavlink.MAV_MISSION_ERROR  # not in PX4, which stores a fence's other items unused
    if msg.command in POLYGON_VERTICES and not (math.isfinite(msg.param1) and msg.param1 + 0.5 >= 3):
        return mavlink.MAV_MISSION_ERROR  # vertex_count < 3
    if msg.frame in ABSOLUTE_FRAMES + RELATIVE_FRAMES and (is_int or msg.frame not in INT_ONLY_FRAMES):
        if msg.command not in POSITION_COMMANDS + FENCE_COMMANDS + (mavlink.MAV_CMD_NAV_RALLY_POINT,):
            return mavlink.MAV_MISSION_UNSUPPORTED
        if msg.command == mavlink.MAV_CMD_NAV_RALLY_POINT:
            params = (0.0, 0.0, 0.0, 0.0)
        scale = 1e-7 if is_int else 1.0
        # Not in PX4, which stores what it gets: a position that is not one would fly the simulator into NaNs
        if not (math.isfinite(msg.x) and abs(msg.x * scale) <= 90.0):
            return mavlink.MAV_MISSION_INVALID_PARAM5_X
        if not (math.isfinite(msg.y) and abs(msg.y * scale) <= 180.0):
            return mavlink.MAV_MISSION_INVALID_PARAM6_Y
        if not math.isfinite(msg.z):
            return mavlink.MAV_MISSION_INVALID_PARAM7
        return MissionItem(msg.command, params, msg.x * scale, msg.y * scale, msg.z, positional=True,
                           relative=msg.frame in RELATIVE_FRAMES, autocontinue=bool(msg.autocontinue))
    if msg.frame == mavlink.MAV_FRAME_MISSION:
        if msg.command not in NAVIGATION_COMMANDS + PAYLOAD_COMMANDS:
            return mavlink.MAV_MISSION_UNSUPPORTED
        return MissionItem(msg.command, params, float(msg.x), float(msg.y), msg.z, positional=False,
                           autocontinue=bool(msg.autocontinue))
    return mavlink.MAV_MISSION_UNSUPPORTED_FRAME


@dataclass
class _Transfer:
    """An upload being received ("receiving") or a download being sent ("sending")."""

    direction: str
    endpoint: Endpoint
    partner: tuple[int, int]  # the client's system and component
    mission_type: int
    count: int
    next_seq: int = 0
    items: list[MissionItem] | None = None
    current_seq: int = -1  # the uploaded item marked current, if any
    last_received_s: float = 0.0
    last_request_s: float = -math.inf


class MissionTransfer:
    """The mission protocol of one vehicle: the stored mission, fence and rally points, and at most one transfer at
    a time.

    ``on_mission(items, current_seq)`` hands a completed mission upload (or a clear: no items) to the navigator,
    with the uploaded item marked current (-1: none); ``on_fence(items)`` a fence, ``on_rally(items)`` the rally
    points; ``current_seq()`` reads the navigator's current item for a download; ``set_current(seq)`` asks the
    navigator to jump; ``text(text, severity)`` sends PX4's STATUSTEXTs.
    """

    def __init__(self, on_mission: Callable[[list[MissionItem], int], None],
                 on_fence: Callable[[list[MissionItem]], None], current_seq: Callable[[], int],
                 set_current: Callable[[int], None], text: Callable[[str, int], None],
                 on_rally: Callable[[list[MissionItem]], None] = lambda items: None):
        self.stored: dict[int, list[MissionItem]] = {MISSION: [], FENCE: [], RALLY: []}
        self.int_mode = True  # PX4 main; v1.14 started in float mode (docs/sitl.md)
        self.transfer: _Transfer | None = None
        self._last_upload: tuple[tuple[int, int], int, int] | None = None  # (client, type, count) of the last ACK
        self._on_stored: dict[int, Callable[[list[MissionItem], int], None]] = {
            MISSION: on_mission, FENCE: lambda items, current: on_fence(items),
            RALLY: lambda items, current: on_rally(items)}
        self._current_seq, self._set_current, self._text = current_seq, set_current, text

    @property
    def items(self) -> list[MissionItem]:
        """The stored mission."""
        return self.stored[MISSION]

    @property
    def fence(self) -> list[MissionItem]:
        """The stored fence items."""
        return self.stored[FENCE]

    @property
    def rally(self) -> list[MissionItem]:
        """The stored rally points (PX4's safe points)."""
        return self.stored[RALLY]

    # ------------------------------------------------------------------ upload
    def on_count(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        partner, kind = (msg.get_srcSystem(), msg.get_srcComponent()), msg.mission_type
        busy = self.transfer
        if busy is not None:
            if busy.direction == "receiving" and busy.partner == partner and busy.next_seq == 0:
                self._request(busy, now)  # our first request was lost: ask again
            else:
                receiving = busy.direction == "receiving"
                self._text("WPM: REJ. CMD: Busy\t" if receiving else "WPM: IGN MISSION_COUNT: Busy\t",
                           mavlink.MAV_SEVERITY_CRITICAL)
                self._ack(endpoint, partner, mavlink.MAV_MISSION_ERROR, kind)
            return
        if kind not in CAPACITY:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_INVALID, kind)
            return
        if msg.count > CAPACITY[kind]:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_NO_SPACE, kind)
            return
        if msg.count == 0:  # an empty upload clears
            self._store(kind, [], -1)
            self._ack(endpoint, partner, ACCEPTED, kind)
            return
        self.transfer = _Transfer("receiving", endpoint, partner, kind, msg.count, items=[], last_received_s=now)
        self._request(self.transfer, now)

    def on_item(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        self.int_mode = msg.get_type() == "MISSION_ITEM_INT"
        t, partner = self.transfer, (msg.get_srcSystem(), msg.get_srcComponent())
        if t is None and self._last_upload == (partner, msg.mission_type, msg.seq + 1):
            self._ack(endpoint, partner, ACCEPTED, msg.mission_type)  # the last item again: our ACK was lost
            return
        if t is None or t.direction != "receiving":
            self._text("IGN MISSION_ITEM: No transfer\t", mavlink.MAV_SEVERITY_CRITICAL)
            self._ack(endpoint, partner, mavlink.MAV_MISSION_ERROR, msg.mission_type)
            return
        if msg.mission_type != t.mission_type:
            self._abort(mavlink.MAV_MISSION_ERROR)
            return
        if msg.seq != t.next_seq:
            return  # PX4 ignores it; the retry asks for the one it wants
        t.last_received_s = now
        item = parse_item(msg, t.mission_type)
        if isinstance(item, int):
            self._text("IGN MISSION_ITEM: Invalid item\t", mavlink.MAV_SEVERITY_CRITICAL)
            self._abort(item)
            return
        assert t.items is not None
        t.items.append(item)
        if msg.current == 1:
            t.current_seq = msg.seq
        t.next_seq += 1
        if t.next_seq < t.count:
            self._request(t, now)
            return
        self.transfer = None
        self._store(t.mission_type, t.items, t.current_seq)
        self._last_upload = (t.partner, t.mission_type, t.count)
        self._ack(t.endpoint, t.partner, ACCEPTED, t.mission_type)

    def _request(self, t: _Transfer, now: float) -> None:
        cls = mavlink.MAVLink_mission_request_int_message if self.int_mode else mavlink.MAVLink_mission_request_message
        t.endpoint.send(cls(*t.partner, t.next_seq, t.mission_type))
        t.last_request_s = now

    def _store(self, kind: int, items: list[MissionItem], current_seq: int) -> None:
        self.stored[kind], self._last_upload = list(items), None
        self._on_stored[kind](self.stored[kind], current_seq)

    def _abort(self, result: int) -> None:
        t = self.transfer
        assert t is not None
        self.transfer = None
        self._ack(t.endpoint, t.partner, result, t.mission_type)

    # ------------------------------------------------------------------ download
    def on_request_list(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        partner, kind = (msg.get_srcSystem(), msg.get_srcComponent()), msg.mission_type
        t = self.transfer
        if t is not None and t.direction == "sending" and t.next_seq >= t.count:
            t = self.transfer = None  # every item went out: a new list request need not wait for the lost ACK
        if t is not None and not (t.direction == "sending" and t.partner == partner and t.mission_type == kind):
            self._text("Mission download request ignored, already active\t", mavlink.MAV_SEVERITY_INFO)
            return
        count = len(self.stored.get(kind, []))
        self.transfer = None
        if count:
            self.transfer = _Transfer("sending", endpoint, partner, kind, count, last_received_s=now)
        endpoint.send(mavlink.MAVLink_mission_count_message(*partner, count, kind))

    def on_request(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        self.int_mode = msg.get_type() == "MISSION_REQUEST_INT"
        t = self.transfer
        if t is None:
            return  # PX4 ignores requests when idle
        if t.direction == "receiving":
            self._text("WPM: REJ. CMD: Busy\t", mavlink.MAV_SEVERITY_CRITICAL)
            return
        if msg.seq not in (t.next_seq, t.next_seq - 1) or msg.seq >= t.count:
            self.transfer = None
            self._text("WPM: REJ. CMD: Req. WP was unexpected\t", mavlink.MAV_SEVERITY_CRITICAL)
            self._ack(endpoint, t.partner, mavlink.MAV_MISSION_ERROR, t.mission_type)
            return
        t.last_received_s = now
        t.next_seq = msg.seq + 1
        current = t.mission_type == MISSION and msg.seq == self._current_seq()
        endpoint.send(item_message(self.stored[t.mission_type][msg.seq], msg.seq, current, t.partner, self.int_mode,
                                   t.mission_type))

    def on_ack(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        t = self.transfer
        if t is None:
            return
        if t.direction == "sending":
            self.transfer = None  # the client's ACK (any type) ends a download
        elif msg.type == mavlink.MAV_MISSION_UNSUPPORTED:  # the client wants the other form of request
            self.int_mode = not self.int_mode
            self._request(t, now)

    # ------------------------------------------------------------------ clear, set current, time
    def on_clear_all(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        if self.transfer is not None:
            self._text("WPM: IGN CLEAR CMD: Busy\t", mavlink.MAV_SEVERITY_CRITICAL)
            return  # no ACK
        for kind in CAPACITY:
            if msg.mission_type in (kind, mavlink.MAV_MISSION_TYPE_ALL):
                self._store(kind, [], -1)
        self._ack(endpoint, (msg.get_srcSystem(), msg.get_srcComponent()), ACCEPTED, msg.mission_type)

    def on_set_current(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        if self.transfer is not None:
            self._text("WPM: IGN WP CURR CMD: Busy\t", mavlink.MAV_SEVERITY_CRITICAL)
        elif msg.seq >= len(self.items):
            self._text("WPM: WP CURR CMD: Not in list\t", mavlink.MAV_SEVERITY_CRITICAL)
        else:
            self._set_current(msg.seq)

    def tick(self, now: float) -> None:
        """Re-request an item the client has not sent, and give up on a transfer gone silent."""
        t = self.transfer
        if t is None:
            return
        if now - t.last_received_s >= TIMEOUT_S:
            self.transfer = None
            self._text("Operation timeout\t", mavlink.MAV_SEVERITY_CRITICAL)
        elif t.direction == "receiving" and now - t.last_request_s >= RETRY_S:
            self._request(t, now)

    @staticmethod
    def _ack(endpoint: Endpoint, partner: tuple[int, int], result: int, mission_type: int = MISSION) -> None:
        endpoint.send(mavlink.MAVLink_mission_ack_message(*partner, result, mission_type))
