"""ArduPilot's mission item protocol, the part every mission type shares, and the routing of the messages by type.

Read in ArduPilot master at 9070097 (docs/sitl.md, "ArduPilot missions"): ``libraries/GCS_MAVLink/
MissionItemProtocol.cpp`` runs one transfer per mission type (MISSION, FENCE and RALLY each have their own
``MissionItemProtocol_*`` object), and ``GCS_Common.cpp`` hands each message to the object of its ``mission_type``
(``get_prot_for_mission_type``; a type without one: MISSION_ACK UNSUPPORTED).

* **upload**: MISSION_COUNT from another client while one uploads: DENIED; a count over ``max_items()``: NO_SPACE
  and "Only N items are supported"; else the items are asked for with MISSION_REQUEST (the float form, always),
  again after a second without one, and the upload is given up 8 s after the last item ("<type> upload timeout",
  ACK OPERATION_CANCELLED). An item while no upload runs: ERROR; with the wrong seq: INVALID_SEQUENCE (the upload
  goes on); from another client: DENIED; refused: its MAV_MISSION_RESULT, and the upload ends. After the last item
  (at once for a count of 0) the type's ``complete()`` gives the final ACK.
* **download**: MISSION_REQUEST_LIST and MISSION_REQUEST_INT are DENIED while an upload runs; a request for an item
  that is not there: INVALID_SEQUENCE (after a MISSION_COUNT, for MISSION_REQUEST_INT); the client's MISSION_ACK is
  ignored.
* **MISSION_CLEAR_ALL**: DENIED while another client uploads (its own upload is cancelled), then the type's clear.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.endpoint import Endpoint
from sitl_bridge.mission_items import MISSION, MissionItem, item_message

RETRY_S = 1.0  # MissionItemProtocol::update: the request again after a second without the item
TIMEOUT_S = 8.0  # upload_timeout_ms
ACCEPTED = mavlink.MAV_MISSION_ACCEPTED


@dataclass
class Upload:
    """An upload being received: its client, how many items, the next one wanted and what arrived."""

    endpoint: Endpoint
    partner: tuple[int, int]
    count: int
    next_seq: int = 0
    items: list[MissionItem] = field(default_factory=list)
    last_received_s: float = 0.0
    last_request_s: float = -math.inf


class ItemProtocol:
    """One mission type's side of the protocol: ``items`` is what it stores, ``on_change(items)`` tells the autopilot
    when they change, ``text(text, severity)`` sends STATUSTEXT. Subclasses say how the type stores: ``begin``
    (MISSION_COUNT arrived), ``take`` (an item arrived: store or refuse it), ``complete`` (the last arrived),
    ``clear`` and ``get_item``, and how many items it holds (``MAX_ITEMS``)."""

    MISSION_TYPE = MISSION
    MAX_ITEMS = 0
    TIMEOUT_TEXT = "Mission upload timeout"

    def __init__(self, on_change: Callable[[list[MissionItem]], None], text: Callable[[str, int], None]):
        self.items: list[MissionItem] = []
        self.upload: Upload | None = None
        self._on_change, self._text = on_change, text

    # ------------------------------------------------------------------ what each type defines
    def max_items(self) -> int:
        return self.MAX_ITEMS

    def item_count(self) -> int:
        return len(self.items)

    def begin(self, count: int) -> None:
        """MISSION_COUNT was accepted (``truncate``)."""

    def take(self, seq: int, msg: mavlink.MAVLink_message, upload: Upload) -> int:
        """``replace_item`` / ``append_item``: the MAV_MISSION_RESULT of item ``seq``."""
        raise NotImplementedError

    def complete(self, upload: Upload) -> int:
        """The last item arrived (or the count was 0): the MAV_MISSION_RESULT of the final ACK."""
        raise NotImplementedError

    def clear(self) -> int:
        """``clear_all_items``: ACCEPTED or ERROR."""
        self.items = []
        self._on_change(self.items)
        return ACCEPTED

    def get_item(self, seq: int) -> tuple[MissionItem, int] | int:
        """Item ``seq`` for a download and the frame it goes out in, or the MAV_MISSION_RESULT refusing it."""
        raise NotImplementedError

    # ------------------------------------------------------------------ upload
    def _cancel_upload(self, endpoint: Endpoint, partner: tuple[int, int], mission_type: int) -> bool:
        """cancel_upload: False (and DENIED) while another client uploads; the client's own upload ends."""
        if self.upload is not None and self.upload.partner != partner:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_DENIED, mission_type)
            return False
        self.upload = None
        return True

    def on_count(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        if not self._cancel_upload(endpoint, partner, self.MISSION_TYPE):
            return
        if msg.count > self.max_items():
            self._text(f"Only {self.max_items()} items are supported", mavlink.MAV_SEVERITY_WARNING)
            self._ack(endpoint, partner, mavlink.MAV_MISSION_NO_SPACE)
            return
        self.begin(msg.count)
        upload = Upload(endpoint, partner, msg.count, last_received_s=now)
        if msg.count == 0:
            self._ack(endpoint, partner, self.complete(upload))
            return
        self.upload = upload
        self._request(now)

    def on_item(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        partner, up = (msg.get_srcSystem(), msg.get_srcComponent()), self.upload
        if up is None:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_ERROR)
            return
        if msg.seq != up.next_seq:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_INVALID_SEQUENCE)  # the upload goes on
            return
        if partner != up.partner:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_DENIED)
            return
        result = self.take(msg.seq, msg, up)
        if result != ACCEPTED:
            self.upload = None
            self._ack(endpoint, partner, result)
            return
        up.next_seq, up.last_received_s = up.next_seq + 1, now
        if up.next_seq < up.count:
            self._request(now)
            return
        self.upload = None
        self._ack(up.endpoint, up.partner, self.complete(up))

    def _request(self, now: float) -> None:
        up = self.upload
        assert up is not None
        up.endpoint.send(mavlink.MAVLink_mission_request_message(*up.partner, up.next_seq, self.MISSION_TYPE))
        up.last_request_s = now

    def tick(self, now: float) -> None:
        """The request again after a second without the item; the upload given up after 8 s."""
        up = self.upload
        if up is None:
            return
        if now - up.last_received_s > TIMEOUT_S:
            self.upload = None
            self._text(self.TIMEOUT_TEXT, mavlink.MAV_SEVERITY_WARNING)
            self._ack(up.endpoint, up.partner, mavlink.MAV_MISSION_OPERATION_CANCELLED)
        elif now - up.last_request_s >= RETRY_S:
            self._request(now)

    # ------------------------------------------------------------------ download, clear
    def on_request_list(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        if self.upload is not None:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_DENIED, msg.mission_type)
            return
        endpoint.send(mavlink.MAVLink_mission_count_message(*partner, self.item_count(), self.MISSION_TYPE))

    def on_request(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        """MISSION_REQUEST_INT (refused while an upload runs) or MISSION_REQUEST: the item in that form."""
        partner, as_int = (msg.get_srcSystem(), msg.get_srcComponent()), msg.get_type() == "MISSION_REQUEST_INT"
        if as_int and self.upload is not None:
            self._ack(endpoint, partner, mavlink.MAV_MISSION_DENIED)
            return
        found = self.get_item(msg.seq)
        if isinstance(found, int):
            if as_int and found == mavlink.MAV_MISSION_INVALID_SEQUENCE:  # "educate the GCS" on the real count
                endpoint.send(mavlink.MAVLink_mission_count_message(*partner, self.item_count(), self.MISSION_TYPE))
            self._ack(endpoint, partner, found)
            return
        item, frame = found
        sent = item_message(item, msg.seq, False, partner, as_int, self.MISSION_TYPE)
        sent.frame = frame
        endpoint.send(sent)

    def on_ack(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        """ArduPilot ignores a client's MISSION_ACK ("not used")."""

    def on_clear_all(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        partner = (msg.get_srcSystem(), msg.get_srcComponent())
        if self._cancel_upload(endpoint, partner, msg.mission_type):
            self._ack(endpoint, partner, self.clear(), msg.mission_type)

    def _ack(self, endpoint: Endpoint, partner: tuple[int, int], result: int, mission_type: int | None = None) -> None:
        mission_type = self.MISSION_TYPE if mission_type is None else mission_type
        endpoint.send(mavlink.MAVLink_mission_ack_message(*partner, result, mission_type))


class CopterTransfers:
    """GCS_MAVLINK's routing: each mission message to the protocol of its ``mission_type``. MISSION_CLEAR_ALL of
    MAV_MISSION_TYPE_ALL goes to the mission (ArduPilot answers it UNSUPPORTED: no protocol has that type)."""

    def __init__(self, mission: ItemProtocol, fence: ItemProtocol, rally: ItemProtocol):
        self.mission, self.fence, self.rally = mission, fence, rally
        self.by_type = {protocol.MISSION_TYPE: protocol for protocol in (mission, fence, rally)}

    def _protocol(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, refuse: bool = True) -> ItemProtocol | None:
        kind = msg.mission_type
        if msg.get_type() == "MISSION_CLEAR_ALL" and kind == mavlink.MAV_MISSION_TYPE_ALL:
            kind = MISSION
        protocol = self.by_type.get(kind)
        if protocol is None and refuse:
            endpoint.send(mavlink.MAVLink_mission_ack_message(msg.get_srcSystem(), msg.get_srcComponent(),
                                                              mavlink.MAV_MISSION_UNSUPPORTED, msg.mission_type))
        return protocol

    def on_count(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        protocol = self._protocol(endpoint, msg)
        if protocol is not None:
            protocol.on_count(endpoint, msg, now)

    def on_item(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> bool:
        """An item of an upload; False when it is not one (a guided-mode item, current 2 or 3, for GUIDED)."""
        if msg.mission_type == MISSION and msg.current in (2, 3):
            return False
        protocol = self._protocol(endpoint, msg)
        if protocol is not None:
            protocol.on_item(endpoint, msg, now)
        return True

    def on_request(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        protocol = self._protocol(endpoint, msg, refuse=False)  # GCS_MAVLINK::handle_mission_request: no answer
        if protocol is not None:
            protocol.on_request(endpoint, msg, now)

    def on_request_list(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        protocol = self._protocol(endpoint, msg)
        if protocol is not None:
            protocol.on_request_list(endpoint, msg, now)

    def on_clear_all(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        protocol = self._protocol(endpoint, msg)
        if protocol is not None:
            protocol.on_clear_all(endpoint, msg, now)

    def on_ack(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, now: float) -> None:
        """Not used by ArduPilot."""

    def tick(self, now: float) -> None:
        for protocol in self.by_type.values():
            protocol.tick(now)

    def cancel_uploads(self) -> None:
        """A reboot: no transfer survives it."""
        for protocol in self.by_type.values():
            protocol.upload = None
