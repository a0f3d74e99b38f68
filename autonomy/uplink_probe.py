"""Does the vehicle still hear us? TIMESYNC requests as a probe of the uplink.

An outage of the uplink alone (the vehicle hears nothing from the companion computer, telemetry still flows) trips
the autopilot's offboard-loss failsafe, but the runner sees no silence, and a real PX4 >= 1.14 does not say in a
STATUSTEXT why it left OFFBOARD: ``FailsafeBase::notifyUser`` sends "Failsafe activated" for every failsafe, the
cause only as an event. So the runner asks the vehicle a question it always answers: a TIMESYNC request (tc1 = 0,
ts1 = our stamp), which PX4 (``MavlinkTimesync::handle_message``) and ArduPilot (``GCS_MAVLINK::handle_timesync``)
answer at once with tc1 = their clock and ts1 echoed. Requests that stay unanswered while telemetry flows mean
the vehicle stopped hearing us: positive evidence of an uplink outage (:mod:`autonomy.link_loss`).

A single lost request or reply is ordinary on a lossy radio, so only a stretch of at least ``min_stretch_s`` of
consecutive unanswered requests counts (five requests at the default 10 Hz: at 20 % loss each way a false stretch
starts with probability 0.36^5 = 0.6 %; at 2 % loss, 1e-7). The probe runs only while the companion computer flies
the vehicle (OFFBOARD and SEARCH), the only time the evidence is used.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Callable

from missions.validation import check_fields


@dataclass(frozen=True)
class UplinkProbeConfig:
    """How the runner probes the uplink (both backends: pymavlink, and MAVSDK through its MavlinkDirect plugin)."""

    period_s: float = 0.1
    """One request this often (the setpoint stream's rate: both travel the same uplink)."""
    reply_timeout_s: float = 0.5
    """A request not answered within this (s) was lost, one way or the other."""
    min_stretch_s: float = 0.5
    """Consecutive unanswered requests spanning at least this (s) mean the vehicle stopped hearing us."""

    def __post_init__(self) -> None:
        check_fields(self, (("period_s", 0.02, 5.0), ("reply_timeout_s", 0.05, 10.0), ("min_stretch_s", 0.0, 60.0)))


class UplinkProbe:
    """Sends the requests, matches the replies; :meth:`unanswered_since` says since when the vehicle is deaf."""

    def __init__(self, config: UplinkProbeConfig, send: Callable[[int], None]):
        self.config, self._send = config, send
        self._pending: deque[tuple[int, float]] = deque(maxlen=1000)  # (ts1, sent at), oldest first
        self._next_s = -math.inf
        self.sent = self.answered = 0
        self._ended: list[tuple[float, float]] = []  # deaf stretches an answer ended, not yet taken

    def tick(self, now_s: float, replies: list[int], active: bool) -> None:
        """Match ``replies`` (the ts1 of TIMESYNC replies received since the last tick), then send a request if
        one is due and ``active``."""
        for ts1 in replies:
            for index, (stamp, sent) in enumerate(self._pending):
                if stamp == ts1:  # answered: every request before it was lost (or its answer was)
                    first_lost = self._pending[0][1]
                    if index and sent - first_lost >= self.config.min_stretch_s + self.config.period_s - 1e-9:
                        self._ended.append((first_lost, sent))
                    for _ in range(index + 1):
                        self._pending.popleft()
                    self.answered += 1
                    break
        if not active:
            self._pending.clear()  # a pause is not an outage
            self._next_s = -math.inf
            return
        if now_s + 1e-9 >= self._next_s:
            stamp = int(round(now_s * 1e9)) + self.sent % 1000  # unique even if the clock stands still
            self._send(stamp)
            self._pending.append((stamp, now_s))
            self.sent += 1
            self._next_s = max(self._next_s + self.config.period_s, now_s)

    def take_ended(self) -> list[tuple[float, float]]:
        """The deaf stretches (first unanswered request's send time, first answered one's) that answers ended since
        the last call: an outage shorter than the reply timeout plus ``min_stretch_s`` shows only here."""
        ended, self._ended = self._ended, []
        return ended

    def unanswered_since(self, now_s: float) -> float | None:
        """When the oldest request still unanswered was sent, if the requests unanswered past the reply timeout
        span at least ``min_stretch_s``; None while the vehicle answers."""
        timeout = self.config.reply_timeout_s
        if not self._pending or now_s - self._pending[0][1] <= timeout:
            return None
        # requests go out in time order: the overdue ones are a prefix, and only the newest few are not overdue
        first = self._pending[0][1]
        last = next(sent for _, sent in reversed(self._pending) if now_s - sent > timeout)
        return first if last - first >= self.config.min_stretch_s - 1e-9 else None
