"""The simulated vehicle's side of MAVLink 2 signing: PX4's rules on top of :mod:`mavlink_signing`.

With a key, the vehicle signs everything it sends and accepts only correctly signed, fresh frames, except the
few messages PX4 accepts unsigned (``PX4_UNSIGNED_ALLOW_LIST``: radios and traffic receivers cannot sign).
MAVLink 1 frames cannot carry a signature and are rejected like unsigned MAVLink 2 ones, so an attacker
cannot downgrade a signed link. SETUP_SIGNING installs a new key only while the vehicle is disarmed.
"""
from __future__ import annotations

from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from mavlink_signing import KEY_BYTES, LinkSigning

PX4_UNSIGNED_ALLOW_LIST = frozenset({
    mavlink.MAVLINK_MSG_ID_HEARTBEAT,
    mavlink.MAVLINK_MSG_ID_RADIO_STATUS,
    mavlink.MAVLINK_MSG_ID_ADSB_VEHICLE,
    mavlink.MAVLINK_MSG_ID_COLLISION,
})


def vehicle_signing(key: bytes, now: Callable[[], int]) -> LinkSigning:
    """The vehicle's signing state for ``key``, timestamps from ``now`` (see mavlink_signing)."""
    return LinkSigning(key, now, allow_unsigned=PX4_UNSIGNED_ALLOW_LIST.__contains__)


def requested_key(msg: mavlink.MAVLink_setup_signing_message) -> bytes | None:
    """The key a SETUP_SIGNING carries; None for the all-zero key, which the spec uses to switch signing off."""
    key = bytes(msg.secret_key) if isinstance(msg.secret_key, (bytes, bytearray)) else bytes(
        int(value) & 0xFF for value in msg.secret_key)
    key = key.ljust(KEY_BYTES, b"\0")[:KEY_BYTES]  # pymavlink strips trailing zero bytes of byte arrays
    return None if not any(key) else key
