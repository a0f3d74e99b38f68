"""The fleet's planner: greedy Bayes for several drones on one shared map (``missions.fleet_search``), split so that
two drones do not search the same water.

* **sequential greedy**: when drones choose their next cell, they choose one after the other (in the fleet's
  order), each on the map with the water around every other drone's cell taken out (``claim_radius_m``): the
  cells another drone is flying to, or just chose, are its water. A drone whose cell is reached or searched down
  chooses again the same way. This is the sequential-greedy allocation of multi-robot search (each robot takes
  the best cell given the others' claims), on the crew's own probability map;
* **one drone per candidate**: each candidate worth a close look (and the confirmed victim) is flown to by the
  nearest searching drone only; the others keep searching;
* drones that are not searching (``BeliefSearchState.searching``: gone home, failed safe, blind) claim nothing and
  are given no candidate, so the others take over their water.

Every other rule (bingo, fence margin, hazards, close looks) is greedy Bayes' (``missions.searchers.rules``).
"""
from __future__ import annotations

import numpy as np

from missions.search_state_v1 import BeliefSearchState
from missions.searchers.rules import GreedyBayes, ScriptedSettings

CLAIM_RADIUS_M = 150.0
"""Water within this distance (m) of the cell another drone flies to is that drone's: about two sweep widths of the
camera at the search altitude, so that two drones' tracks do not overlap."""


class FleetGreedyBayes(GreedyBayes):
    """Greedy Bayes for the rows of a fleet's search state (module docstring)."""

    def __init__(self, core: BeliefSearchState, settings: ScriptedSettings = ScriptedSettings(),
                 claim_radius_m: float = CLAIM_RADIUS_M):
        super().__init__(core, settings)
        self.claim_radius_m = claim_radius_m

    def choose_cells(self, rows: np.ndarray, north: np.ndarray, east: np.ndarray) -> np.ndarray:
        core, grid = self.core, self.core.belief.shape[1]
        travel = self.travel_s(rows, north, east)
        claimed = [(north[r, self.cell[r] // grid], east[r, self.cell[r] % grid])
                   for r in np.flatnonzero(self.core.searching) if self.cell[r] >= 0 and r not in rows]
        chosen = np.empty(len(rows), dtype=np.int64)
        for k, row in enumerate(rows):
            belief = core.belief[row].copy()
            for point_n, point_e in claimed:
                taken = np.hypot(north[row, :, None] - point_n, east[row, None, :] - point_e) <= self.claim_radius_m
                belief[taken] = 0.0
            score = self.greedy_score(belief[None], travel[k:k + 1])
            chosen[k] = int(score.reshape(-1).argmax())
            if self.core.searching[row]:
                claimed.append((north[row, chosen[k] // grid], east[row, chosen[k] % grid]))
        return chosen

    def own_candidates(self, worth: np.ndarray) -> np.ndarray:
        """Each candidate goes to the nearest live drone: the others do not fly to it."""
        core = self.core
        if not self.core.searching.any():
            return worth
        distance = np.hypot(*(core.candidate_estimates() - core.position[:, None, :]).transpose(2, 0, 1))
        distance[~self.core.searching] = np.inf
        nearest = distance.argmin(axis=0)  # per object
        mine = nearest[None, :] == np.arange(core.n)[:, None]
        return worth & mine

