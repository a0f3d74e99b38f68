"""What both SAC agents (``policies.agents.sac``, ``policies.agents.discrete_sac``) share besides their networks: seeds
and private random streams, the checkpoint state, the Polyak step of the target critics and the batch check."""
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
        raise ValueError(f"batch[{name!r}] must have shape {shape}, got {tuple(tensor.shape)}")
    return tensor


class CheckpointedAgent:
    """``state_dict`` / ``load_state_dict`` shared by SAC and discrete SAC: networks, target critics, optimisers,
    the entropy temperature and every random stream, so that a resumed run gives bit-identical next updates."""

    _MODULES = ("actor", "critic", "critic_target", "actor_optim", "critic_optim", "alpha_optim")

    def state_dict(self) -> dict:
        """Everything a resumed run needs (like ``nn.Module.state_dict``, tensors are shared: ``torch.save`` or
        deep-copy it for a snapshot)."""
        state = {name: getattr(self, name).state_dict() for name in self._MODULES}
        state.update(log_alpha=self.log_alpha.detach().clone(), generator=self.generator.get_state(),
                     dropout_rng=self.dropout_rng.state.clone(), num_updates=self.num_updates)
        return state

    def load_state_dict(self, state: dict) -> None:
        for name in self._MODULES:
            getattr(self, name).load_state_dict(state[name])
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])  # in place: alpha_optim holds this very tensor
        self.generator.set_state(state["generator"])
        self.dropout_rng.state = state["dropout_rng"].clone()
        self.num_updates = int(state["num_updates"])
