"""What the training loop's tests share (tests/test_training_*.py): small networks and the smallest training
settings (800 steps, a checkpoint every 400), and the progress log's rows. Not a test module (pytest does not
collect it)."""
from __future__ import annotations

import csv

from missions.mission import FlightSettings
from policies.config import NetworkConfig, TrainConfig


SMALL = NetworkConfig(hidden=(32, 32))


def small_config(algo: str, **overrides) -> TrainConfig:
    settings = dict(algo=algo, seed=3, total_steps=800, num_envs=2, warmup_steps=200, batch_size=32,
                    meta_batch_size=8, buffer_size=5_000, meta_buffer_size=1_000, checkpoint_every=400,
                    log_every=100, eval_every=0, updates_per_step=0.5, actor=SMALL, critic=SMALL, meta_actor=SMALL,
                    meta_critic=SMALL, flight=FlightSettings(max_steps=120, subgoal_interval=10))
    settings.update(overrides)
    return TrainConfig.from_preset("default", **settings)


def log_rows(path) -> list[dict]:
    with open(path, newline="") as handle:
        return [{k: v for k, v in row.items() if k != "steps_per_s"} for row in csv.DictReader(handle)]
