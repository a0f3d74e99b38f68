"""What the vehicle does with each MAVLink message it receives (a mixin of :class:`SimulatedVehicle`).

Commands get a COMMAND_ACK in the same tick, addressed to the sender; commands that are about the link rather than
the flight (message intervals, requested messages, ArduPilot's data streams and home requests) are handled here,
the rest by the autopilot personality. Parameters travel PX4's way (integers bytewise) or ArduPilot's (floats).
"""
from __future__ import annotations

import math
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from mavlink_signing import LinkSigning
from sitl_bridge import telemetry
from sitl_bridge.ardupilot.item_protocol import CopterTransfers
from sitl_bridge.ardupilot.mission_protocol import CopterMissionTransfer
from sitl_bridge.autopilot_base import ACCEPTED, DENIED, FAILED, AutopilotBase, as_int
from sitl_bridge.endpoint import AUTOPILOT_COMPONENT, Endpoint
from sitl_bridge.multirotor import VehicleState
from sitl_bridge.params import ParameterStore, decode_bytewise, decode_float, encode_bytewise
from sitl_bridge.px4.mission_protocol import MissionTransfer
from sitl_bridge.signing import requested_key
from sitl_bridge.telemetry_profiles import ARDUPILOT_STREAM_MESSAGES, DATA_STREAM_GROUPS, STREAM_GROUPS
from sitl_bridge.vehicle_config import VehicleConfig

CAMERA_COMPONENT = mavlink.MAV_COMP_ID_CAMERA  # zoom commands may be addressed to the camera
# PX4's mission manager also takes messages addressed to the mission planner's component (CHECK_SYSID_COMPID_MISSION)
MISSION_COMPONENTS = (AUTOPILOT_COMPONENT, mavlink.MAV_COMP_ID_MISSIONPLANNER)
REQUESTABLE = (mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES)


