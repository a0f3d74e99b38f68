"""Evaluation of a checkpoint split across workers, with results identical to one serial batch.

Scenario i of the split is flown with episode seed i in every case; the episodes are cut into contiguous
chunks (one per worker), each chunk is flown as one vectorised batch (:func:`policies.evaluation.episodes.run_episodes`)
and the per-episode arrays are concatenated in order before the metrics are computed. Two things make a chunk's
episodes bit-identical to the same episodes inside the whole batch:

* everything in the environment is per row (the detection draws come from a generator keyed by the episode
  seed, the physics and the search state are element-wise numpy), so the other rows of a batch do not matter;
* the policy's matrix products are: torch's CPU kernels give the same row whatever else is in the batch, except
  for batches of 1-3 rows, which take a different (matrix-vector) path with another summation order (the actions
  of 1-3 rows differ in the last bits from the same rows in a larger batch). Every policy call is therefore padded
  to at least :data:`MIN_POLICY_ROWS` rows; serial and chunked runs both pad, so both see the same numbers (a meta
  decision for 2 remaining episodes is a batch of 8 either way).

Workers also compute with one torch thread each (:mod:`simulation.worker_pool`), as the serial path does.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from policies.checkpoint import CheckpointPolicy, checkpoint_file, load_checkpoint_state
from policies.config import TrainConfig
from policies.evaluation.episodes import episode_batch, run_episodes, summarise
from simulation.worker_pool import PoolConfig, contiguous_chunks, run_tasks

MIN_POLICY_ROWS = 8
POLICY_STATE_KEYS = ("config", "normalizer", "low", "meta", "step")  # what acting needs (no replay buffers)


@dataclass(frozen=True)
class EpisodeChunk:
    """Episodes ``slots`` (a contiguous part of ``range(episodes)``) of ``split``, for one worker."""

    policy_state: dict
    """The checkpoint's networks, normaliser and config (not its replay buffers): workers need no shared disk."""
    checkpoint: str
    """Where the state came from (reported, never read by the worker)."""
    split: str
    """Scenario split."""
    episodes: int
    """Episodes of the whole evaluation (the size of the scenario pool the chunk's episodes index)."""
    slots: range
    """The episodes (= scenario indices = episode seeds) this chunk flies."""
    constant_goal: int | None = None
    """HRL-SAC: fly this goal at every decision instead of the meta-controller's (the learned low level flies it)."""
    environment: dict = field(default_factory=dict)
    """Further ``SarSearchConfig`` fields: the scenarios (``generator``, or a fixed list ``scenarios``)."""
    flight_rules: bool = False
    """Fly with the mission runner's rules (``policies.evaluation.episodes.run_episodes``)."""


def padded(fn: Callable[[np.ndarray], np.ndarray], rows: int = MIN_POLICY_ROWS) -> Callable[[np.ndarray], np.ndarray]:
    """``fn`` on a batch padded (with copies of its first row) to at least ``rows`` rows, cut back after."""

    def call(batch: np.ndarray) -> np.ndarray:
        count = len(batch)
        if count == 0 or count >= rows:
            return fn(batch)
        filler = np.repeat(batch[:1], rows - count, axis=0)
        return fn(np.concatenate([batch, filler]))[:count]

    return call


def fly_chunk(chunk: EpisodeChunk, on_progress: Callable[[int], None] | None = None) -> dict[str, np.ndarray]:
    """The per-episode outcome arrays of one chunk (runs in a worker, or in this process, where ``on_progress`` may
    follow its episodes: ``run_episodes``)."""
    policy = CheckpointPolicy.from_state(chunk.policy_state, Path(chunk.checkpoint))
    return fly_policy(policy, episode_batch(chunk.split, chunk.episodes, policy.config.flight,
                                            goal_conditioned=policy.hierarchical, slots=chunk.slots,
                                            task=policy.config.task, action_frame=policy.config.action_frame,
                                            **chunk.environment), chunk.constant_goal, chunk.flight_rules, on_progress)


def fly_policy(policy: CheckpointPolicy, core, constant_goal: int | None = None, flight_rules: bool = False,
               on_progress: Callable[[int], None] | None = None) -> dict[str, np.ndarray]:
    """The per-episode outcome arrays of ``policy`` (deterministic, padded calls) flying every slot of ``core``;
    ``constant_goal``: that goal at every decision instead of the meta-controller's; ``flight_rules``: the mission
    runner's rules instead of training's."""
    act = padded(policy.act)
    choose = padded(policy.choose_goals) if policy.hierarchical else None
    if constant_goal is not None:
        def choose(meta_obs: np.ndarray) -> np.ndarray:
            return np.full(len(meta_obs), constant_goal)
    return run_episodes(core, lambda batch: act(batch.obs), choose, flight_rules, on_progress)


