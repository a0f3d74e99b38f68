"""Proportional prioritised experience replay (Schaul et al. 2016) on an array-based sum tree.

The buffer stores named fields (``obs``, ``action``, ``reward``, ...) in preallocated numpy arrays and samples
transitions with probability P(i) = p_i^alpha / sum_k p_k^alpha; the agents learn from them as a
:class:`policies.agents.replay_batch.ReplayBatch` (``sample_transitions``). Everything per sample is vectorised: a
minibatch is drawn by one descent of the tree that loops over its depth (18 levels for 200,000 items), never over
the batch. All randomness comes from the buffer's own seeded ``numpy.random.Generator``, which is part of
``state_dict()``, so a resumed run draws exactly the samples an uninterrupted one would have drawn.
"""
from __future__ import annotations

import copy

import numpy as np

from policies.agents.replay_batch import ReplayBatch


class SumTree:
    """Binary sum tree over ``capacity`` leaf priorities (array-based, capacity rounded up to a power of 2).

    Node 1 is the root, node ``n`` has children ``2n`` and ``2n + 1``, and leaf ``i`` lives at node
    ``leaf_offset + i``. Leaves past ``capacity`` stay at priority 0 and are never found. Besides the sums, the
    tree keeps the minimum over the leaves that were ever written (unwritten leaves count as +inf): the replay
    buffer needs the smallest stored priority to normalise importance weights.
    """

    def __init__(self, capacity: int):
        if isinstance(capacity, bool) or not isinstance(capacity, (int, np.integer)) or capacity < 1:
            raise ValueError(f"SumTree capacity must be a positive integer, got {capacity!r}")
        self.capacity = int(capacity)
        self.depth = (self.capacity - 1).bit_length()  # levels below the root
        self.leaf_offset = 1 << self.depth
        # float64 sums: float32 would lose the small priorities once the total grows over 200,000 leaves.
        self._sum = np.zeros(2 * self.leaf_offset, dtype=np.float64)
        self._min = np.full(2 * self.leaf_offset, np.inf, dtype=np.float64)

    def update(self, indices: np.ndarray, priorities: np.ndarray) -> None:
        """Set the priorities of leaves ``indices``; with repeated indices the last write wins."""
        indices = np.asarray(indices, dtype=np.int64).reshape(-1)
        priorities = np.broadcast_to(np.asarray(priorities, dtype=np.float64), indices.shape)
        if indices.size == 0:
            return
        if indices.min() < 0 or indices.max() >= self.capacity:
            raise IndexError(f"SumTree leaf indices must be in [0, {self.capacity}), got {indices}")
        if not np.all(np.isfinite(priorities)) or priorities.min() < 0.0:
            raise ValueError("SumTree priorities must be finite and non-negative")
        # numpy does not promise an order for fancy assignment with repeated indices, so keep the last
        # occurrence of each index explicitly.
        if np.unique(indices).size != indices.size:
            last = indices.size - 1 - np.unique(indices[::-1], return_index=True)[1]
            indices, priorities = indices[last], priorities[last]
        nodes = indices + self.leaf_offset
        self._sum[nodes] = priorities
        self._min[nodes] = priorities
        # Recompute each ancestor from its two children rather than adding deltas: the tree then never drifts
        # from its leaves, and a rebuild from the leaves (load_state_dict) reproduces it bit for bit. Repeated
        # parents just write the same value twice.
        for _ in range(self.depth):
            nodes = nodes >> 1
            left, right = 2 * nodes, 2 * nodes + 1
            self._sum[nodes] = self._sum[left] + self._sum[right]
            self._min[nodes] = np.minimum(self._min[left], self._min[right])

    @property
    def total(self) -> float:
        """Sum of all leaf priorities."""
        return float(self._sum[1])

    @property
    def min(self) -> float:
        """Smallest priority among the leaves ever written (+inf if none was)."""
        return float(self._min[1])

    def find(self, values: np.ndarray) -> np.ndarray:
        """Leaf index whose prefix-sum interval ``[c_{i-1}, c_i)`` contains each value in ``[0, total)``.

        Rounding can leave a value a hair past the sum of the subtree it was sent into; the descent then turns
        left instead of entering an empty (priority 0) subtree, so a leaf with priority 0 is never returned,
        even for values at or beyond ``total``.
        """
        if not self._sum[1] > 0.0:
            raise ValueError("SumTree.find needs a positive total priority")
        values = np.maximum(np.asarray(values, dtype=np.float64), 0.0)
        nodes = np.ones(values.shape, dtype=np.int64)
        for _ in range(self.depth):
            left = 2 * nodes
            left_sum = self._sum[left]
            go_right = (values >= left_sum) & (self._sum[left + 1] > 0.0)
            values = values - np.where(go_right, left_sum, 0.0)
            nodes = left + go_right
        return nodes - self.leaf_offset

    def __getitem__(self, indices) -> np.ndarray | float:
        """Leaf priorities at ``indices`` (an int gives a float)."""
        indices = np.asarray(indices, dtype=np.int64)
        if indices.size and (indices.min() < 0 or indices.max() >= self.capacity):
            raise IndexError(f"SumTree leaf indices must be in [0, {self.capacity})")
        priorities = self._sum[indices + self.leaf_offset]
        return float(priorities) if indices.ndim == 0 else priorities

    def leaves(self, count: int | None = None) -> np.ndarray:
        """Copy of the first ``count`` (default: all ``capacity``) leaf priorities."""
        count = self.capacity if count is None else count
        return self._sum[self.leaf_offset:self.leaf_offset + count].copy()

    def rebuild(self, priorities: np.ndarray) -> None:
        """Reset the tree to leaves ``priorities`` (the first ``len(priorities)`` leaves; the rest unwritten)."""
        priorities = np.asarray(priorities, dtype=np.float64).reshape(-1)
        if priorities.size > self.capacity:
            raise ValueError(f"{priorities.size} priorities do not fit a SumTree of capacity {self.capacity}")
        self._sum.fill(0.0)
        self._min.fill(np.inf)
        self.update(np.arange(priorities.size), priorities)


