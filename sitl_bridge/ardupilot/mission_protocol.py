"""The vehicle's side of the MAVLink mission protocol as ArduPilot runs it (the ArduCopter personality).

Read in ArduPilot master at 9070097 (through a fork whose only own commits move submodules, as the repository is
too large for the search tools; docs/sitl.md, "ArduPilot missions", has the references):
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

The transfer itself is the protocol every mission type shares (``sitl_bridge.ardupilot.item_protocol``); the fence
and rally types are ``sitl_bridge.ardupilot.fence_protocol`` and ``sitl_bridge.ardupilot.rally``.
"""
from __future__ import annotations

import math
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.item_protocol import ACCEPTED, ItemProtocol, Upload
from sitl_bridge.ardupilot.targets import LOCATION_ALT_MAX_M
from sitl_bridge.endpoint import Endpoint
from sitl_bridge.mission_items import ABSOLUTE_FRAMES, MISSION, RELATIVE_FRAMES, MissionItem

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


class CopterMissionTransfer(ItemProtocol):
    """ArduPilot's mission protocol for one vehicle (MissionItemProtocol_Waypoints): ``items`` is the stored mission
    without home (item 1 first); the transfer rules are ``ItemProtocol``'s.

    ``home()`` gives home as (lat, lon, AMSL altitude) or None; ``running()`` whether the mission is being flown
    (armed, in AUTO); ``on_mission(items)`` hands a completed upload or a clear to the AUTO mode;
    ``set_current(seq) -> bool`` moves the mission's current command; ``send_current()`` sends MISSION_CURRENT on
    every link; ``text(text, severity)`` sends STATUSTEXT."""

    MISSION_TYPE = MISSION
    MAX_ITEMS = 650  # (storage - 4) / 15 in SITL's mission storage areas, home included
    TIMEOUT_TEXT = "Mission upload timeout"

    def __init__(self, home: Callable[[], tuple[float, float, float] | None], running: Callable[[], bool],
                 on_mission: Callable[[list[MissionItem]], None], set_current: Callable[[int], bool],
                 send_current: Callable[[int], None], text: Callable[[str, int], None]):
        super().__init__(on_mission, text)
        self.uploaded = False  # MIS_TOTAL stays 0, home not counted, until a mission is uploaded (4.5)
        self._home, self._running = home, running
        self._set_current, self._send_current = set_current, send_current

    @property
    def count(self) -> int:
        """MIS_TOTAL: the items with home, or 0 before any upload (and after a clear)."""
        return len(self.items) + 1 if self.uploaded else 0

    def item_count(self) -> int:
        return self.count

    def take(self, seq: int, msg: mavlink.MAVLink_message, upload: Upload) -> int:
        item = parse_copter_item(msg)
        if isinstance(item, int):
            return item
        if seq > 0:  # item 0 is home's place: checked, not kept
            upload.items.append(item)
        return ACCEPTED

    def complete(self, upload: Upload) -> int:
        self.items, self.uploaded = list(upload.items), upload.count > 0
        self._on_change(self.items)
        self._text("Flight plan received", mavlink.MAV_SEVERITY_INFO)
        return ACCEPTED

    def clear(self) -> int:
        if self._running():  # AP_Mission::clear: not while armed and running
            return mavlink.MAV_MISSION_ERROR
        self.items, self.uploaded = [], False
        self._on_change([])
        return ACCEPTED

    def get_item(self, seq: int) -> tuple[MissionItem, int] | int:
        home = self._home()
        if seq >= max(self.count, 1) or (seq == 0 and home is None):
            return mavlink.MAV_MISSION_INVALID_SEQUENCE
        if seq == 0:
            item = MissionItem(mavlink.MAV_CMD_NAV_WAYPOINT, (0.0, 0.0, 0.0, 0.0), *home, positional=True)
        else:
            item = self.items[seq - 1]
        # current 0 (get_item compares a command id with an index), and the float frames whatever the request
        # (mission_cmd_to_mavlink_int): GLOBAL_RELATIVE_ALT or GLOBAL, GLOBAL for a command without a place
        return item, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT if item.relative else mavlink.MAV_FRAME_GLOBAL

    def on_set_current(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        """No ACK: a MISSION_CURRENT with the requested seq says it worked (nothing: it did not)."""
        if self._set_current(msg.seq):
            self._send_current(msg.seq)
