"""A mission: a scenario plus how to fly it (altitude, speed, geofence, decision timing, limits)."""
from __future__ import annotations

from dataclasses import dataclass, field

from missions.fleet import MAX_SEARCH_ALTITUDE_M, Fleet
from missions.geodesy import GeoPoint, LocalFrame
from missions.scenario import Scenario, SearchArea
from missions.validation import check_fields


@dataclass(frozen=True)
class FlightSettings:
    """How the search is flown; shared by the training environment and the mission runner."""

    altitude_m: float = 50.0
    """Search altitude above home (m), held constant; sets the camera footprint. Allowed [10, 120]."""
    max_speed_mps: float = 10.0
    """Horizontal speed at full movement command |a| = 1 (m/s). Allowed [1, 20]."""
    step_period_s: float = 1.0
    """Time between policy decisions (s): one environment step. Allowed [0.1, 10]."""
    subgoal_interval: int = 30
    """K: low-level steps between meta-controller decisions. Allowed [1, 1000]."""
    max_steps: int = 1000
    """Decision steps before the episode is truncated (paper preset: 10,000). Allowed [10, 100000]."""
    reach_radius_m: float = 15.0
    """Horizontal distance to the primary target that counts as reaching it (m). Allowed [1, 100]."""

    def __post_init__(self) -> None:
        check_fields(self, (("altitude_m", 10.0, 120.0), ("max_speed_mps", 1.0, 20.0), ("step_period_s", 0.1, 10.0),
                            ("subgoal_interval", 1, 1000), ("max_steps", 10, 100_000), ("reach_radius_m", 1.0, 100.0)),
                     integers=("subgoal_interval", "max_steps"))


@dataclass(frozen=True)
class Mission:
    """What the runner flies and what the environment trains on."""

    scenario: Scenario = field(default_factory=Scenario)
    flight: FlightSettings = field(default_factory=FlightSettings)
    name: str = "mission"
    geofence: SearchArea | None = None
    """Where the drone may fly; None means the search area itself. Must contain the search area."""
    home_altitude_known: bool = True
    """Whether ``scenario.home.alt_m`` was given (a mission file may leave it out). The runner holds the search
    altitude relative to the vehicle's own home either way; a known altitude is also checked against it."""
    fleet: Fleet | None = None
    """The drones of a fleet mission (``missions.fleet``); None for a single drone launched from the scenario's
    start."""

    def __post_init__(self) -> None:
        fence, area = self.geofence, self.scenario.area
        if fence is not None and not (fence.north_min_m <= area.north_min_m and fence.north_max_m >= area.north_max_m
                                      and fence.east_min_m <= area.east_min_m and fence.east_max_m >= area.east_max_m):
            raise ValueError("Mission.geofence must contain the search area (scenario.area)")
        if self.fleet is not None:
            self._check_fleet(self.fleet)

    def _check_fleet(self, fleet: Fleet) -> None:
        """Every launch point inside the geofence, and the highest layer within the search altitude limit."""
        for vehicle in fleet.vehicles:
            if not self.fence.contains(vehicle.north_m, vehicle.east_m):
                raise ValueError(f"Mission.fleet must launch inside the geofence: {vehicle.name} launches at north "
                                 f"{vehicle.north_m:g} m, east {vehicle.east_m:g} m")
        top = fleet.search_altitude_m(len(fleet.vehicles) - 1, self.flight.altitude_m)
        if top > MAX_SEARCH_ALTITUDE_M:
            raise ValueError(f"Mission.fleet must search at most {MAX_SEARCH_ALTITUDE_M:g} m up: its highest drone "
                             f"would fly at {top:g} m (flight.altitude_m + {len(fleet.vehicles) - 1} x "
                             "altitude_layer_m); lower the altitude or the layer")

    @property
    def launch_point(self) -> GeoPoint:
        """Where the drone takes off: the scenario's start (normally home), at home's altitude. A vehicle flying
        this mission should have its home here (the simulated vehicle boots here in a replay)."""
        scenario = self.scenario
        lat, lon, alt = LocalFrame(scenario.home).to_geodetic(scenario.start_north_m, scenario.start_east_m, 0.0)
        return GeoPoint(lat, lon, alt)

    @property
    def fence(self) -> SearchArea:
        """The effective geofence: leaving it ends an episode (and is refused in flight)."""
        return self.geofence or self.scenario.area
