"""A search survives a short link loss: telling the vehicle's own link-loss failsafe from a pilot taking over.

When the radio drops out during SEARCH, the autopilot acts on its own: PX4 leaves OFFBOARD after COM_OF_LOSS_T
without a setpoint (for POSCTL, HOLD, RTL or LAND: COM_OBL_RC_ACT), ArduPilot stops after GUID_TIMEOUT (staying in
GUIDED) and, with its GCS failsafe on, switches to RTL or LAND. Ending the search there throws away a search that a
2 s outage interrupted. A pilot switching modes, on the other hand, has taken the vehicle and the search must end.

:class:`LinkLossMonitor` keeps the evidence the runner needs to tell the two apart:

* **silences**: every stretch of at least ``gap_s`` without a message from the vehicle (the runner's side of an
  outage, which is also when its setpoints were most likely lost);
* **failsafe announcements**: STATUSTEXTs matching the autopilot's own link-loss wording (an uplink-only outage
  shows no silence on our side, but the vehicle says what it did);
* **safety announcements**: STATUSTEXTs of the autopilot's other failsafes (its geofence, the battery, the
  estimator). A mode change they explain is the autopilot keeping the drone safe: never resumed over, whatever
  silence there was.

A mode change out of the companion mode into one of the autopilot's failsafe modes counts as the vehicle's own
link-loss failsafe when a silence or an announcement falls within ``evidence_window_s`` before the change was seen,
and no safety announcement does. Then the
runner may resume (stream again, request OFFBOARD/GUIDED again, carry on from the same search state), at most
``max_resumptions`` times. Anything else (another mode, no evidence) is a pilot's decision: the search ends.

Limitation, stated where it matters (docs/runner.md): a pilot who switches modes during a link outage cannot be told
from the failsafe by the companion computer; the autopilot's RC override (PX4's COM_RC_OVERRIDE, ArduPilot's mode
switch) still wins, because the pilot's next stick or switch input takes the vehicle again.
"""
from __future__ import annotations

from dataclasses import dataclass

from autonomy.autopilots import AutopilotFlavour
from missions.validation import check_fields


@dataclass(frozen=True)
class LinkLossConfig:
    """What the runner does when the link to the vehicle drops out during SEARCH."""

    resume: bool = True
    """Resume the search after the vehicle's own link-loss failsafe (False: any mode change ends it, as before)."""
    max_resumptions: int = 3
    """Resumptions per mission; one more failsafe after them ends the search (a link that keeps failing)."""
    gap_s: float = 1.0
    """A silence this long means the link is down: the stream holds (zero velocity) and decisions pause until
    telemetry is back (a policy must not fly on a pose it cannot see)."""
    evidence_window_s: float = 20.0
    """A silence or failsafe announcement at most this long before a mode change explains it."""
    wait_s: float = 60.0
    """With ``resume``, SEARCH waits this long for lost telemetry to come back before returning home."""

    def __post_init__(self) -> None:
        check_fields(self, (("max_resumptions", 0, 100), ("gap_s", 0.1, 60.0), ("evidence_window_s", 1.0, 600.0),
                            ("wait_s", 0.5, 3600.0)), integers=("max_resumptions",))


@dataclass(frozen=True)
class Silence:
    """A stretch without vehicle messages, in runner time."""

    start_s: float
    end_s: float | None  # None while it lasts


class LinkLossMonitor:
    """Records silences and failsafe announcements; see the module docstring."""

    def __init__(self, config: LinkLossConfig, flavour: AutopilotFlavour):
        self.config, self.flavour = config, flavour
        self.silences: list[Silence] = []
        self.announcements: list[tuple[float, str]] = []
        self.safety_announcements: list[tuple[float, str]] = []
        self.resumptions = 0

    def observe(self, now_s: float, last_message_s: float | None, new_texts: list[tuple[float, str]]) -> None:
        """Call every tick with the time of the vehicle's last message and the STATUSTEXTs received since."""
        for time_s, text in new_texts:
            if self.flavour.failsafe_text.search(text.lower()):
                self.announcements.append((time_s, text))
            if self.flavour.safety_text.search(text.lower()):
                self.safety_announcements.append((time_s, text))
        if last_message_s is None:
            return
        ongoing = self.silences[-1] if self.silences and self.silences[-1].end_s is None else None
        if now_s - last_message_s >= self.config.gap_s:
            if ongoing is None:
                self.silences.append(Silence(last_message_s, None))
        elif ongoing is not None:
            self.silences[-1] = Silence(ongoing.start_s, last_message_s)

    def link_down(self) -> bool:
        """Whether the vehicle is silent now (for at least ``gap_s``)."""
        return bool(self.silences) and self.silences[-1].end_s is None

    def safety_failsafe(self, now_s: float) -> str | None:
        """The latest safety announcement within the evidence window before ``now_s`` (None: none)."""
        since = now_s - self.config.evidence_window_s
        texts = [text for time_s, text in self.safety_announcements if time_s >= since]
        return texts[-1] if texts else None

    def failsafe_evidence(self, now_s: float, mode: str | None) -> str | None:
        """Why a switch to ``mode`` seen at ``now_s`` is the vehicle's own link-loss failsafe, in words; None when
        nothing says so (then it is a pilot's mode change) or a safety announcement explains it."""
        if mode not in self.flavour.failsafe_modes or self.safety_failsafe(now_s) is not None:
            return None
        since = now_s - self.config.evidence_window_s
        texts = [text for time_s, text in self.announcements if time_s >= since]
        if texts:
            return f"the vehicle announced it: {texts[-1]!r}"
        gaps = [s for s in self.silences if (s.end_s if s.end_s is not None else now_s) >= since]
        if gaps:
            gap = gaps[-1]
            length = (gap.end_s if gap.end_s is not None else now_s) - gap.start_s
            return f"the link was lost for {length:.1f} s from {gap.start_s:.1f} s"
        return None

    def may_resume(self) -> bool:
        return self.config.resume and self.resumptions < self.config.max_resumptions
