"""Telemetry: how each message is filled, and the per-link schedule that says when it is due.

Which messages stream at which default rate is the vehicle's telemetry profile
(:mod:`sitl_bridge.telemetry_profiles`); every one can be changed per link with MAV_CMD_SET_MESSAGE_INTERVAL.
Builders read the *sensor* values (noisy GPS, baro, attitude), never the simulator's ground truth, as a real
autopilot's estimate would be. What differs between PX4 and ArduPilot (HEARTBEAT fields, battery state,
AUTOPILOT_VERSION) is asked of the autopilot personality; times are the autopilot's time since boot.
"""
from __future__ import annotations

import math
from typing import Callable, Protocol

from pymavlink.dialects.v20 import common as mavlink

from missions.geodesy import GeoPoint, LocalFrame
from sitl_bridge.autopilot_base import CELL_COUNT, CELL_NOMINAL_V, AutopilotBase, battery_voltage_v
from sitl_bridge.multirotor import VehicleState
from sitl_bridge.sensors import SensorSuite
from sitl_bridge.vehicle_config import VehicleConfig

SENSORS = (mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
           | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
           | mavlink.MAV_SYS_STATUS_SENSOR_GPS | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
           | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION | mavlink.MAV_SYS_STATUS_SENSOR_YAW_POSITION
           | mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
           | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
           | mavlink.MAV_SYS_STATUS_PREARM_CHECK)

UINT16_MAX = 65535


class TelemetrySource(Protocol):
    """What the builders read of the vehicle (:class:`sitl_bridge.vehicle.SimulatedVehicle` is one). Declared here
    rather than imported so that this module, which the vehicle imports, does not import the vehicle."""

    config: VehicleConfig
    system_id: int
    autopilot: AutopilotBase
    sensors: SensorSuite
    state: VehicleState
    frame: LocalFrame
    home: GeoPoint
    origin_ned: tuple[float, float, float]
    ground_velocity: tuple[float, float, float]
    yaw_rate_rad_s: float
    power_w: float
    is_ardupilot: bool
    mission_reports: MissionReports  # PX4's MISSION_CURRENT pacing and state

    @property
    def time_boot_ms(self) -> int: ...

    @property
    def time_since_boot_s(self) -> float: ...


class MissionReports:
    """MISSION_CURRENT and MISSION_ITEM_REACHED as mavlink_mission.cpp's send() paces them: MISSION_CURRENT at once
    when the current item changes and at 1 Hz, MISSION_ITEM_REACHED for each item reached and the last one again at
    1 Hz, ten more times. PX4 also sends MISSION_CURRENT (total 65535) without a mission; this simulator stays
    silent then, so that a flight without a mission carries no mission messages."""

    REPEATS = 10

    def __init__(self) -> None:
        self.mission_state = mavlink.MISSION_STATE_UNKNOWN
        self._current: int | None = None
        self._current_s = -math.inf
        self._reached = -1  # the last one sent, repeated at 1 Hz
        self._reached_s = -math.inf
        self._repeats_left = 0

    def due(self, now: float, current: int, total: int, reached: list[int],
            state_of: Callable[[int], tuple[int, int]]) -> list[mavlink.MAVLink_message]:
        """The messages to send this tick; ``reached``: the items reached since the last call (emptied here),
        ``state_of(previous)`` gives (mission_state, mission_mode)."""
        news, reached[:] = list(reached), []
        if total == 0:
            self._current, self._repeats_left = None, 0
            return []
        self.mission_state, mode = state_of(self.mission_state)
        out = []
        if current != self._current or now - self._current_s >= 1.0:
            out.append(mavlink.MAVLink_mission_current_message(current, total, self.mission_state, mode))
            self._current, self._current_s = current, now
        for seq in news:
            out.append(mavlink.MAVLink_mission_item_reached_message(seq))
            self._reached, self._reached_s, self._repeats_left = seq, now, self.REPEATS
        if not news and self._repeats_left and now - self._reached_s >= 1.0:
            out.append(mavlink.MAVLink_mission_item_reached_message(self._reached))
            self._reached_s, self._repeats_left = now, self._repeats_left - 1
        return out


def _deg_e7(value_deg: float) -> int:
    return int(round(value_deg * 1e7))


def heartbeat(v: TelemetrySource) -> mavlink.MAVLink_message:
    autopilot, base_mode, custom_mode, status = v.autopilot.heartbeat_fields()
    return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, autopilot, base_mode, custom_mode, status, 3)


