"""Running observation statistics for standardising network inputs (frozen and shipped at export)."""
from __future__ import annotations

import numpy as np

VARIANCE_FLOOR = 1e-8
"""Added to the variance before the square root, so that a constant feature divides by 1e-4, not 0."""


class RunningMeanStd:
    """Running mean and variance (Chan et al. parallel update) of observations, for standardising inputs.

    Like Stable-Baselines3's ``RunningMeanStd``: the statistics start as mean 0, variance 1 with a pseudo-count
    ``epsilon``, so ``normalize`` is defined before any data arrives, and that prior's weight is negligible after
    the first real batch (1e-4 against thousands of observations). Statistics are kept in float64 so that
    millions of updates do not accumulate rounding; ``normalize`` returns float32 for the networks. Training
    updates the statistics; export copies ``mean`` and ``var`` into the artifact, where they stay frozen.
    """

    def __init__(self, shape: tuple[int, ...], epsilon: float = 1e-4, clip: float = 10.0):
        if not epsilon > 0.0:
            raise ValueError(f"epsilon must be positive, got {epsilon}")
        if not clip > 0.0:
            raise ValueError(f"clip must be positive, got {clip}")
        self.shape = tuple(int(d) for d in shape)
        self.epsilon = float(epsilon)
        self.clip = float(clip)
        self.mean = np.zeros(self.shape, dtype=np.float64)
        self.var = np.ones(self.shape, dtype=np.float64)
        self.count = float(epsilon)

    def update(self, batch: np.ndarray) -> None:
        """Fold in a batch of observations of shape ``(B, *shape)``."""
        batch = np.asarray(batch, dtype=np.float64)
        if batch.shape[1:] != self.shape:
            raise ValueError(f"RunningMeanStd expects batches of shape (B, {self.shape}), got {batch.shape}")
        if batch.shape[0] == 0:
            return
        if not np.all(np.isfinite(batch)):
            # One NaN would poison the statistics for the rest of the run (and the exported policy).
            raise ValueError("RunningMeanStd.update got non-finite observations")
        self._merge(batch.mean(axis=0), batch.var(axis=0), batch.shape[0])

    def _merge(self, batch_mean: np.ndarray, batch_var: np.ndarray, batch_count: int) -> None:
        # Chan, Golub & LeVeque: combine the two groups' sums of squared deviations instead of raw moments,
        # which stays accurate when the mean is large compared with the spread.
        delta = batch_mean - self.mean
        total = self.count + batch_count
        m2 = self.var * self.count + batch_var * batch_count + delta ** 2 * self.count * batch_count / total
        self.mean = self.mean + delta * batch_count / total
        self.var = m2 / total
        self.count = total

    def normalize(self, x: np.ndarray) -> np.ndarray:
        """``(x - mean) / sqrt(var + 1e-8)`` clipped to ``[-clip, clip]``, as float32 (any leading dims).

        ``x`` may hold only the first D features (the meta-controller sees a prefix of the observation)."""
        x = np.asarray(x, dtype=np.float64)
        d = x.shape[-1]
        standardised = (x - self.mean[..., :d]) / self.std()[..., :d]
        return np.clip(standardised, -self.clip, self.clip).astype(np.float32)

    def std(self) -> np.ndarray:
        """``sqrt(var + 1e-8)``, the divisor of :meth:`normalize` (float64; the export freezes it as is)."""
        return np.sqrt(self.var + VARIANCE_FLOOR)

    def state_dict(self) -> dict:
        return {"mean": self.mean.copy(), "var": self.var.copy(), "count": self.count,
                "epsilon": self.epsilon, "clip": self.clip}

    def load_state_dict(self, state: dict) -> None:
        mean = np.asarray(state["mean"], dtype=np.float64)
        var = np.asarray(state["var"], dtype=np.float64)
        if mean.shape != self.shape or var.shape != self.shape:
            raise ValueError(f"normaliser state has shape {mean.shape}, expected {self.shape}")
        self.mean, self.var = mean.copy(), var.copy()
        self.count = float(state["count"])
        self.epsilon = float(state.get("epsilon", self.epsilon))
        self.clip = float(state.get("clip", self.clip))
