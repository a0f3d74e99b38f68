"""The fuzzer's frames (benchmarks/fuzz.py): a corpus of valid MAVLink frames of both directions and the mutations
that turn one into an attack (random bytes, bit flips, truncation, a lying length, a wrong CRC, an unknown id, a
swapped marker, a garbage signature, two frames spliced, hostile field values). Seeded: the same generator gives the
same frames. The tests (tests/test_fuzz_mavlink.py) use them too.
"""
from __future__ import annotations

import math
import random
import struct

from pymavlink.dialects.v20 import common as mavlink

ATTACKER_KEY = bytes(range(101, 133))  # what the corpus's signed frames use: the fuzzer never has the real key
MUTATIONS = ("random_bytes", "bit_flips", "truncate", "length_lie", "bad_crc", "unknown_msgid", "marker_swap",
             "signed_garbage", "splice", "hostile_fields", "hostile_fields", "valid")  # hostile twice as often
HOSTILE_FLOATS = (math.nan, math.inf, -math.inf, 3.4e38, -3.4e38, 1e-45, -0.0, 0.0, 1.0, -1.0)
# Messages a vehicle or a companion computer acts on: what hostile field values are tried on.
HOSTILE_TYPES = ("HEARTBEAT", "COMMAND_LONG", "COMMAND_INT", "SET_POSITION_TARGET_LOCAL_NED", "PARAM_SET",
                 "PARAM_REQUEST_READ", "PARAM_REQUEST_LIST", "TIMESYNC", "SET_MODE", "MISSION_REQUEST_LIST",
                 "SETUP_SIGNING", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "HOME_POSITION", "SYS_STATUS",
                 "COMMAND_ACK", "STATUSTEXT", "EXTENDED_SYS_STATE", "ATTITUDE", "GPS_RAW_INT", "RADIO_STATUS",
                 "ADSB_VEHICLE", "COLLISION", "AUTOPILOT_VERSION", "PARAM_VALUE", "BATTERY_STATUS",
                 "MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_REQUEST_INT", "MISSION_REQUEST",
                 "MISSION_ACK", "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT")
_CLASSES = {cls.msgname: cls for cls in mavlink.mavlink_map.values()}
# Commands the vehicle acts on (random command numbers would almost never reach its logic), and its mode numbers.
KNOWN_COMMANDS = (mavlink.MAV_CMD_COMPONENT_ARM_DISARM, mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_CMD_NAV_TAKEOFF,
                  mavlink.MAV_CMD_NAV_LAND, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_SET_CAMERA_ZOOM,
                  mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAV_CMD_REQUEST_MESSAGE,
                  mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, mavlink.MAV_CMD_MISSION_START)
PLAUSIBLE_PARAMS = (1.0, 0.0, 1.0, 4.0, 6.0, 3.0, 2.0, 33.0, 24.0, 500.0)  # arm, custom-mode numbers, msg ids
# Mission items' commands and types: the mission, fence and rally uploads both personalities parse.
ITEM_COMMANDS = (mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND,
                 mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_DO_CHANGE_SPEED,
                 mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
                 mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION,
                 mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT, mavlink.MAV_CMD_NAV_RALLY_POINT)
MISSION_TYPES = (mavlink.MAV_MISSION_TYPE_MISSION, mavlink.MAV_MISSION_TYPE_FENCE, mavlink.MAV_MISSION_TYPE_RALLY,
                 mavlink.MAV_MISSION_TYPE_ALL)


class _NoFile:
    def write(self, data: bytes) -> None:
        pass


def encoder(system: int, component: int, key: bytes | None = None) -> mavlink.MAVLink:
    """A pymavlink encoder (optionally signing with ``key``) used only to pack frames."""
    mav = mavlink.MAVLink(_NoFile(), srcSystem=system, srcComponent=component)
    if key is not None:
        mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.timestamp = key, True, 10**11
    return mav


# ---------------------------------------------------------------------------------------------- frames
def hostile_value(rng: random.Random, fieldtype: str):
    """A value of a MAVLink field type chosen to hurt: NaN/inf/extremes for floats, the edges for integers."""
    if fieldtype in ("float", "double"):
        return rng.choice(HOSTILE_FLOATS) if rng.random() < 0.7 else rng.uniform(-1e6, 1e6)
    if fieldtype == "char":
        return bytes(rng.randrange(256) for _ in range(rng.randrange(4)))
    bits = int(fieldtype.removesuffix("_t").lstrip("uint") or 8)
    signed = not fieldtype.startswith("u")
    low, high = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    return rng.choice((low, high, 0, 1, -1 if signed else 2, rng.randint(low, high)))


