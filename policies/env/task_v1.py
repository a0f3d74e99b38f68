"""SarSearch-v1's environment core: N searches with ambiguous sightings, close looks, a belief and an endurance.

The same frame as SarSearch-v0 (:class:`policies.env.core.FlownSearch`: scenario pool, exact multirotor dynamics,
observations), on the search state of ``missions.search_state_v1`` that the mission runner's pilot flies too. One
step: the action (movement in [-1, 1], north/east or towards / right of the target (``action_frame``), search
intensity and zoom in [0, 1]) becomes a velocity command, passes the safety shield (``missions.shield``: danger
zones and geofence, as the pilot applies it in flight) and is flown for one period;
the search state advances (the camera's altitude, drift, sightings, candidates, close looks, the belief); the
reward is the paper's table without its time and energy costs, which the endurance replaces, and with the task's
two new ends:

* no cost per step and none for the action (the paper's -0.1 and -0.01 ||a||^2): time and energy are the
  endurance now, and a running cost made giving up the best policy as soon as success looked unlikely, since
  coming home ends the episode (measured: docs/training.md, "How the defaults were chosen");
* +100 when the drone is within the reach radius of the victim once a close look has confirmed it;
* -50 inside a danger zone, -10 outside the geofence;
* -50 when the endurance runs out away from home (``ran_dry``: the drone is lost);
* +20 for coming back over home, hovering, with at least ``RETURN_RESERVE`` of the endurance left (``returned``;
  with less, 0).

Each of these ends the episode (terminated); the step limit truncates it.
"""
from __future__ import annotations

import numpy as np

from autonomy.observation import LAYOUT_V4
from missions import belief
from missions.search_state_v1 import CONFIRMED, RETURN_RESERVE, BeliefSearchState
from policies.env.core import REWARD_BOUNDARY, REWARD_COLLISION, REWARD_TARGET, FlownSearch, SarSearchConfig

REWARD_RAN_DRY = -50.0
REWARD_RETURNED = 20.0
"""For coming home with at least ``missions.search_state_v1.RETURN_RESERVE`` of the endurance left."""


class AmbiguousSearchBatch(FlownSearch, BeliefSearchState):
    """SarSearch-v1: N independent searches stepped together; see the module docstring."""

    layout = LAYOUT_V4
    shielded = True
    step_reward = 0.0

    def __init__(self, config: SarSearchConfig, num_envs: int):
        areas = ([scenario.area for scenario in config.scenarios] if config.scenarios
                 else [config.scenario_distribution.area()])
        sides = np.array([(a.north_min_m, a.north_max_m, a.east_min_m, a.east_max_m) for a in areas])
        # the map's cells are sized for the largest area the batch will fly (its scenarios are drawn later)
        BeliefSearchState.__init__(self, self._placeholder(config, num_envs), config.flight,
                                   map_cells=belief.map_cells(sides))
        self._setup_vehicles(self.layout.dim)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """Advance every environment one decision; returns (obs, reward, terminated, truncated, info).

        Finished environments are NOT reset here; the wrappers decide when. The info arrays are views of live
        state, valid until the next call."""
        flight = self.flight
        energy_before = self.energy_left.copy()
        a, position = self.fly(actions)
        out = self.advance(position, a[:, 2], a[:, 3], flight.step_period_s)
        with_reserve = out.returned & (energy_before >= RETURN_RESERVE)
        reward = (REWARD_TARGET * out.success + REWARD_COLLISION * out.collision + REWARD_BOUNDARY * out.out_of_bounds
                  + REWARD_RAN_DRY * out.ran_dry + REWARD_RETURNED * with_reserve)
        self.episode_return += reward
        terminated = out.success | out.collision | out.out_of_bounds | out.ran_dry | out.returned
        truncated = (self.steps >= flight.max_steps) & ~terminated
        victim = self.status[self._arange, self.scen.primary_index]
        info = {"success": out.success, "collision": out.collision, "out_of_bounds": out.out_of_bounds,
                "ran_dry": out.ran_dry, "returned": out.returned, "returned_with_reserve": with_reserve,
                "distance_to_victim_m": out.distance_to_victim_m, "coverage_ratio": self.coverage_ratio,
                "searched_cells": self.searched_cells,
                "first_detection_step": self.first_detection_step, "victim_detected": self.has_detection,
                "victim_confirmed": victim == CONFIRMED,
                "position": self.position, "goal_point": out.step_goal_point, "goal_reached": out.goal_reached,
                "goal_completed": out.goal_reached & (out.goal_moved_on | terminated | truncated),
                "belief_removed": out.belief_removed, "identify_chance": out.identify_chance,
                "energy_left": self.energy_left,
                "path_length_m": self.path_length_m, "episode_return": self.episode_return, "steps": self.steps,
                **self.step_start_info()}
        return self.observe(), reward.astype(np.float32), terminated, truncated, info
