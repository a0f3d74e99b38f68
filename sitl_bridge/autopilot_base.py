"""What the simulated autopilot personalities (PX4, ArduPilot Copter) share.

Each personality (:class:`sitl_bridge.px4.autopilot.Px4Autopilot` for PX4,
:class:`sitl_bridge.ardupilot.autopilot.ArduCopter` for ArduPilot Copter) is a subclass of :class:`AutopilotBase`.
The vehicle talks to both through the same methods: ``handle_command``, ``handle_setpoint``,
``handle_set_mode_message``, ``on_heartbeat``, ``guidance``, ``landed_state``, ``prearm_failure``,
``heartbeat_fields`` and ``battery_charge_state``. No I/O and no MAVLink encoding happens here.

:class:`FlightStatus` is the personality-neutral view of "what is the autopilot doing" for code that must judge a
flight without knowing PX4 or ArduPilot modes (``simulation.flight_outcome``): read ``vehicle.autopilot.status``.
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from missions.geodesy import LocalFrame
from sitl_bridge.multirotor import MultirotorParams, VehicleState, VelocityCommand
from sitl_bridge.params import ParameterStore

ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
DENIED = mavlink.MAV_RESULT_DENIED
UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
FAILED = mavlink.MAV_RESULT_FAILED

ARRIVED_RADIUS_M = 0.3
CELL_COUNT = 4  # the battery is reported as a 4S LiPo: 3.5 V (empty) to 4.2 V (full) per cell
CELL_NOMINAL_V = 3.7

# SET_POSITION_TARGET_LOCAL_NED.type_mask bits (POSITION_TARGET_TYPEMASK)
MASK_POSITION = 0b111
MASK_VELOCITY = 0b111000
MASK_ACCELERATION = 0b111000000
MASK_FORCE = 512
MASK_YAW = 1024
MASK_YAW_RATE = 2048

# SET_POSITION_TARGET_GLOBAL_INT frames by what their altitude is measured from
AMSL_FRAMES = (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT)
ABOVE_HOME_FRAMES = (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
TERRAIN_FRAMES = (mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)


def as_int(value: float, default: int = -1) -> int:
    """A command parameter as an integer; NaN/inf (MAVSDK sends NaN for unused params) become ``default``."""
    return int(value) if math.isfinite(value) else default


def battery_voltage_v(fraction: float) -> float:
    """Pack voltage of the simulated 4S battery at a remaining-energy fraction (linear 14.0-16.8 V)."""
    return CELL_COUNT * (3.5 + 0.7 * max(0.0, fraction))


def consumed_mah(used_wh: float) -> float:
    """Charge drawn from the pack so far (mAh) for ``used_wh`` of energy at the nominal voltage."""
    return used_wh / (CELL_COUNT * CELL_NOMINAL_V) * 1000.0


def body_to_ned(forward: float, right: float, yaw_rad: float) -> tuple[float, float]:
    """Rotate a body-frame (x forward, y right) horizontal vector into north/east by the heading."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return c * forward - s * right, s * forward + c * right


@dataclass(frozen=True)
class Setpoint:
    """An accepted offboard/guided setpoint, already in local NED (the simulator's frame)."""

    time_s: float
    is_velocity: bool  # else a position
    north: float
    east: float
    down: float
    yaw_rad: float | None = None
    yaw_rate_rad_s: float | None = None
    feedforward: tuple[float, float, float] | None = None
    """A position setpoint's velocity feed-forward (NED, m/s), added to the position controller's output."""


@dataclass(frozen=True)
class AutopilotEvent:
    """Something worth telling the operator (STATUSTEXT) and the log."""

    time_s: float
    text: str
    severity: int = mavlink.MAV_SEVERITY_INFO
    broadcast: bool = True
    """False: for the operator log only (the real autopilot sends no STATUSTEXT for it)."""


