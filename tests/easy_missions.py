"""The easy missions of the learning checks (tests/test_learning.py, tests/test_learning_sac.py) and what "learned"
means there; benchmarks/easy_learning.py counts seeds with the same code.

The easy missions (SarSearch-v1, the default task): a person 80 m from the start in one of eight directions, the
datum on the victim (sigma 20 m), calm clear day, 100-step limit; success needs the close look that confirms the
victim, then reaching it. Before training both policies succeed only where the victim happens to lie on their
initial straight-line drift (at most 1 of 8 directions).

HRL-SAC uses the paper's low-level reward (-||s' - g||) here: with the fence 300 m away it learns these missions
within 16,000 steps at one update every other step. Flat SAC learns from the same shaping (``flat_shaping``): from
the environment reward alone it learns these missions much more slowly. (On the real task the paper's distance
form learns to leave the area instead; see TrainConfig.intrinsic_reward.)

Both train with the default float32 updates. How often one seed learns, by precision, is measured by
``benchmarks/easy_learning.py`` (docs/training.md); in bfloat16 which seeds learned depended on the CPU's kernels
(AMX or AVX-512 BF16), so a bfloat16 test would pass or fail with the machine.
"""
from __future__ import annotations

import math

import numpy as np

from missions.mission import FlightSettings, Mission
from missions.mission_writer import save_mission
from missions.scenario import Scenario, SearchArea, Target
from policies.config import NetworkConfig, TrainConfig
from policies.env.core import SarSearchConfig
from policies.env.tasks import make_batch
from policies.evaluation.episodes import run_episodes, summarise
from policies.training.trainer import Trainer

FLIGHT = FlightSettings(max_steps=100, subgoal_interval=10)
NET = NetworkConfig(hidden=(64, 64))


def easy_scenarios() -> tuple[Scenario, ...]:
    out = []
    for k in range(8):
        angle = 2 * math.pi * k / 8
        north, east = 80 * math.cos(angle), 80 * math.sin(angle)
        out.append(Scenario(area=SearchArea(-300, 300, -300, 300), datum_north_m=north, datum_east_m=east,
                            datum_sigma_m=20, targets=(Target("person", north, east, primary=True),),
                            name=f"easy-{k}"))
    return tuple(out)


def evaluate(trainer: Trainer) -> dict:
    core = make_batch(SarSearchConfig(scenarios=easy_scenarios(), flight=FLIGHT, goal_conditioned=trainer.hrl),
                      list(range(32)))
    goals = None
    if trainer.hrl:
        goals = lambda meta_obs: trainer.meta.act(trainer.normalizer.normalize(meta_obs), deterministic=True)  # noqa: E731
    return summarise(run_episodes(core, lambda c: trainer.low.act(trainer.normalizer.normalize(c.obs),
                                                                  deterministic=True), goals))


STEPS = {"hrl-sac": 16_000, "sac": 15_000}
UPDATES_PER_STEP = 0.5
"""One update of each network every other environment step: the update is most of a step's time, and both agents
learn these missions at this rate (docs/training.md)."""
HRL_SETTINGS = {"meta_returned_reward": 0.0}
"""HRL-SAC's meta-controller learns with a return home paying nothing, as the shipped policy is trained: with the
environment's +20, the meta-controller of most seeds settled on ReturnToBase before the low level had learned to
reach the victim (docs/training.md, "SarSearch-v1 options")."""


def easy_trainer(tmp_path, algo: str, seed: int = 0, **overrides) -> Trainer:
    """A Trainer of ``algo`` on the easy missions (written into ``tmp_path``), with the test's budget and settings;
    ``overrides``: other TrainConfig fields (benchmarks/easy_learning.py varies ``update_dtype``)."""
    missions = []
    for scenario in easy_scenarios():
        path = tmp_path / f"{scenario.name}.yaml"
        save_mission(Mission(scenario=scenario, flight=FLIGHT, name=scenario.name), path)
        missions.append(str(path))
    settings = {**(HRL_SETTINGS if algo == "hrl-sac" else {}), **overrides}
    config = TrainConfig.from_preset("default", algo=algo, seed=seed, total_steps=STEPS[algo], num_envs=4,
                                     warmup_steps=1_000, batch_size=64, meta_batch_size=32, buffer_size=20_000,
                                     meta_buffer_size=5_000, updates_per_step=UPDATES_PER_STEP, checkpoint_every=10**9,
                                     log_every=1_000, actor=NET, critic=NET, meta_actor=NET, meta_critic=NET,
                                     flight=FLIGHT, missions=tuple(missions), intrinsic_reward="distance",
                                     flat_shaping=algo == "sac", **settings)
    return Trainer(config, tmp_path / "run")


def check_learns(tmp_path, algo: str) -> None:
    """Train ``algo`` on the easy missions with the test's budget and assert :func:`learning_checks`."""
    trainer = easy_trainer(tmp_path, algo)
    before = evaluate(trainer)
    trainer.run(progress=False)
    after = evaluate(trainer)
    print(f"{algo}: success {before['success_rate']:.2f} -> {after['success_rate']:.2f}, "
          f"reward {before['reward_mean']:.1f} -> {after['reward_mean']:.1f}")
    checks = learning_checks(before, after, trainer)
    assert all(checks.values()), checks


def learning_checks(before: dict, after: dict, trainer: Trainer) -> dict[str, bool]:
    """What "learned" means here (benchmarks/easy_learning.py counts seeds by the same checks)."""
    return {
        "success +20 points": after["success_rate"] >= before["success_rate"] + 0.2,  # two more of eight directions
        "reward +20": after["reward_mean"] >= before["reward_mean"] + 20.0,
        # The last 100 training episodes (stochastic actions) succeed too. Over seeds 0-5 in float32 they reached
        # 21-98 % where the evaluation had learned (benchmarks/results/easy_learning_float32_checks.json, measured
        # with the threshold at 40 %, which 2 of 6 HRL-SAC seeds missed), and 1-4 % in runs that learned nothing
        # (HRL-SAC's failed bfloat16 seeds, benchmarks/results/easy_learning_bfloat16_failures.json).
        "training episodes > 15 % success": float(np.mean([episode[0] for episode in trainer.recent])) > 0.15,
    }
