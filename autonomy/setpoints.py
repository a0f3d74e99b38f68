"""The setpoint stream: the latest velocity command, re-sent at a fixed rate from its own schedule.

PX4 and ArduPilot fly OFFBOARD / GUIDED velocity control only while setpoints keep arriving (PX4 leaves
OFFBOARD when none arrived for COM_OF_LOSS_T, 1 s by default, and refuses to enter it without a stream).
A policy decides once per step (1 s); the stream therefore re-sends the latest decision at ``rate_hz``
(20 Hz by default), independent of how long a decision takes:

* :meth:`SetpointStreamer.command` stores a new decision (clamped to the limits) with the time it was made;
* :meth:`SetpointStreamer.tick` is called by the runner's loop every tick and sends when a period is due, so a
  slow policy never pauses the stream (the policy runs elsewhere: a worker thread in real time, a simulated
  latency in lockstep);
* a decision older than ``stale_after_s`` is replaced by zero velocity (hover in place) until a fresh one
  arrives: the drone must not keep flying the last command of a stalled policy.

Each message is SET_POSITION_TARGET_LOCAL_NED in MAV_FRAME_LOCAL_NED with the velocity-only type mask 3527,
addressed to the vehicle's system and autopilot component.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from pymavlink.dialects.v20 import common as mavlink

from missions.validation import check_fields

VELOCITY_ONLY_TYPE_MASK = 3527
"""SET_POSITION_TARGET_LOCAL_NED.type_mask: ignore position, acceleration, yaw and yaw rate; use vx, vy, vz."""


@dataclass(frozen=True)
class StreamConfig:
    """How the stream runs and what it may command."""

    rate_hz: float = 20.0
    """Setpoints per second (PX4 wants > 2 Hz; 20-50 Hz is usual for companion computers)."""
    stale_after_s: float = 2.5
    """A decision older than this is replaced by zero velocity (a policy step is 1 s; 2.5 s = two missed)."""
    max_horizontal_mps: float = 10.0
    """Clamp of the horizontal speed (the mission's max_speed_mps)."""
    max_vertical_mps: float = 2.0
    """Clamp of the vertical speed (altitude hold corrections)."""

    def __post_init__(self) -> None:
        check_fields(self, (("rate_hz", 2.5, 100.0), ("stale_after_s", 0.1, 60.0),
                            ("max_horizontal_mps", 0.1, 30.0), ("max_vertical_mps", 0.1, 10.0)))


@dataclass(frozen=True)
class VelocityCommand:
    """North, east, down velocity (m/s) in the local NED frame."""

    vn: float = 0.0
    ve: float = 0.0
    vd: float = 0.0


HOLD = VelocityCommand()


class SetpointStreamer:
    """Re-sends the latest velocity command at a fixed rate; see the module docstring."""

    def __init__(self, config: StreamConfig, send: Callable[[VelocityCommand, float], None]):
        """``send(command, now_s)`` puts one SET_POSITION_TARGET_LOCAL_NED on the link."""
        self.config = config
        self._send = send
        self.shape: Callable[[VelocityCommand, float], VelocityCommand] | None = None
        """Changes each setpoint as it goes out (``shape(command, now_s)``, then clamped), except the hold of a
        stale decision: a fleet's separation shield, judged on the pose at the moment the setpoint is sent."""
        self.period_s = 1.0 / config.rate_hz
        self.running = False
        self.latest = HOLD
        self.latest_at_s = -math.inf
        self.next_send_s = 0.0
        self.sent = 0
        self.stale = False
        """True while the stream sends zero velocity because the latest decision is too old."""

    def start(self, now_s: float, command: VelocityCommand = HOLD) -> None:
        """Begin streaming ``command`` from the next tick on."""
        self.running = True
        self.command(command, now_s)
        self.next_send_s = -math.inf  # the first tick sends and anchors the schedule

    def stop(self) -> None:
        self.running = False

    def command(self, command: VelocityCommand, now_s: float) -> VelocityCommand:
        """A fresh decision: clamp it to the limits and stream it from now on; returns what will be sent."""
        self.latest = self.clamp(command)
        self.latest_at_s = now_s
        return self.latest

    def clamp(self, command: VelocityCommand) -> VelocityCommand:
        """Horizontal speed scaled down to its limit (direction kept), vertical clipped; NaN/inf -> hold."""
        values = (command.vn, command.ve, command.vd)
        if not all(math.isfinite(v) for v in values):
            return HOLD
        limit = self.config.max_horizontal_mps
        speed = math.hypot(command.vn, command.ve)
        scale = min(1.0, limit / speed) if speed > 0 else 1.0
        vd = min(max(command.vd, -self.config.max_vertical_mps), self.config.max_vertical_mps)
        return VelocityCommand(command.vn * scale, command.ve * scale, vd)

    def current(self, now_s: float) -> VelocityCommand:
        """What a setpoint sent now carries: the latest decision, or hold once it is stale."""
        self.stale = now_s - self.latest_at_s > self.config.stale_after_s
        return HOLD if self.stale else self.latest

    def tick(self, now_s: float) -> bool:
        """Send if a period is due; returns whether a setpoint went out. Call at least at ``rate_hz``."""
        if not self.running or now_s + 1e-9 < self.next_send_s:
            return False
        command = self.current(now_s)
        if self.shape is not None and not self.stale:
            command = self.clamp(self.shape(command, now_s))
        self._send(command, now_s)
        self.sent += 1
        # Next send one period after the scheduled one (not after now): the rate stays exact even when
        # ticks jitter; after a long stall (or at the first send), skip missed periods instead of a burst.
        self.next_send_s += self.period_s
        if self.next_send_s <= now_s:
            self.next_send_s = now_s + self.period_s
        return True


def setpoint_message_args(command: VelocityCommand, time_boot_ms: int, target_system: int,
                          target_component: int) -> tuple:
    """The arguments of ``mav.set_position_target_local_ned_send`` for a velocity-only setpoint."""
    return (time_boot_ms, target_system, target_component, mavlink.MAV_FRAME_LOCAL_NED, VELOCITY_ONLY_TYPE_MASK,
            0.0, 0.0, 0.0, command.vn, command.ve, command.vd, 0.0, 0.0, 0.0, 0.0, 0.0)