@dataclass(frozen=True)
class FlightStatus:
    """What the autopilot is doing, in words that mean the same for PX4 and ArduPilot (``autopilot.status``)."""

    armed: bool
    """Motors armed."""
    mode_name: str
    """The personality's own mode name (PX4: ``OFFBOARD``, ``HOLD``...; ArduPilot: ``GUIDED``, ``LOITER``...)."""
    phase: str
    """One of ``on_ground`` (disarmed, or armed and landed), ``taking_off``, ``guided`` (flying the
    companion computer's setpoints: PX4 OFFBOARD, ArduPilot GUIDED), ``holding`` (PX4 HOLD/POSCTL/ORBIT, ArduPilot
    LOITER/BRAKE), ``returning`` (RTL before its landing), ``landing`` (LAND, or RTL's final landing), ``manual``
    (ArduPilot STABILIZE: no pilot input, so throttle low), ``mission`` (PX4 Mission mode, ArduPilot AUTO: flying
    an uploaded mission)."""
    last_setpoint_s: float | None
    """Simulated time of the last accepted setpoint (s), None before the first."""
    setpoint_timeout_s: float
    """How long the autopilot flies a setpoint without a new one before its own guard acts (s): PX4 COM_OF_LOSS_T
    (then the offboard-loss failsafe), ArduPilot GUID_TIMEOUT (then it stops, staying in GUIDED)."""

    @property
    def companion_in_control(self) -> bool:
        """The companion computer's setpoints are what the vehicle flies (OFFBOARD / GUIDED)."""
        return self.phase == "guided"