def quick_evaluation(policy: CheckpointPolicy) -> dict[str, float]:
    """The trainer's quick evaluation (``Trainer(evaluate=...)``): the success rate and the share of sorties that ran
    dry of the deterministic policy on the first ``eval_episodes`` val scenarios, in this process, with its own
    environments; with ``TrainConfig.eval_flight_rules``, flown with the mission runner's rules."""
    cfg = policy.config
    core = episode_batch("val", cfg.eval_episodes, cfg.flight, goal_conditioned=policy.hierarchical, task=cfg.task,
                         action_frame=cfg.action_frame)
    record = fly_policy(policy, core, flight_rules=cfg.eval_flight_rules)
    return {"success_rate": float(record["success"].mean()), "ran_dry_rate": float(record["ran_dry"].mean())}


def merge_records(records: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Per-episode arrays of consecutive chunks, concatenated in chunk order."""
    return {key: np.concatenate([record[key] for record in records]) for key in records[0]}


def evaluate_in_chunks(path, split: str, episodes: int, pool: PoolConfig | None = None,
                       on_progress: Callable[[int], None] | None = None, environment: dict | None = None,
                       constant_goal: int | None = None, flight_rules: bool = False) -> dict:
    """The paper's metrics of the checkpoint at ``path`` (file or run folder) on the first ``episodes``
    scenarios of ``split`` (or of ``environment``'s: ``generator`` / ``scenarios``), flown on ``pool`` (default: in
    this process). ``on_progress(episodes_done)`` follows the episodes: as each chunk is flown, and step by step
    when the only chunk flies in this process; ``constant_goal``: see :class:`EpisodeChunk`."""
    pool = pool or PoolConfig()
    path = checkpoint_file(path)
    state = load_checkpoint_state(path, path)  # a damaged or wrong file is one ValueError naming it
    policy_state = {key: state[key] for key in POLICY_STATE_KEYS}
    del state  # the replay buffers can be hundreds of MB; workers get only what acting needs
    config = TrainConfig.from_dict(policy_state["config"])
    if constant_goal is not None and config.algo != "hrl-sac":
        raise ValueError(f"{path}: a constant goal needs an HRL-SAC run (this one is {config.algo})")
    chunks = [EpisodeChunk(policy_state, str(path), split, episodes, slots, environment=dict(environment or {}),
                           constant_goal=constant_goal, flight_rules=flight_rules)
              for slots in contiguous_chunks(episodes, pool.workers)]
    fly, chunk_done = fly_chunk, None
    if on_progress is not None:
        flown = []

        def chunk_done(index: int, _) -> None:
            flown.append(len(chunks[index].slots))
            on_progress(sum(flown))

        if len(chunks) == 1 and not pool.uses_ray:  # flown in this process (run_tasks): it can report every step
            fly = functools.partial(fly_chunk, on_progress=on_progress)
    record = merge_records(run_tasks(fly, chunks, pool, chunk_done))
    return {"algo": config.algo, "preset": config.preset, "seed": config.seed, "checkpoint": str(path),
            "trained_steps": int(policy_state["step"]), "split": split, "task": config.task,
            "max_steps": config.flight.max_steps, "constant_goal": constant_goal, "flight_rules": flight_rules,
            **summarise(record, config.flight.step_period_s)}


def evaluate_checkpoint(path, split: str = "test", episodes: int = 100, pool=None, on_progress=None,
                        environment: dict | None = None, constant_goal: int | None = None,
                        flight_rules: bool = False) -> dict:
    """The paper's metrics of a trained run's deterministic policy on ``split`` (or on ``environment``'s scenarios:
    ``SarSearchConfig`` fields ``generator`` or ``scenarios``); with ``pool`` (an ``simulation.worker_pool.PoolConfig``)
    the episodes are split across workers, with identical results. ``constant_goal``: HRL-SAC's learned low level
    flying that goal at every decision; ``flight_rules``: the mission runner's rules (ReturnToBase and the pilot's
    bingo failsafe end the search) instead of training's."""
    return evaluate_in_chunks(path, split, episodes, pool, on_progress, environment, constant_goal, flight_rules)
