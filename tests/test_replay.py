"""Prioritised replay (sum tree, sampling distribution, importance weights, ring buffer, exact resume), the
beta schedule and the running observation normaliser."""
from __future__ import annotations

import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from policies.agents.normalizer import RunningMeanStd
from policies.agents.prioritized_replay import PrioritizedReplayBuffer, SumTree, linear_beta

SCALAR_FIELDS = {"value": ((), np.float32)}
TRANSITION_FIELDS = {"obs": ((6,), np.float32), "action": ((2,), np.float32), "reward": ((), np.float32),
                     "step": ((), np.int64)}

# 99.9 % quantiles of the chi-square distribution (scipy.stats.chi2.ppf(0.999, df)).
CHI2_999 = {3: 16.266, 7: 24.322}


def reference_find(priorities: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Brute force: the leaf i with cumsum[i-1] <= v < cumsum[i]."""
    return np.searchsorted(np.cumsum(priorities), values, side="right")


def assert_find_matches(tree: SumTree, priorities: np.ndarray, values: np.ndarray) -> None:
    """find() agrees with the brute force, except for values within rounding distance of an interval edge."""
    found = tree.find(values)
    expected = reference_find(priorities, values)
    edges = np.concatenate([[0.0], np.cumsum(priorities)])
    above = np.clip(np.searchsorted(edges, values), 1, edges.size - 1)
    distance = np.minimum(np.abs(values - edges[above - 1]), np.abs(edges[above] - values))
    near_edge = distance < 1e-9 * max(tree.total, 1.0)
    mismatch = (found != expected) & ~near_edge
    assert not mismatch.any(), f"find {found[mismatch]} != brute force {expected[mismatch]} at {values[mismatch]}"
    assert np.all(priorities[found] > 0), "find returned a leaf of priority 0"


def fill(buffer: PrioritizedReplayBuffer, count: int) -> None:
    buffer.add(value=np.arange(count, dtype=np.float32))


def sample_counts(buffer: PrioritizedReplayBuffer, draws: int, batch_size: int = 200) -> np.ndarray:
    counts = np.zeros(len(buffer), dtype=np.int64)
    for _ in range(draws // batch_size):
        _, indices, _ = buffer.sample(batch_size, beta=0.4)
        counts += np.bincount(indices, minlength=len(buffer))
    return counts


def chi_square(counts: np.ndarray, probabilities: np.ndarray) -> float:
    expected = counts.sum() * probabilities
    return float(np.sum((counts - expected) ** 2 / expected))


# --------------------------------------------------------------------------------------------------- sum tree

@pytest.mark.parametrize("capacity", [1, 2, 5, 8, 100, 1000, 4097])
def test_sum_tree_total_and_find_match_cumsum_through_many_updates(capacity):
    rng = np.random.default_rng(capacity)
    tree = SumTree(capacity)
    priorities = np.zeros(capacity)
    written = np.zeros(capacity, dtype=bool)
    for _ in range(60):
        count = int(rng.integers(1, min(2 * capacity + 2, 500)))
        indices = rng.integers(0, capacity, count)
        # Priorities over six orders of magnitude, with some exact zeros.
        new = np.where(rng.random(count) < 0.1, 0.0, 10.0 ** rng.uniform(-3, 3, count))
        tree.update(indices, new)
        for index, priority in zip(indices, new):  # sequential writes: the last one wins
            priorities[index] = priority
        written[indices] = True
        assert tree.min == priorities[written].min()
        if priorities.sum() == 0:
            continue
        assert tree.total == pytest.approx(priorities.sum(), rel=1e-12)
        np.testing.assert_array_equal(tree[np.arange(capacity)], priorities)
        values = rng.uniform(0, tree.total, 500)
        mids = (np.cumsum(priorities) - priorities / 2)[priorities > 0]
        assert_find_matches(tree, priorities, np.concatenate([values, mids]))
        # The very top of the range (and beyond it, from rounding in callers) lands on a real leaf.
        top = tree.find(np.array([np.nextafter(tree.total, 0.0), tree.total, tree.total * 1.01]))
        assert np.all(top == np.flatnonzero(priorities)[-1])


@settings(max_examples=150, deadline=None)
@given(capacity=st.integers(1, 70),
       updates=st.lists(st.tuples(st.integers(0, 10_000), st.floats(0.0, 1e4, allow_nan=False)), min_size=1,
                        max_size=200),
       fractions=st.lists(st.floats(0.0, 1.0, exclude_max=True), min_size=1, max_size=20))
def test_sum_tree_property(capacity, updates, fractions):
    tree = SumTree(capacity)
    priorities = np.zeros(capacity)
    written = np.zeros(capacity, dtype=bool)
    indices = np.array([index % capacity for index, _ in updates])
    values = np.array([priority for _, priority in updates])
    tree.update(indices, values)
    for index, priority in zip(indices, values):
        priorities[index] = priority
        written[index] = True
    assert tree.total == pytest.approx(priorities.sum(), rel=1e-12, abs=1e-300)
    assert tree.min == priorities[written].min()
    if tree.total > 0:
        assert_find_matches(tree, priorities, np.array(fractions) * tree.total)


def test_sum_tree_repeated_indices_last_write_wins_and_rejects_bad_input():
    tree = SumTree(6)
    tree.update(np.array([2, 4, 2, 2, 4]), np.array([1.0, 2.0, 3.0, 7.0, 5.0]))
    assert tree[2] == 7.0 and tree[4] == 5.0 and tree.total == 12.0
    with pytest.raises(IndexError):
        tree.update(np.array([6]), np.array([1.0]))
    with pytest.raises(ValueError):
        tree.update(np.array([0]), np.array([np.nan]))
    with pytest.raises(ValueError):
        tree.update(np.array([0]), np.array([-1.0]))
    with pytest.raises(ValueError):
        SumTree(4).find(np.array([0.0]))  # nothing to find in an all-zero tree


# ------------------------------------------------------------------------------------------ sampling distribution

def test_sampling_frequencies_are_proportional_to_priority_to_the_alpha():
    buffer = PrioritizedReplayBuffer(8, SCALAR_FIELDS, alpha=0.6, seed=1)
    fill(buffer, 8)
    td = np.array([0.01, 0.1, 0.5, 1.0, 2.0, 5.0, 20.0, 100.0])
    buffer.update_priorities(np.arange(8), td)
    probabilities = (td + buffer.eps) ** 0.6 / np.sum((td + buffer.eps) ** 0.6)
    counts = sample_counts(buffer, 200_000)
    assert chi_square(counts, probabilities) < CHI2_999[7]
    np.testing.assert_allclose(counts / counts.sum(), probabilities, rtol=0.05)
    # The same draws are far from proportional to p itself (alpha = 1): the test can tell them apart.
    linear = (td + buffer.eps) / np.sum(td + buffer.eps)
    assert chi_square(counts, linear) > 1000 * CHI2_999[7]


def test_alpha_zero_samples_uniformly_whatever_the_priorities():
    buffer = PrioritizedReplayBuffer(8, SCALAR_FIELDS, alpha=0.0, seed=2)
    fill(buffer, 8)
    buffer.update_priorities(np.arange(8), np.array([1e-4, 1e-2, 1.0, 10.0, 100.0, 1e3, 1e4, 1e5]))
    counts = sample_counts(buffer, 200_000)
    assert chi_square(counts, np.full(8, 1 / 8)) < CHI2_999[7]
    _, _, weights = buffer.sample(64, beta=1.0)
    np.testing.assert_array_equal(weights, 1.0)  # uniform sampling needs no correction


def test_update_priorities_changes_subsequent_sampling():
    buffer = PrioritizedReplayBuffer(4, SCALAR_FIELDS, alpha=1.0, seed=3)
    fill(buffer, 4)
    before = sample_counts(buffer, 40_000)
    assert chi_square(before, np.full(4, 0.25)) < CHI2_999[3]  # all new items share the initial priority 1
    buffer.update_priorities(np.arange(4), np.array([1.0, 1.0, 1.0, 97.0]))
    after = sample_counts(buffer, 40_000)
    probabilities = np.array([1.0, 1.0, 1.0, 97.0]) + buffer.eps
    assert chi_square(after, probabilities / probabilities.sum()) < CHI2_999[3]
    assert after[3] / after.sum() > 0.95


def test_stratified_sampling_draws_one_value_per_segment():
    # Four equal priorities and a batch of 4: one draw per segment means each item exactly once.
    buffer = PrioritizedReplayBuffer(4, SCALAR_FIELDS, seed=4)
    fill(buffer, 4)
    for _ in range(50):
        _, indices, _ = buffer.sample(4, beta=0.5)
        np.testing.assert_array_equal(indices, np.arange(4))


# ------------------------------------------------------------------------------------------- importance weights

def test_importance_weights_match_the_formula_with_max_over_stored_items():
    alpha, beta = 0.5, 0.4
    buffer = PrioritizedReplayBuffer(5, SCALAR_FIELDS, alpha=alpha, eps=1e-6, seed=5)
    fill(buffer, 5)
    td = np.array([0.25, 1.0, 4.0, 9.0, 16.0])
    buffer.update_priorities(np.arange(5), td)
    p = td + 1e-6
    probabilities = p ** alpha / np.sum(p ** alpha)
    raw = (5 * probabilities) ** -beta
    expected = raw / raw.max()  # max over all 5 stored items (the paper), i.e. the least likely item 0
    assert expected[0] == 1.0 and expected[4] == pytest.approx((0.25 / 16.0) ** (alpha * beta), rel=1e-5)
    seen = np.zeros(5, dtype=bool)
    for _ in range(300):
        batch, indices, weights = buffer.sample(3, beta=beta)
        assert weights.dtype == np.float32 and weights.max() <= 1.0
        np.testing.assert_allclose(weights, expected[indices], rtol=1e-6)
        np.testing.assert_array_equal(batch["value"], indices.astype(np.float32))
        if 0 not in indices:  # normalised by the stored items, not the batch: no weight reaches 1
            assert weights.max() < 1.0
        seen[indices] = True
    assert seen.all()


def test_importance_weight_max_is_one_and_beta_zero_gives_ones():
    buffer = PrioritizedReplayBuffer(50, SCALAR_FIELDS, alpha=0.7, seed=6)
    fill(buffer, 50)
    buffer.update_priorities(np.arange(50), np.linspace(0.5, 3.0, 50))
    _, indices, weights = buffer.sample(2000, beta=0.6)
    assert 0 in indices and weights[indices == 0].max() == 1.0 and weights.max() == 1.0
    _, _, weights = buffer.sample(64, beta=0.0)
    np.testing.assert_array_equal(weights, 1.0)


def test_new_items_get_the_current_max_priority():
    buffer = PrioritizedReplayBuffer(10, SCALAR_FIELDS, alpha=0.6, seed=7)
    fill(buffer, 3)
    np.testing.assert_array_equal(buffer.tree[np.arange(3)], 1.0)  # before any update: priority 1
    buffer.update_priorities(np.array([0, 1, 2]), np.array([0.5, 7.0, 0.1]))
    buffer.update_priorities(np.array([1]), np.array([0.2]))  # the max stays the largest ever seen
    fill(buffer, 2)
    assert buffer.max_priority == pytest.approx(7.0 + 1e-6)
    np.testing.assert_allclose(buffer.tree[np.array([3, 4])], (7.0 + 1e-6) ** 0.6, rtol=1e-12)
    assert buffer.tree[1] == pytest.approx((0.2 + 1e-6) ** 0.6, rel=1e-12)


# ------------------------------------------------------------------------------------------------- ring buffer

def test_ring_overwrite_keeps_the_newest_transitions():
    buffer = PrioritizedReplayBuffer(5, TRANSITION_FIELDS, seed=8)
    step = 0
    for chunk in (3, 4, 1, 5, 2):
        steps = np.arange(step, step + chunk)
        buffer.add(obs=np.repeat(steps[:, None], 6, axis=1).astype(np.float32), action=np.zeros((chunk, 2)),
                   reward=steps.astype(np.float32), step=steps)
        step += chunk
        assert len(buffer) == min(step, 5)
        assert sorted(buffer.data["step"][:len(buffer)]) == list(range(max(0, step - 5), step))
    # A chunk longer than the capacity leaves what adding its rows one by one would have left.
    one_by_one = PrioritizedReplayBuffer(5, SCALAR_FIELDS, seed=0)
    at_once = PrioritizedReplayBuffer(5, SCALAR_FIELDS, seed=0)
    fill(one_by_one, 2)
    fill(at_once, 2)
    for value in range(12):
        one_by_one.add(value=np.array([value], dtype=np.float32))
    at_once.add(value=np.arange(12, dtype=np.float32))
    np.testing.assert_array_equal(one_by_one.data["value"], at_once.data["value"])
    assert one_by_one.position == at_once.position and len(at_once) == 5
    batch, indices, _ = buffer.sample(64, beta=0.5)
    np.testing.assert_array_equal(batch["obs"][:, 0], batch["step"])  # rows stay aligned across fields


def test_overwritten_items_take_the_max_priority_again():
    buffer = PrioritizedReplayBuffer(3, SCALAR_FIELDS, alpha=1.0, seed=9)
    fill(buffer, 3)
    buffer.update_priorities(np.arange(3), np.array([4.0, 0.1, 0.1]))
    fill(buffer, 1)  # overwrites row 0
    assert buffer.tree[0] == pytest.approx(4.0 + 1e-6)
    buffer.update_priorities(np.array([0]), np.array([0.1]))
    assert buffer.tree.min == pytest.approx(0.1 + 1e-6)


def test_add_and_update_reject_malformed_input():
    buffer = PrioritizedReplayBuffer(4, TRANSITION_FIELDS, seed=10)
    good = dict(obs=np.zeros((2, 6)), action=np.zeros((2, 2)), reward=np.zeros(2), step=np.zeros(2))
    with pytest.raises(KeyError):
        buffer.add(**{k: v for k, v in good.items() if k != "reward"})
    with pytest.raises(ValueError):
        buffer.add(**{**good, "obs": np.zeros((2, 5))})
    with pytest.raises(ValueError):
        buffer.add(**{**good, "reward": np.zeros(3)})
    with pytest.raises(ValueError):
        buffer.sample(2, beta=0.5)  # empty
    buffer.add(**good)
    with pytest.raises(IndexError):
        buffer.update_priorities(np.array([2]), np.array([1.0]))  # row 2 holds nothing yet
    with pytest.raises(ValueError):
        buffer.update_priorities(np.array([0]), np.array([np.inf]))


# ------------------------------------------------------------------------------------- determinism and resume

def run_steps(buffer: PrioritizedReplayBuffer, steps: int, data_seed: int) -> list:
    """A training-loop-like sequence of adds, samples and priority updates; returns every sample."""
    data_rng = np.random.default_rng(data_seed)
    samples = []
    for _ in range(steps):
        count = 3
        buffer.add(obs=data_rng.standard_normal((count, 6)).astype(np.float32),
                   action=data_rng.uniform(-1, 1, (count, 2)).astype(np.float32),
                   reward=data_rng.standard_normal(count).astype(np.float32),
                   step=data_rng.integers(0, 1000, count))
        batch, indices, weights = buffer.sample(16, beta=0.5)
        buffer.update_priorities(indices, data_rng.standard_normal(16) * 2)
        samples.append((batch, indices, weights))
    return samples


def assert_same_samples(first: list, second: list) -> None:
    assert len(first) == len(second)
    for (batch_a, indices_a, weights_a), (batch_b, indices_b, weights_b) in zip(first, second):
        np.testing.assert_array_equal(indices_a, indices_b)
        np.testing.assert_array_equal(weights_a, weights_b)
        for name in batch_a:
            np.testing.assert_array_equal(batch_a[name], batch_b[name])


def test_same_seed_same_calls_same_samples():
    a = run_steps(PrioritizedReplayBuffer(64, TRANSITION_FIELDS, seed=11), 40, data_seed=0)
    b = run_steps(PrioritizedReplayBuffer(64, TRANSITION_FIELDS, seed=11), 40, data_seed=0)
    c = run_steps(PrioritizedReplayBuffer(64, TRANSITION_FIELDS, seed=12), 40, data_seed=0)
    assert_same_samples(a, b)
    assert any(not np.array_equal(x[1], y[1]) for x, y in zip(a, c))


@pytest.mark.parametrize("steps_before", [5, 40])  # a partly filled and a wrapped-around (full) buffer
def test_state_dict_round_trip_resumes_exactly(steps_before):
    uninterrupted = PrioritizedReplayBuffer(64, TRANSITION_FIELDS, alpha=0.6, seed=13)
    run_steps(uninterrupted, steps_before, data_seed=1)
    state = uninterrupted.state_dict()
    pickled = pickle.dumps(state)  # as a checkpoint file would hold it
    # Keep going after the snapshot: the state must be a copy, not a view of the live arrays.
    expected = run_steps(uninterrupted, 30, data_seed=2)

    for saved in (state, pickle.loads(pickled)):
        resumed = PrioritizedReplayBuffer(64, TRANSITION_FIELDS, alpha=0.6, seed=999)
        run_steps(resumed, 7, data_seed=3)  # whatever it held before is replaced
        resumed.load_state_dict(saved)
        assert_same_samples(expected, run_steps(resumed, 30, data_seed=2))
        assert resumed.max_priority == uninterrupted.max_priority
        assert resumed.position == uninterrupted.position and len(resumed) == len(uninterrupted)
        np.testing.assert_array_equal(resumed.tree._sum, uninterrupted.tree._sum)
        np.testing.assert_array_equal(resumed.tree._min, uninterrupted.tree._min)


def test_load_state_dict_rejects_a_different_buffer():
    state = PrioritizedReplayBuffer(8, SCALAR_FIELDS, alpha=0.6).state_dict()
    with pytest.raises(ValueError):
        PrioritizedReplayBuffer(16, SCALAR_FIELDS, alpha=0.6).load_state_dict(state)
    with pytest.raises(ValueError):
        PrioritizedReplayBuffer(8, {"value": ((2,), np.float32)}, alpha=0.6).load_state_dict(state)
    with pytest.raises(ValueError):
        PrioritizedReplayBuffer(8, SCALAR_FIELDS, alpha=0.5).load_state_dict(state)


# ------------------------------------------------------------------------------------------------- beta schedule

def test_linear_beta_anneals_from_start_to_one_and_clips():
    assert linear_beta(0, 1000, 0.4) == pytest.approx(0.4)
    assert linear_beta(500, 1000, 0.4) == pytest.approx(0.7)
    assert linear_beta(1000, 1000, 0.4) == pytest.approx(1.0)
    assert linear_beta(5000, 1000, 0.4) == pytest.approx(1.0)
    assert linear_beta(-10, 1000, 0.4) == pytest.approx(0.4)
    assert linear_beta(0, 0, 0.4) == 1.0


# -------------------------------------------------------------------------------------------------- performance

def test_running_mean_std_matches_numpy_over_chunks():
    rng = np.random.default_rng(15)
    data = rng.normal(loc=[5.0, -3.0, 0.0], scale=[2.0, 0.1, 30.0], size=(20_000, 3))
    stats = RunningMeanStd(shape=(3,))
    for chunk in np.split(data, [1, 8, 1000, 1001, 7000, 19_999]):
        stats.update(chunk)
    np.testing.assert_allclose(stats.mean, data.mean(axis=0), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(stats.var, data.var(axis=0), rtol=1e-6, atol=1e-6)
    assert stats.count == pytest.approx(20_000 + 1e-4)


def test_running_mean_std_normalize_standardises_and_clips():
    stats = RunningMeanStd(shape=(2,), clip=5.0)
    # Enough data that the epsilon pseudo-count is negligible: mean (2, 10), variance (8/3, ~0).
    stats.update(np.tile([[0.0, 10.0], [2.0, 10.0], [4.0, 10.0]], (10_000, 1)))
    x = np.array([[2.0 + np.sqrt(8 / 3), 10.0], [1000.0, 10.1], [-1000.0, 9.9], [3.0, 10.0]])
    out = stats.normalize(x)
    assert out.dtype == np.float32
    np.testing.assert_allclose(out, np.clip((x - stats.mean) / np.sqrt(stats.var + 1e-8), -5.0, 5.0), rtol=1e-6)
    np.testing.assert_allclose(out[0], [1.0, 0.0], atol=1e-3)
    # Far outliers and any change of a (nearly) constant input saturate at the clip instead of exploding.
    np.testing.assert_array_equal(out[1:3], [[5.0, 5.0], [-5.0, -5.0]])
    assert np.all(np.abs(stats.normalize(np.random.default_rng(0).normal(0, 1e6, (100, 2)))) <= 5.0)
    with pytest.raises(ValueError):
        stats.update(np.array([[np.nan, 0.0]]))
    with pytest.raises(ValueError):
        stats.update(np.zeros((4, 3)))


def test_running_mean_std_state_dict_round_trip():
    rng = np.random.default_rng(16)
    stats = RunningMeanStd(shape=(4,))
    stats.update(rng.normal(size=(100, 4)))
    restored = RunningMeanStd(shape=(4,))
    restored.load_state_dict(pickle.loads(pickle.dumps(stats.state_dict())))
    x = rng.normal(size=(10, 4))
    np.testing.assert_array_equal(restored.normalize(x), stats.normalize(x))
    batch = rng.normal(size=(50, 4))
    stats.update(batch)
    restored.update(batch)
    np.testing.assert_array_equal(restored.mean, stats.mean)
    np.testing.assert_array_equal(restored.var, stats.var)
