"""A search survives a short link loss: telling the vehicle's own link-loss failsafe from a pilot taking over.

When the radio drops out during SEARCH, the autopilot acts on its own: PX4 leaves OFFBOARD after COM_OF_LOSS_T
without a setpoint (for POSCTL, HOLD, RTL or LAND: COM_OBL_RC_ACT), ArduPilot stops after GUID_TIMEOUT (staying in
GUIDED) and, with its GCS failsafe on, switches to RTL or LAND. Ending the search there throws away a search that a
2 s outage interrupted. A pilot switching modes, on the other hand, has taken the vehicle and the search must end.

:class:`LinkLossMonitor` keeps the evidence the runner needs to tell the two apart:

* **silences**: every stretch of at least ``gap_s`` without a message from the vehicle (the runner's side of an
  outage, which is also when its setpoints were most likely lost);
* **deaf stretches**: the vehicle stopped answering the runner's TIMESYNC requests while its telemetry still
  flowed (:mod:`autonomy.uplink_probe`): an uplink-only outage, which shows no silence on our side;
* **failsafe announcements**: STATUSTEXTs matching the autopilot's own link-loss wording (ArduPilot's "GCS
  Failsafe"; PX4 >= 1.14 names no cause in STATUSTEXT, only "Failsafe activated");
* **safety announcements**: STATUSTEXTs of the autopilot's other failsafes (its geofence, the battery, the
  estimator). A mode change they explain is the autopilot keeping the drone safe: never resumed over, whatever
  silence there was.

A mode change out of the companion mode into one of the autopilot's failsafe modes counts as the vehicle's own
link-loss failsafe when a silence, a deaf stretch or an announcement falls within ``evidence_window_s`` before the
change was seen, and no safety announcement does, including one that comes up to ``settle_s`` after the change (PX4
reports health changes, the geofence among them, at most every 2 s: ``Report::report``). Then the
runner may resume (stream again, request OFFBOARD/GUIDED again, carry on from the same search state), at most
``max_resumptions`` times. Anything else (another mode, no evidence) is a pilot's decision: the search ends.

Limitation, stated where it matters (docs/runner.md): a pilot who switches modes during a link outage cannot be told
from the failsafe by the companion computer; the autopilot's RC override (PX4's COM_RC_OVERRIDE, ArduPilot's mode
switch) still wins, because the pilot's next stick or switch input takes the vehicle again.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from autonomy.autopilots import AutopilotFlavour
from autonomy.uplink_probe import UplinkProbe, UplinkProbeConfig
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
    settle_s: float = 2.5
    """A mode change out of the companion mode is judged this long after it was seen (the drone holds meanwhile),
    so that a safety announcement sent just after it still vetoes a resumption."""
    probe: UplinkProbeConfig = field(default_factory=UplinkProbeConfig)
    """The TIMESYNC probe of the uplink (both backends)."""

    def __post_init__(self) -> None:
        check_fields(self, (("max_resumptions", 0, 100), ("gap_s", 0.1, 60.0), ("evidence_window_s", 1.0, 600.0),
                            ("wait_s", 0.5, 3600.0), ("settle_s", 0.0, 30.0)), integers=("max_resumptions",))


@dataclass(frozen=True)
class Silence:
    """A stretch without vehicle messages, in runner time."""

    start_s: float
    end_s: float | None  # None while it lasts


class LinkLossMonitor:
    """Records silences and failsafe announcements; see the module docstring."""

    def __init__(self, config: LinkLossConfig, flavour: AutopilotFlavour,
                 send_probe: Callable[[int], None] | None = None):
        """``send_probe(ts1)`` sends a TIMESYNC request (None: the link cannot, and deaf stretches are not seen)."""
        self.config, self.flavour = config, flavour
        self.probe = UplinkProbe(config.probe, send_probe) if send_probe is not None else None
        self.deaf: list[Silence] = []
        """Stretches in which the vehicle did not answer (its uplink was lost), in runner time."""
        self.silences: list[Silence] = []
        self.announcements: list[tuple[float, str]] = []
        self.safety_announcements: list[tuple[float, str]] = []
        self.resumptions = 0
        self.modes = flavour.failsafe_modes
        """The modes this vehicle's link-loss failsafe may switch to (autopilots.link_loss_modes, from its
        parameters; the judge keeps it current)."""
        self.left_companion_s: float | None = None
        """When the runner saw the vehicle leave the companion mode, while that switch is being settled."""

    def observe(self, now_s: float, last_message_s: float | None, new_texts: list[tuple[float, str]],
                probe_replies: list[int] = (), probing: bool = False) -> None:
        """Call every tick with the time of the vehicle's last message, the STATUSTEXTs and the ts1 of the TIMESYNC
        replies received since, and whether the uplink is to be probed now (the companion flies the vehicle)."""
        if self.probe is not None:
            self.probe.tick(now_s, list(probe_replies), probing)
            self._observe_deafness(now_s, last_message_s)
        for time_s, text in new_texts:
            if self.flavour.failsafe_text is not None and self.flavour.failsafe_text.search(text.lower()):
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

    def _observe_deafness(self, now_s: float, last_message_s: float | None) -> None:
        ongoing = self.deaf[-1] if self.deaf and self.deaf[-1].end_s is None else None
        for start, end in self.probe.take_ended():
            if ongoing is not None:
                self.deaf[-1] = ongoing = Silence(ongoing.start_s, end)
            else:
                self.deaf.append(Silence(start, end))
        since = self.probe.unanswered_since(now_s)
        hearing = last_message_s is not None and now_s - last_message_s < self.config.gap_s
        ongoing = self.deaf[-1] if self.deaf and self.deaf[-1].end_s is None else None
        if since is not None and hearing and ongoing is None:
            self.deaf.append(Silence(since, None))

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
        if mode not in self.modes or self.safety_failsafe(now_s) is not None:
            return None
        since = now_s - self.config.evidence_window_s
        texts = [text for time_s, text in self.announcements if time_s >= since]
        if texts:
            return f"the vehicle announced it: {texts[-1]!r}"
        for stretches, what in ((self.silences, "the link was lost"),
                                (self.deaf, "the vehicle stopped answering the runner (its uplink was lost)")):
            recent = [s for s in stretches if (s.end_s if s.end_s is not None else now_s) >= since]
            if recent:
                gap = recent[-1]
                length = (gap.end_s if gap.end_s is not None else now_s) - gap.start_s
                return f"{what} for {length:.1f} s from {gap.start_s:.1f} s"
        return None

    def settling(self, now_s: float, mode: str | None) -> bool:
        """Whether a switch to ``mode`` (a failsafe mode, a resumption left) is still within ``settle_s`` of when
        it was first seen; the first call starts the clock. The caller clears ``left_companion_s`` when it
        judges the switch."""
        if mode not in self.modes or not self.may_resume():
            return False
        if self.left_companion_s is None:
            self.left_companion_s = now_s
        return now_s - self.left_companion_s < self.config.settle_s

    def may_resume(self) -> bool:
        return self.config.resume and self.resumptions < self.config.max_resumptions
