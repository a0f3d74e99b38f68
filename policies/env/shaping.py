"""The learning rewards: what the agents learn from, as opposed to the environment reward they are judged by.

``shaped_reward`` is the continuous SAC's: HRL-SAC's low-level shaping towards its goal point, which flat SAC gets
too with ``TrainConfig.flat_shaping`` (towards its own target, the observation's ``target_offset`` point).
``meta_learning_reward`` is the meta-controller's. Both read only what a step returns (reward and info).

Per step, with g the point the step flew towards (the goal's point; flat SAC: TrackObject's point):
``(||s - g|| - ||s' - g||) / intrinsic_scale_m`` (or the paper's ``-||s' - g|| / intrinsic_scale_m``) minus
``cross_track_penalty`` x the metres flown sideways to the line to g, + ``coverage_bonus`` per newly covered cell
(or per cell of ground swept, ``coverage_swept``; SarSearch-v1: per cell of cumulative probability of detection;
times the intensity with ``coverage_by_intensity``), + ``belief_bonus`` x the belief the look removed and
``identify_bonus`` x the chance that a close look identified a candidate (both SarSearch-v1, both under the crew's
model), + ``detection_bonus`` x the first-detection chance (SarSearch-v0); HRL-SAC adds ``intrinsic_goal_bonus``
on completing g and ``extrinsic_weight`` x the environment reward without its per-step cost; flat SAC adds that
environment reward whole (still without the per-step cost: with it, leaving the area at once, -10, is worth about
as much as a long search).
"""
from __future__ import annotations

import numpy as np

from missions import search
from policies.config import TrainConfig
from policies.env.core import CAMERA_ZOOM, SEARCH_INTENSITY
from policies.env.task_v1 import REWARD_RETURNED


def cross_track_m(start: np.ndarray, end: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """(N,) metres each step from ``start`` to ``end`` moved sideways to the line from ``start`` to ``goal``:
    |d x u| for the step d and the unit vector u towards the goal (0 where the drone is already at the goal)."""
    step, to_goal = end - start, goal - start
    length = np.hypot(*to_goal.T)
    cross = np.abs(step[:, 0] * to_goal[:, 1] - step[:, 1] * to_goal[:, 0])
    return np.divide(cross, length, out=np.zeros_like(length), where=length > 1e-6)


def shaped_reward(config: TrainConfig, hrl: bool, actions: np.ndarray, info: dict, reward: np.ndarray,
                  step_reward: float) -> np.ndarray:
    """(N,) the learning reward of a step (module docstring) from the step's ``info`` (its ``step_start_info``
    entries say where the step started), its environment ``reward`` and the environment's constant per-step part
    of that reward, ``step_reward``, which the learning reward leaves out."""
    cfg, position = config, info["position"]
    start, target = info["start_position"], info["step_target"]
    distance = np.hypot(*(position - target).T)
    toward = np.hypot(*(start - target).T) - distance if cfg.intrinsic_reward == "progress" else -distance
    sideways = cross_track_m(start, position, target) if cfg.cross_track_penalty else 0.0
    out = ((toward - cfg.cross_track_penalty * sideways) / cfg.intrinsic_scale_m
           + cfg.coverage_bonus * searched_cells(cfg, actions, info)
           + cfg.belief_bonus * info.get("belief_removed", 0.0)
           + cfg.identify_bonus * info.get("identify_chance", 0.0)
           + cfg.detection_bonus * info.get("first_detection_chance", 0.0))
    if hrl:
        # The bonus pays for completing g (info["goal_completed"]), not for being within reach of it: over an
        # unsearched cell with the sensor off the goal stays put, and a bonus for arriving would pay every step of
        # hovering there (measured: docs/training.md, "How the defaults were chosen").
        return (out + cfg.intrinsic_goal_bonus * info["goal_completed"]
                + cfg.extrinsic_weight * (reward - step_reward))
    return out + (reward - step_reward)


def searched_cells(config: TrainConfig, actions: np.ndarray, info: dict) -> np.ndarray:
    """What the coverage bonus counts this step, in grid cells: the newly covered cells (SarSearch-v1: the cells'
    gain in cumulative probability of detection), or with ``coverage_swept``
    the ground the camera footprint swept (sensor on), either times the search intensity with
    ``coverage_by_intensity``."""
    cfg, intensity = config, actions[:, SEARCH_INTENSITY].clip(0.0, 1.0)
    if cfg.coverage_swept:
        step_m = np.hypot(*(info["position"] - info["start_position"]).T)
        half_width = search.footprint_half_width_m(cfg.flight.altitude_m, actions[:, CAMERA_ZOOM].clip(0.0, 1.0))
        searched = step_m * 2.0 * half_width / info["cell_area_m2"] * (intensity >= search.SENSOR_ON_INTENSITY)
    else:
        searched = info["newly_searched_cells"]
    return searched * intensity if cfg.coverage_by_intensity else searched


def meta_learning_reward(config: TrainConfig, reward: np.ndarray, info: dict) -> np.ndarray:
    """(N,) the environment reward the meta-controller learns from: with ``meta_returned_reward`` set, a return home
    with reserve pays that instead of the environment's ``REWARD_RETURNED``, and ``meta_belief_bonus`` times the
    belief the step's look removed is added (both SarSearch-v1)."""
    if "returned_with_reserve" not in info:
        return reward
    if config.meta_returned_reward is not None:
        reward = reward + (config.meta_returned_reward - REWARD_RETURNED) * info["returned_with_reserve"]
    if config.meta_belief_bonus:
        reward = reward + config.meta_belief_bonus * info["belief_removed"]
    return reward
