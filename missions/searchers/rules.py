"""What every SarSearch-v1 scripted searcher shares (:class:`ScriptedSearch`: the rules around its search pattern,
package ``missions.searchers``), its settings (:class:`ScriptedSettings`) and greedy Bayes, which the lookahead
planner (``missions.searchers.lookahead``) builds on. The searchers use what a crew knows, never the hidden victim."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from missions import goals as goal_logic
from missions.action_frames import arrival_speed_fraction
from missions.search_state_v1 import BeliefSearchState
from missions.sweep_width import sweep_width_m
from missions.validation import check_fields



def fly_straight(position: np.ndarray, goal: np.ndarray, flight, zoom: float | np.ndarray,
                 turn: Callable | None = None) -> np.ndarray:
    """(N, 4) actions flying from ``position`` straight at ``goal`` (both (N, 2) metres) at full speed, slowing over
    the last step so as to stop on the point instead of overshooting it, with the sensor on and the camera at
    ``zoom``. ``turn(position, direction, step_m)`` may bend the unit direction (hazard avoidance)."""
    offset = goal - position
    distance = np.hypot(*offset.T)
    step_m = flight.max_speed_mps * flight.step_period_s
    speed_fraction = arrival_speed_fraction(distance, flight.max_speed_mps, flight.step_period_s, steps=1.0)
    direction = offset / np.maximum(distance, 1e-9)[:, None]
    if turn is not None:
        direction = turn(position, direction, step_m)
    actions = np.zeros((len(position), 4))
    actions[:, 0:2] = direction * speed_fraction[:, None]
    actions[:, 2] = 1.0
    actions[:, 3] = zoom
    return actions


@dataclass(frozen=True)
class ScriptedSettings:
    """The knobs of the scripted searchers (tuned on the val split)."""

    coverage_factor: float = 1.0
    """IAMSAR's coverage factor C = W / S: the track spacing is the sweep width over it. Allowed [0.25, 4]."""
    bound_sigmas: float = 2.5
    """Patterns: half side of the expanding square / the parallel-track box, in datum sigmas. Allowed [0.5, 10]."""
    investigate_plausibility: float = 0.0
    """Candidates at least this plausible (``BeliefSearchState.plausibility``) are looked at. Allowed [0, 1]."""
    close_look_zoom: float = 0.5
    """Zoom while hovering over a candidate. Allowed [0, 1]."""
    reserve_s: float = 60.0
    """Bingo: head home when the endurance left is the way home plus this (s). Allowed [0, 3600]."""
    travel_time_s: float = 30.0
    """Greedy Bayes (and the lookahead's): tau in belief / (travel time + tau) (s). Allowed [1, 3600]."""
    lookahead_s: float = 60.0
    """Lookahead Bayes: how far ahead each option is flown in the belief (s). Allowed [1, 600]."""
    lookahead_options: int = 6
    """Lookahead Bayes: cells tried per choice, half greedy Bayes' best, half the best regions'. Allowed 1-32."""

    def __post_init__(self) -> None:
        check_fields(self, (("coverage_factor", 0.25, 4.0), ("bound_sigmas", 0.5, 10.0),
                            ("investigate_plausibility", 0.0, 1.0), ("close_look_zoom", 0.0, 1.0),
                            ("reserve_s", 0.0, 3600.0), ("travel_time_s", 1.0, 3600.0), ("lookahead_s", 1.0, 600.0),
                            ("lookahead_options", 1, 32)), integers=("lookahead_options",))