class AutopilotBase:
    """State and helpers common to every personality; subclasses implement the rules."""

    PARAMS_BYTEWISE = False
    """True: integer parameters travel with their bytes in the float field (PX4); False: as float values."""
    STATUSTEXT_ID_PER_TEXT = False
    """True: every STATUSTEXT gets the next id, whatever its length, and a text filling its last chunk ends there
    (PX4's STATUSTEXT stream); False: only texts over 50 bytes get an id, and one filling its last chunk is followed
    by an empty chunk (ArduPilot's GCS::send_textv)."""

    def __init__(self, params: ParameterStore, airframe: MultirotorParams, frame: LocalFrame):
        self.params = params
        self.airframe = airframe
        self.frame = frame  # the simulator's NED frame (origin: the configured home), for geodetic targets
        self.armed = False
        self.gps_ok = False  # set by the vehicle from the sensors
        self.events: list[AutopilotEvent] = []
        self.state_changed = False  # a mode or arming change the vehicle must announce at once
        self.home_ned: tuple[float, float, float] = (0.0, 0.0, 0.0)  # home in the simulator's NED frame
        self.home_changed = False  # set when the autopilot moves home itself (the vehicle re-announces it)
        self.zoom_percent = 0.0
        self.setpoint: Setpoint | None = None
        self.setpoints_ignored: Counter[str] = Counter()

    def ned_of(self, lat_deg: float, lon_deg: float) -> tuple[float, float]:
        """(north, east) in the simulator's frame of a latitude and longitude (taken at home's altitude: the
        difference at the vehicle's is about a centimetre per 100 m of height, a kilometre out)."""
        north, east, _ = self.frame.to_ned(lat_deg, lon_deg, self.frame.home.alt_m)
        return north, east

    def down_of(self, alt_amsl_m: float) -> float:
        """The simulator frame's down of an AMSL altitude (flat, as the vehicle's own altitude is)."""
        return self.frame.home.alt_m - alt_amsl_m

    def global_target(self, frame: int, lat_int: int, lon_int: int, alt_m: float) -> tuple[float, float, float] | str:
        """A SET_POSITION_TARGET_GLOBAL_INT position in the simulator's NED frame, or why it cannot be one: the
        altitude is above mean sea level in the GLOBAL frames and above home in the GLOBAL_RELATIVE_ALT ones; the
        terrain frames need terrain data, which is not simulated."""
        if frame in TERRAIN_FRAMES:
            return "terrain frame (no terrain data)"
        if frame not in AMSL_FRAMES + ABOVE_HOME_FRAMES:
            return f"frame {frame}"
        if not math.isfinite(alt_m):
            return "non-finite altitude"
        north, east = self.ned_of(lat_int / 1e7, lon_int / 1e7)
        return north, east, self.down_of(alt_m) if frame in AMSL_FRAMES else self.home_ned[2] - alt_m

    def _event(self, now: float, text: str, severity: int = mavlink.MAV_SEVERITY_INFO, broadcast: bool = True) -> None:
        self.events.append(AutopilotEvent(now, text, severity, broadcast))

    @property
    def motors_running(self) -> bool:
        """Whether the motors produce thrust (the dynamics fly the command); False: ballistic when airborne."""
        return self.armed

    def on_heartbeat(self, system_id: int, now: float) -> None:
        """A HEARTBEAT from another system arrived (ArduPilot's GCS failsafe counts them; PX4 ignores them)."""

    def battery_fraction(self, state: VehicleState) -> float:
        return state.battery_wh / self.airframe.battery_capacity_wh

    @property
    def battery_monitored(self) -> bool:
        """Whether the autopilot measures its battery (ArduPilot: BATT_MONITOR non-zero); without, SYS_STATUS says
        so (-1) and there is no battery failsafe."""
        return True

    @property
    def battery_healthy(self) -> bool:
        """SYS_STATUS's battery health bit (ArduPilot clears it once the battery failsafe has triggered)."""
        return True

    def _zoom(self, zoom_type: int, value: float, now: float) -> int:
        """MAV_CMD_SET_CAMERA_ZOOM: zoom range (0-100 %) or steps of 10 %."""
        if zoom_type == mavlink.ZOOM_TYPE_RANGE and 0.0 <= value <= 100.0:
            self.zoom_percent = value
        elif zoom_type == mavlink.ZOOM_TYPE_STEP and math.isfinite(value):
            self.zoom_percent = min(100.0, max(0.0, self.zoom_percent + 10.0 * value))
        else:
            return DENIED
        self._event(now, f"camera zoom {self.zoom_percent:.0f} %")
        return ACCEPTED

    # The interface the vehicle calls; each personality implements it.
    def handle_command(self, command: int, p: tuple[float, ...], now: float, state: VehicleState,
                       source_component: int = 190, frame: int | None = None) -> int:
        raise NotImplementedError

    def handle_setpoint(self, now: float, state: VehicleState, frame: int, mask: int,
                        position: tuple[float, float, float], velocity: tuple[float, float, float],
                        yaw: float, yaw_rate: float) -> bool:
        raise NotImplementedError

    def handle_global_setpoint(self, now: float, state: VehicleState, frame: int, mask: int,
                               position: tuple[int, int, float], velocity: tuple[float, float, float],
                               yaw: float, yaw_rate: float) -> bool:
        """SET_POSITION_TARGET_GLOBAL_INT; ``position`` is (lat_int, lon_int, alt) as on the wire."""
        raise NotImplementedError

    def handle_set_mode_message(self, base_mode: int, custom_mode: int, now: float, state: VehicleState) -> int | None:
        """The legacy SET_MODE message; returns the COMMAND_ACK result to send, or None for no ACK."""
        raise NotImplementedError

    def guidance(self, now: float, state: VehicleState) -> VelocityCommand:
        raise NotImplementedError

    def landed_state(self, state: VehicleState) -> int:
        raise NotImplementedError

    def prearm_failure(self, state: VehicleState) -> str | None:
        raise NotImplementedError

    def heartbeat_fields(self) -> tuple[int, int, int, int]:
        """(autopilot, base_mode, custom_mode, system_status) for HEARTBEAT."""
        raise NotImplementedError

    def battery_charge_state(self, fraction: float) -> int:
        raise NotImplementedError

    @property
    def status(self) -> FlightStatus:
        raise NotImplementedError
