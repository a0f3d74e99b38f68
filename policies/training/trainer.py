"""Training HRL-SAC and flat SAC on ``SarSearch-v1`` (or v0): one loop, readable top to bottom (CleanRL style).

Per vector step (``num_envs`` environments at once):

1. HRL-SAC only: every environment whose sub-goal has run K steps (or that starts an episode) gets a new goal
   from the meta-controller (uniformly random during warm-up); the environment grounds it to a point g. The meta
   transition stores the observation the meta-controller acted on (before the goal's point shows in it).
2. The low-level (or flat) SAC acts on the normalised observation (uniform random during warm-up).
3. Transitions are stored raw in prioritised replay (n-step with ``n_step`` > 1): the low level's with the shaped
   reward of ``policies.env.shaping`` (progress towards g, cross-track penalty, goal, coverage and belief bonuses);
   flat SAC's with the environment reward, or with the same shaping towards its target (``flat_shaping``); the
   meta-controller's, once its goal has run K steps or the episode ended, with the K-step discounted extrinsic
   return and discount ``meta_gamma ** k``.
4. After warm-up: ``updates_per_step`` low-level updates per environment step and
   ``meta_updates_per_transition`` meta updates (1 by default) per meta transition, with importance weights and
   new priorities from the TD errors.
5. The meta-only phase (the last ``meta_only_steps`` of the run, off by default): the low level and the observation
   normaliser stop learning, the low level flies its mean action (as an exported policy does), the meta replay
   buffer starts empty and only the meta-controller learns, with its own entropy target
   (``meta_only_entropy_scale``), against the low level it will fly with.

Checkpoints (every ``checkpoint_every`` steps and at the end) hold everything needed to continue exactly:
networks, optimisers, temperatures, replay buffers, the observation normaliser, the environments' state and
every random generator; ``--resume`` continues a killed run and gives the same next update as an
uninterrupted one.
"""
from __future__ import annotations

import json
import math
import sys
import time
from collections import deque
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from missions.goals import GOAL_NAMES, RETURN_TO_BASE
from missions.mission_file import load_mission
from missions.search_state_v1 import BINGO_RESERVE_S
from policies.agents.n_step import NStepReturns
from policies.agents.normalizer import RunningMeanStd
from policies.agents.prioritized_replay import PrioritizedReplayBuffer, linear_beta
from policies.checkpoint import (
    CHECKPOINT,
    CheckpointPolicy,
    atomic_torch_save,
    dump_environment,
    load_checkpoint_state,
    load_environment,
    new_agents,
)
from policies.config import TrainConfig
from policies.env.core import ACTION_HIGH, ACTION_LOW, SarSearchConfig
from policies.env.shaping import meta_learning_reward, shaped_reward
from policies.env.vector import SarSearchVectorEnv
from policies.training.progress_log import WINDOW, ProgressLog, progress_row, truncate_after


