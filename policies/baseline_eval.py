"""Running the scripted baselines on a scenario split and summarising their search performance."""
from __future__ import annotations

import numpy as np

from missions.mission import FlightSettings
from policies.baselines import BASELINES
from policies.env_core import SarSearchConfig, make_batch
from policies.evaluation_stats import quantiles, wilson_interval


def run_baseline(name: str, split: str = "test", episodes: int = 200, flight: FlightSettings = FlightSettings(),
                 seed: int = 0) -> dict:
    """One episode on each of the first ``episodes`` scenarios of ``split`` (episode seed i -> scenario i)."""
    core = make_batch(SarSearchConfig(split=split, flight=flight, pool_size=max(episodes, 1)), list(range(episodes)))
    policy = BASELINES[name](core, seed) if name == "random" else BASELINES[name](core)
    done = np.zeros(episodes, dtype=bool)
    outcome = {key: np.zeros(episodes, dtype=bool) for key in ("success", "collision", "out_of_bounds")}
    length = np.zeros(episodes, dtype=np.int64)
    first_detection = np.full(episodes, -1, dtype=np.int64)
    returns = np.zeros(episodes)
    coverage = np.zeros(episodes)
    while not done.all():
        _, _, terminated, truncated, info = core.step(policy.act())
        ended = (terminated | truncated) & ~done
        for key in outcome:
            outcome[key][ended] = info[key][ended]
        length[ended] = info["steps"][ended]
        first_detection[ended] = info["first_detection_step"][ended]
        returns[ended] = info["episode_return"][ended]
        coverage[ended] = info["coverage_ratio"][ended]
        done |= ended
    successes = int(outcome["success"].sum())
    low, high = wilson_interval(successes, episodes)
    return {
        "baseline": name, "split": split, "episodes": episodes, "max_steps": flight.max_steps,
        "success_rate": successes / episodes, "success_ci95": [low, high],
        "collision_rate": float(outcome["collision"].mean()), "out_of_bounds_rate": float(outcome["out_of_bounds"].mean()),
        "mean_return": float(returns.mean()), "mean_coverage": float(coverage.mean()),
        "mean_length": float(length.mean()),
        "steps_to_success": quantiles(length[outcome["success"]]),
        "steps_to_first_detection": quantiles(first_detection[first_detection >= 0]),
        "detection_rate": float((first_detection >= 0).mean()),
    }
