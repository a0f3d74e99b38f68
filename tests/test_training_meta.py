"""The training loop's meta-controller: meta transitions with K-step discounted returns and the state the
meta-controller acted on, meta updates per completed transition, random goals past the bingo call, the meta-only
phase (the low level frozen, its options checked) and meta_keep_best (the best evaluation's meta-controller, a
ran-dry limit)."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from training_helpers import small_config

from autonomy.observation import META_OBS_DIM
from missions.mission import FlightSettings
from policies.checkpoint import CheckpointPolicy
from policies.training.trainer import Trainer


def test_meta_transitions_carry_k_step_discounted_returns(tmp_path):
    config = small_config("hrl-sac", flight=FlightSettings(max_steps=500, subgoal_interval=5), meta_gamma=0.9)
    trainer = Trainer(config, tmp_path)
    rewards, real_step = [], trainer.env.step

    def spy(actions):
        result = real_step(actions)
        rewards.append(result[1].copy())
        return result

    trainer.env.step = spy
    for _ in range(5):
        trainer.collect()
    meta = trainer.meta_buffer
    assert len(meta) == 2  # one finished 5-step segment per environment
    expected = sum(0.9 ** i * rewards[i] for i in range(5))
    np.testing.assert_allclose(meta.data["reward"][:2], expected, rtol=1e-6)
    np.testing.assert_allclose(meta.data["discount"][:2], 0.9 ** 5, rtol=1e-6)
    assert trainer.needs_goal.all()


def test_meta_transitions_store_the_state_the_meta_controller_acted_on(tmp_path):
    """Two runs alike but for the goal their meta-controller picks: the state each stores for that decision is the
    environment's meta observation at the moment of the decision (read from the environment, not from the
    trainer), the same in both runs, although the observations right after the goals were set differ."""
    stored, acted_on, after_goal = {}, {}, {}
    for goal in (0, 3):  # ExploreArea's point lies away from the start, ReturnToBase's on it
        config = small_config("hrl-sac", warmup_steps=0, flight=FlightSettings(max_steps=500, subgoal_interval=5))
        trainer = Trainer(config, tmp_path / str(goal))
        seen, real_set_goals = [], trainer.env.set_goals

        def choose(normalised_obs, trainer=trainer, seen=seen, goal=goal):
            seen.append(trainer.env.core.meta_observation.copy())  # what the environment showed at the decision
            return np.full(len(normalised_obs), goal)

        def set_goals(goals, mask, goal=goal, real_set_goals=real_set_goals):
            after_goal[goal] = real_set_goals(goals, mask)[:, :META_OBS_DIM].copy()
            return real_set_goals(goals, mask)

        trainer.meta.act, trainer.env.set_goals = choose, set_goals
        for _ in range(5):
            trainer.collect()
        assert len(seen) == 1 and len(trainer.meta_buffer) == 2
        stored[goal], acted_on[goal] = trainer.meta_buffer.data["obs"][:2].copy(), seen[0]
        np.testing.assert_array_equal(trainer.meta_buffer.data["action"][:2], [goal, goal])
    np.testing.assert_array_equal(stored[0], acted_on[0])
    np.testing.assert_array_equal(stored[0], stored[3])
    assert not np.array_equal(after_goal[0], after_goal[3])  # the goal's point shows once it is set


@pytest.mark.parametrize("per_transition", [1, 3])
def test_meta_updates_run_per_completed_meta_transition(tmp_path, per_transition):
    config = small_config("hrl-sac", total_steps=600, warmup_steps=100, meta_updates_per_transition=per_transition)
    trainer = Trainer(config, tmp_path)
    learning_transitions, real_learn = [], trainer.learn

    def count(meta_transitions):  # transitions completed once meta learning is on (warm-up over, a batch stored)
        if trainer.step >= config.warmup_steps and len(trainer.meta_buffer) >= config.meta_batch_size:
            learning_transitions.append(meta_transitions)
        real_learn(meta_transitions)

    trainer.learn = count
    trainer.run(progress=False)
    assert sum(learning_transitions) > 10
    assert trainer.meta.num_updates == per_transition * sum(learning_transitions)


def test_the_meta_only_phase_freezes_the_low_level_and_starts_the_meta_buffer_afresh(tmp_path):
    config = small_config("hrl-sac", total_steps=1_200, meta_only_steps=600, meta_only_entropy_scale=0.25)
    assert config.meta_only_from == 600
    trainer = Trainer(config, tmp_path / "run")
    trainer.run(progress=False, stop_at=600)
    assert len(trainer.meta_buffer) > 50  # the joint phase's meta transitions, there until the phase's first step
    actor = {k: v.clone() for k, v in trainer.low.actor.state_dict().items()}
    critic = {k: v.clone() for k, v in trainer.low.critic.state_dict().items()}
    meta_actor = {k: v.clone() for k, v in trainer.meta.actor.state_dict().items()}
    normaliser, low_buffered, low_updates = trainer.normalizer.state_dict(), len(trainer.low_buffer), \
        trainer.low.num_updates
    assert trainer.low_level_frozen
    trainer.collect()  # the first step of the phase drops them
    assert len(trainer.meta_buffer) <= 2
    trainer.run(progress=False)
    assert trainer.step == 1_200 and trainer.low.num_updates == low_updates
    assert all(torch.equal(actor[k], v) for k, v in trainer.low.actor.state_dict().items())
    assert all(torch.equal(critic[k], v) for k, v in trainer.low.critic.state_dict().items())
    assert not all(torch.equal(meta_actor[k], v) for k, v in trainer.meta.actor.state_dict().items())
    assert len(trainer.low_buffer) == low_buffered
    np.testing.assert_array_equal(trainer.normalizer.state_dict()["mean"], normaliser["mean"])
    # 600 steps on 2 environments, one meta transition per K = 10 steps or finished episode
    assert 600 / 10 <= len(trainer.meta_buffer) <= 600 / 10 + 20
    assert trainer.meta.target_entropy == pytest.approx(0.25 * np.log(4))


def test_meta_keep_best_ends_with_the_meta_controller_of_the_best_evaluation(tmp_path):
    """The evaluations' scores are scripted (a real small run scores 0 everywhere, which would not tell the best
    apart): the joint phase's evaluation at step 500 scores highest but is not a candidate; in the phase, step
    1,100 is the best and step 1,400 only ties with it, so the run must end with step 1,100's meta-controller."""
    config = small_config("hrl-sac", total_steps=1_600, meta_only_steps=1_000, meta_keep_best=True,
                          eval_every=100, eval_episodes=4)
    scripted = {500: 1.0, 1_100: 0.75, 1_400: 0.75}
    actors = {}

    def scripted_evaluation(policy):
        actors[policy.step] = {k: v.clone() for k, v in policy.meta.actor.state_dict().items()}
        return scripted.get(policy.step, 0.25)

    trainer = Trainer(config, tmp_path, evaluate=scripted_evaluation)
    trainer.run(progress=False)
    assert sorted(actors) == list(range(100, 1_700, 100))
    assert trainer.best["step"] == 1_100 and trainer.best["success"] == 0.75
    assert not all(torch.equal(actors[1_100][k], actors[1_600][k]) for k in actors[1_100])  # the phase learned
    policy = CheckpointPolicy.load(tmp_path)  # the run, and its checkpoint, end with step 1,100's
    for actor in (trainer.meta.actor.state_dict(), policy.meta.actor.state_dict()):
        assert all(torch.equal(actor[k], actors[1_100][k]) for k in actor)


