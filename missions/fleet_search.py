"""One search flown by a fleet: a :class:`missions.search_state_v1.BeliefSearchState` with one row per drone, all
rows on the same scenario, sharing one crew map and one list of candidates.

Each row is one drone: its own position, launch point (``scen.start``: where it returns and lands), search altitude
(its layer, ``missions.fleet.Fleet.search_altitude_m``), camera and endurance, and its own detection draws (keyed by
:func:`drone_seed`, so two drones over the same water do not see the same luck). What a crew shares is shared:

* **the map**: every drone's look lowers the same belief and raises the same cumulative probability of detection,
  one look after the other within a step (looks are independent, so the order does not change the product); after
  the step every row holds the shared map again;
* **the candidates**: a sighting by any drone is a candidate for all; a close look by any drone confirms or
  rejects it for all. Within one step, the strongest news about an object wins (confirmed, then rejected, then
  sighted, then lost: a drone that sees it again proves it is not lost);
* **the find**: the victim is detected once any drone has seen it.

A drone that is not searching (still climbing, blind, or gone home) is advanced with its camera off
(``intensity`` 0): its row moves on in time with the others but its looks credit nothing. A fleet of one drone is
exactly the single-drone search (the same draws, the same map), which ``tests/test_fleet_search.py`` checks.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from missions.fleet import Fleet
from missions.mission import Mission
from missions.search import ScenarioBatch
from missions import belief as belief_logic
from missions.search_state_v1 import CONFIRMED, REJECTED, TARGET_SLOTS, BeliefSearchState

SEED_STRIDE = np.uint64(0x9E3779B97F4A7C15)
"""Added per drone to the mission seed (modulo 2^64): drone 0 keeps the seed itself."""


def drone_seed(seed: int, index: int) -> np.uint64:
    """The detection-draw seed of drone ``index`` (from 0) of a fleet flying with ``seed``."""
    with np.errstate(over="ignore"):
        return np.uint64(seed) + np.uint64(index) * SEED_STRIDE


def fleet_scenarios(mission: Mission) -> ScenarioBatch:
    """One row per drone of ``mission.fleet``: the mission's scenario launched from that drone's launch point,
    padded to the environment's target slots (the detection draws are keyed by slot)."""
    fleet: Fleet = mission.fleet
    scenario = mission.scenario
    rows = [dataclasses.replace(scenario, start_north_m=vehicle.north_m, start_east_m=vehicle.east_m)
            for vehicle in fleet.vehicles]
    return ScenarioBatch.from_scenarios(rows, [mission.geofence] * len(rows),
                                        num_targets=max(TARGET_SLOTS, len(scenario.targets)))


class FleetSearchState(BeliefSearchState):
    """The search state of a fleet (module docstring): one row per drone, one shared map and candidate list."""

    def __init__(self, mission: Mission, seed: int = 0):
        if mission.fleet is None:
            raise ValueError("FleetSearchState needs a fleet mission (a mission file with a fleet section)")
        super().__init__(fleet_scenarios(mission), mission.flight)
        fleet = mission.fleet
        self.search_altitude_m[:] = [fleet.search_altitude_m(i, mission.flight.altitude_m) for i in range(self.n)]
        seeds = np.array([drone_seed(seed, i) for i in range(self.n)], dtype=np.uint64)
        self.reset(np.arange(self.n), seeds)

    def _look(self, position, zoom, intensity, size_m, factor) -> np.ndarray:
        """Every drone's look on the one shared map (row 0's), in turn; then each row holds that map."""
        removed = np.zeros(self.n)
        area, offset = self.scen.area, self.belief_offset
        for i in range(self.n):
            one = slice(i, i + 1)
            removed[i] = belief_logic.look(self.belief[:1], self.coverage[:1], area[one], offset[one], position[one],
                                           self.altitude[one], zoom[one], intensity[one], size_m[one],
                                           factor[one])[0]
        self.belief[1:] = self.belief[0]
        self.coverage[1:] = self.coverage[0]
        return removed

    def _update_candidates(self, sighted, intensity, zoom, dt_s) -> None:
        """Each drone's sightings and close looks as a single drone's, then the strongest news of each object
        shared with every drone (module docstring)."""
        before = self.status[0].copy()
        super()._update_candidates(sighted, intensity, zoom, dt_s)
        changed = self.status != before[None, :]
        news = np.select([changed & (self.status == CONFIRMED), changed & (self.status == REJECTED), sighted, changed],
                         [4, 3, 2, 1], 0)
        source = news.argmax(axis=0)  # per object, the drone with the strongest news (row 0 when there is none)
        objects = np.arange(self.max_targets)
        for array in (self.status, self.sighting, self.sighted_s, self.plausibility):
            array[:] = array[source, objects]
        seen = sighted.any(axis=0)
        self.unseen_look_s[:] = np.where(seen, 0.0, self.unseen_look_s.max(axis=0))
        self._new_candidate[:] = self._new_candidate.any()

    def advance(self, position, intensity, zoom, dt_s):
        outcome = super().advance(position, intensity, zoom, dt_s)
        if self.has_detection.any():
            first = self.first_detection_step[self.first_detection_step >= 0].min()
            self.has_detection[:] = True
            self.first_detection_step[:] = first
        return outcome