def sys_status(v: TelemetrySource) -> mavlink.MAVLink_message:
    health = SENSORS
    if not v.autopilot.gps_ok:
        health &= ~mavlink.MAV_SYS_STATUS_SENSOR_GPS
    if v.autopilot.prearm_failure(v.state) is not None:
        health &= ~mavlink.MAV_SYS_STATUS_PREARM_CHECK
    if not v.autopilot.battery_monitored:
        # ArduPilot without a battery monitor (GCS_Common.cpp, update_sensor_status_flags: the battery bit is always
        # present, enabled only with an instance, healthy only when healthy; send_sys_status: voltage() * 1000 = 0,
        # current and remaining -1 unless the battery is healthy)
        enabled = SENSORS & ~mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
        return mavlink.MAVLink_sys_status_message(SENSORS, enabled, health & enabled, 150, 0, -1, -1,
                                                  0, 0, 0, 0, 0, 0)
    if not v.autopilot.battery_healthy:
        health &= ~mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
    volts, amps, fraction = battery_reading(v)
    return mavlink.MAVLink_sys_status_message(SENSORS, SENSORS, health, 150, int(volts * 1000), int(amps * 100),
                                              int(round(fraction * 100)), 0, 0, 0, 0, 0, 0)


def battery_reading(v: TelemetrySource) -> tuple[float, float, float]:
    """(voltage V, current A, remaining fraction) from the dynamics' energy and power."""
    fraction = max(0.0, v.state.battery_wh / v.config.airframe.battery_capacity_wh)
    volts = battery_voltage_v(fraction)
    return volts, v.power_w / volts, fraction


def battery_status(v: TelemetrySource) -> mavlink.MAVLink_message | None:
    if not v.autopilot.battery_monitored:
        return None
    volts, amps, fraction = battery_reading(v)
    capacity_wh = v.config.airframe.battery_capacity_wh
    used_wh = capacity_wh - v.state.battery_wh
    charge = v.autopilot.battery_charge_state(fraction)
    remaining_s = int(v.state.battery_wh * 3600 / v.power_w) if v.power_w > 1.0 else 0
    return mavlink.MAVLink_battery_status_message(
        0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, 32767,
        [int(volts * 1000)] + [UINT16_MAX] * 9, int(amps * 100),
        int(used_wh / (CELL_COUNT * CELL_NOMINAL_V) * 1000), int(used_wh * 36), int(round(fraction * 100)),
        remaining_s, charge, [0, 0, 0, 0], 0, 0)


def _estimate(v: TelemetrySource) -> tuple[float, float, float, float, float, float]:
    """What the autopilot believes: GPS horizontal position/velocity and baro altitude (NED)."""
    fix = v.sensors.gps
    return fix.north_m, fix.east_m, -v.sensors.baro_alt_m, fix.vn_mps, fix.ve_mps, fix.vd_mps


def global_position_int(v: TelemetrySource) -> mavlink.MAVLink_message | None:
    if v.sensors.gps is None:
        return None  # PX4 publishes no global position before it has one
    north, east, down, vn, ve, vd = _estimate(v)
    lat, lon, alt = v.frame.to_geodetic(north, east, down)
    heading = int(round(math.degrees(v.sensors.attitude_rpy[2]) * 100)) % 36000
    relative_alt = -(down - v.autopilot.home_ned[2])
    return mavlink.MAVLink_global_position_int_message(
        v.time_boot_ms, _deg_e7(lat), _deg_e7(lon), int(round(alt * 1000)), int(round(relative_alt * 1000)),
        int(round(vn * 100)), int(round(ve * 100)), int(round(vd * 100)), heading)


def local_position_ned(v: TelemetrySource) -> mavlink.MAVLink_message | None:
    if v.sensors.gps is None:
        return None
    north, east, down, vn, ve, vd = _estimate(v)
    origin_n, origin_e, origin_d = v.origin_ned  # the EKF origin: where the position was first known after boot
    return mavlink.MAVLink_local_position_ned_message(v.time_boot_ms, north - origin_n, east - origin_e,
                                                      down - origin_d, vn, ve, vd)


def attitude(v: TelemetrySource) -> mavlink.MAVLink_message:
    roll, pitch, yaw = v.sensors.attitude_rpy
    return mavlink.MAVLink_attitude_message(v.time_boot_ms, roll, pitch, yaw, 0.0, 0.0, v.yaw_rate_rad_s)


