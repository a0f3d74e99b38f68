"""SarSearch-v0's environment core: the paper's task (victim-aware search logic, exact forecast, no endurance).

The frame both tasks share (scenario pool, exact multirotor dynamics, observations) is
:class:`policies.env.core.FlownSearch`; the search state is ``missions.search_state_v0``'s, which the flight
runtime keeps too. SarSearch-v1's core is ``policies.env.task_v1``.

One step is one policy decision (``FlightSettings.step_period_s``, 1 s by default):

1. the action (movement north/east in [-1, 1], search intensity and zoom in [0, 1]) becomes a horizontal
   velocity command of up to ``max_speed_mps``; the drone flies it for one period at the search altitude
   through the exact multirotor dynamics;
2. objects drift with current and wind; the camera footprint (altitude, zoom) marks coverage and may detect
   objects (Bernoulli draws from a counter-based generator keyed by the episode seed, so every environment
   of a batch has its own reproducible stream);
3. reward (the paper's table): -0.1 per step, -0.01 * ||a||^2, +100 on reaching the victim, -50 on entering a
   danger zone, -10 on leaving the geofence. Reaching, collision and leaving end the episode (terminated);
   the step limit truncates it.
4. HRL-SAC (goal-conditioned mode): a goal whose point the drone reached is grounded again from the new search
   state (``missions.goals``), so the low level always has somewhere useful to fly until the next meta decision.
"""
from __future__ import annotations

import numpy as np

from autonomy.observation import LAYOUT_V3
from missions.search_state_v0 import SearchState
from policies.env.core import (
    ENERGY_COMPONENTS,
    REWARD_BOUNDARY,
    REWARD_COLLISION,
    REWARD_ENERGY,
    REWARD_STEP,
    REWARD_TARGET,
    FlownSearch,
    SarSearchConfig,
)


class SarSearchBatch(FlownSearch, SearchState):
    """SarSearch-v0: N independent search episodes, stepped together: the search state (``missions.search_state_v0``,
    shared with the flight runtime) plus the vehicle dynamics, the reward and the observations. Arrays are
    (N, ...); nothing here loops over N except resets, which copy each new episode's cached scenario arrays."""

    layout = LAYOUT_V3

    def __init__(self, config: SarSearchConfig, num_envs: int):
        SearchState.__init__(self, self._placeholder(config, num_envs), config.flight)
        self._setup_vehicles(self.layout.dim)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """Advance every environment one decision; returns (obs, reward, terminated, truncated, info).

        Finished environments are NOT reset here; the wrappers decide when (gymnasium's auto-reset rules).
        The info arrays are views of live state, valid until the next call.
        """
        flight = self.flight
        a, position = self.fly(actions)
        out = self.advance(position, a[:, 2], a[:, 3], flight.step_period_s)

        energy = a[:, ENERGY_COMPONENTS]
        reward = (REWARD_STEP + REWARD_ENERGY * np.einsum("ij,ij->i", energy, energy) + REWARD_TARGET * out.success
                  + REWARD_COLLISION * out.collision + REWARD_BOUNDARY * out.out_of_bounds)
        self.episode_return += reward
        terminated = out.success | out.collision | out.out_of_bounds
        truncated = (self.steps >= flight.max_steps) & ~terminated
        # Views of the live arrays: valid until the next step (the wrappers copy what they hand out).
        info = {"success": out.success, "collision": out.collision, "out_of_bounds": out.out_of_bounds,
                "distance_to_victim_m": out.distance_to_victim_m, "coverage_ratio": self.coverage_ratio,
                "searched_cells": self.searched_cells,
                "first_detection_step": self.first_detection_step, "victim_detected": self.has_detection,
                "position": self.position, "goal_point": out.step_goal_point, "goal_reached": out.goal_reached,
                # A sub-goal is completed when reaching it moves the search on, or on the episode's last step.
                "goal_completed": out.goal_reached & (out.goal_moved_on | terminated | truncated),
                "first_detection_chance": out.first_detection_chance,
                "path_length_m": self.path_length_m, "episode_return": self.episode_return, "steps": self.steps,
                **self.step_start_info()}
        return self.observe(), reward.astype(np.float32), terminated, truncated, info
