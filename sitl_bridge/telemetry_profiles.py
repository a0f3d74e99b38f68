"""Which messages stream at which rate on each link: the telemetry profiles a vehicle can be given.

``VehicleConfig.telemetry_profile`` picks one:

* ``legacy``: the rates this simulator always had, the same on every link (GLOBAL_POSITION_INT and
  LOCAL_POSITION_NED 10 Hz, ...). Lockstep replays made before the profiles existed stay byte-identical with it.
* ``px4``: PX4's defaults per MAVLink mode (src/modules/mavlink/mavlink_main.cpp,
  Mavlink::configure_streams_to_default): the link named ``gcs`` runs the "normal" mode a ground station link
  gets (GLOBAL_POSITION_INT 5 Hz, LOCAL_POSITION_NED 1 Hz, ATTITUDE 15 Hz), every other link (the API link, the
  in-memory link of a replay) the "onboard" mode PX4 SITL starts on its API port 14580 (GLOBAL_POSITION_INT 50 Hz,
  LOCAL_POSITION_NED 30 Hz, ATTITUDE 100 Hz).
* ``px4_sitl``: as ``px4``, plus what PX4 SITL's startup script adds on its GCS link
  (ROMFS/px4fmu_common/init.d-posix/px4-rc.mavlink: ``mavlink stream -r 50`` for LOCAL_POSITION_NED,
  GLOBAL_POSITION_INT and ATTITUDE).
* ``ardupilot``: ArduCopter's defaults: the SRn_* stream rates are all 0 (libraries/GCS_MAVLink/
  GCS_MAVLink_Parameters.cpp), so a link carries only HEARTBEAT (and replies, STATUSTEXT, HOME_POSITION when home
  is set) until a client asks with REQUEST_DATA_STREAM or MAV_CMD_SET_MESSAGE_INTERVAL. Link ``n`` uses the
  ``SRn_*`` parameters (set them at boot with ``--param SR0_POSITION=10``).
* ``default``: ``legacy`` for the PX4 personality (unchanged behaviour), ``ardupilot`` for ArduPilot.

Only the messages the vehicle builds appear; PX4's "unlimited" GPS_RAW_INT (sent on every fix) is the GPS rate.
"""
from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from sitl_bridge.ardupilot.params import STREAM_GROUPS, STREAM_LINKS
from sitl_bridge.params import ParameterStore

HEARTBEAT = mavlink.MAVLINK_MSG_ID_HEARTBEAT
SYS_STATUS = mavlink.MAVLINK_MSG_ID_SYS_STATUS
EXTENDED_SYS_STATE = mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE
GLOBAL_POSITION_INT = mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT
LOCAL_POSITION_NED = mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED
ATTITUDE = mavlink.MAVLINK_MSG_ID_ATTITUDE
GPS_RAW_INT = mavlink.MAVLINK_MSG_ID_GPS_RAW_INT
VFR_HUD = mavlink.MAVLINK_MSG_ID_VFR_HUD
HOME_POSITION = mavlink.MAVLINK_MSG_ID_HOME_POSITION
BATTERY_STATUS = mavlink.MAVLINK_MSG_ID_BATTERY_STATUS
MISSION_CURRENT = mavlink.MAVLINK_MSG_ID_MISSION_CURRENT

PROFILES = ("default", "legacy", "px4", "px4_sitl", "ardupilot")

