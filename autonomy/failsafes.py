"""What ends, pauses or resumes a search, judged every control tick from what the vehicle has said.

A search pauses (holds position, no decisions) while the runner cannot see where the drone is
(``blind_reason``). It ends or resumes on the first of these that applies (``judge_search``), in
order (the first that applies wins):

1. **telemetry lost**: no message for ``telemetry_timeout_s``. With link-loss resumption on, the runner first waits
   up to ``link_loss.wait_s`` for it to come back (``wait``); after that, or without resumption, the search ends.
2. while the link is down (a silence of ``link_loss.gap_s``) nothing else is judged: the checks below need it up.
3. **disarmed** in flight: a reboot or a crash; there is nothing to resume or to bring home.
4. **policy stalled**: no decision applied for ``policy_stall_rtl_s``.
5. **low battery**: at or below ``low_battery_pct``.
6. **the vehicle left the companion mode** (OFFBOARD / GUIDED): the autopilot's own safety failsafe (its geofence,
   the battery: announced; or the drone at the autopilot's acting fence, ``autopilot_fence.fence_reached``) ends
   the search; a switch into one of its failsafe modes is held for
   ``link_loss.settle_s`` first (``wait``: a safety text may come just after it); the vehicle's own link-loss
   failsafe then resumes it when
   ``autonomy.link_loss`` has the evidence and resumptions are left (``resume``); anything else is a pilot's
   decision (``end``).

The runner acts on the verdict (``autonomy.search_loop.SearchLoop._check_failsafes``): it records the event, ends
the search with ``search_end`` (then returns home), or resumes.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from autonomy.autopilot_fence import fence_reached
from autonomy.autopilots import LINK_LOSS_PARAM, AutopilotFlavour, link_loss_modes
from autonomy.estimator import PoseEstimator
from autonomy.link_loss import LinkLossMonitor
from autonomy.runner_config import RunnerConfig
from autonomy.vehicle_connection import VehicleConnection
from autonomy.vehicle_time import BootTimeMap


@dataclass(frozen=True)
class Verdict:
    """A reason to act, in words (``message``) for the mission's event log."""

    action: str
    """"wait" (telemetry lost, waiting for it), "end" (the search ends with ``search_end``) or "resume"."""
    message: str
    search_end: str | None = None
    mode: str | None = None
    """"resume": the mode the vehicle's failsafe switched it to; "wait": the mode being settled (None: waiting for
    telemetry)."""
    evidence: str | None = None
    """"resume": why that switch was the vehicle's own link-loss failsafe."""


def judge_search(now: float, link: VehicleConnection, config: RunnerConfig, flavour: AutopilotFlavour,
                 link_loss: LinkLossMonitor, boot_time: BootTimeMap, last_resumed_s: float,
                 from_home: Callable[[], tuple[float, float, float] | None] = lambda: None) -> Verdict | None:
    """The verdict on the search at ``now`` (None: carry on). ``link`` is the vehicle link (pymavlink or MAVSDK);
    ``last_resumed_s`` is when the search last had news of its policy (its last decision, the last transition, the
    link coming back); ``from_home()`` where the drone is from the vehicle's home (north, east, height; m), asked
    only when the vehicle left the companion mode."""
    last, waiting = link.last_vehicle_message_s, config.link_loss
    silent_s = now - last if last is not None else 0.0
    if silent_s > config.telemetry_timeout_s:
        if waiting.resume and silent_s <= waiting.wait_s:
            return Verdict("wait", f"telemetry lost for {silent_s:.1f} s: waiting up to {waiting.wait_s:g} s for it "
                                   "to come back")
        return Verdict("end", f"telemetry lost for {silent_s:.1f} s", "telemetry lost")
    if link_loss.link_down():
        return None
    mode, companion = link.flight_mode, flavour.companion_mode
    if not link.armed:
        rebooted = f" ({boot_time.last_change})" if boot_time.timeline_changes else ""
        return Verdict("end", f"the vehicle is disarmed{rebooted}", "vehicle disarmed")
    if now - last_resumed_s > config.policy_stall_rtl_s:
        return Verdict("end", f"no policy decision for {config.policy_stall_rtl_s:g} s: RTL", "policy stalled")
    battery = link.battery_percent()
    if battery is not None and battery <= config.low_battery_pct:
        return Verdict("end", f"battery at {battery:g} %: RTL", "low battery")
    if mode != companion:
        params = link.params
        link_loss.modes = link_loss_modes(flavour, params)
        safety = link_loss.safety_failsafe(now)
        where = from_home() if safety is None else None
        if where is not None:  # at the autopilot's fence: its failsafe, announced or not
            safety = fence_reached(flavour.name, params, *where)
        if safety is not None:
            link_loss.left_companion_s = None
            return Verdict("end", f"the vehicle left {companion} (now {mode}): the autopilot's own failsafe "
                                  f"({safety!r})", f"vehicle switched to {mode}")
        if link_loss.settling(now, mode):
            return Verdict("wait", f"the vehicle left {companion} (now {mode}): holding {waiting.settle_s:g} s for "
                                   "what the autopilot says before judging it", mode=mode)
        link_loss.left_companion_s = None
        evidence = link_loss.failsafe_evidence(now, mode)
        if evidence is not None and link_loss.may_resume():
            return Verdict("resume", "", mode=mode, evidence=evidence)
        used_up = f"; {evidence}, but no resumption is left" if evidence is not None else ""
        if mode in flavour.failsafe_modes and mode not in link_loss.modes:
            name = LINK_LOSS_PARAM[flavour.name]
            used_up = f"; not its link-loss failsafe ({name} {params[name]:g} does not switch to {mode})"
        return Verdict("end", f"the vehicle left {companion} (now {mode}){used_up}", f"vehicle switched to {mode}")
    # In the companion mode (again: PX4 returns to OFFBOARD by itself once setpoints flow again): carry on.
    link_loss.left_companion_s = None
    return None


def blind_reason(now: float, link_loss: LinkLossMonitor, estimator: PoseEstimator, gap_s: float) -> str | None:
    """Why the runner cannot see where the drone is now (None when it can): no telemetry for ``gap_s``, or no
    position fused for longer than the estimator trusts (a policy or the fence guard must not act on a pose
    extrapolated over a gap, as after an autopilot reboot)."""
    if link_loss.link_down():
        return f"no telemetry for {gap_s:g} s"
    if link_loss.left_companion_s is not None:
        return "the vehicle left the companion mode"
    pose = estimator.predict_to(now)
    return f"no position fused for {pose.age_s:.1f} s" if pose.stale else None
