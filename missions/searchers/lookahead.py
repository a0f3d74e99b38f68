"""SarSearch-v1's lookahead planner (:class:`LookaheadBayes`): greedy Bayes that chooses each next cell by flying
its options forward in the crew's own belief (how it compares with greedy Bayes: docs/results.md)."""
from __future__ import annotations

import numpy as np

from missions import belief as belief_logic
from missions import goals as goal_logic
from missions import search
from missions.search_state_v1 import BeliefSearchState
from missions.searchers.rules import GreedyBayes, ScriptedSettings



def box_sum(belief: np.ndarray, cells: int) -> np.ndarray:
    """Each cell's belief summed with its neighbours' within ``cells`` cells (a square 2 * cells + 1 on a side,
    clipped at the grid's edge), by an integral image; ``belief`` is (n, G, G)."""
    grid = belief.shape[1]
    integral = np.pad(belief, ((0, 0), (1, 0), (1, 0))).cumsum(axis=1).cumsum(axis=2)
    low = np.clip(np.arange(grid) - cells, 0, grid)
    high = np.clip(np.arange(grid) + cells + 1, 0, grid)
    return (integral[:, high[:, None], high[None, :]] - integral[:, low[:, None], high[None, :]]
            - integral[:, high[:, None], low[None, :]] + integral[:, low[:, None], low[None, :]])


def top_cells(score: np.ndarray, count: int) -> np.ndarray:
    """(R, count) flat indices of each row's ``count`` highest-scoring cells of ``score`` (R, G, G), best first."""
    flat = score.reshape(len(score), -1)
    if count == 0:
        return np.zeros((len(score), 0), dtype=np.int64)
    best = np.argpartition(-flat, count - 1, axis=1)[:, :count]
    order = np.argsort(-np.take_along_axis(flat, best, axis=1), axis=1)
    return np.take_along_axis(best, order, axis=1)


class LookaheadBayes(GreedyBayes):
    """Greedy Bayes choosing its next cell by lookahead in the belief: a planner on the crew's own model.

    Before committing to a cell it flies each of ``lookahead_options`` options forward in the belief
    (``missions.belief``: the prior, drift and look model the search state keeps), continuing greedily after the
    option, and keeps the one whose rollout removes the most belief within ``lookahead_s``, i.e. the one most
    likely to have detected the victim by then under the crew's model. Rollouts read the belief only, never the
    hidden objects. The options are the best cells by greedy Bayes' own score and the best by their neighbourhood's
    belief (within ``REGION_CELLS`` cells) per travel time: the near cell greedy Bayes would take, and the far
    region it might never cross to. A rollout stops counting once the drone could no longer come home with
    ``reserve_s``, so the planner also weighs where a sortie ends. With one option it is greedy Bayes.

    The rollout model is simpler than the environment where that does not change which option is better: the
    drone moves at full speed in a straight line (no acceleration, no routing around danger zones), the camera at
    its widest at the search altitude, and the forecast error's blur is left out over the horizon.
    """

    REGION_CELLS = 2

    def __init__(self, core: BeliefSearchState, settings: ScriptedSettings = ScriptedSettings()):
        super().__init__(core, settings)
        self.horizon_steps = max(1, int(round(settings.lookahead_s / core.flight.step_period_s)))

    def choose_cells(self, rows: np.ndarray, north: np.ndarray, east: np.ndarray) -> np.ndarray:
        belief, travel = self.core.belief[rows], self.travel_s(rows, north, east)
        count = self.settings.lookahead_options
        near = top_cells(self.greedy_score(belief, travel), (count + 1) // 2)
        region = top_cells(self.greedy_score(box_sum(belief, self.REGION_CELLS), travel), count // 2)
        options = np.concatenate([near, region], axis=1)
        value = self.rollout(rows, options)
        return options[np.arange(len(rows)), value.argmax(axis=1)]  # ties keep greedy Bayes' own first choice

    def rollout(self, rows: np.ndarray, options: np.ndarray) -> np.ndarray:
        """(R, M) belief each option's rollout removes within the horizon, flying to the option's cell first and
        then on greedily (a cell kept until reached or searched down to half), while it could still come home."""
        core, flight, scen = self.core, self.core.flight, self.core.scen
        grid, m = core.belief.shape[1], options.shape[1]
        rep = np.repeat(rows, m)
        n, index = len(rep), np.arange(len(rep))
        belief, searched = core.belief[rep].copy(), np.zeros((n, grid, grid))
        offset, area = core.belief_offset[rep].copy(), scen.area[rep]
        position, home = core.position[rep].copy(), scen.start[rep]
        victim = scen.primary_index[rep]
        size, factor = search.OBJECT_SIZE_M[scen.target_category[rep, victim]], scen.detection_factor[rep, victim]
        left_s = (core.energy_left * scen.endurance_s)[rep]
        altitude, zoom, intensity = np.full(n, flight.altitude_m), np.zeros(n), np.ones(n)
        base_north, base_east = goal_logic.cell_centres(area, grid)
        cell = options.reshape(-1).copy()
        cell_belief = belief.reshape(n, -1)[index, cell]
        removed = np.zeros(n)
        step_m = flight.max_speed_mps * flight.step_period_s
        for _ in range(self.horizon_steps):
            north, east = base_north + offset[:, 0:1], base_east + offset[:, 1:2]
            goal = np.stack([north[index, cell // grid], east[index, cell % grid]], axis=1)
            done = ((np.hypot(*(goal - position).T) <= flight.reach_radius_m)
                    | (belief.reshape(n, -1)[index, cell] < 0.5 * cell_belief))
            if done.any():
                again = np.flatnonzero(done)
                travel = np.hypot(north[again, :, None] - position[again, 0, None, None],
                                  east[again, None, :] - position[again, 1, None, None]) / flight.max_speed_mps
                cell[again] = self.greedy_score(belief[again], travel).reshape(len(again), -1).argmax(axis=1)
                cell_belief[again] = belief.reshape(n, -1)[again, cell[again]]
                goal[again] = np.stack([north[again, cell[again] // grid], east[again, cell[again] % grid]], axis=1)
            to_goal = goal - position
            distance = np.hypot(*to_goal.T)
            position += to_goal * (np.minimum(distance, step_m) / np.maximum(distance, 1e-9))[:, None]
            left_s -= flight.step_period_s
            belief_logic.drift((belief, searched), offset, area, scen.forecast_drift[rep], flight.step_period_s)
            can_return = left_s - np.hypot(*(position - home).T) / flight.max_speed_mps > self.settings.reserve_s
            removed += can_return * belief_logic.look(belief, searched, area, offset, position, altitude, zoom,
                                                      intensity, size, factor)
        return removed.reshape(len(rows), m)
