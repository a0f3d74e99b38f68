"""The small tools of both SAC agents' common base (``policies.agents.off_policy``): seeds and private random
streams, the Polyak step of the target critics and the strict batch check."""
from __future__ import annotations

import numpy as np
import torch


@torch.no_grad()
def polyak_update(online: list[torch.Tensor], target: list[torch.Tensor], tau: float) -> None:
    """target <- target + tau * (online - target) for paired parameter lists (one fused foreach call)."""
    torch._foreach_lerp_(target, online, tau)


class PrivateTorchRNG:
    """A private stream for the *global* torch CPU RNG, swapped in for the duration of a ``with`` block.

    ``nn.Dropout`` cannot take a ``torch.Generator``: it always draws from the global RNG. To keep an agent's
    dropout masks a function of its own seed (and restorable from a checkpoint) without disturbing the
    caller's global RNG, the agent keeps its own RNG state here and swaps it in around each update.
    Not thread-safe (nothing that touches the global torch RNG is).
    """

    def __init__(self, seed: int):
        self.state = torch.Generator().manual_seed(int(seed)).get_state()
        self._outer: torch.Tensor | None = None

    def __enter__(self) -> "PrivateTorchRNG":
        self._outer = torch.get_rng_state()
        torch.set_rng_state(self.state)
        return self

    def __exit__(self, *exc) -> None:
        self.state = torch.get_rng_state()
        torch.set_rng_state(self._outer)
        self._outer = None


def derive_seeds(seed: int, count: int) -> list[int]:
    """``count`` independent 63-bit seeds from one seed (numpy SeedSequence), one per random stream."""
    states = np.random.SeedSequence(int(seed)).generate_state(count, dtype=np.uint64)
    return [int(s) >> 1 for s in states]


def as_float_tensor(name: str, value, shape: tuple[int, ...]) -> torch.Tensor:
    """A float32 tensor from a numpy batch entry, with a strict shape check.

    Strict on purpose: a (B, 1) reward broadcast against (B,) Q-values silently trains on a (B, B) target.
    """
    tensor = torch.as_tensor(np.asarray(value, dtype=np.float32))
    if tuple(tensor.shape) != shape:
        raise ValueError(f"batch.{name} must have shape {shape}, got {tuple(tensor.shape)}")
    return tensor
