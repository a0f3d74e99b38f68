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
"""
from __future__ import annotations

import math

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
