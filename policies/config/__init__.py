"""Every setting of a training run: ``TrainConfig``, with the paper's and our presets, and ``NetworkConfig``.

``TrainConfig.from_preset("paper")`` follows the paper's tables (3 x 512 low-level networks with LayerNorm, ReLU and
Dropout 0.1; 2 x 256 meta networks; Adam 3e-4; gamma 0.99; tau 0.005; K = 30; batches 128 / 64; prioritised
replay; 2,000 warm-up steps). ``"default"`` keeps the structure but is sized for a small CPU: 2 x 256 low-level
networks without dropout, since a paper-sized update, and Dropout above all, costs several times as much on a CPU
core (docs/training.md).
"""
from __future__ import annotations

from policies.config.network import NetworkConfig
from policies.config.train_config import TrainConfig

__all__ = ["NetworkConfig", "TrainConfig"]
