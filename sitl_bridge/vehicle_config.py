"""What defines one simulated vehicle: :class:`VehicleConfig` (home, physics rate, airframe, wind, sensors,
parameters, telemetry, signing, autopilot personality, boot and reboot times)."""
from __future__ import annotations

from dataclasses import dataclass, field

from mavlink_signing import KEY_BYTES
from missions.geodesy import GeoPoint
from missions.validation import check_fields, check_number
from sitl_bridge.multirotor import MultirotorParams
from sitl_bridge.sensors import SensorConfig
from sitl_bridge.telemetry_profiles import PROFILES
from sitl_bridge.wind import Wind

DEFAULT_HOME = GeoPoint(47.397742, 8.545594, 488.0)  # PX4 SITL's default home (Zurich)
AUTOPILOT_TYPES = ("px4", "ardupilot")


@dataclass(frozen=True)
class VehicleConfig:
    """Everything that defines one simulated vehicle; the same config and seed give the same flight."""

    home: GeoPoint = DEFAULT_HOME
    """Geodetic home: the local NED origin, where the vehicle starts on the ground."""
    physics_rate_hz: float = 100.0
    """Physics ticks per simulated second (>= 100)."""
    seed: int = 0
    """Seeds the sensor noise (the only randomness in the vehicle)."""
    system_id: int = 1
    """MAVLink system id of the vehicle (component id is always 1, the autopilot)."""
    airframe: MultirotorParams = field(default_factory=MultirotorParams)
    """Physical limits, time constants and battery of the multirotor."""
    wind: Wind = field(default_factory=Wind)
    """Steady wind and gusts."""
    sensors: SensorConfig = field(default_factory=SensorConfig)
    """GPS, barometer and attitude noise."""
    params: dict[str, float] = field(default_factory=dict)
    """Parameter overrides by name, of the chosen autopilot (PX4: sitl_bridge.params.PARAM_SPECS, ArduPilot:
    sitl_bridge.ardupilot.params.ARDUPILOT_PARAM_SPECS)."""
    telemetry_rates_hz: dict[int, float] = field(default_factory=dict)
    """Overrides of the profile's stream rates by message id, on every link (0 disables a stream)."""
    signing_key: bytes | None = field(default=None, repr=False)
    """MAVLink 2 signing secret (32 bytes, see mavlink_signing.load_key_file); None: no signing."""
    autopilot: str = "px4"
    """The autopilot personality: "px4" (PX4 custom modes, OFFBOARD) or "ardupilot" (ArduCopter modes, GUIDED)."""
    telemetry_profile: str = "default"
    """Default stream rates (sitl_bridge.telemetry_profiles): "default" ("legacy" for PX4, "ardupilot" for
    ArduPilot), "legacy" (this simulator's historic rates; replays stay byte-identical), "px4" (PX4's onboard mode
    on API links, normal mode on the GCS link), "px4_sitl" (as px4 SITL starts them) or "ardupilot" (SRn_* = 0:
    only HEARTBEAT until a client asks for streams)."""
    boot_time_s: float = 0.0
    """The autopilot booted this long before the simulation starts (s, [0, 1e7]; rounded to the physics tick):
    time_boot_ms, TIMESYNC and the other boot-relative times start there, e.g. 600 for an autopilot up 10 minutes."""
    reboot_at_s: float | None = None
    """Simulated time (s, [0, 1e7]) at which the autopilot reboots; None: never."""
    reboot_downtime_s: float = 5.0
    """How long a reboot keeps the autopilot silent, motors off (s, [0.1, 600]); it then boots afresh."""

    def __post_init__(self) -> None:
        check_fields(self, (("physics_rate_hz", 100.0, 2000.0), ("system_id", 1, 250), ("boot_time_s", 0.0, 1e7),
                            ("reboot_downtime_s", 0.1, 600.0)), integers=("system_id",))
        if self.signing_key is not None and len(self.signing_key) != KEY_BYTES:
            raise ValueError(f"signing_key must be {KEY_BYTES} bytes, got {len(self.signing_key)}; "
                             "load it with mavlink_signing.load_key_file")
        if self.autopilot not in AUTOPILOT_TYPES:
            raise ValueError(f"VehicleConfig.autopilot must be one of {', '.join(AUTOPILOT_TYPES)}, "
                             f"got {self.autopilot!r}")
        if self.telemetry_profile not in PROFILES:
            raise ValueError(f"VehicleConfig.telemetry_profile must be one of {', '.join(PROFILES)}, "
                             f"got {self.telemetry_profile!r}")
        if self.reboot_at_s is not None:
            check_number(type(self).__name__, "reboot_at_s", self.reboot_at_s, 0.0, 1e7)