LEGACY_RATES_HZ: dict[int, float] = {
    HEARTBEAT: 1.0, SYS_STATUS: 1.0, EXTENDED_SYS_STATE: 1.0, GLOBAL_POSITION_INT: 10.0, LOCAL_POSITION_NED: 10.0,
    ATTITUDE: 10.0, GPS_RAW_INT: 1.0, VFR_HUD: 2.0, HOME_POSITION: 0.5, BATTERY_STATUS: 1.0,
}
PX4_ONBOARD_RATES_HZ: dict[int, float] = {  # MAVLINK_MODE_ONBOARD (HEARTBEAT is always 1 Hz)
    HEARTBEAT: 1.0, SYS_STATUS: 5.0, EXTENDED_SYS_STATE: 5.0, GLOBAL_POSITION_INT: 50.0, LOCAL_POSITION_NED: 30.0,
    ATTITUDE: 100.0, GPS_RAW_INT: 10.0, VFR_HUD: 10.0, HOME_POSITION: 0.5, BATTERY_STATUS: 0.5,
}
PX4_NORMAL_RATES_HZ: dict[int, float] = {  # MAVLINK_MODE_NORMAL
    HEARTBEAT: 1.0, SYS_STATUS: 1.0, EXTENDED_SYS_STATE: 1.0, GLOBAL_POSITION_INT: 5.0, LOCAL_POSITION_NED: 1.0,
    ATTITUDE: 15.0, GPS_RAW_INT: 5.0, VFR_HUD: 4.0, HOME_POSITION: 0.5, BATTERY_STATUS: 0.5,
}
PX4_SITL_GCS_RATES_HZ: dict[int, float] = {**PX4_NORMAL_RATES_HZ, LOCAL_POSITION_NED: 50.0,
                                           GLOBAL_POSITION_INT: 50.0, ATTITUDE: 50.0}

# ArduPilot's stream groups (GCS_MAVLink_Parameters.cpp, STREAM_*_msgs), restricted to the messages we build.
ARDUPILOT_STREAM_MESSAGES: dict[str, tuple[int, ...]] = {
    "EXT_STAT": (SYS_STATUS, GPS_RAW_INT, MISSION_CURRENT), "POSITION": (GLOBAL_POSITION_INT, LOCAL_POSITION_NED),
    "EXTRA1": (ATTITUDE,), "EXTRA2": (VFR_HUD,), "EXTRA3": (BATTERY_STATUS,),
}
DATA_STREAM_GROUPS: dict[int, str] = {  # REQUEST_DATA_STREAM.req_stream_id -> group
    mavlink.MAV_DATA_STREAM_EXTENDED_STATUS: "EXT_STAT", mavlink.MAV_DATA_STREAM_POSITION: "POSITION",
    mavlink.MAV_DATA_STREAM_EXTRA1: "EXTRA1", mavlink.MAV_DATA_STREAM_EXTRA2: "EXTRA2",
    mavlink.MAV_DATA_STREAM_EXTRA3: "EXTRA3",
}
assert tuple(ARDUPILOT_STREAM_MESSAGES) == STREAM_GROUPS


def resolve_profile(profile: str, autopilot: str) -> str:
    """The concrete profile ``default`` stands for with this autopilot personality."""
    if profile != "default":
        return profile
    return "ardupilot" if autopilot == "ardupilot" else "legacy"


def ardupilot_stream_rates_hz(params: ParameterStore, link_index: int) -> dict[int, float]:
    """Per-message rates from link ``link_index``'s SRn_* parameters (links beyond SR2 stream nothing)."""
    rates = {HEARTBEAT: 1.0}
    for group, messages in ARDUPILOT_STREAM_MESSAGES.items():
        name = f"SR{link_index}_{group}"
        rate = params[name] if link_index < STREAM_LINKS and name in params.specs else 0.0
        rates.update({msg_id: rate for msg_id in messages})
    return rates


def link_rates_hz(profile: str, link_name: str, link_index: int, params: ParameterStore) -> dict[int, float]:
    """The default rate of every streamed message on one link (0 = not streamed), for a resolved profile."""
    if profile == "legacy":
        return dict(LEGACY_RATES_HZ)
    if profile in ("px4", "px4_sitl"):
        if link_name != "gcs":
            return dict(PX4_ONBOARD_RATES_HZ)
        return dict(PX4_SITL_GCS_RATES_HZ if profile == "px4_sitl" else PX4_NORMAL_RATES_HZ)
    if profile == "ardupilot":
        return ardupilot_stream_rates_hz(params, link_index)
    raise ValueError(f"unknown telemetry profile {profile!r} (choose from {', '.join(PROFILES)})")
