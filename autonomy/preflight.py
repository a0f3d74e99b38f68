"""Checks the runner makes before it arms: does the mission fit the vehicle it is about to fly?

* :func:`home_disagreement`: the mission's launch point (its scenario's start, at home's altitude) must lie where
  the vehicle's home is (HOME_POSITION), within a horizontal and a vertical tolerance. The search state, the
  geofence and the victim's drift are all in the mission's frame; a vehicle whose home is elsewhere would search
  the wrong water. The search altitude itself is always held relative to the vehicle's home (as the autopilot's
  own takeoff and RTL are), so a small vertical disagreement does no harm; a large one means the mission was
  written for another place (or left ``alt_m`` at a wrong value) and is refused rather than flown.
* :func:`flight_mismatches`: the mission's flight settings against the policy's training settings (the artifact's
  ``manifest.training_config["flight"]``). The action scale, the camera footprint, what one step and ``time_progress``
  mean all come from them; a policy flown with other settings is flown outside what it learned. ``hrlsac mission``
  refuses such a mission unless ``--accept-flight-mismatch`` is given (then it warns, naming each difference).
* :func:`judge_autopilot_settings`: the autopilot's parameters as read, judged: its own geofence against the
  mission (:mod:`autonomy.autopilot_fence`, a refusal if it would stop the search) and what it does if the companion
  computer goes silent (:mod:`autonomy.companion_loss`, a warning if it would hover until its battery is empty).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from autonomy.autopilot_fence import fence_params, judge_autopilot_fence
from autonomy.companion_loss import companion_loss_params, judge_companion_loss
from missions.geodesy import GeoPoint, LocalFrame
from missions.mission import FlightSettings, Mission


def describe_point(point: GeoPoint) -> str:
    """``47.397742, 8.545594, 488.0 m AMSL``: how positions are named in refusals."""
    return f"{point.lat_deg:.6f}, {point.lon_deg:.6f}, {point.alt_m:.1f} m AMSL"


def home_disagreement(mission: Mission, vehicle_home: GeoPoint, horizontal_tolerance_m: float,
                      vertical_tolerance_m: float) -> str | None:
    """Why ``mission`` must not be flown by a vehicle whose home is ``vehicle_home``, in one line; None if it fits.

    The vertical check needs the mission's home altitude; a mission file that leaves ``alt_m`` out is checked
    horizontally only (``Mission.home_altitude_known``).
    """
    launch = mission.launch_point
    north, east, _ = LocalFrame(vehicle_home).to_ned(launch.lat_deg, launch.lon_deg, vehicle_home.alt_m)
    horizontal_m = math.hypot(north, east)
    vertical_m = launch.alt_m - vehicle_home.alt_m if mission.home_altitude_known else 0.0
    if horizontal_m <= horizontal_tolerance_m and abs(vertical_m) <= vertical_tolerance_m:
        return None
    launch_text = describe_point(launch) if mission.home_altitude_known else \
        describe_point(launch).replace(" m AMSL", " m AMSL (alt_m not given)")
    return (f"the mission's launch point {launch_text} is {horizontal_m:.0f} m from the vehicle's home "
            f"{describe_point(vehicle_home)} horizontally and {abs(vertical_m):.1f} m vertically (tolerance "
            f"{horizontal_tolerance_m:g} m and {vertical_tolerance_m:g} m): correct the mission's scenario.home "
            "and start, or fly it from its own launch point")


CHECKED_FLIGHT_FIELDS = ("altitude_m", "max_speed_mps", "step_period_s", "subgoal_interval", "max_steps")
"""The flight settings a policy's inputs and outputs depend on: the camera footprint (altitude), the action scale
(speed), what one step is (step period), the meta-controller's cadence (K) and ``time_progress`` (max_steps)."""


def flight_mismatches(flight: FlightSettings, training_config: dict) -> list[str]:
    """The checked flight settings in which a mission differs from the policy's training, one ``name: mission X,
    trained Y`` each; empty when they agree or the artifact does not record its training flight settings."""
    trained = training_config.get("flight")
    if not isinstance(trained, dict):
        return []
    differences = []
    for name in CHECKED_FLIGHT_FIELDS:
        ours, theirs = getattr(flight, name), trained.get(name)
        if theirs is not None and not math.isclose(float(ours), float(theirs), rel_tol=1e-9, abs_tol=1e-9):
            differences.append(f"{name}: mission {ours:g}, trained {theirs:g}")
    return differences


@dataclass
class SettingsJudgement:
    """What :func:`judge_autopilot_settings` found: the report's two records, a refusal or None, and the events to
    record (kind, text) in order."""

    autopilot_fence: dict
    companion_loss: dict | None
    refusal: str | None = None
    events: list[tuple[str, str]] = field(default_factory=list)


def _read(params: dict[str, float], names: tuple[str, ...]) -> dict[str, float] | None:
    """The parameters ``names`` as read, or None if any is missing."""
    values = {name: params.get(name) for name in names}
    return None if None in values.values() else values


def judge_autopilot_settings(autopilot: str, params: dict[str, float], mission: Mission, home: GeoPoint,
                             fence_margin_m: float, companion_system_id: int | None,
                             param_timeout_s: float) -> SettingsJudgement:
    """The autopilot's fence and companion-loss parameters (``params``: what was read within ``param_timeout_s``)
    judged for ``mission`` flown from ``home``. A check whose parameters were not all read is not made, and says so.
    ``autopilot``: the flavour's name ("PX4" or "ArduPilot Copter")."""
    fence = _read(params, fence_params(autopilot))
    if fence is None:
        judgement = SettingsJudgement({"checked": False, "reason": "its parameters were not read"}, None,
                                      events=[("autopilot-fence", f"not checked (its parameters were not read "
                                                                  f"within {param_timeout_s:g} s)")])
    else:
        record, refusal, note = judge_autopilot_fence(autopilot, fence, mission, home, fence_margin_m)
        if refusal is not None:
            return SettingsJudgement(record, None, refusal=f"refused before arming: {refusal}")
        judgement = SettingsJudgement(record, None, events=[("autopilot-fence", note)])
    failsafes = _read(params, companion_loss_params(autopilot, {}))  # those every autopilot has
    if failsafes is None:
        judgement.companion_loss = {"checked": False, "reason": "its parameters were not read"}
        judgement.events.append(("warning", "what the autopilot does if this computer goes silent is not known: its "
                                            "failsafe parameters were not read"))
        return judgement
    failsafes |= {name: params[name] for name in companion_loss_params(autopilot) if name in params}
    judgement.companion_loss, warning = judge_companion_loss(autopilot, failsafes, companion_system_id)
    if warning is not None:
        judgement.events.append(("warning", warning))
    return judgement