class PrioritizedReplayBuffer:
    """Proportional prioritised experience replay (Schaul et al. 2016).

    Sampling probability P(i) = p_i^alpha / sum_k p_k^alpha, with p_i = |TD error_i| + eps. Importance weights
    are w_i = (N P(i))^-beta / max_j w_j where the max runs over *all stored items* (as in the paper's
    Algorithm 1), not only the batch: max_j w_j belongs to the item with the smallest priority, which the sum
    tree tracks, so w_i = (p_i^alpha / min_j p_j^alpha)^-beta. Weights are therefore <= 1, equal to 1 only for
    the least likely stored item, and do not depend on which other items happen to share the batch.

    New items get the largest priority seen so far (1.0 before any update), so every transition is replayed at
    least about once before its TD error is known. The running max never decreases, also when the item that
    set it is overwritten (as in the paper and OpenAI baselines).

    Each field is declared as ``name: (shape, dtype)`` and stored in a ring buffer of ``capacity`` rows.
    """

    def __init__(self, capacity: int, fields: dict[str, tuple[tuple[int, ...], np.dtype]], alpha: float = 0.6,
                 eps: float = 1e-6, seed: int = 0):
        if isinstance(capacity, bool) or not isinstance(capacity, (int, np.integer)) or capacity < 1:
            raise ValueError(f"PrioritizedReplayBuffer capacity must be a positive integer, got {capacity!r}")
        if not fields:
            raise ValueError("PrioritizedReplayBuffer needs at least one field")
        if not 0.0 <= alpha <= 1.0:
            raise ValueError(f"alpha must be in [0, 1], got {alpha}")
        if not (np.isfinite(eps) and eps > 0.0):
            raise ValueError(f"eps must be positive (a zero priority would make its importance weight infinite), "
                             f"got {eps}")
        self.capacity = int(capacity)
        self.fields = {name: (tuple(int(d) for d in shape), np.dtype(dtype)) for name, (shape, dtype) in fields.items()}
        self.alpha = float(alpha)
        self.eps = float(eps)
        self.rng = np.random.default_rng(seed)
        self.data = {name: np.zeros((self.capacity, *shape), dtype=dtype)
                     for name, (shape, dtype) in self.fields.items()}
        self.tree = SumTree(self.capacity)
        self.position = 0  # next row to write
        self.size = 0
        self.max_priority = 1.0  # in |td| + eps units, before the alpha exponent

    def __len__(self) -> int:
        return self.size

    def add(self, **items: np.ndarray) -> None:
        """Append B transitions at once: every declared field, each with a leading batch dimension B.

        When full, the oldest rows are overwritten. A chunk longer than the capacity keeps its newest rows,
        exactly as adding its transitions one by one would.
        """
        if set(items) != set(self.fields):
            raise KeyError(f"add() needs exactly the fields {sorted(self.fields)}, got {sorted(items)}")
        arrays = {name: np.asarray(value) for name, value in items.items()}
        count = None
        for name, value in arrays.items():
            shape = self.fields[name][0]
            if value.ndim != len(shape) + 1 or value.shape[1:] != shape:
                raise ValueError(f"field {name!r} must have shape (B, {', '.join(map(str, shape))}), got {value.shape}")
            if count is None:
                count = value.shape[0]
            elif value.shape[0] != count:
                raise ValueError(f"all fields must have the same batch size, field {name!r} has {value.shape[0]} "
                                 f"rows instead of {count}")
        if count == 0:
            return
        kept = min(count, self.capacity)
        rows = (self.position + count - kept + np.arange(kept)) % self.capacity
        for name, value in arrays.items():
            self.data[name][rows] = value[count - kept:]
        self.tree.update(rows, np.full(kept, self.max_priority ** self.alpha))
        self.position = (self.position + count) % self.capacity
        self.size = min(self.size + count, self.capacity)

    def sample(self, batch_size: int, beta: float) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
        """Draw ``batch_size`` transitions: ``(batch, indices, weights)`` with float32 importance weights.

        Stratified as in the paper: the total priority is cut into ``batch_size`` equal segments and one
        uniform value is drawn in each, which lowers the variance of a batch while each draw's marginal stays
        P(i). An item whose priority spans several segments can appear more than once.
        """
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        if batch_size < 1:
            raise ValueError(f"batch_size must be positive, got {batch_size}")
        if not 0.0 <= beta <= 1.0:
            raise ValueError(f"beta must be in [0, 1], got {beta}")
        total = self.tree.total
        segment = total / batch_size
        values = (np.arange(batch_size) + self.rng.random(batch_size)) * segment
        indices = self.tree.find(values)
        # (N P_i)^-beta / (N P_min)^-beta: N and the total cancel, which keeps the ratio exact and the max at 1.
        weights = (self.tree[indices] / self.tree.min) ** -beta
        batch = {name: array[indices] for name, array in self.data.items()}
        return batch, indices, weights.astype(np.float32)

    def sample_transitions(self, batch_size: int, beta: float) -> ReplayBatch:
        """:meth:`sample` of a buffer of transitions (the fields of :class:`ReplayBatch`), as one batch that carries
        its importance weights and the rows it came from."""
        fields, indices, weights = self.sample(batch_size, beta)
        return ReplayBatch.from_fields(fields, weights, indices)

    def update_priorities(self, indices: np.ndarray, td_errors: np.ndarray) -> None:
        """Set p = |td| + eps for sampled ``indices`` (repeated indices: the last one wins)."""
        indices = np.asarray(indices, dtype=np.int64).reshape(-1)
        td_errors = np.asarray(td_errors, dtype=np.float64).reshape(-1)
        if indices.shape != td_errors.shape:
            raise ValueError(f"{indices.size} indices but {td_errors.size} TD errors")
        if indices.size == 0:
            return
        if indices.min() < 0 or indices.max() >= self.size:
            raise IndexError(f"indices must be in [0, {self.size}) (the stored items)")
        if not np.all(np.isfinite(td_errors)):
            raise ValueError("TD errors must be finite (a NaN priority would corrupt the whole sum tree)")
        priorities = np.abs(td_errors) + self.eps
        self.tree.update(indices, priorities ** self.alpha)
        self.max_priority = max(self.max_priority, float(priorities.max()))

    def state_dict(self) -> dict:
        """A snapshot (copies, not views) from which ``load_state_dict`` resumes exactly.

        Holds the filled rows of every field, the filled leaves of the sum tree (p^alpha), the write
        position, the size, the running max priority and the generator's ``bit_generator.state``. Only numpy
        arrays and plain Python values, so it pickles (``torch.save``) as is.
        """
        return {
            "capacity": self.capacity,
            "fields": {name: (list(shape), dtype.str) for name, (shape, dtype) in self.fields.items()},
            "alpha": self.alpha,
            "eps": self.eps,
            "data": {name: array[:self.size].copy() for name, array in self.data.items()},
            "priorities": self.tree.leaves(self.size),
            "position": self.position,
            "size": self.size,
            "max_priority": self.max_priority,
            "rng_state": copy.deepcopy(self.rng.bit_generator.state),
        }

    def load_state_dict(self, state: dict) -> None:
        """Restore a ``state_dict()`` into a buffer built with the same capacity, fields, alpha and eps."""
        fields = {name: (tuple(shape), np.dtype(dtype)) for name, (shape, dtype) in state["fields"].items()}
        if state["capacity"] != self.capacity or fields != self.fields:
            raise ValueError("replay state was saved from a buffer with a different capacity or fields")
        if state["alpha"] != self.alpha or state["eps"] != self.eps:
            raise ValueError(f"replay state has alpha={state['alpha']}, eps={state['eps']}; this buffer has "
                             f"alpha={self.alpha}, eps={self.eps} (stored priorities are already p^alpha)")
        size = int(state["size"])
        for name, array in self.data.items():
            array[:size] = state["data"][name]
            array[size:] = 0
        # Rebuilding from the leaves gives the same tree bit for bit: every internal node is always the sum
        # (and min) of its current children, computed in the same order.
        self.tree.rebuild(state["priorities"])
        self.position = int(state["position"])
        self.size = size
        self.max_priority = float(state["max_priority"])
        self.rng.bit_generator.state = copy.deepcopy(state["rng_state"])


def linear_beta(step: int, total_steps: int, beta_start: float) -> float:
    """Importance-weight exponent annealed linearly from ``beta_start`` at step 0 to 1.0 at ``total_steps``."""
    if total_steps <= 0:
        return 1.0
    fraction = min(max(step / total_steps, 0.0), 1.0)
    return beta_start + fraction * (1.0 - beta_start)
