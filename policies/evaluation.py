"""Evaluating a search policy (learned or scripted) on a scenario split, with the paper's metrics.

Each of the first ``episodes`` scenarios of the split is flown once (episode seed i -> scenario i), all in one
vectorised batch, deterministically. Metrics: success rate with a Wilson 95 % interval, cumulative extrinsic
reward, coverage ratio, episode length, sub-goal reachability (HRL: share of goal segments in which the drone
came within the reach radius of the goal's point), time to first detection of the victim, and the collision and
out-of-bounds rates.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from missions.mission import FlightSettings
from policies.env_core import SarSearchBatch, SarSearchConfig, make_batch
from policies.evaluation_stats import quantiles, wilson_interval

ActFn = Callable[[SarSearchBatch], np.ndarray]
GoalFn = Callable[[np.ndarray], np.ndarray]


def run_episodes(core: SarSearchBatch, act: ActFn, choose_goals: GoalFn | None = None) -> dict[str, np.ndarray]:
    """Fly every slot of ``core`` to the end of its current episode; per-episode outcome arrays.

    ``act(core)`` returns (N, 4) actions; ``choose_goals(meta_obs)`` (HRL) returns goal indices for the rows it
    is given, called every K steps.
    """
    n, k = core.n, core.flight.subgoal_interval
    done = np.zeros(n, dtype=bool)
    record = {key: np.zeros(n, dtype=bool) for key in ("success", "collision", "out_of_bounds")}
    record.update(length=np.zeros(n, dtype=np.int64), first_detection=np.full(n, -1, dtype=np.int64),
                  episode_return=np.zeros(n), coverage=np.zeros(n))
    segments, reached_segments = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    reached = np.zeros(n, dtype=bool)
    while not done.all():
        if choose_goals is not None:
            decide = (core.steps % k == 0) & ~done
            if decide.any():
                had_goal = decide & (core.steps > 0)
                segments += had_goal
                reached_segments += had_goal & reached
                reached[decide] = False
                goals = np.zeros(n, dtype=np.int64)
                goals[decide] = choose_goals(core.meta_observation[decide])
                core.set_goals(goals, decide)
        _, _, terminated, truncated, info = core.step(act(core))
        if choose_goals is not None:
            reached |= np.hypot(*(info["position"] - info["goal_point"]).T) <= core.flight.reach_radius_m
        ended = (terminated | truncated) & ~done
        for key in ("success", "collision", "out_of_bounds"):
            record[key][ended] = info[key][ended]
        record["length"][ended] = info["steps"][ended]
        record["first_detection"][ended] = info["first_detection_step"][ended]
        record["episode_return"][ended] = info["episode_return"][ended]
        record["coverage"][ended] = info["coverage_ratio"][ended]
        if choose_goals is not None:
            segments += ended
            reached_segments += ended & reached
        done |= ended
    record["subgoal_segments"], record["subgoals_reached"] = segments, reached_segments
    return record


def summarise(record: dict[str, np.ndarray]) -> dict:
    """The paper's metrics from :func:`run_episodes`' arrays."""
    episodes = len(record["success"])
    successes = int(record["success"].sum())
    low, high = wilson_interval(successes, episodes)
    detected = record["first_detection"] >= 0
    segments = int(record["subgoal_segments"].sum())
    return {
        "episodes": episodes, "success_rate": successes / episodes, "success_ci95": [low, high],
        "reward_mean": float(record["episode_return"].mean()), "reward_std": float(record["episode_return"].std()),
        "coverage_mean": float(record["coverage"].mean()), "coverage_std": float(record["coverage"].std()),
        "length_mean": float(record["length"].mean()), "length_std": float(record["length"].std()),
        "collision_rate": float(record["collision"].mean()), "out_of_bounds_rate": float(record["out_of_bounds"].mean()),
        "subgoal_reachability": (float(record["subgoals_reached"].sum()) / segments) if segments else None,
        "detection_rate": float(detected.mean()),
        "time_to_first_detection": quantiles(record["first_detection"][detected]),
        "steps_to_success": quantiles(record["length"][record["success"]]),
        "per_episode": {"success": record["success"].astype(int).tolist(),
                        "reward": np.round(record["episode_return"], 3).tolist(),
                        "length": record["length"].tolist(), "first_detection": record["first_detection"].tolist()},
    }


def episode_batch(split: str, episodes: int, flight: FlightSettings, goal_conditioned: bool) -> SarSearchBatch:
    """One slot per scenario 0..episodes-1 of ``split``."""
    config = SarSearchConfig(split=split, flight=flight, pool_size=max(episodes, 1), goal_conditioned=goal_conditioned)
    return make_batch(config, list(range(episodes)))


def evaluate_checkpoint(path, split: str = "test", episodes: int = 100) -> dict:
    """The paper's metrics of a trained run's deterministic policy on ``split``."""
    from policies.checkpoint_policy import CheckpointPolicy

    policy = CheckpointPolicy.load(path)
    core = episode_batch(split, episodes, policy.config.flight, goal_conditioned=policy.hierarchical)
    record = run_episodes(core, lambda batch: policy.act(batch.obs),
                          policy.choose_goals if policy.hierarchical else None)
    return {"algo": policy.config.algo, "preset": policy.config.preset, "seed": policy.config.seed,
            "checkpoint": str(policy.path), "trained_steps": policy.step, "split": split,
            "max_steps": policy.config.flight.max_steps, **summarise(record)}
