"""The mission runner's settings: timing, limits, failsafe thresholds, link-loss and home checks."""
from __future__ import annotations

from dataclasses import dataclass, field

from autonomy.link_loss import LinkLossConfig
from autonomy.setpoints import StreamConfig
from autonomy.vehicle_time import BootTimeConfig
from missions.validation import check_fields


@dataclass(frozen=True)
class RunnerConfig:
    """Timing, limits and failsafe thresholds of the runner."""

    stream: StreamConfig = field(default_factory=StreamConfig)
    """The setpoint stream (rate, stale timeout, clamps); its horizontal clamp is set from the mission."""
    offboard_lead_s: float = 1.2
    """Setpoints streamed before OFFBOARD/GUIDED is requested. PX4 accepts the switch as soon as one setpoint is
    recent; a second of stream first is good practice (the vehicle holds the first setpoint it gets)."""
    connect_timeout_s: float = 15.0
    """Wait for the vehicle's first HEARTBEAT."""
    preflight_timeout_s: float = 30.0
    """Wait for a converged pose estimate and a home position."""
    takeoff_timeout_s: float = 60.0
    """Wait for the climb to the search altitude."""
    land_timeout_s: float = 600.0
    """Wait for the return, landing and disarm."""
    command_timeout_s: float = 1.5
    """Wait for one COMMAND_ACK before sending the command again."""
    command_retries: int = 5
    """Attempts per command before the runner gives up on it (5: on a link losing 30 % each way, an attempt and its
    answer both get through about half the time, so three attempts all fail one time in eight, five one in 32)."""
    telemetry_timeout_s: float = 3.0
    """No vehicle message for this long = telemetry lost (failsafe; during SEARCH with ``link_loss.resume``, the
    runner holds and waits ``link_loss.wait_s`` for it first)."""
    link_loss: LinkLossConfig = field(default_factory=LinkLossConfig)
    """What a link outage during SEARCH does (autonomy.link_loss): hold, wait, and resume after the vehicle's own
    link-loss failsafe (default on)."""
    link_recovery_s: float = 60.0
    """The return command (RTL) is re-sent (every ``command_timeout_s``) for this long before the runner gives up:
    after a telemetry loss or on a lossy link, a link that comes back within it still brings the vehicle home
    (PX4 has no data-link-loss action by default)."""
    policy_stall_rtl_s: float = 5.0
    """No fresh policy decision for this long = policy stalled (failsafe: RTL)."""
    failsafe_hold_s: float = 1.0
    """After a non-finite action, zero velocity is streamed this long before RTL is requested."""
    low_battery_pct: float = 20.0
    """Battery remaining at or below this = return (failsafe: RTL)."""
    fence_margin_m: float = 20.0
    """The guard keeps the drone this far inside the geofence."""
    fence_lookahead_s: float = 2.0
    """The guard turns back when the commanded velocity would cross the margin within this time."""
    altitude_gain: float = 0.5
    """Vertical velocity per metre of altitude error (holds the search altitude above the vehicle's home)."""
    home_tolerance_m: float = 50.0
    """Largest horizontal distance between the mission's launch point and the vehicle's home (HOME_POSITION);
    farther, and the mission is refused before arming (GPS homes agree within a few metres)."""
    boot_time: BootTimeConfig = field(default_factory=BootTimeConfig)
    """How the vehicle's time_boot_ms is mapped onto the runner's clock (autonomy.vehicle_time)."""
    param_timeout_s: float = 5.0
    """Wait for the autopilot's fence parameters (asked for at CONNECT) once the pose has converged; unread, the
    autopilot's fence is not checked (a warning)."""
    home_altitude_tolerance_m: float = 15.0
    """Largest difference between the mission's home altitude (when the file gives it) and the vehicle's home
    altitude, AMSL; more, and the mission is refused before arming (GPS altitude errs by a few metres)."""

    def __post_init__(self) -> None:
        check_fields(self, (("offboard_lead_s", 1.0, 10.0), ("connect_timeout_s", 0.1, 600.0),
                            ("preflight_timeout_s", 0.1, 600.0), ("takeoff_timeout_s", 1.0, 600.0),
                            ("land_timeout_s", 1.0, 3600.0), ("command_timeout_s", 0.05, 30.0),
                            ("command_retries", 1, 20), ("telemetry_timeout_s", 0.5, 60.0),
                            ("link_recovery_s", 0.0, 3600.0),
                            ("policy_stall_rtl_s", 0.5, 120.0), ("failsafe_hold_s", 0.0, 30.0),
                            ("low_battery_pct", 0.0, 100.0),
                            ("fence_margin_m", 0.0, 500.0), ("fence_lookahead_s", 0.0, 30.0),
                            ("altitude_gain", 0.01, 5.0), ("home_tolerance_m", 0.0, 10_000.0),
                            ("home_altitude_tolerance_m", 0.0, 10_000.0), ("param_timeout_s", 0.1, 120.0)),
                     integers=("command_retries",))