def hostile_message(rng: random.Random, name: str | None = None) -> mavlink.MAVLink_message:
    """A message of a type the targets act on, every field hostile; addressed to system 1 half of the time."""
    cls = _CLASSES[name or rng.choice(HOSTILE_TYPES)]
    values = []
    for field_name, fieldtype, length in zip(cls.fieldnames, cls.fieldtypes, cls.array_lengths):
        if fieldtype == "char":
            values.append(bytes(rng.randrange(256) for _ in range(rng.randrange(length + 1))))
        elif length:
            values.append([hostile_value(rng, fieldtype) for _ in range(length)])
        else:
            values.append(hostile_value(rng, fieldtype))
        if field_name in ("target_system", "target_component") and rng.random() < 0.5:
            values[-1] = 1 if field_name == "target_system" else rng.choice((0, 1))
        elif field_name == "command" and rng.random() < 0.8:
            values[-1] = rng.choice(ITEM_COMMANDS if cls.msgname.startswith("MISSION_ITEM") else KNOWN_COMMANDS)
        elif field_name == "mission_type" and rng.random() < 0.8:
            values[-1] = rng.choice(MISSION_TYPES)
        elif field_name.startswith("param") and fieldtype == "float" and rng.random() < 0.4:
            values[-1] = rng.choice(PLAUSIBLE_PARAMS)
    return cls(*values)


# Senders of the fuzzed frames: a ground station, the vehicle, a companion computer and the vehicle signing with
# the attacker's key (so both receive paths see MAVLink 1 and 2, signed and unsigned, from plausible sources).
_ENCODERS = (encoder(255, 190), encoder(1, 1), encoder(1, 191, ATTACKER_KEY), encoder(1, 1, ATTACKER_KEY))


def hostile_frame(rng: random.Random) -> bytes:
    """A valid frame (correct CRC) of a fresh :func:`hostile_message`, MAVLink 1 one time in five."""
    while True:
        msg, mav = hostile_message(rng), rng.choice(_ENCODERS)
        try:
            return msg.pack(mav, force_mavlink1=rng.random() < 0.2 and msg.id < 256)
        except (struct.error, mavlink.MAVError, ValueError, TypeError, OverflowError):
            continue  # a value pymavlink itself cannot pack is not a frame


def corpus(rng: random.Random, size: int = 256) -> list[bytes]:
    """Valid frames of both directions, the material the mutations damage."""
    return [hostile_frame(rng) for _ in range(size)]


def _frame_crc_offset(frame: bytearray) -> int:
    header = 10 if frame[0] == 0xFD else 6
    return header + frame[1]


def mutate(frame: bytes, kind: str, rng: random.Random, other: bytes = b"") -> bytes:
    """``frame`` damaged by one of ``MUTATIONS`` (``other``: a second frame, for splices)."""
    data = bytearray(frame)
    if kind == "random_bytes":
        return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 300)))
    if kind == "bit_flips":
        for _ in range(rng.randint(1, 8)):
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    elif kind == "truncate":
        del data[rng.randrange(len(data)):]
    elif kind == "length_lie":
        data[1] = rng.randrange(256)
    elif kind == "bad_crc" and _frame_crc_offset(data) + 2 <= len(data):
        data[_frame_crc_offset(data) + rng.randrange(2)] ^= rng.randrange(1, 256)
    elif kind == "unknown_msgid":
        if data[0] == 0xFD:
            data[7:10] = rng.choice((0xFFFFFF, 0x123456, 60000, 299)).to_bytes(3, "little")
        else:
            data[5] = rng.choice((255, 180, 201))
    elif kind == "marker_swap":
        data[0] = 0xFE if data[0] == 0xFD else 0xFD
    elif kind == "signed_garbage" and data[0] == 0xFD:
        data[2] |= 0x01
        if rng.random() < 0.7:
            data += bytes(rng.randrange(256) for _ in range(13))
    elif kind == "splice":
        cut, other_cut = rng.randrange(len(data) + 1), rng.randrange(len(other) + 1)
        return bytes(data[:cut]) + other[other_cut:]
    elif kind == "hostile_fields":
        return hostile_frame(rng)  # a fresh valid frame, every field hostile
    return bytes(data)


def fuzz_frame(rng: random.Random, frames: list[bytes]) -> tuple[str, bytes]:
    """One fuzzed frame: (mutation, bytes)."""
    kind = rng.choice(MUTATIONS)
    return kind, mutate(rng.choice(frames), kind, rng, rng.choice(frames))