class Trainer:
    """One training run in ``run_dir``; create with a config (new run) or with ``resume=True``.

    ``evaluate`` measures the policy as it stands every ``eval_every`` steps (a dict with its ``success_rate`` and
    ``ran_dry_rate``, or a success rate alone; without it there are no quick evaluations). ``hrlsac train`` and
    sweeps hand in ``policies.evaluation.parallel.quick_evaluation``: evaluation is given to the trainer, so that
    training code does not import evaluation code (which reads checkpoints training writes)."""

    def __init__(self, config: TrainConfig, run_dir: Path | str, resume: bool = False,
                 evaluate: Callable[[CheckpointPolicy], dict[str, float] | float] | None = None):
        if (config.meta_keep_best or config.keep_best) and evaluate is None:
            name = "meta_keep_best" if config.meta_keep_best else "keep_best"
            raise ValueError(f"TrainConfig.{name} chooses by quick evaluations: give the Trainer an evaluate "
                             "function (policies.evaluation.parallel.quick_evaluation)")
        self.run_dir = Path(run_dir)
        self.evaluate = evaluate
        self.config = cfg = config
        self.hrl = cfg.algo == "hrl-sac"
        torch.set_num_threads(cfg.torch_threads)
        torch.manual_seed(cfg.seed)
        scenarios = tuple(load_mission(path).scenario for path in cfg.missions)
        self.env = SarSearchVectorEnv(cfg.num_envs, SarSearchConfig(
            task=cfg.task, split=cfg.split, scenarios=scenarios, flight=cfg.flight, goal_conditioned=self.hrl,
            action_frame=cfg.action_frame))
        self.rng = np.random.default_rng(cfg.seed)
        self.obs_dim, self.meta_dim = cfg.layout.dim, cfg.layout.meta_dim
        self.normalizer = RunningMeanStd((self.obs_dim,))
        self.low, self.meta = new_agents(cfg)  # the meta-controller: HRL-SAC only
        fields = {"obs": ((self.obs_dim,), np.float32), "action": ((4,), np.float32), "reward": ((), np.float32),
                  "next_obs": ((self.obs_dim,), np.float32), "done": ((), np.float32)}
        if cfg.n_step > 1:  # one-step runs keep the buffer layout (and the numbers) they always had
            fields["discount"] = ((), np.float32)
        self.low_buffer = PrioritizedReplayBuffer(cfg.buffer_size, fields, cfg.per_alpha, cfg.per_eps, cfg.seed)
        self.n_step = NStepReturns(cfg.n_step, cfg.sac_gamma, cfg.num_envs) if cfg.n_step > 1 else None
        self.meta_buffer = self._new_meta_buffer() if self.hrl else None
        n = cfg.num_envs
        self.step = 0  # environment steps so far (summed over environments)
        self.update_budget = 0.0
        self.needs_goal = np.ones(n, dtype=bool)
        self.segment_obs = np.zeros((n, self.meta_dim), dtype=np.float32)
        self.segment_goal = np.zeros(n, dtype=np.int64)
        self.segment_return = np.zeros(n)
        self.segment_steps = np.zeros(n, dtype=np.int64)
        self.segment_reached = np.zeros(n, dtype=bool)
        self.episodes = 0
        self.recent: deque = deque(maxlen=WINDOW)  # (success, return, length, coverage) of finished episodes
        self.recent_subgoals: deque = deque(maxlen=10 * WINDOW)  # 1 if a sub-goal point was reached in time
        self.metrics: dict[str, float] = {}
        # meta_keep_best / keep_best: {"success", "ran_dry", "step", "actor"} of the best quick evaluation so far
        # (keep_best also its "normalizer": the flat actor was trained on observations normalised by it)
        self.best: dict | None = None
        self.run_dir.mkdir(parents=True, exist_ok=True)
        if resume:
            self._load(self.run_dir / CHECKPOINT)
        else:
            seeds = self.rng.integers(0, 2**62, size=n)
            self.obs, _ = self.env.reset(seed=[int(s) for s in seeds])
            (self.run_dir / "config.json").write_text(json.dumps(cfg.to_dict(), indent=2))

    def _new_meta_buffer(self) -> PrioritizedReplayBuffer:
        cfg = self.config
        return PrioritizedReplayBuffer(cfg.meta_buffer_size, {
            "obs": ((self.meta_dim,), np.float32), "action": ((), np.int64), "reward": ((), np.float32),
            "next_obs": ((self.meta_dim,), np.float32), "done": ((), np.float32),
            "discount": ((), np.float32)}, cfg.per_alpha, cfg.per_eps, cfg.seed + 1)

    @property
    def low_level_frozen(self) -> bool:
        """True in the meta-only phase (``TrainConfig.meta_only_steps``): the low level and the normaliser are
        fixed and the low level flies its mean action. Never for flat SAC."""
        return self.hrl and self.step >= self.config.meta_only_from

    @property
    def meta_learns(self) -> bool:
        """Whether the meta-controller chooses the goals and learns now (``TrainConfig.meta_joint_goals``)."""
        return self.config.meta_joint_goals == "learned" or self.low_level_frozen

    # ------------------------------------------------------------------ acting
    def _norm(self, obs: np.ndarray) -> np.ndarray:
        return self.normalizer.normalize(obs)

    def _choose_goals(self) -> None:
        need = self.needs_goal
        if not need.any():
            return
        meta_obs = self.obs[need, :self.meta_dim]
        if self.step < self.config.warmup_steps or not self.meta_learns:
            goals = self.rng.integers(0, len(GOAL_NAMES), size=int(need.sum()))
            margin = getattr(self.env.core, "bingo_margin_s", None)  # SarSearch-v1: home from the bingo call on
            if margin is not None:
                goals[margin[need] <= BINGO_RESERVE_S] = RETURN_TO_BASE
        else:
            goals = self.meta.act(self._norm(meta_obs))
        all_goals = np.zeros(self.config.num_envs, dtype=np.int64)
        all_goals[need] = goals
        # The meta transition's state is what the meta-controller acted on: after set_goals the observation's
        # target_offset points at the chosen goal's point, so the critics would learn from states revealing
        # the action.
        self.segment_obs[need] = meta_obs
        self.obs = self.env.set_goals(all_goals, need)
        self.segment_goal[need] = goals
        self.segment_return[need] = 0.0
        self.segment_steps[need] = 0
        self.segment_reached[need] = False
        self.needs_goal[:] = False

    def collect(self) -> int:
        """One vector step of experience; returns the number of meta transitions it completed."""
        cfg = self.config
        frozen = self.low_level_frozen
        if frozen:
            if self.step < cfg.meta_only_from + cfg.num_envs:  # the first vector step of the phase
                self.meta_buffer = self._new_meta_buffer()
            self.meta.target_entropy = cfg.meta_only_entropy_scale * math.log(len(GOAL_NAMES))
        if self.hrl:
            self._choose_goals()
        if self.step < cfg.warmup_steps:
            actions = self.rng.uniform(ACTION_LOW, ACTION_HIGH, size=(cfg.num_envs, 4)).astype(np.float32)
        else:
            actions = self.low.act(self._norm(self.obs), deterministic=frozen).astype(np.float32)
        next_obs, reward, terminated, truncated, info = self.env.step(actions)
        done = terminated | truncated
        real_next = next_obs.copy()  # the observation the transition really ended in (not the reset one)
        for i in np.flatnonzero(done):
            real_next[i] = info["final_obs"][i]
        if self.hrl or cfg.flat_shaping:
            low_reward = shaped_reward(cfg, self.hrl, actions, info, reward, self.env.step_reward)
        else:
            low_reward = reward
        if self.hrl:
            self.segment_reached |= info["goal_reached"]  # (the environment has already grounded those again)
        if not frozen:
            self._store_low(actions, low_reward.astype(np.float32), real_next, terminated, done)
            self.normalizer.update(self.obs)
        completed = 0
        if self.hrl:
            self.segment_return += cfg.meta_gamma ** self.segment_steps * meta_learning_reward(cfg, reward, info)
            self.segment_steps += 1
            # a decision is due before the next step (every K steps, or after a decision event); done: a new episode
            finish = self.env.core.goal_due(cfg.flight.subgoal_interval) | done
            if finish.any() and self.meta_learns:
                self.meta_buffer.add(obs=self.segment_obs[finish], action=self.segment_goal[finish],
                                     reward=self.segment_return[finish].astype(np.float32),
                                     next_obs=real_next[finish, :self.meta_dim],
                                     done=terminated[finish].astype(np.float32),
                                     discount=(cfg.meta_gamma ** self.segment_steps[finish]).astype(np.float32))
            if finish.any():
                self.recent_subgoals.extend(self.segment_reached[finish].astype(float).tolist())
                self.needs_goal |= finish
                completed = int(finish.sum())
        for i in np.flatnonzero(done):
            self.episodes += 1
            self.recent.append((float(info["success"][i]), float(info["episode_return"][i]),
                                float(info["steps"][i]), float(info["coverage_ratio"][i])))
        self.obs = next_obs
        self.step += cfg.num_envs
        return completed

    # ------------------------------------------------------------------ learning
    def learn(self, meta_transitions: int) -> None:
        cfg = self.config
        if self.step < cfg.warmup_steps or len(self.low_buffer) < cfg.batch_size:
            return
        # annealed to 1 over the steps in which the low level learns, so that a run with a meta-only phase
        # trains exactly as one without it until the phase starts
        beta = linear_beta(self.step, cfg.meta_only_from, cfg.per_beta_start)
        if not self.low_level_frozen:
            self.update_budget += cfg.updates_per_step * cfg.num_envs
        while self.update_budget >= 1.0:
            self.update_budget -= 1.0
            batch = self.low_buffer.sample_transitions(cfg.batch_size, beta)
            batch.obs, batch.next_obs = self._norm(batch.obs), self._norm(batch.next_obs)
            td, metrics = self.low.update(batch)
            self.low_buffer.update_priorities(batch.indices, td)
            self.metrics.update(metrics)
        if self.hrl and len(self.meta_buffer) >= cfg.meta_batch_size:
            for _ in range(meta_transitions * cfg.meta_updates_per_transition):
                batch = self.meta_buffer.sample_transitions(cfg.meta_batch_size, beta)
                batch.obs, batch.next_obs = self._norm(batch.obs), self._norm(batch.next_obs)
                td, metrics = self.meta.update(batch)
                self.meta_buffer.update_priorities(batch.indices, td)
                self.metrics.update({f"meta_{k}": v for k, v in metrics.items()})

    def _store_low(self, actions: np.ndarray, reward: np.ndarray, real_next: np.ndarray, terminated: np.ndarray,
                   done: np.ndarray) -> None:
        if self.n_step is None:
            self.low_buffer.add(obs=self.obs, action=actions, reward=reward, next_obs=real_next,
                                done=terminated.astype(np.float32))
            return
        transitions = self.n_step.add(self.obs, actions, reward, real_next, terminated, done)
        if transitions is not None:
            self.low_buffer.add(**transitions.stored_fields())

    # ------------------------------------------------------------------ the loop
    def run(self, progress: bool = True, stop_at: int | None = None) -> Path:
        """Train to ``total_steps`` (or stop early at ``stop_at`` steps, for tests); returns the checkpoint path."""
        cfg = self.config
        end = min(cfg.total_steps, stop_at) if stop_at is not None else cfg.total_steps
        started, started_step = time.perf_counter(), self.step
        last_log = self.step // cfg.log_every
        last_checkpoint = self.step // cfg.checkpoint_every
        last_eval = self.step // cfg.eval_every if cfg.eval_every else 0
        with ProgressLog(self.run_dir, self.step, end, progress) as log:
            while self.step < end:
                self.learn(self.collect())
                log.advance(self.step)
                if cfg.eval_every and self.evaluate and self.step // cfg.eval_every > last_eval:
                    last_eval = self.step // cfg.eval_every
                    self.quick_evaluation()
                if self.step // cfg.log_every > last_log:
                    last_log = self.step // cfg.log_every
                    steps_per_s = (self.step - started_step) / max(time.perf_counter() - started, 1e-9)
                    log.write(progress_row(self.step, self.episodes, self.recent, self.recent_subgoals,
                                           self.metrics, steps_per_s))
                if self.step // cfg.checkpoint_every > last_checkpoint:
                    last_checkpoint = self.step // cfg.checkpoint_every
                    self.save()
        if self.step >= cfg.total_steps and self.best is not None:
            self._restore_best()  # meta_keep_best / keep_best: the run ends with the best policy
        path = self.save()
        if progress and self.best is not None and self.step >= cfg.total_steps:
            kept = "meta-controller" if self.hrl else "policy"
            print(f"kept the {kept} of step {self.best['step']:,} (val success {self.best['success']:.1%}, ran dry "
                  f"{self.best.get('ran_dry', 0.0):.1%}, on {cfg.eval_episodes} episodes)", file=sys.stderr)
        log.close()
        return path

    def quick_evaluation(self) -> float:
        """Success rate of the deterministic policy as it stands, as measured by the ``evaluate`` function the
        trainer was given (``policies.evaluation.parallel.quick_evaluation``: the first ``eval_episodes`` val
        scenarios), logged as ``eval_success_rate`` (and ``eval_ran_dry_rate``); with ``meta_keep_best``, in the
        meta-only phase, remembers the meta-controller of the best one (:meth:`_better`), with ``keep_best`` the
        flat SAC's actor and observation normaliser. The evaluation must use
        no random generator of the run, so that training goes on exactly as without it."""
        cfg = self.config
        policy = CheckpointPolicy(cfg, self.normalizer, self.low, self.meta, self.step, self.run_dir)
        result = self.evaluate(policy)
        scores = result if isinstance(result, dict) else {"success_rate": result}
        success, ran_dry = float(scores["success_rate"]), float(scores.get("ran_dry_rate", 0.0))
        self.metrics["eval_success_rate"] = success
        self.metrics["eval_ran_dry_rate"] = ran_dry if "ran_dry_rate" in scores else math.nan
        candidate = (cfg.meta_keep_best and self.low_level_frozen) or cfg.keep_best
        if candidate and self._better(success, ran_dry):
            acting = self.meta.actor if self.hrl else self.low.actor
            actor = {key: value.clone() for key, value in acting.state_dict().items()}
            self.best = {"success": success, "ran_dry": ran_dry, "step": self.step, "actor": actor}
            if not self.hrl:
                self.best["normalizer"] = self.normalizer.state_dict()
        return success

    def _restore_best(self) -> None:
        """Load the acting network of the best quick evaluation (and, flat, the normaliser its inputs had)."""
        if self.hrl:
            self.meta.actor.load_state_dict(self.best["actor"])
        else:
            self.low.actor.load_state_dict(self.best["actor"])
            self.normalizer.load_state_dict(self.best["normalizer"])

    def _better(self, success: float, ran_dry: float) -> bool:
        """Whether an evaluation beats the best so far, by the rule the scripted searchers are tuned with: the
        highest success among those that ran dry in at most ``meta_keep_best_max_ran_dry`` of the episodes, and
        while none does, the fewest that ran dry (ties: the earlier evaluation stays)."""
        if self.best is None:
            return True
        limit = self.config.meta_keep_best_max_ran_dry

        def score(s: float, r: float) -> tuple[float, float]:
            return (s, 0.0) if r <= limit else (-1.0, -r)

        return score(success, ran_dry) > score(self.best["success"], self.best.get("ran_dry", 0.0))

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict:
        return {
            "format": 1, "config": self.config.to_dict(), "step": self.step, "update_budget": self.update_budget,
            "low": self.low.state_dict(), "low_buffer": self.low_buffer.state_dict(),
            "meta": self.meta.state_dict() if self.meta else None,
            "meta_buffer": self.meta_buffer.state_dict() if self.meta_buffer else None,
            "normalizer": self.normalizer.state_dict(), "env": dump_environment(self.env.core),
            "obs": self.obs.copy(), "needs_goal": self.needs_goal.copy(),
            "segment": [self.segment_obs.copy(), self.segment_goal.copy(), self.segment_return.copy(),
                        self.segment_steps.copy(), self.segment_reached.copy()],
            "rng": self.rng.bit_generator.state, "torch_rng": torch.get_rng_state(), "episodes": self.episodes,
            "recent": list(self.recent), "recent_subgoals": list(self.recent_subgoals), "metrics": dict(self.metrics),
            "best_meta": self.best, "n_step": self.n_step.pending if self.n_step else None,
        }

    def save(self) -> Path:
        path = self.run_dir / CHECKPOINT
        atomic_torch_save(self.state_dict(), path)
        return path

    def _load(self, path: Path) -> None:
        if not path.exists():
            raise FileNotFoundError(f"cannot resume: no checkpoint at {path}")
        state = load_checkpoint_state(path, path)  # a damaged file is one ValueError naming it
        self.step, self.update_budget = state["step"], state["update_budget"]
        self.low.load_state_dict(state["low"])
        self.low_buffer.load_state_dict(state["low_buffer"])
        if self.meta is not None:
            self.meta.load_state_dict(state["meta"])
            self.meta_buffer.load_state_dict(state["meta_buffer"])
        self.normalizer.load_state_dict(state["normalizer"])
        self.env.core = load_environment(state["env"])
        self.obs, self.needs_goal = state["obs"], state["needs_goal"]
        (self.segment_obs, self.segment_goal, self.segment_return, self.segment_steps,
         self.segment_reached) = state["segment"]
        self.rng.bit_generator.state = state["rng"]
        torch.set_rng_state(state["torch_rng"])
        self.episodes = state["episodes"]
        self.recent.extend(state["recent"])
        self.recent_subgoals.extend(state["recent_subgoals"])
        self.metrics = dict(state["metrics"])
        self.best = state.get("best_meta")  # (the key predates keep_best; checkpoints before meta_keep_best lack it)
        if self.n_step is not None:
            self.n_step.pending = state["n_step"]
        truncate_after(self.run_dir, self.step)
