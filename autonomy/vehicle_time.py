"""One time base for the runner: the vehicle's ``time_boot_ms`` mapped onto the runner's own clock.

Telemetry is stamped with the autopilot's time since boot; the runner decides, predicts and guards on its own clock
(which starts when the runner starts). The two differ by an offset that is unknown (the autopilot may have booted
minutes before the runner), drifts a little (two crystals) and jumps when the autopilot reboots (``time_boot_ms``
restarts near 0). Mixing them silently skips the Kalman prediction (vehicle time ahead of runner time) or
extrapolates the pose over the whole difference (vehicle time behind, after a reboot: 160 m at 8 m/s over 20 s).

:class:`BootTimeMap` estimates the offset from the messages themselves, as time-synchronisation schemes without a
request do (MAVLink's TIMESYNC exchange would give the same estimate with one more message type to trust):

* ``arrival - time_boot`` is the offset plus the link latency, which is never negative, so the smallest value seen
  is the best estimate. It may rise by at most ``drift_ppm`` (the vehicle's clock running slow), and falls at once
  when a message arrives faster;
* a message that arrives later than the estimate allows is just late: it keeps the estimate (and the estimator
  decides whether it is too old to fuse);
* ``time_boot_ms`` going back by more than ``reboot_backstep_s`` is a reboot (or the 49.7-day wrap), and a message
  stamped later than its arrival allows by more than ``jump_tolerance_s`` a jump of the vehicle's clock. Either
  starts a new timeline, adopted once ``confirm_messages`` messages in a row agree with it (one corrupted stamp must
  not move the clock); until then those messages are not used. Adopting one sets :attr:`timeline_changed`, so the
  runner can restart its estimator from the next message instead of connecting two unrelated timelines.

Lockstep replays run the same code: there the arrival time is the simulated clock, so the map is exact.
:func:`receive_telemetry` is the runner's whole receive path: messages in, positions fused on the runner's clock.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from missions.validation import check_fields

if TYPE_CHECKING:  # types only: the link and the estimator do not need this module
    from autonomy.estimator import PoseEstimator
    from autonomy.vehicle_connection import VehicleConnection


@dataclass(frozen=True)
class BootTimeConfig:
    """How the vehicle's boot time is mapped onto the runner's clock (see the module docstring)."""

    drift_ppm: float = 200.0
    """How fast the offset may grow (parts per million of elapsed time): crystals drift by tens of ppm."""
    jump_tolerance_s: float = 0.5
    """A stamp ahead of its arrival by more than this is a jump of the vehicle's clock, not less latency."""
    reboot_backstep_s: float = 3.0
    """``time_boot_ms`` going back by more than this is a reboot (smaller steps back are reordered messages)."""
    confirm_messages: int = 3
    """Messages in a row that must agree with a new timeline before it is adopted."""

    def __post_init__(self) -> None:
        check_fields(self, (("drift_ppm", 0.0, 10_000.0), ("jump_tolerance_s", 0.01, 60.0),
                            ("reboot_backstep_s", 0.1, 3600.0), ("confirm_messages", 1, 100)),
                     integers=("confirm_messages",))


class BootTimeMap:
    """Maps ``time_boot_ms`` of one vehicle onto the runner's clock; see the module docstring."""

    def __init__(self, config: BootTimeConfig = BootTimeConfig()):
        self.config = config
        self.offset_s: float | None = None
        """Runner time minus vehicle boot time (s), None before the first message."""
        self.timeline_changed = False
        """Set when a new timeline (reboot, clock jump) was adopted; the caller clears it."""
        self.timeline_changes = 0
        self.last_change = ""
        self.ignored = 0
        """Messages held back while a new timeline was being confirmed."""
        self._last_arrival_s = 0.0
        self._last_boot_s: float | None = None
        self._pending: tuple[float, int] | None = None  # (offset of a new timeline, messages agreeing with it)

    def to_runner_time(self, time_boot_ms: int, arrival_s: float) -> float | None:
        """The runner-clock time of a message stamped ``time_boot_ms`` that arrived at ``arrival_s``; None while
        the message belongs to a timeline that is not yet confirmed."""
        boot_s = time_boot_ms / 1000.0
        candidate = arrival_s - boot_s
        cfg = self.config
        if self.offset_s is None:
            self._adopt(candidate, arrival_s, boot_s, "")
            return boot_s + candidate
        rebooted = self._last_boot_s is not None and boot_s < self._last_boot_s - cfg.reboot_backstep_s
        jumped = candidate < self.offset_s - cfg.jump_tolerance_s
        if rebooted or jumped:
            return self._confirm(candidate, arrival_s, boot_s, "rebooted" if rebooted else "clock jumped")
        self._pending = None
        allowed = self.offset_s + cfg.drift_ppm * 1e-6 * max(0.0, arrival_s - self._last_arrival_s)
        self.offset_s = min(candidate, allowed)  # lower latency at once, a slow clock at most drift_ppm
        self._last_arrival_s = arrival_s
        self._last_boot_s = max(boot_s, self._last_boot_s)
        return boot_s + self.offset_s

    def _confirm(self, candidate: float, arrival_s: float, boot_s: float, why: str) -> float | None:
        tolerance = self.config.jump_tolerance_s
        if self._pending is not None and abs(candidate - self._pending[0]) <= tolerance:
            self._pending = (min(candidate, self._pending[0]), self._pending[1] + 1)
        else:
            self._pending = (candidate, 1)
        if self._pending[1] < self.config.confirm_messages:
            self.ignored += 1
            return None
        offset = self._pending[0]
        self._adopt(offset, arrival_s, boot_s,
                    f"vehicle {why}: time_boot_ms {self._last_boot_s:.1f} s -> {boot_s:.1f} s")
        return boot_s + offset

    def _adopt(self, offset: float, arrival_s: float, boot_s: float, reason: str) -> None:
        self.offset_s, self._last_arrival_s, self._last_boot_s, self._pending = offset, arrival_s, boot_s, None
        if reason:
            self.timeline_changed = True
            self.timeline_changes += 1
            self.last_change = reason


def receive_telemetry(link: VehicleConnection, estimator: PoseEstimator, boot_time: BootTimeMap) -> list:
    """Everything the vehicle sent since the last call, its positions fused into the estimator on the runner's clock
    (``boot_time`` maps their time_boot_ms; a new vehicle timeline restarts the filter). The runner's whole receive
    path: :mod:`tests.test_fuzz_mavlink` feeds it garbage."""
    messages = link.tick()
    now = link.clock()
    for msg in messages:
        if msg.get_type() == "GLOBAL_POSITION_INT":
            time_s = boot_time.to_runner_time(msg.time_boot_ms, now)
            if time_s is None:
                continue
            if boot_time.timeline_changed:
                boot_time.timeline_changed = False
                estimator.restart(boot_time.last_change)
            estimator.update_global_position_int(msg, time_s)
    return messages
