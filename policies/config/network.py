"""The shape of one family of networks (``NetworkConfig``), for the actors and critics of both levels."""
from __future__ import annotations

from dataclasses import dataclass

from missions.validation import Interval, check_fields


@dataclass(frozen=True)
class NetworkConfig:
    """Shape of one family of networks (actor and critics share it)."""

    hidden: tuple[int, ...] = (256, 256)
    """Widths of the hidden layers (each Linear -> LayerNorm -> ReLU -> Dropout)."""
    head: int | None = None
    """Width of an extra last hidden layer before the output (the paper's 256 after 3 x 512); None = none."""
    layer_norm: bool = True
    """LayerNorm after each hidden Linear (the paper: yes)."""
    dropout: float = 0.0
    """Dropout probability after each hidden activation (the paper: 0.1). Off in deterministic evaluation."""

    def __post_init__(self) -> None:
        if not self.hidden or any(int(w) != w or w < 1 for w in self.hidden):
            raise ValueError(f"NetworkConfig.hidden must be positive integers, got {self.hidden}")
        check_fields(self, (("dropout", Interval(0.0, 1.0, high_open=True)),))

    @property
    def layers(self) -> tuple[int, ...]:
        return tuple(self.hidden) + ((self.head,) if self.head else ())