def gps_raw_int(v: TelemetrySource) -> mavlink.MAVLink_message:
    fix = v.sensors.gps
    time_usec = int(v.time_since_boot_s * 1e6)
    if fix is None:
        return mavlink.MAVLink_gps_raw_int_message(time_usec, mavlink.GPS_FIX_TYPE_NO_FIX, 0, 0, 0,
                                                   UINT16_MAX, UINT16_MAX, UINT16_MAX, UINT16_MAX, 0)
    lat, lon, alt = v.frame.to_geodetic(fix.north_m, fix.east_m, fix.down_m)
    course = int(round(math.degrees(math.atan2(fix.ve_mps, fix.vn_mps)) * 100)) % 36000
    return mavlink.MAVLink_gps_raw_int_message(
        time_usec, fix.fix_type, _deg_e7(lat), _deg_e7(lon), int(round(alt * 1000)), int(fix.eph_m * 100),
        int(fix.epv_m * 100), int(round(math.hypot(fix.vn_mps, fix.ve_mps) * 100)), course, fix.satellites)


def vfr_hud(v: TelemetrySource) -> mavlink.MAVLink_message:
    vn, ve, vd = v.ground_velocity
    heading = int(round(math.degrees(v.sensors.attitude_rpy[2]))) % 360
    hover_share = v.power_w / v.config.airframe.hover_power_w if v.autopilot.armed else 0.0
    throttle = int(min(100.0, 50.0 * hover_share))
    alt_amsl = v.config.home.alt_m + v.sensors.baro_alt_m
    return mavlink.MAVLink_vfr_hud_message(math.hypot(vn - v.config.wind.north_mps, ve - v.config.wind.east_mps),
                                           math.hypot(vn, ve), heading, throttle, alt_amsl, -vd)


def extended_sys_state(v: TelemetrySource) -> mavlink.MAVLink_message:
    return mavlink.MAVLink_extended_sys_state_message(mavlink.MAV_VTOL_STATE_UNDEFINED,
                                                      v.autopilot.landed_state(v.state))


def home_position(v: TelemetrySource) -> mavlink.MAVLink_message:
    home = v.home
    home_n, home_e, home_d = v.autopilot.home_ned
    origin_n, origin_e, origin_d = v.origin_ned
    return mavlink.MAVLink_home_position_message(_deg_e7(home.lat_deg), _deg_e7(home.lon_deg),
                                                 int(round(home.alt_m * 1000)), home_n - origin_n, home_e - origin_e,
                                                 home_d - origin_d, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
                                                 int(v.time_since_boot_s * 1e6))


def known_home_position(v: TelemetrySource) -> mavlink.MAVLink_message | None:
    """HOME_POSITION once home is known (a position fix), else nothing: PX4's HOME_POSITION stream sends only a valid
    home (HOME_POSITION.hpp), ArduPilot's send_home_position returns before home is set (GCS_Common.cpp)."""
    return home_position(v) if v.autopilot.gps_ok else None


def mission_current(v: TelemetrySource, seq: int | None = None) -> mavlink.MAVLink_message:
    """MISSION_CURRENT: ArduPilot's (GCS_MAVLINK::send_mission_current: the current navigation command, home
    excluded from the total; ``seq`` as MISSION_SET_CURRENT asked) or PX4's (mavlink_mission.cpp: total 65535
    without a mission)."""
    ap = v.autopilot
    if v.is_ardupilot:
        current, total, state, mode = ap.mission_current_fields()
        return mavlink.MAVLink_mission_current_message(current if seq is None else seq, total, state, mode)
    state, mode = ap.mission_state(v.mission_reports.mission_state)
    return mavlink.MAVLink_mission_current_message(ap.mission_current, len(ap.mission_items) or 0xFFFF, state, mode)


def autopilot_version(v: TelemetrySource) -> mavlink.MAVLink_message:
    ap = v.autopilot
    return mavlink.MAVLink_autopilot_version_message(
        ap.CAPABILITIES, ap.FLIGHT_SW_VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0,
        0x5349_4D00_0000_0000 | v.system_id)  # "SIM" + system id: stable across runs


BUILDERS: dict[int, Callable[[TelemetrySource], mavlink.MAVLink_message | None]] = {
    mavlink.MAVLINK_MSG_ID_HEARTBEAT: heartbeat,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: sys_status,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: extended_sys_state,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: global_position_int,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: local_position_ned,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: attitude,
    mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: gps_raw_int,
    mavlink.MAVLINK_MSG_ID_VFR_HUD: vfr_hud,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: known_home_position,
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: battery_status,
    mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION: autopilot_version,
    mavlink.MAVLINK_MSG_ID_MISSION_CURRENT: mission_current,
}