class ScriptedSearch:
    """The shared rules (module docstring) around a search point that each pattern supplies."""

    def __init__(self, core: BeliefSearchState, settings: ScriptedSettings = ScriptedSettings()):
        self.core, self.settings = core, settings
        self.going_home = np.zeros(core.n, dtype=bool)
        self.started = np.full(core.n, -1, dtype=np.int64)  # the episode (by seed) each slot was planned for

    def search_point(self, fresh: np.ndarray) -> np.ndarray:
        """(N, 2) where the pattern flies now; ``fresh`` (N,) marks slots whose episode just started."""
        raise NotImplementedError

    def spacing_m(self, rows: np.ndarray) -> np.ndarray:
        """Track spacing S (m) of these slots: the sweep width for the reported object over the coverage factor."""
        core, flight = self.core, self.core.flight
        reported = core.scen.primary_index[rows]
        width = sweep_width_m(flight.altitude_m, 0.0, flight.max_speed_mps, flight.step_period_s,
                              core.scen.target_size_m[rows, reported], core.scen.detection_factor[rows, reported])
        return width / self.settings.coverage_factor

    def own_candidates(self, worth: np.ndarray) -> np.ndarray:
        """(N, T) the candidates worth flying to that each slot flies to: all of them (a fleet's planner gives each
        to one drone, ``missions.searchers.fleet``)."""
        return worth

    def act(self) -> np.ndarray:
        core, settings, flight = self.core, self.settings, self.core.flight
        fresh = (core.steps == 0) | (self.started != core.episode_seed.astype(np.int64))
        self.started[fresh] = core.episode_seed[fresh].astype(np.int64)
        self.going_home[fresh] = False
        point = self.search_point(fresh)
        estimates, kind = core.candidate_estimates(), core.candidate_kind()
        worth = (kind == 2) | ((kind == 1) & (core.plausibility >= settings.investigate_plausibility))
        worth = self.own_candidates(worth)
        candidate, has_candidate = goal_logic.candidate_point(core.position, estimates, np.where(worth, kind, 0))
        point = np.where(has_candidate[:, None], candidate, point)
        home = core.scen.start
        left_s = core.energy_left * core.scen.endurance_s
        self.going_home |= left_s - np.hypot(*(core.position - home).T) / flight.max_speed_mps <= settings.reserve_s
        point = np.where(self.going_home[:, None], home, point)
        area, margin = core.scen.area, goal_logic.FENCE_MARGIN_M
        point[:, 0] = np.clip(point[:, 0], area[:, 0] + margin, area[:, 1] - margin)
        point[:, 1] = np.clip(point[:, 1], area[:, 2] + margin, area[:, 3] - margin)
        routed = goal_logic.route_around_hazards(core.position, point, core.scen.obstacles, core.scen.obstacle_valid,
                                                 area)
        looking = has_candidate & ~self.going_home & (np.hypot(*(candidate - core.position).T) <= flight.reach_radius_m)
        zoom = np.where(looking, settings.close_look_zoom, 0.0)
        actions = fly_straight(core.position, routed, flight, zoom)
        # over a candidate or home: hold still (a close look needs a steady camera; home is where it lands)
        hold = looking | (self.going_home & (np.hypot(*(core.position - home).T) <= flight.reach_radius_m))
        actions[hold, 0:2] = np.clip((routed - core.position)[hold] / (flight.max_speed_mps * 4.0), -0.2, 0.2)
        return actions


class GreedyBayes(ScriptedSearch):
    """The cell with the most belief per travel time, kept until reached or half searched (module docstring)."""

    def __init__(self, core: BeliefSearchState, settings: ScriptedSettings = ScriptedSettings()):
        super().__init__(core, settings)
        self.cell = np.full(core.n, -1, dtype=np.int64)
        self.cell_belief = np.zeros(core.n)

    def search_point(self, fresh: np.ndarray) -> np.ndarray:
        core, flight = self.core, self.core.flight
        n, grid = core.n, core.belief.shape[1]
        north, east = goal_logic.cell_centres(core.scen.area, grid)
        north, east = north + core.belief_offset[:, 0:1], east + core.belief_offset[:, 1:2]
        flat = core.belief.reshape(n, -1)
        index = np.arange(n)
        current = np.stack([north[index, self.cell // grid], east[index, self.cell % grid]], axis=1)
        reached = np.hypot(*(current - core.position).T) <= flight.reach_radius_m
        searched = flat[index, self.cell] < 0.5 * self.cell_belief
        choose = fresh | (self.cell < 0) | reached | searched
        if choose.any():
            rows = np.flatnonzero(choose)
            best = self.choose_cells(rows, north, east)
            self.cell[rows], self.cell_belief[rows] = best, flat[rows, best]
            current[rows] = np.stack([north[rows, best // grid], east[rows, best % grid]], axis=1)
        return current

    def travel_s(self, rows: np.ndarray, north: np.ndarray, east: np.ndarray) -> np.ndarray:
        """(len(rows), G, G): the flight time at full speed from each of these slots to every cell centre."""
        core = self.core
        return np.hypot(north[rows, :, None] - core.position[rows, 0, None, None],
                        east[rows, None, :] - core.position[rows, 1, None, None]) / core.flight.max_speed_mps

    def greedy_score(self, belief: np.ndarray, travel_s: np.ndarray) -> np.ndarray:
        """log(belief / (travel time + tau)) of every cell (belief and travel_s (R, G, G)): greedy Bayes' choice."""
        return np.log(np.maximum(belief, 1e-300)) - np.log(travel_s + self.settings.travel_time_s)

    def choose_cells(self, rows: np.ndarray, north: np.ndarray, east: np.ndarray) -> np.ndarray:
        """The flat index of the cell each of these slots flies to next: the most belief per travel time."""
        score = self.greedy_score(self.core.belief[rows], self.travel_s(rows, north, east))
        return score.reshape(len(rows), -1).argmax(axis=1)
