"""Small statistics shared by evaluations, comparisons and benchmarks: Wilson intervals, quantile summaries, Student-t
intervals across seeds (scipy's t distribution) and the pooled statistics of a group of evaluations."""
from __future__ import annotations

import math

import numpy as np


def wilson_interval(successes: int, trials: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """95 % Wilson score interval of a success rate (good for small samples and rates near 0 or 1)."""
    if trials == 0:
        return 0.0, 1.0
    p = successes / trials
    denominator = 1.0 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denominator
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denominator
    return max(0.0, centre - half), min(1.0, centre + half)


def quantiles(values, qs=(0.1, 0.25, 0.5, 0.75, 0.9)) -> dict[str, float | None]:
    """Named quantiles (p10, p25, ...) of a sample; None for an empty sample."""
    values = np.asarray(values, dtype=np.float64)
    if values.size == 0:
        return {f"p{round(q * 100)}": None for q in qs}
    return {f"p{round(q * 100)}": float(np.quantile(values, q)) for q in qs}


def t_quantile_975(dof: int) -> float:
    """The 0.975 quantile of Student's t with ``dof`` degrees of freedom (the 95 % two-sided critical value)."""
    if dof < 1:
        raise ValueError(f"dof must be >= 1, got {dof}")
    from scipy.stats import t  # on first use: scipy.stats is slower to import than all the evaluation code

    return float(t.ppf(0.975, dof))


def t_interval(values) -> tuple[float, float | None, tuple[float, float] | None]:
    """Mean, sample standard deviation and 95 % t-interval of the mean (None for fewer than 2 values)."""
    values = np.asarray(values, dtype=np.float64)
    mean = float(values.mean())
    if len(values) < 2:
        return mean, None, None
    std = float(values.std(ddof=1))
    half = t_quantile_975(len(values) - 1) * std / math.sqrt(len(values))
    return mean, std, (mean - half, mean + half)


def intervals_overlap(a: tuple[float, float], b: tuple[float, float]) -> bool:
    return a[0] <= b[1] and b[0] <= a[1]


def _pooled_mean_std(metrics: list[dict], name: str) -> tuple[float, float]:
    """Mean and (population) standard deviation over all episodes, from per-run means and standard deviations."""
    n = np.array([m["episodes"] for m in metrics], dtype=np.float64)
    means = np.array([m[f"{name}_mean"] for m in metrics], dtype=np.float64)
    stds = np.array([m[f"{name}_std"] for m in metrics], dtype=np.float64)
    mean = float((n * means).sum() / n.sum())
    return mean, float(math.sqrt((n * (stds ** 2 + (means - mean) ** 2)).sum() / n.sum()))


def _median(values) -> float | None:
    return float(np.median(values)) if len(values) else None


def pooled_stats(metrics: list[dict]) -> dict:
    """Statistics over all episodes of one or more evaluations (seeds of one method, or one baseline)."""
    episodes = sum(int(m["episodes"]) for m in metrics)
    successes = sum(int(round(m["success_rate"] * m["episodes"])) for m in metrics)
    per_episode = [m.get("per_episode") for m in metrics]
    stats = {"episodes": episodes, "successes": successes, "success": successes / episodes,
             "wilson95": list(wilson_interval(successes, episodes))}
    for name in ("reward", "coverage", "length"):
        stats[f"{name}_mean"], stats[f"{name}_std"] = _pooled_mean_std(metrics, name)
    weights = np.array([m["episodes"] for m in metrics], dtype=np.float64) / episodes
    for name in ("collision_rate", "out_of_bounds_rate", "detection_rate"):
        values = [m.get(name) for m in metrics]
        stats[name] = None if None in values else float(np.dot(weights, values))
    reach = [m["subgoal_reachability"] for m in metrics if m.get("subgoal_reachability") is not None]
    stats["subgoal_reachability"] = float(np.mean(reach)) if reach else None
    if all(p is not None for p in per_episode):
        first = np.concatenate([np.asarray(p["first_detection"], dtype=np.float64) for p in per_episode])
        success = np.concatenate([np.asarray(p["success"], dtype=bool) for p in per_episode])
        length = np.concatenate([np.asarray(p["length"], dtype=np.float64) for p in per_episode])
        stats["median_time_to_detection"] = _median(first[first >= 0])
        stats["median_steps_to_success"] = _median(length[success])
    else:
        stats["median_time_to_detection"] = stats["median_steps_to_success"] = None
    return stats


def group_stats(metrics: list[dict]) -> dict:
    """:func:`pooled_stats` plus the across-seed statistics of the success rate and of the mean extrinsic reward
    (the paper's cumulative reward: on SarSearch-v1 it prices a lost aircraft, -50 for running dry, beside the
    +100 of a success)."""
    rates = [float(m["success_rate"]) for m in metrics]
    mean, std, interval = t_interval(rates)
    if interval is not None:
        interval = (max(0.0, interval[0]), min(1.0, interval[1]))
    rewards = [float(m["reward_mean"]) for m in metrics]
    reward_mean, _, reward_interval = t_interval(rewards)
    return {"seeds": len(metrics), "seed_success": rates, "success_mean": mean, "success_std": std,
            "success_t95": list(interval) if interval else None, "seed_reward": rewards,
            "reward_seed_mean": reward_mean, "reward_t95": list(reward_interval) if reward_interval else None,
            **pooled_stats(metrics)}
