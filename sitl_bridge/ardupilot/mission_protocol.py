"""The vehicle's side of the MAVLink mission protocol as ArduPilot runs it (the ArduCopter personality).

Read in ArduPilot master at 9070097 (2025-07, through a fork whose only own commits move submodules, as the
repository is too large for the search tools; docs/sitl.md, "ArduPilot missions", has the references):
``libraries/GCS_MAVLink/MissionItemProtocol.cpp`` and ``MissionItemProtocol_Waypoints.cpp``, ``GCS_Common.cpp``
(``handle_mission_item``, ``handle_mission_set_current``), ``libraries/AP_Mission/AP_Mission.cpp``
(``mavlink_int_to_mission_cmd``, ``mission_cmd_to_mavlink_int``, ``clear``). Where it differs from PX4's:

* item 0 is **home**: an upload's item 0 must be a valid item but is not used, a download's item 0 is home (frame
  GLOBAL, altitude above mean sea level), and every count includes it;
* an upload is answered with MISSION_REQUEST (the float form), whatever the client sends; the request is repeated
  every second and the upload given up after 8 s ("Mission upload timeout", ACK OPERATION_CANCELLED); an item with
  the wrong seq gets ACK INVALID_SEQUENCE and the upload goes on; the last item gives "Flight plan received", then
  ACK ACCEPTED; an upload from another client meanwhile is DENIED;
* a download is stateless: each MISSION_REQUEST(_INT) is answered, the client's MISSION_ACK is ignored; frames come
  back in their float form (GLOBAL, GLOBAL_RELATIVE_ALT), a waypoint's param2-4 as 0 (Copter keeps only param1);
* MISSION_CLEAR_ALL is refused (ERROR) while armed and the mission runs; MISSION_SET_CURRENT answers with a
  MISSION_CURRENT at once; guided-mode items (MISSION_ITEM with current 2 or 3) go to GUIDED, not the mission.

Only the MISSION type is stored; fence and rally uploads get UNSUPPORTED (the fences are the FENCE_* parameters).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.targets import LOCATION_ALT_MAX_M
from sitl_bridge.endpoint import Endpoint
from sitl_bridge.mission_items import ABSOLUTE_FRAMES, MISSION, RELATIVE_FRAMES, MissionItem, item_message

RETRY_S = 1.0  # MissionItemProtocol::update: the request again after a second without the item
TIMEOUT_S = 8.0  # upload_timeout_ms
MAX_ITEMS = 650  # (storage - 4) / 15 in SITL's mission storage areas, home included

ACCEPTED = mavlink.MAV_MISSION_ACCEPTED
# The commands the AUTO mode here flies (sitl_bridge.ardupilot.auto); ArduCopter takes many more
LOCATION_COMMANDS = (mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND,
                     mavlink.MAV_CMD_NAV_LOITER_TIME, mavlink.MAV_CMD_NAV_LOITER_UNLIM)
OTHER_COMMANDS = (mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_DO_CHANGE_SPEED)
NAN_PARAM4 = (mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_LOITER_UNLIM, mavlink.MAV_CMD_NAV_LAND,
              mavlink.MAV_CMD_NAV_TAKEOFF)  # sanity_check_params: only these may have a NaN param4


def parse_copter_item(msg: mavlink.MAVLink_message) -> MissionItem | int:
    """AP_Mission::mavlink_int_to_mission_cmd for the emulated commands, or the MAV_MISSION_RESULT refusing it."""
    if msg.command not in LOCATION_COMMANDS + OTHER_COMMANDS:
        return mavlink.MAV_MISSION_UNSUPPORTED
    params = (msg.param1, msg.param2, msg.param3, msg.param4)
    for index, value in enumerate(params):
        if math.isinf(value) or (math.isnan(value) and not (index == 3 and msg.command in NAN_PARAM4)):
            return mavlink.MAV_MISSION_INVALID_PARAM1 + index
    if msg.command not in LOCATION_COMMANDS:
        return MissionItem(msg.command, params, 0.0, 0.0, 0.0, positional=False)
    scale = 1e-7 if msg.get_type() == "MISSION_ITEM_INT" else 1.0
    lat, lon = msg.x * scale, msg.y * scale
    if not (math.isfinite(lat) and abs(lat) <= 90.0):
        return mavlink.MAV_MISSION_INVALID_PARAM5_X
    if not (math.isfinite(lon) and abs(lon) <= 180.0):
        return mavlink.MAV_MISSION_INVALID_PARAM6_Y
    if not (math.isfinite(msg.z) and abs(msg.z) < LOCATION_ALT_MAX_M):
        return mavlink.MAV_MISSION_INVALID_PARAM7
    if msg.frame not in (mavlink.MAV_FRAME_MISSION, *ABSOLUTE_FRAMES, *RELATIVE_FRAMES):
        return mavlink.MAV_MISSION_UNSUPPORTED_FRAME  # terrain frames too: no terrain data is simulated
    if msg.command == mavlink.MAV_CMD_NAV_WAYPOINT:
        params = (msg.param1, 0.0, 0.0, 0.0)  # Copter stores only the delay
    return MissionItem(msg.command, params, lat, lon, msg.z, positional=True, relative=msg.frame in RELATIVE_FRAMES)


@dataclass
class _Upload:
    endpoint: Endpoint
    partner: tuple[int, int]
    count: int
    next_seq: int = 0  # item 0 (home's place) is requested and checked too
    items: list[MissionItem] | None = None
    last_received_s: float = 0.0
    last_request_s: float = -math.inf


class CopterMissionTransfer:
    """ArduPilot's mission protocol for one vehicle: ``items`` is the stored mission without home (item 1 first).

    ``home()`` gives home as (lat, lon, AMSL altitude) or None; ``running()`` whether the mission is being flown
    (armed, in AUTO); ``on_mission(items)`` hands a completed upload or a clear to the AUTO mode;
    ``current_seq()`` / ``set_current(seq) -> bool`` read and move the mission's current command; ``send_current()``
    sends MISSION_CURRENT on every link; ``text(text, severity)`` sends STATUSTEXT."""

    def __init__(self, home: Callable[[], tuple[float, float, float] | None], running: Callable[[], bool],
                 on_mission: Callable[[list[MissionItem]], None], set_current: Callable[[int], bool],
                 send_current: Callable[[int], None], text: Callable[[str, int], None]):
        self.items: list[MissionItem] = []
        self.uploaded = False  # MIS_TOTAL stays 0, home not counted, until a mission is uploaded (4.5)
        self.upload: _Upload | None = None
        self._home, self._running, self._on_mission = home, running, on_mission
        self._set_current, self._send_current, self._text = set_current, send_current, text

    @property
    def count(self) -> int:
        """MIS_TOTAL: the items with home, or 0 before any upload (and after a clear)."""
        return len(self.items) + 1 if self.uploaded else 0

    # ------------------------------------------------------------------ upload
    def on_count(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        if msg.mission_type != MISSION:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_UNSUPPORTED, msg.mission_type)
            return
        if self.upload is not None and self.upload.partner != partner:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_DENIED)
            return
        if msg.count > MAX_ITEMS:
            self._text(f"Only {MAX_ITEMS} items are supported", mavlink.MAV_SEVERITY_WARNING)
            self._ack(endpoint, partner, mavlink.MAV_MISSION_NO_SPACE)
            return
        self.upload = None
        if msg.count == 0:
            self._complete(endpoint, partner, [], uploaded=False)
            return
        self.upload = _Upload(endpoint, partner, msg.count, next_seq=0, items=[], last_received_s=now)
        self._request(now)

    def on_item(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> bool:
        """An item of an upload; False when it is not one (a guided-mode item, for GUIDED to take)."""
        if msg.current in (2, 3):
            return False
        partner, up = (msg.get_srcSystem(), msg.get_srcComponent()), self.upload
        if up is None:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_ERROR)
            return True
        if partner != up.partner:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_DENIED)
            return True
        if msg.seq != up.next_seq:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_INVALID_SEQUENCE)  # the upload goes on
            return True
        item = parse_copter_item(msg)
        if isinstance(item, int):
            self.upload = None
            self._ack(endpoint, partner, item)
            return True
        assert up.items is not None
        if msg.seq > 0:  # item 0 is home's place: checked, not kept
            up.items.append(item)
        up.next_seq, up.last_received_s = up.next_seq + 1, now
        if up.next_seq < up.count:
            self._request(now)
        else:
            self._complete(up.endpoint, up.partner, up.items, uploaded=True)
        return True

    def _request(self, now: float) -> None:
        up = self.upload
        assert up is not None
        up.endpoint.send(mavlink.MAVLink_mission_request_message(*up.partner, up.next_seq, MISSION))
        up.last_request_s = now

    def _complete(self, endpoint: Endpoint, partner: tuple[int, int], items: list[MissionItem],
                  uploaded: bool) -> None:
        self.upload, self.items, self.uploaded = None, list(items), uploaded
        self._on_mission(self.items)
        self._text("Flight plan received", mavlink.MAV_SEVERITY_INFO)
        self._ack(endpoint, partner, ACCEPTED)

    def tick(self, now: float) -> None:
        up = self.upload
        if up is None:
            return
        if now - up.last_received_s > TIMEOUT_S:
            self.upload = None
            self._text("Mission upload timeout", mavlink.MAV_SEVERITY_WARNING)
            self._ack(up.endpoint, up.partner, mavlink.MAV_MISSION_OPERATION_CANCELLED)
        elif now - up.last_request_s >= RETRY_S:
            self._request(now)

    # ------------------------------------------------------------------ download, clear, set current
    def on_request_list(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        if self.upload is not None:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_DENIED, msg.mission_type)
            return
        count = self.count if msg.mission_type == MISSION else 0
        endpoint.send(mavlink.MAVLink_mission_count_message(*partner, count, msg.mission_type))

    def on_request(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        partner, as_int = (msg.get_srcSystem(), msg.get_srcComponent()), msg.get_type() == "MISSION_REQUEST_INT"
        if msg.mission_type != MISSION:
            return
        home = self._home()
        if msg.seq >= max(self.count, 1) or (msg.seq == 0 and home is None):
            if as_int:
                endpoint.send(mavlink.MAVLink_mission_count_message(*partner, self.count, MISSION))
            self._ack(endpoint, partner, mavlink.MAV_MISSION_INVALID_SEQUENCE)
            return
        if msg.seq == 0:
            item = MissionItem(mavlink.MAV_CMD_NAV_WAYPOINT, (0.0, 0.0, 0.0, 0.0), *home, positional=True)
        else:
            item = self.items[msg.seq - 1]
        # current 0 (get_item compares a command id with an index), and the float frames whatever the request
        # (mission_cmd_to_mavlink_int): GLOBAL_RELATIVE_ALT or GLOBAL, GLOBAL for a command without a place
        sent = item_message(item, msg.seq, False, partner, as_int=as_int)
        sent.frame = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT if item.relative else mavlink.MAV_FRAME_GLOBAL
        endpoint.send(sent)

    def on_ack(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        """ArduPilot ignores a client's MISSION_ACK ("not used")."""

    def on_clear_all(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        if msg.mission_type not in (MISSION, mavlink.MAV_MISSION_TYPE_ALL):
            self._ack(endpoint, partner, mavlink.MAV_MISSION_UNSUPPORTED, msg.mission_type)
            return
        if self._running():  # AP_Mission::clear: not while armed and running
            self._ack(endpoint, partner, mavlink.MAV_MISSION_ERROR, msg.mission_type)
            return
        self.upload, self.items, self.uploaded = None, [], False
        self._on_mission([])
        self._ack(endpoint, partner, ACCEPTED, msg.mission_type)

    def on_set_current(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        """No ACK: a MISSION_CURRENT with the requested seq says it worked (nothing: it did not)."""
        if self._set_current(msg.seq):
            self._send_current(msg.seq)

    @staticmethod
    def _ack(endpoint: Endpoint, partner: tuple[int, int], result: int, mission_type: int = MISSION) -> None:
        endpoint.send(mavlink.MAVLink_mission_ack_message(*partner, result, mission_type))
