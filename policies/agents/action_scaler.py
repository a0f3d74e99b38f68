"""The affine map between a SAC actor's unit box and the environment's action box (with the action margin)."""
from __future__ import annotations

import math

import numpy as np
import torch


class ActionScaler:
    """Affine map between the policy's unit box [-1, 1]^d and the environment's box [low, high].

    The SarSearch action box is low = [-1, -1, 0, 0], high = [1, 1, 1, 1] (movement x / y, search intensity,
    camera zoom). Works on numpy arrays and torch tensors (same type out as in).

    ``margin`` > 0 maps the unit box onto the environment's box widened by ``margin`` x its range on each side,
    and clips to the environment's box (TrainConfig.action_margin): the policy then reaches a bound of the
    environment's range (sensor fully on, widest zoom, full speed) short of tanh's saturation, where its
    gradient still flows, and the actions beyond the bound all fly that bound.
    """

    def __init__(self, low: np.ndarray, high: np.ndarray, margin: float = 0.0):
        low = np.asarray(low, dtype=np.float32).reshape(-1)
        high = np.asarray(high, dtype=np.float32).reshape(-1)
        if low.shape != high.shape or not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
            raise ValueError(f"action bounds must be finite and of one shape, got {low} / {high}")
        if not np.all(high > low):
            raise ValueError(f"action bounds need high > low in every dimension, got {low} / {high}")
        if not (math.isfinite(margin) and margin >= 0.0):
            raise ValueError(f"action margin must be a finite number >= 0, got {margin}")
        self.low, self.high, self.margin = low, high, float(margin)
        widen = np.float32(margin) * (high - low)
        self.policy_low = low - widen  # where the unit box's -1 lands
        self._half_range = (high - low + 2.0 * widen) / 2.0
        self._low_t, self._high_t = torch.from_numpy(low.copy()), torch.from_numpy(high.copy())
        self._policy_low_t = torch.from_numpy(self.policy_low.copy())
        self._half_range_t = torch.from_numpy(self._half_range.copy())

    @property
    def dim(self) -> int:
        return int(self.low.shape[0])

    @property
    def half_range(self) -> np.ndarray:
        """Half the width of the box the unit box maps onto (the environment's, widened by the margin)."""
        return self._half_range.copy()

    def to_env(self, a_unit):
        """[-1, 1] -> [low, high]: ``low' + (a + 1) / 2 * (high' - low')`` over the widened box, clipped."""
        if isinstance(a_unit, torch.Tensor):
            action = self._policy_low_t.to(a_unit.dtype) + (a_unit + 1.0) * self._half_range_t.to(a_unit.dtype)
            return torch.clamp(action, self._low_t.to(a_unit.dtype), self._high_t.to(a_unit.dtype))
        return np.clip(self.policy_low + (np.asarray(a_unit) + 1.0) * self._half_range, self.low, self.high)

    def to_unit(self, a_env):
        """[low, high] -> [-1, 1], the inverse of :meth:`to_env` (over the environment's box)."""
        if isinstance(a_env, torch.Tensor):
            return (a_env - self._policy_low_t.to(a_env.dtype)) / self._half_range_t.to(a_env.dtype) - 1.0
        return (np.asarray(a_env) - self.policy_low) / self._half_range - 1.0

    def flown(self, a_unit: torch.Tensor) -> torch.Tensor:
        """The unit action the environment really flies for ``a_unit``: clipped to the environment's box.

        The critics learn from the buffer's (flown) actions, so the policy's actions go through this before the
        critics judge them: beyond a bound Q is flat, as it is in the environment. Without a margin: a_unit."""
        if self.margin == 0.0:
            return a_unit
        return self.to_unit(self.to_env(a_unit))
