"""Parity of an exported artifact with the eager policy it came from, on observations recorded in flight.

An artifact is only a faithful copy if it acts like the checkpoint on the observations it will meet, not on
random vectors (whose coverage and one-hot blocks look like nothing the policy saw). So the observations are
recorded from the environment: every slot of a batch flies a validation scenario, half of them with the
policy's own actions (the states it visits) and half with uniformly random ones (states it might be pushed
into), episodes restarting as they end; HRL-SAC slots take the meta-controller's goals every K steps.
Agreement means identical goals and actions within the tolerance of the artifact's precision (``TOLERANCES``):
``ACTION_TOLERANCE`` (float32 rounding) for a float32 artifact, ``INT8_ACTION_TOLERANCE`` for an int8 one (the
rounding of int8 weights and bfloat16 activations; docs/export.md, "Precision"). The manifest states the tolerance
its artifact was checked against.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from autonomy.observation import META_OBS_DIM, NO_GOAL
from autonomy.policy import Policy
from policies.checkpoint import CheckpointPolicy
from policies.env.core import ACTION_HIGH, ACTION_LOW, FlownSearch
from policies.evaluation.episodes import episode_batch

PARITY_OBSERVATIONS = 10_000
ACTION_TOLERANCE = 1e-6
INT8_ACTION_TOLERANCE = 0.05
TOLERANCES = {"float32": ACTION_TOLERANCE, "int8": INT8_ACTION_TOLERANCE}
"""Largest accepted |action difference| per artifact precision (``policies.export.module.PRECISIONS``)."""


@dataclass(frozen=True)
class Parity:
    """How far the artifact is from the eager policy on ``observations`` recorded observations."""

    observations: int
    max_action_difference: float
    goal_mismatches: int
    tolerance: float = ACTION_TOLERANCE

    @property
    def ok(self) -> bool:
        return self.max_action_difference <= self.tolerance and self.goal_mismatches == 0

    def summary(self) -> str:
        return (f"{self.observations:,} observations, max |action difference| {self.max_action_difference:.1e} "
                f"(tolerance {self.tolerance:.0e}), {self.goal_mismatches} different goals")


def check_parity(policy: CheckpointPolicy, artifact: Policy, obs: np.ndarray) -> Parity:
    """Compare actions and goals of the eager ``policy`` and the loaded ``artifact`` on the same batch, against the
    tolerance of the artifact's precision."""
    meta_obs = obs[:, :META_OBS_DIM]
    expected = policy.choose_goals(meta_obs) if policy.hierarchical else np.full(len(obs), NO_GOAL)
    return compare_with(policy.act(obs), expected, artifact, obs)


def compare_with(actions: np.ndarray, goals: np.ndarray, artifact: Policy, obs: np.ndarray) -> Parity:
    """How far the loaded ``artifact`` is, on the batch ``obs``, from the ``actions`` and ``goals`` the policy it was
    exported from gives on the same batch, against the tolerance of the artifact's precision."""
    difference = np.abs(np.asarray(actions, dtype=np.float64) - artifact.act(obs))
    # NaN anywhere (in either) is a failure, not something max() may skip.
    max_difference = float(difference.max()) if np.isfinite(difference).all() else float("inf")
    mismatches = int(np.count_nonzero(goals != artifact.select_goal(obs[:, :META_OBS_DIM])))
    return Parity(len(obs), max_difference, mismatches, TOLERANCES[artifact.manifest.precision])


def record_observations(policy: CheckpointPolicy, count: int = PARITY_OBSERVATIONS, envs: int = 100,
                        seed: int = 0) -> np.ndarray:
    """(count, 288) float32 observations met by flying ``policy`` (and random actions) on the val split."""
    config = policy.config
    core = episode_batch("val", envs, config.flight, goal_conditioned=policy.hierarchical, task=config.task,
                         action_frame=config.action_frame)
    choose_goals = policy.choose_goals if policy.hierarchical else None
    return fly_and_record(core, policy.act, count, seed, choose_goals, config.flight.subgoal_interval)


def fly_and_record(core: FlownSearch, act: Callable[[np.ndarray], np.ndarray], count: int = PARITY_OBSERVATIONS,
                   seed: int = 0, choose_goals: Callable[[np.ndarray], np.ndarray] | None = None,
                   subgoal_interval: int = 1) -> np.ndarray:
    """(count, obs width) float32 observations met by flying every slot of ``core``: even slots with ``act(obs)``
    (which returns a new array of actions: the odd slots' are written into it), odd ones with uniformly random
    actions, episodes restarting as they end; with ``choose_goals`` (HRL-SAC) the meta-controller's goals whenever
    the search state says one is due (every ``subgoal_interval`` steps)."""
    envs = core.n
    rng = np.random.default_rng(seed)
    random_slots = np.arange(envs) % 2 == 1
    next_episode, recorded = envs, []
    while len(recorded) * envs < count:
        if choose_goals is not None:
            decide = core.goal_due(subgoal_interval)
            if decide.any():
                goals = np.zeros(envs, dtype=np.int64)
                goals[decide] = choose_goals(core.meta_observation[decide])
                core.set_goals(goals, decide)
        recorded.append(core.obs.copy())
        actions = act(core.obs)
        actions[random_slots] = rng.uniform(ACTION_LOW, ACTION_HIGH, size=(int(random_slots.sum()), 4))
        _, _, terminated, truncated, _ = core.step(actions)
        ended = np.flatnonzero(terminated | truncated)
        if len(ended):
            core.reset(ended, np.arange(next_episode, next_episode + len(ended)))
            next_episode += len(ended)
    return np.concatenate(recorded)[:count]