class MessageHandlers:
    """The ``_on_<MESSAGE>`` handlers; :meth:`handlers` maps message names to them.

    What they use of the vehicle is declared here and set by :class:`~sitl_bridge.vehicle.SimulatedVehicle`, so
    that this module, which the vehicle imports, does not import the vehicle.
    """

    config: VehicleConfig
    system_id: int
    params: ParameterStore
    autopilot: AutopilotBase
    state: VehicleState
    endpoints: list[Endpoint]
    signing: LinkSigning | None
    missions: MissionTransfer | None
    copter_missions: CopterMissionTransfer | None
    copter_transfers: CopterTransfers | None
    setup_signing_refused: int
    is_ardupilot: bool
    dt_s: float
    tick: int
    _reboot_tick: int | None
    time_s: float
    time_since_boot_s: float
    log: Callable[[str], None]
    broadcast: Callable[[mavlink.MAVLink_message], None]
    _enable_signing: Callable[[bytes], None]

    def handlers(self) -> dict:
        table = {
            "COMMAND_LONG": self._on_command_long,
            "COMMAND_INT": self._on_command_int,
            "SET_POSITION_TARGET_LOCAL_NED": self._on_setpoint,
            "SET_POSITION_TARGET_GLOBAL_INT": self._on_global_setpoint,
            "PARAM_REQUEST_LIST": self._on_param_request_list,
            "PARAM_REQUEST_READ": self._on_param_request_read,
            "PARAM_SET": self._on_param_set,
            "TIMESYNC": self._on_timesync,
            "SET_MODE": self._on_set_mode,
            "HEARTBEAT": self._on_heartbeat,
            "SETUP_SIGNING": self._on_setup_signing,
        }
        if self.is_ardupilot:  # PX4 implements neither REQUEST_DATA_STREAM nor guided-mode mission items
            table["REQUEST_DATA_STREAM"] = self._on_request_data_stream
            table["MISSION_ITEM_INT"] = table["MISSION_ITEM"] = self._on_mission_item
        if self.copter_transfers is not None:  # ArduPilot's mission item protocols (sitl_bridge.ardupilot)
            c = self.copter_transfers
            for name, method in (("MISSION_COUNT", c.on_count), ("MISSION_REQUEST_INT", c.on_request),
                                 ("MISSION_REQUEST", c.on_request), ("MISSION_ACK", c.on_ack),
                                 ("MISSION_REQUEST_LIST", c.on_request_list), ("MISSION_CLEAR_ALL", c.on_clear_all),
                                 ("MISSION_SET_CURRENT", self.copter_missions.on_set_current)):
                table[name] = self._mission_handler(method, (AUTOPILOT_COMPONENT,))
        elif self.missions is not None:  # PX4: the mission protocol (sitl_bridge.px4.mission_protocol)
            m = self.missions
            for name, method in (("MISSION_COUNT", m.on_count), ("MISSION_ITEM_INT", m.on_item),
                                 ("MISSION_ITEM", m.on_item), ("MISSION_REQUEST_INT", m.on_request),
                                 ("MISSION_REQUEST", m.on_request), ("MISSION_ACK", m.on_ack),
                                 ("MISSION_REQUEST_LIST", m.on_request_list), ("MISSION_CLEAR_ALL", m.on_clear_all),
                                 ("MISSION_SET_CURRENT", m.on_set_current)):
                table[name] = self._mission_handler(method)
        return table

    def _mission_handler(self, method: Callable, components: tuple[int, ...] = MISSION_COMPONENTS) -> Callable:
        def handle(endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
            if self._for_us(msg, components):
                method(endpoint, msg, self.time_s)
        return handle

    def _for_us(self, msg: mavlink.MAVLink_message,
                components: tuple[int, ...] = (AUTOPILOT_COMPONENT,)) -> bool:
        return (msg.target_system in (0, self.system_id)
                and msg.target_component in (0, *components))

    # ------------------------------------------------------------------ commands
    def _on_command_long(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        self._execute(endpoint, msg, msg.command, params, frame=None)

    def _on_command_int(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, float(msg.x), float(msg.y), msg.z)
        self._execute(endpoint, msg, msg.command, params, frame=msg.frame)

    def _execute(self, endpoint: Endpoint, msg: mavlink.MAVLink_message, command: int,
                 p: tuple[float, ...], frame: int | None) -> None:
        if not self._for_us(msg, (AUTOPILOT_COMPONENT, CAMERA_COMPONENT)):
            return
        now = self.time_s
        follow_up: mavlink.MAVLink_message | None = None
        if command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            msg_id = as_int(p[0])
            ok = (msg_id in telemetry.BUILDERS and msg_id != mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION
                  and endpoint.set_message_interval(msg_id, p[1], now, self.dt_s))
            result = ACCEPTED if ok else DENIED
        elif command in REQUESTABLE:
            msg_id = (as_int(p[0]) if command == mavlink.MAV_CMD_REQUEST_MESSAGE
                      else mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
            builder = telemetry.BUILDERS.get(msg_id)
            follow_up = builder(self) if builder else None
            if self.is_ardupilot:
                # GCS_Common.cpp handle_command_request_message: FAILED for an id with no ap_message, else
                # ACCEPTED and send_message(), which sends nothing when there is nothing to report (no battery
                # monitor, no home yet)
                result = ACCEPTED if builder else FAILED
            else:
                # mavlink_receiver.cpp handle_request_message_command: ACCEPTED only if the stream sent it
                result = ACCEPTED if follow_up is not None else DENIED
        elif command == mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN:
            result = self.reboot_request(p[0])
        elif command == mavlink.MAV_CMD_GET_HOME_POSITION and self.is_ardupilot:
            # GCS_MAVLINK::handle_command_get_home_position: FAILED until home is set, else the message
            follow_up = telemetry.known_home_position(self)
            result = ACCEPTED if follow_up is not None else FAILED
        else:
            result = self.autopilot.handle_command(command, p, now, self.state, msg.get_srcComponent(), frame)
        endpoint.send(mavlink.MAVLink_command_ack_message(command, result, 0, 0, msg.get_srcSystem(),
                                                          msg.get_srcComponent()))
        if follow_up is not None:  # the spec: ACK first, then the requested message
            endpoint.send(follow_up)
        if command not in (mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL) or result != ACCEPTED:
            self.log(f"command {_command_name(command)} from {msg.get_srcSystem()}/{msg.get_srcComponent()}: "
                     f"{_result_name(result)}")

    def reboot_request(self, what: float) -> int:
        """MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN's result for the autopilot (param1 ``what``); an accepted reboot
        starts a moment after the ACK went out. PX4 (Commander.cpp): 0 does nothing, 1 reboots unless armed, else
        DENIED; the reboot follows after 400 ms (px4_reboot_request). ArduPilot (GCS_Common.cpp
        handle_preflight_reboot): only 1 and 3 (to the bootloader) are known, FAILED while armed, the reboot 200 ms
        after the ACK."""
        code = int(what) if math.isfinite(what) else -1
        if self.is_ardupilot:
            if code not in (1, 3):
                return mavlink.MAV_RESULT_UNSUPPORTED
            if self.autopilot.armed:
                return mavlink.MAV_RESULT_FAILED
            delay_s = 0.2
        else:
            if code == 0:
                return mavlink.MAV_RESULT_ACCEPTED
            if code != 1 or self.autopilot.armed:
                return mavlink.MAV_RESULT_DENIED
            delay_s = 0.4
        self._reboot_tick = self.tick + max(1, int(round(delay_s / self.dt_s)))
        return mavlink.MAV_RESULT_ACCEPTED

    def _on_request_data_stream(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        """GCS_MAVLINK::handle_request_data_stream: start_stop 1 streams the group at req_message_rate, 0 stops it;
        MAV_DATA_STREAM_ALL sets every group. The link's SRn_ parameters take the rates. No ACK."""
        if not self._for_us(msg) or msg.start_stop not in (0, 1):
            return
        rate = float(msg.req_message_rate) if msg.start_stop == 1 else 0.0
        if msg.req_stream_id == mavlink.MAV_DATA_STREAM_ALL:
            groups = STREAM_GROUPS
        elif msg.req_stream_id in DATA_STREAM_GROUPS:
            groups = (DATA_STREAM_GROUPS[msg.req_stream_id],)
        else:
            return  # a stream of messages this vehicle does not build
        for group in groups:
            name = f"SR{endpoint.index}_{group}"
            if name in self.params.specs:
                self.params.set(name, min(rate, self.params.specs[name].maximum))
            endpoint.set_stream_rate(ARDUPILOT_STREAM_MESSAGES[group], rate, self.time_s)
        self.log(f"REQUEST_DATA_STREAM on link {endpoint.index}: {', '.join(groups)} at {rate:g} Hz")

    def _on_setpoint(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        if not self._for_us(msg):
            return
        self.autopilot.handle_setpoint(self.time_s, self.state, msg.coordinate_frame, msg.type_mask,
                                       (msg.x, msg.y, msg.z), (msg.vx, msg.vy, msg.vz), msg.yaw, msg.yaw_rate)

    def _on_global_setpoint(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        if not self._for_us(msg):
            return
        self.autopilot.handle_global_setpoint(self.time_s, self.state, msg.coordinate_frame, msg.type_mask,
                                              (msg.lat_int, msg.lon_int, msg.alt), (msg.vx, msg.vy, msg.vz),
                                              msg.yaw, msg.yaw_rate)

    def _on_set_mode(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        """The legacy SET_MODE message: PX4 sends no ACK, ArduPilot a COMMAND_ACK with command 11."""
        if msg.target_system != self.system_id:
            return
        result = self.autopilot.handle_set_mode_message(msg.base_mode, msg.custom_mode, self.time_s, self.state)
        if result is not None:
            endpoint.send(mavlink.MAVLink_command_ack_message(mavlink.MAVLINK_MSG_ID_SET_MODE, result, 0, 0,
                                                              msg.get_srcSystem(), msg.get_srcComponent()))

    def _on_heartbeat(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        self.autopilot.on_heartbeat(msg.get_srcSystem(), self.time_s)

    # ------------------------------------------------------------------ parameters
    def _param_value(self, name: str) -> mavlink.MAVLink_message:
        spec = self.params.specs[name]
        value = encode_bytewise(self.params[name], spec.kind) if self.autopilot.PARAMS_BYTEWISE else self.params[name]
        return mavlink.MAVLink_param_value_message(name.encode(), value, spec.kind, len(self.params),
                                                   self.params.index(name))

    def _on_param_request_list(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        if self._for_us(msg):
            for name in self.params.names:
                endpoint.send(self._param_value(name))

    def _on_param_request_read(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        if not self._for_us(msg):
            return
        if msg.param_index >= 0:
            if msg.param_index < len(self.params):
                endpoint.send(self._param_value(self.params.names[msg.param_index]))
        elif self.params.visible(_param_name(msg.param_id)):  # unknown or hidden: no answer, as ArduPilot and PX4
            endpoint.send(self._param_value(_param_name(msg.param_id)))

    def _on_param_set(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        if not self._for_us(msg):
            return
        name = _param_name(msg.param_id)
        spec = self.params.specs.get(name)
        if not self.params.visible(name):
            self.log(f"PARAM_SET {name!r}: " + ("unknown parameter" if spec is None else
                                                f"hidden while {spec.enabled_by} is 0") + ", ignored")
            return
        decode = decode_bytewise if self.autopilot.PARAMS_BYTEWISE else decode_float
        error = self.params.set(name, decode(msg.param_value, spec.kind))
        self.log(f"PARAM_SET {name} = {self.params[name]:g}" + (f" refused: {error}" if error else ""))
        # Echo the (possibly unchanged) value on every link, as PX4 and ArduPilot do, so all clients stay in sync.
        self.broadcast(self._param_value(name))

    # ------------------------------------------------------------------ small protocol services
    def _on_timesync(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        if msg.tc1 == 0:  # a request: answer with our time since boot in ns
            # The target fields stay 0, as both autopilots leave them (PX4 mavlink_timesync.cpp and ArduPilot
            # GCS_Common.cpp handle_timesync fill tc1 and ts1 only).
            endpoint.send(mavlink.MAVLink_timesync_message(int(self.time_since_boot_s * 1e9), msg.ts1))

    def _on_mission_item(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        """ArduPilot: an item of a mission, fence or rally upload, or a guided-mode waypoint (current 2 or 3),
        answered with MISSION_ACK."""
        if not self._for_us(msg):
            return
        if self.copter_transfers is not None and self.copter_transfers.on_item(endpoint, msg, self.time_s):
            return
        if msg.get_type() == "MISSION_ITEM":  # floats in degrees: ArduPilot converts them to the _INT form
            # (a NaN or infinite one fails check_lat / check_lng: out of range here too)
            lat_int, lon_int = (int(round(v * 1e7)) if math.isfinite(v) else 2**31 for v in (msg.x, msg.y))
        else:
            lat_int, lon_int = msg.x, msg.y
        result = self.autopilot.handle_mission_item(msg.current, msg.command, msg.frame, lat_int, lon_int, msg.z,
                                                    self.time_s, self.state)
        endpoint.send(mavlink.MAVLink_mission_ack_message(msg.get_srcSystem(), msg.get_srcComponent(), result,
                                                          msg.mission_type))

    def _on_setup_signing(self, endpoint: Endpoint, msg: mavlink.MAVLink_message) -> None:
        # No ACK in the protocol: the sender learns the outcome from whether our next frames verify.
        if not self._for_us(msg):
            return
        if self.autopilot.armed:  # a key change in flight could cut the link to the pilot
            self.setup_signing_refused += 1
            self.log("SETUP_SIGNING refused: the vehicle is armed")
            return
        key = requested_key(msg)
        if key is None:
            self.signing = None
            for other in self.endpoints:
                other.mav.signing = mavlink.MAVLinkSigning()
            self.log("SETUP_SIGNING: signing switched off (all-zero key)")
        elif self.signing is None:
            self._enable_signing(key)
            self.log("SETUP_SIGNING: signing switched on with the new key")
        else:
            self.signing.replace_key(key, msg.initial_timestamp)
            self.log("SETUP_SIGNING: new key installed")


def _param_name(raw: str | bytes) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", errors="replace")
    return raw.split("\x00", 1)[0]


def _command_name(command: int) -> str:
    entry = mavlink.enums["MAV_CMD"].get(command)
    return entry.name.removeprefix("MAV_CMD_") if entry else str(command)


def _result_name(result: int) -> str:
    return mavlink.enums["MAV_RESULT"][result].name.removeprefix("MAV_RESULT_")
