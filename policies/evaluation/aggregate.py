"""Aggregate scores over runs the way rliable does (Agarwal et al., "Deep Reinforcement Learning at the Edge of the
Statistical Precipice", NeurIPS 2021), written here without the dependency.

A method's scores form a (runs x tasks) matrix. Here a run is a training seed (a scripted searcher: a detection
stream, ``policies.evaluation.episodes.episode_batch``'s ``stream``) and a task a stratum of the test scenarios by their
conditions (time of day x sea state: 12 strata), each score the success rate of that run on that stratum's
scenarios.

* **IQM**, the interquartile mean: the mean of the middle 50 % of all runs x tasks scores (a 25 % trimmed mean;
  the lowest and highest quarter may be fractional, so the cut-off scores count with their fraction), robust to
  an outlying run where the mean is not, and more efficient than the median.
* **Stratified bootstrap**: a 95 % percentile interval from resampling the runs with replacement, separately in
  each task (the tasks are fixed, the runs are the random part), ``BOOTSTRAP_SAMPLES`` times with a seeded
  generator: the same scores always give the same interval.
"""
from __future__ import annotations

import numpy as np

BOOTSTRAP_SAMPLES = 2_000
BOOTSTRAP_SEED = 0
STRATA = ("time_of_day", "sea")
"""Scenario fields whose combinations are the tasks (4 x 3 = 12)."""


def interquartile_mean(scores: np.ndarray) -> float:
    """The mean of the middle 50 % of ``scores`` (any shape, flattened), counting fractional cut-off scores
    with their fraction (``scipy.stats.trim_mean(x, 0.25)`` does the same when 4 divides the count)."""
    values = np.sort(np.asarray(scores, dtype=np.float64).ravel())
    n = len(values)
    if n == 0:
        raise ValueError("interquartile_mean of no scores")
    low, high = 0.25 * n, 0.75 * n
    # weight of each sorted score in [low, high]: the overlap of [i, i + 1] with it
    index = np.arange(n)
    weight = np.clip(np.minimum(index + 1, high) - np.maximum(index, low), 0.0, 1.0)
    return float((weight * values).sum() / weight.sum())


def stratified_bootstrap_ci(scores: np.ndarray, statistic=interquartile_mean, samples: int = BOOTSTRAP_SAMPLES,
                            seed: int = BOOTSTRAP_SEED, confidence: float = 0.95) -> tuple[float, float]:
    """Percentile interval of ``statistic`` over (runs x tasks) ``scores``, the runs resampled within each task."""
    scores = np.asarray(scores, dtype=np.float64)
    if scores.ndim != 2 or scores.shape[0] < 1:
        raise ValueError(f"scores must be a (runs, tasks) matrix, got shape {scores.shape}")
    runs, tasks = scores.shape
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, runs, size=(samples, runs, tasks))  # per sample, per task: which runs
    resampled = np.take_along_axis(np.broadcast_to(scores, (samples, runs, tasks)), picks, axis=1)
    values = np.array([statistic(sample) for sample in resampled])
    tail = (1.0 - confidence) / 2.0
    return float(np.quantile(values, tail)), float(np.quantile(values, 1.0 - tail))


def paired_scenario_bootstrap(a: np.ndarray, b: np.ndarray, samples: int = 10_000, seed: int = BOOTSTRAP_SEED,
                              confidence: float = 0.95) -> tuple[float, float, float]:
    """Mean of ``a - b`` and its percentile interval from resampling the *scenarios*: ``a`` and ``b`` are
    (runs, episodes) successes of two methods on the same scenarios (episode i = scenario i; runs: detection streams
    or seeds, averaged per scenario first). Pairing over runs alone covers their luck but not which scenarios were
    drawn; this covers both (a val gain that an interval over runs alone showed need not hold on other scenarios:
    docs/results.md)."""
    a, b = np.atleast_2d(np.asarray(a, dtype=np.float64)), np.atleast_2d(np.asarray(b, dtype=np.float64))
    if a.shape[1:] != b.shape[1:] or a.shape[1] < 1:
        raise ValueError(f"paired successes need the same scenarios, got shapes {a.shape} and {b.shape}")
    per_scenario = a.mean(axis=0) - b.mean(axis=0)
    rng = np.random.default_rng(seed)
    means = per_scenario[rng.integers(0, len(per_scenario), size=(samples, len(per_scenario)))].mean(axis=1)
    tail = (1.0 - confidence) / 2.0
    return float(per_scenario.mean()), float(np.quantile(means, tail)), float(np.quantile(means, 1.0 - tail))


def strata_of(scenarios) -> tuple[np.ndarray, list[str]]:
    """(episodes,) stratum index of each scenario and the strata's names ("night, rough sea", ...)."""
    from missions.scenario import SeaState, TimeOfDay

    times, seas = list(TimeOfDay), list(SeaState)
    index = np.array([int(s.conditions.time_of_day) * len(seas) + int(s.conditions.sea) for s in scenarios])
    names = [f"{t.name.lower()}, {s.name.lower()} sea" for t in times for s in seas]
    return index, names


def score_matrix(successes: list[np.ndarray], strata: np.ndarray, count: int) -> np.ndarray:
    """(runs, tasks) success rates of each run's per-episode successes on each of ``count`` strata (strata with no
    episode are left out)."""
    present = [k for k in range(count) if np.any(strata == k)]
    return np.array([[float(np.mean(np.asarray(run, dtype=np.float64)[strata == k])) for k in present]
                     for run in successes])


def aggregate(successes: list[np.ndarray], strata: np.ndarray, count: int) -> dict:
    """IQM with its stratified-bootstrap 95 % interval, and the mean over runs with its bootstrap interval, of per-run,
    per-episode successes (each (episodes,) in scenario order)."""
    scores = score_matrix(successes, strata, count)
    return {"iqm": interquartile_mean(scores), "iqm_ci95": list(stratified_bootstrap_ci(scores)),
            "mean": float(scores.mean()), "mean_ci95": list(stratified_bootstrap_ci(scores, np.mean)),
            "runs": scores.shape[0], "tasks": scores.shape[1]}