def test_meta_keep_best_with_a_ran_dry_limit_prefers_the_safe_meta_controller(tmp_path):
    """With ``meta_keep_best_max_ran_dry`` 0.01, the evaluations whose sorties ran dry more often do not compete on
    success: step 1,200 (85 %, 10 % ran dry) loses to step 1,400 (80 %, 1 % ran dry); while none qualified, the one
    that ran dry least was kept (step 1,300 over the phase's first ones)."""
    config = small_config("hrl-sac", total_steps=1_600, meta_only_steps=1_000, meta_keep_best=True,
                          meta_keep_best_max_ran_dry=0.01, eval_every=100, eval_episodes=4)
    scripted = {1_200: (0.85, 0.10), 1_300: (0.50, 0.05), 1_400: (0.80, 0.01), 1_500: (0.79, 0.0)}
    kept = []

    def scripted_evaluation(policy):
        success, ran_dry = scripted.get(policy.step, (0.9, 0.2))
        return {"success_rate": success, "ran_dry_rate": ran_dry}

    trainer = Trainer(config, tmp_path, evaluate=scripted_evaluation)
    original = trainer._better

    def watched(success, ran_dry):
        better = original(success, ran_dry)
        kept.append((trainer.step, better))
        return better

    trainer._better = watched
    trainer.run(progress=False)
    assert trainer.best["step"] == 1_400 and trainer.best["ran_dry"] == 0.01
    assert (1_300, True) in kept and (1_500, False) in kept
    with pytest.raises(ValueError, match=r"meta_keep_best_max_ran_dry must be a number in \[0, 1\]"):
        small_config("hrl-sac", meta_keep_best_max_ran_dry=1.5)


def test_random_goals_go_home_from_the_bingo_call_on(tmp_path):
    """In the warm-up and the joint phase's random goals (SarSearch-v1), a search past the bingo call gets
    ReturnToBase, the others their uniform draw, and the draws of the generator are the same either way."""
    from missions.goals import RETURN_TO_BASE
    from missions.search_state_v1 import BINGO_RESERVE_S

    config = small_config("hrl-sac", num_envs=8, meta_joint_goals="random", meta_only_steps=400)
    trainer = Trainer(config, tmp_path)
    core = trainer.env.core
    assert np.all(core.bingo_margin_s > BINGO_RESERVE_S)  # at home, with the whole endurance left
    core.time_s[:4] = core.scen.endurance_s[:4] - BINGO_RESERVE_S + 1.0  # four of them past the bingo call
    state = trainer.rng.bit_generator.state
    expected = np.random.default_rng()
    expected.bit_generator.state = state
    uniform = expected.integers(0, 4, size=8)
    trainer.needs_goal[:] = True
    trainer._choose_goals()
    assert core.goal[:4].tolist() == [RETURN_TO_BASE] * 4
    assert core.goal[4:].tolist() == uniform[4:].tolist()
    assert trainer.rng.bit_generator.state == expected.bit_generator.state


def test_meta_keep_best_needs_an_evaluation_handed_to_the_trainer(tmp_path):
    config = small_config("hrl-sac", total_steps=1_600, meta_only_steps=1_000, meta_keep_best=True, eval_every=100)
    with pytest.raises(ValueError, match="meta_keep_best chooses by quick evaluations: give the Trainer an evaluate"):
        Trainer(config, tmp_path)


@pytest.mark.parametrize("overrides, problem", [
    ({"meta_only_steps": 1_000}, "must be below total_steps"), ({"meta_only_steps": -1}, "must be an integer"),
    ({"meta_keep_best": True, "eval_every": 100}, "needs a meta-only phase and quick evaluations"),
    ({"meta_keep_best": True, "meta_only_steps": 500}, "needs a meta-only phase and quick evaluations"),
    ({"eval_episodes": 0}, "eval_episodes must be an integer")])
def test_meta_only_options_are_validated(overrides, problem):
    with pytest.raises(ValueError, match=problem):
        small_config("hrl-sac", total_steps=1_000, **overrides)
