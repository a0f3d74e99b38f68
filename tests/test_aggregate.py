"""rliable-style aggregates (``policies.evaluation.aggregate``): the interquartile mean and its stratified bootstrap
interval."""
from __future__ import annotations

import numpy as np
import pytest

from policies.evaluation.aggregate import (
    aggregate,
    interquartile_mean,
    paired_scenario_bootstrap,
    score_matrix,
    stratified_bootstrap_ci,
)


def test_interquartile_mean_is_the_trimmed_mean_with_fractional_cut_offs():
    # 10 scores: the quarter cut off each side is 2.5 scores, so 2 and 7 count half: (1 + 3 + 4 + 5 + 6 + 3.5) / 5
    assert interquartile_mean(np.arange(10)) == pytest.approx(4.5)
    assert interquartile_mean([0.0, 1.0, 1.0, 100.0]) == pytest.approx(1.0)  # an outlying run does not move it
    scipy_stats = pytest.importorskip("scipy.stats")
    scores = np.random.default_rng(3).uniform(size=(5, 12))  # 60 scores: the cut-offs are whole
    assert interquartile_mean(scores) == pytest.approx(scipy_stats.trim_mean(scores.ravel(), 0.25))


def test_stratified_bootstrap_resamples_runs_within_tasks_and_is_reproducible():
    same = np.tile([[0.2, 0.5, 0.9]], (5, 1))  # every run scores alike in each task: nothing to resample
    assert stratified_bootstrap_ci(same) == pytest.approx((interquartile_mean(same),) * 2)
    spread = np.random.default_rng(0).uniform(size=(5, 12))
    low, high = stratified_bootstrap_ci(spread)
    assert low < interquartile_mean(spread) < high
    assert (low, high) == stratified_bootstrap_ci(spread)  # seeded
    wider = stratified_bootstrap_ci(spread[:2])  # fewer runs, a wider interval
    assert wider[1] - wider[0] > high - low


def test_score_matrix_and_aggregate_from_per_episode_successes():
    strata = np.array([0, 0, 1, 1, 1, 3])  # stratum 2 has no episode: left out
    runs = [np.array([1, 0, 1, 1, 0, 1]), np.array([0, 0, 1, 0, 0, 1])]
    np.testing.assert_allclose(score_matrix(runs, strata, 4), [[0.5, 2 / 3, 1.0], [0.0, 1 / 3, 1.0]])
    result = aggregate(runs, strata, 4)
    assert (result["runs"], result["tasks"]) == (2, 3) and result["mean"] == pytest.approx(3.5 / 6)


def test_the_paired_bootstrap_resamples_scenarios_after_averaging_the_streams():
    """Each scenario's difference is averaged over the streams first, so what varies is which scenarios were drawn:
    a method that wins the same scenario on every stream gains exactly that scenario's share, with an interval from
    resampling the 4 scenarios; identical methods give (0, 0, 0); shapes that do not pair are refused."""
    b = np.array([[1, 0, 0, 1], [1, 0, 1, 1], [1, 0, 0, 1]])  # 3 streams x 4 scenarios
    a = b.copy()
    a[:, 1] = 1  # scenario 1 is found on every stream
    mean, low, high = paired_scenario_bootstrap(a, b)
    assert mean == pytest.approx(0.25) and low == pytest.approx(0.0) and high == pytest.approx(0.75)
    assert paired_scenario_bootstrap(a, b) == (mean, low, high)  # seeded
    assert paired_scenario_bootstrap(b, b) == (0.0, 0.0, 0.0)
    wide = np.random.default_rng(1).integers(0, 2, size=(5, 400))
    narrow = paired_scenario_bootstrap(np.clip(wide + 1, 0, 1), wide)  # +1 wherever wide had 0
    assert narrow[1] <= narrow[0] <= narrow[2] and narrow[2] - narrow[1] < 0.1
    with pytest.raises(ValueError, match="same scenarios"):
        paired_scenario_bootstrap(np.ones((2, 5)), np.ones((2, 6)))
