"""The training loop: exact resume after a kill, meta transitions with K-step discounted returns, the low-level
reward, checkpoint policies and evaluation, and the train / evaluate commands."""
from __future__ import annotations

import csv
import json
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from autonomy.observation import META_OBS_DIM
from autonomy.policy import load_policy
from missions.goals import SEARCH_LOCATION
from missions.mission import FlightSettings
from missions.search import footprint_half_width_m
from policies.checkpoint import CheckpointPolicy
from policies.config import NetworkConfig, TrainConfig
from policies.env.shaping import cross_track_m
from policies.evaluation.parallel import evaluate_checkpoint, quick_evaluation
from policies.training.sweep_config import load_sweep
from policies.training.trainer import Trainer

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


def test_progress_bars_show_rate_and_time_left_on_stderr_and_change_nothing_else(tmp_path, capsys, monkeypatch):
    from policies.cli import evaluate as evaluate_command
    from hrlsac_cli import progress

    monkeypatch.setattr(progress, "LOG_EVERY_S", 0.0)  # not a terminal: a line at every update, from the first
    config = small_config("sac", total_steps=400)
    runs = {}
    for name, quiet in (("quiet", True), ("shown", False)):
        runs[name] = Trainer(config, tmp_path / name)
        runs[name].run(progress=not quiet)
        argv = [str(tmp_path / name), "--split", "val", "--episodes", "4", "--out", str(tmp_path / f"{name}.json")]
        assert evaluate_command.main(argv + (["--quiet"] if quiet else [])) == 0
        runs[name].stderr = capsys.readouterr().err.splitlines()
    assert runs["quiet"].stderr == []
    training = [line for line in runs["shown"].stderr if line.startswith("training:")]
    assert training[-1].startswith("training: 100%") and " 400/400 [" in training[-1]
    assert "step/s" in training[-1] and "<00:00" in training[-1] and "episodes " in training[-1]
    evaluating = [line for line in runs["shown"].stderr if line.startswith("evaluating:")]
    assert len(evaluating) > 2 and evaluating[-1].startswith("evaluating: 100%")  # step by step, in this process
    assert " 4/4 [" in evaluating[-1] and "episode/s" in evaluating[-1]
    assert log_rows(tmp_path / "quiet" / "progress.csv") == log_rows(tmp_path / "shown" / "progress.csv")
    for a, b in zip(runs["quiet"].low.actor.state_dict().values(), runs["shown"].low.actor.state_dict().values()):
        assert torch.equal(a, b)
    metrics = [json.loads((tmp_path / f"{name}.json").read_text()) for name in ("quiet", "shown")]
    assert [{k: v for k, v in m.items() if k != "checkpoint"} for m in metrics][0] == \
        {k: v for k, v in metrics[1].items() if k != "checkpoint"}


@pytest.mark.parametrize("algo", ["sac", "hrl-sac"])
def test_resuming_after_a_kill_continues_exactly(tmp_path, algo):
    config = small_config(algo)
    uninterrupted = Trainer(config, tmp_path / "a")
    uninterrupted.run(progress=False)
    killed = Trainer(config, tmp_path / "b")
    killed.run(progress=False, stop_at=400)  # the checkpoint at step 400 is all that survives the kill
    resumed = Trainer(config, tmp_path / "b", resume=True)
    assert resumed.step == 400
    resumed.run(progress=False)
    for a, b in zip(uninterrupted.low.actor.state_dict().values(), resumed.low.actor.state_dict().values()):
        assert torch.equal(a, b)
    for a, b in zip(uninterrupted.low.critic.state_dict().values(), resumed.low.critic.state_dict().values()):
        assert torch.equal(a, b)
    if algo == "hrl-sac":
        for a, b in zip(uninterrupted.meta.actor.state_dict().values(), resumed.meta.actor.state_dict().values()):
            assert torch.equal(a, b)
    assert uninterrupted.episodes == resumed.episodes and uninterrupted.episodes > 0
    assert log_rows(tmp_path / "a" / "progress.csv") == log_rows(tmp_path / "b" / "progress.csv")
    np.testing.assert_array_equal(uninterrupted.obs, resumed.obs)


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


@pytest.mark.parametrize(
    "task, kind, coverage_bonus, by_intensity, swept, detection_bonus, belief_bonus, cross_track", [
    ("SarSearch-v1", "progress", 0.0, True, False, 0.0, 0.0, 0.0),
    ("SarSearch-v1", "distance", 0.0, True, False, 0.0, 0.0, 0.0),
    ("SarSearch-v1", "progress", 0.5, False, False, 0.0, 0.0, 0.0),
    ("SarSearch-v0", "progress", 0.5, True, False, 0.0, 0.0, 0.0),
    ("SarSearch-v1", "progress", 0.5, False, True, 0.0, 0.0, 0.0),
    ("SarSearch-v0", "progress", 0.5, True, True, 0.0, 0.0, 0.0),
    ("SarSearch-v0", "progress", 0.0, False, False, 3.0, 0.0, 0.0),
    ("SarSearch-v1", "progress", 0.0, False, False, 0.0, 100.0, 0.0),
    ("SarSearch-v1", "progress", 0.0, False, False, 0.0, 0.0, 2.0)])
def test_low_level_reward_measures_the_way_to_the_goal_point(tmp_path, task, kind, coverage_bonus, by_intensity, swept,
                                                             detection_bonus, belief_bonus, cross_track):
    config = small_config("hrl-sac", task=task, intrinsic_reward=kind, intrinsic_scale_m=100.0,
                          intrinsic_goal_bonus=1.0, extrinsic_weight=0.0, coverage_bonus=coverage_bonus,
                          coverage_by_intensity=by_intensity, coverage_swept=swept, detection_bonus=detection_bonus,
                          belief_bonus=belief_bonus, cross_track_penalty=cross_track, warmup_steps=1_000)
    trainer = Trainer(config, tmp_path)
    captured, real_step = {}, trainer.env.step

    def spy(actions):
        core = trainer.env.core
        captured["before"] = np.hypot(*(core.position - core.goal_point).T)
        captured["start"], captured["goal"] = core.position.copy(), core.goal_point.copy()
        actions[:, 2] = (0.7, 0.9)  # in place: the sensor on in both environments, at two intensities
        if cross_track:
            actions[:, :2] = (-0.6, 0.8)  # full speed, south-east: not along env 0's line to its goal point
        if detection_bonus or belief_bonus:
            actions[:, 3] = 0.0  # zoomed out: a 35 m footprint half-width at 50 m
        captured["intensity"], captured["zoom"] = actions[:, 2].copy(), actions[:, 3].copy()
        captured["belief"] = core.belief.sum(axis=(1, 2)) if belief_bonus else 0.0
        result = real_step(actions)
        captured["info"] = result[4]
        captured["belief"] = captured["belief"] - core.belief.sum(axis=(1, 2)) if belief_bonus else 0.0
        return result

    trainer.env.step = spy
    if detection_bonus or belief_bonus:  # environment 0 starts beside its victim / the datum, in the camera's view
        core = trainer.env.core
        near = core.targets[0, core.scen.primary_index[0]] if detection_bonus else core.scen.datum[0]
        core.vehicles.north_m[0], core.vehicles.east_m[0] = near[0] + 20.0, near[1]
        core.position[0] = near + (20.0, 0.0)
    trainer.collect()
    info = captured["info"]
    distance = np.hypot(*(info["position"] - info["goal_point"]).T)
    toward = captured["before"] - distance if kind == "progress" else -distance
    assert kind == "distance" or np.all(np.abs(toward) < 20.0)  # one step of flight, not a distance
    # the grid was empty before the first step: v0 counts the covered cells, v1 sums their probabilities of detection
    newly_covered = (info["coverage_ratio"] * 1024 if task == "SarSearch-v0"
                     else trainer.env.core.coverage.sum(axis=(1, 2)))
    assert coverage_bonus == 0.0 or newly_covered.any()
    if swept:  # the ground the footprint swept, in 31.25 m cells: distance flown x footprint width
        flown = np.hypot(*(info["position"] - captured["start"]).T)
        width = 2.0 * footprint_half_width_m(config.flight.altitude_m, captured["zoom"])
        newly_covered = flown * width / 31.25 ** 2
        assert np.all(newly_covered > 0.0)
    if by_intensity:  # a cell covered at intensity 0.7 earns 0.7 of the bonus
        newly_covered = newly_covered * captured["intensity"]
    moved_on = np.hypot(*(trainer.env.core.goal_point - info["goal_point"]).T) > config.flight.reach_radius_m
    completed = (distance <= config.flight.reach_radius_m) & moved_on
    chance = info["first_detection_chance"] if detection_bonus else 0.0
    assert detection_bonus == 0.0 or (chance[0] > 0.05 and chance[1] == 0.0)
    removed = captured["belief"]  # the look is all that takes belief away on the first step (no drift out yet)
    assert belief_bonus == 0.0 or (removed[0] > 1e-3 and removed[0] > 10 * removed[1])
    # sideways: the step's component across the line from the start to the goal point it was flying to
    to_goal = captured["goal"] - captured["start"]
    across = np.stack([to_goal[:, 1], -to_goal[:, 0]], axis=1) / np.maximum(np.hypot(*to_goal.T), 1e-9)[:, None]
    sideways = np.abs(np.einsum("ij,ij->i", info["position"] - captured["start"], across))
    if cross_track:  # env 0 flies south-east towards a distant point off that line: a real sideways part
        assert np.hypot(*to_goal[0]) > 10.0 and sideways[0] > 0.1
    expected = ((toward - cross_track * sideways) / 100.0 + completed + coverage_bonus * newly_covered
                + detection_bonus * chance + belief_bonus * removed)
    np.testing.assert_allclose(trainer.low_buffer.data["reward"][:2], expected, rtol=1e-5, atol=1e-6)


def test_cross_track_is_the_sideways_part_of_the_step():
    start = np.array([[0.0, 0.0], [0.0, 0.0], [5.0, 5.0], [1.0, 1.0]])
    end = np.array([[3.0, 4.0], [3.0, -4.0], [5.0, 10.0], [2.0, 2.0]])
    goal = np.array([[10.0, 0.0], [10.0, 0.0], [0.0, 5.0], [1.0, 1.0]])  # the last: already at its goal point
    np.testing.assert_allclose(cross_track_m(start, end, goal), [4.0, 4.0, 5.0, 0.0])


@pytest.mark.parametrize("task, goal_conditioned", [("SarSearch-v0", True), ("SarSearch-v1", True),
                                                     ("SarSearch-v1", False)])
def test_the_step_info_says_where_the_step_started(task, goal_conditioned):
    """The learning rewards read only the step's info: its start entries are the state before the step, taken
    independently here from the batch before stepping it."""
    from policies.env.core import SarSearchConfig
    from policies.env.vector import SarSearchVectorEnv

    env = SarSearchVectorEnv(3, SarSearchConfig(task=task, split="val", goal_conditioned=goal_conditioned))
    env.reset(seed=[0, 1, 2])
    if goal_conditioned:
        env.set_goals(np.array([0, 1, 2]))
    rng, added = np.random.default_rng(0), 0.0
    for _ in range(4):
        core = env.core
        position = core.position.copy()
        target = (core.goal_point if goal_conditioned else core.target_position(False)).copy()
        searched = np.array(core.searched_cells, dtype=np.float64)
        area = core.scen.area.copy()
        actions = rng.uniform(-1.0, 1.0, size=(3, 4)).astype(np.float32)
        actions[:, 2] = 1.0  # sensor on: the step covers cells
        _, _, terminated, truncated, info = env.step(actions)
        assert not (terminated | truncated).any()
        np.testing.assert_array_equal(info["start_position"], position)
        np.testing.assert_array_equal(info["step_target"], target)
        np.testing.assert_array_equal(info["newly_searched_cells"], info["searched_cells"] - searched)
        cells = core.coverage[0].size
        np.testing.assert_allclose(info["cell_area_m2"], (area[:, 1] - area[:, 0]) * (area[:, 3] - area[:, 2]) / cells)
        assert not np.array_equal(info["position"], position)
        added += info["newly_searched_cells"].sum()
    assert added > 0
    assert env.step_reward == (-0.1 if task == "SarSearch-v0" else 0.0)


def test_flat_sac_learns_from_the_environment_reward(tmp_path):
    config = small_config("sac")
    trainer = Trainer(config, tmp_path)
    captured, real_step = {}, trainer.env.step

    def spy(actions):
        result = real_step(actions)
        captured["reward"] = result[1]
        return result

    trainer.env.step = spy
    trainer.collect()
    np.testing.assert_allclose(trainer.low_buffer.data["reward"][:2], captured["reward"])
    assert trainer.meta is None and not trainer.obs[:, config.layout.meta_dim:].any()  # no goal one-hot for flat SAC


def test_checkpoint_policy_is_deterministic_and_evaluates(tmp_path):
    Trainer(small_config("hrl-sac", total_steps=400), tmp_path).run(progress=False)
    policy = CheckpointPolicy.load(tmp_path)
    assert policy.hierarchical and policy.step == 400
    obs = np.random.default_rng(0).uniform(0, 1, size=(5, 288)).astype(np.float32)
    np.testing.assert_array_equal(policy.act(obs), policy.act(obs))
    actions = policy.act(obs)
    assert np.all(actions >= [-1, -1, 0, 0]) and np.all(actions <= 1)
    assert set(policy.choose_goals(obs[:, :284]).tolist()) <= {0, 1, 2, 3}
    metrics = evaluate_checkpoint(tmp_path, "val", 6)
    assert metrics["episodes"] == 6 and 0.0 <= metrics["success_rate"] <= 1.0
    assert metrics["subgoal_reachability"] is not None
    assert metrics == evaluate_checkpoint(tmp_path, "val", 6)  # deterministic


def test_train_and_evaluate_commands(tmp_path):
    run = tmp_path / "run"
    base = [sys.executable, "-m", "hrlsac_cli"]
    result = subprocess.run([*base, "train", "--algo", "sac", "--steps", "300", "--out", str(run), "--quiet",
                             "--set", "warmup_steps=100", "--set", "num_envs=2", "--set", "batch_size=16"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert json.loads((run / "config.json").read_text())["total_steps"] == 300
    again = subprocess.run([*base, "train", "--algo", "sac", "--steps", "300", "--out", str(run)],
                           capture_output=True, text=True, timeout=120)
    assert again.returncode == 2 and "already holds a run" in again.stderr
    bad = subprocess.run([*base, "train", "--out", str(tmp_path / "x"), "--set", "warmup=5"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "expected FIELD=VALUE" in bad.stderr
    evaluated = subprocess.run([*base, "evaluate", str(run), "--split", "val", "--episodes", "4"],
                               capture_output=True, text=True, timeout=300)
    assert evaluated.returncode == 0, evaluated.stderr
    metrics = json.loads((run / "eval_val.json").read_text())
    assert metrics["episodes"] == 4 and metrics["algo"] == "sac" and not metrics["flight_rules"]
    flown = subprocess.run([*base, "evaluate", str(run), "--split", "val", "--episodes", "4", "--flight-rules"],
                           capture_output=True, text=True, timeout=300)
    assert flown.returncode == 0 and "eval_val_flight.json" in flown.stdout, flown.stderr
    assert json.loads((run / "eval_val_flight.json").read_text())["flight_rules"]
    missing = subprocess.run([*base, "evaluate", str(tmp_path / "nothing")], capture_output=True, text=True,
                             timeout=120)
    assert missing.returncode == 2 and "no checkpoint" in missing.stderr


def test_a_terminated_training_saves_its_checkpoint_and_resumes(tmp_path):
    import signal
    import time

    run = tmp_path / "run"
    base = [sys.executable, "-m", "hrlsac_cli", "train"]
    process = subprocess.Popen([*base, "--algo", "sac", "--steps", "1000000", "--out", str(run), "--quiet",
                                "--set", "warmup_steps=100", "--set", "num_envs=2", "--set", "log_every=100"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not (run / "progress.csv").exists():
        time.sleep(0.2)
    while time.monotonic() < deadline and len((run / "progress.csv").read_text().splitlines()) < 3:
        time.sleep(0.2)
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert "checkpoint saved" in stderr and "--resume" in stderr
    state = torch.load(run / "checkpoint.pt", map_location="cpu", weights_only=False)
    assert state["step"] >= 200
    resumed = Trainer(TrainConfig.from_dict(json.loads((run / "config.json").read_text())), run, resume=True)
    assert resumed.step == state["step"]


def test_the_goal_bonus_pays_for_a_searched_cell_not_for_hovering_at_it(tmp_path):
    """SearchSpecificLocation: fly to the point with the sensor off and hover there: no bonus however long (the
    cell stays unsearched, the goal stays put); switch the sensor on: the cell is searched, the goal moves on,
    and that step earns the bonus once."""
    config = small_config("hrl-sac", task="SarSearch-v0", warmup_steps=0, coverage_bonus=0.0,
                          intrinsic_goal_bonus=5.0, flight=FlightSettings(max_steps=1_000, subgoal_interval=1_000))
    trainer = Trainer(config, tmp_path)
    trainer.meta.act = lambda obs: np.full(len(obs), SEARCH_LOCATION)
    sensor = {"intensity": 0.0}

    def fly_to_goal(obs, deterministic=False):
        core = trainer.env.core
        velocity = (core.goal_point - core.position) / config.flight.max_speed_mps
        velocity /= np.maximum(1.0, np.linalg.norm(velocity, axis=1, keepdims=True))
        return np.column_stack([velocity, np.full(len(velocity), sensor["intensity"]), np.zeros(len(velocity))])

    trainer.low.act = fly_to_goal
    radius = config.flight.reach_radius_m
    rewards, at_goal = [], []
    for _ in range(300):
        trainer.collect()
        rewards.append(trainer.low_buffer.data["reward"][len(trainer.low_buffer) - 2:len(trainer.low_buffer)].copy())
        at_goal.append(np.hypot(*(trainer.env.core.position - trainer.env.core.goal_point).T) <= radius)
    rewards, at_goal = np.array(rewards), np.array(at_goal)
    assert at_goal[-50:].all()  # both drones arrived and hover within reach of their point
    assert rewards[-50:].max() < 1.0  # progress only (metres / 10 per step): never the bonus of 5

    point_before = trainer.env.core.goal_point.copy()
    sensor["intensity"] = 1.0
    trainer.collect()
    reward = trainer.low_buffer.data["reward"][len(trainer.low_buffer) - 2:len(trainer.low_buffer)]
    assert np.all(np.hypot(*(trainer.env.core.goal_point - point_before).T) > radius)  # the search moved on
    assert np.all(reward > 4.0)  # the bonus, paid for completing the sub-goal


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


def test_the_meta_only_phase_resumes_exactly(tmp_path):
    config = small_config("hrl-sac", total_steps=1_200, meta_only_steps=600, checkpoint_every=400,
                          meta_keep_best=True, eval_every=200, eval_episodes=4)
    uninterrupted = Trainer(config, tmp_path / "a", evaluate=quick_evaluation)
    uninterrupted.run(progress=False)
    killed = Trainer(config, tmp_path / "b", evaluate=quick_evaluation)
    killed.run(progress=False, stop_at=800)  # killed inside the phase, after the checkpoint at step 800
    resumed = Trainer(config, tmp_path / "b", resume=True, evaluate=quick_evaluation)
    assert resumed.step == 800 and resumed.low_level_frozen
    resumed.run(progress=False)
    for a, b in zip(uninterrupted.meta.critic.state_dict().values(), resumed.meta.critic.state_dict().values()):
        assert torch.equal(a, b)
    for a, b in zip(uninterrupted.meta.actor.state_dict().values(), resumed.meta.actor.state_dict().values()):
        assert torch.equal(a, b)
    assert uninterrupted.best["step"] == resumed.best["step"]
    assert log_rows(tmp_path / "a" / "progress.csv") == log_rows(tmp_path / "b" / "progress.csv")


def test_quick_evaluations_are_logged_and_do_not_change_training(tmp_path):
    plain = Trainer(small_config("hrl-sac", eval_every=0), tmp_path / "plain")
    plain.run(progress=False)
    evaluated = Trainer(small_config("hrl-sac", eval_every=200, eval_episodes=4), tmp_path / "evaluated",
                        evaluate=quick_evaluation)
    evaluated.run(progress=False)
    for a, b in zip(plain.low.actor.state_dict().values(), evaluated.low.actor.state_dict().values()):
        assert torch.equal(a, b)
    for a, b in zip(plain.meta.actor.state_dict().values(), evaluated.meta.actor.state_dict().values()):
        assert torch.equal(a, b)
    rows_plain, rows_evaluated = log_rows(tmp_path / "plain" / "progress.csv"), \
        log_rows(tmp_path / "evaluated" / "progress.csv")
    assert [row["eval_success_rate"] for row in rows_plain] == ["nan"] * len(rows_plain)
    evaluations = [row.pop("eval_success_rate") for row in rows_evaluated]
    ran_dry = [row.pop("eval_ran_dry_rate") for row in rows_evaluated]
    assert evaluations[0] == "nan" and all(0.0 <= float(value) <= 1.0 for value in evaluations[1:])
    assert ran_dry[0] == "nan" and all(0.0 <= float(value) <= 1.0 for value in ran_dry[1:])
    evaluated_fields = ("eval_success_rate", "eval_ran_dry_rate")
    assert [{k: v for k, v in row.items() if k not in evaluated_fields} for row in rows_plain] == rows_evaluated
    # the last evaluation is the final policy's success on the first 4 val scenarios, as hrlsac evaluate gives it
    final = evaluate_checkpoint(tmp_path / "evaluated", split="val", episodes=4)
    assert float(evaluations[-1]) == final["success_rate"]


def test_quick_evaluations_can_fly_with_the_mission_runners_rules(tmp_path):
    """eval_flight_rules: the quick evaluation is what hrlsac evaluate --flight-rules gives on the same scenarios."""
    import dataclasses

    trainer = Trainer(small_config("hrl-sac", eval_every=0), tmp_path)
    trainer.run(progress=False)
    policy = CheckpointPolicy.load(tmp_path)
    for rules in (False, True):
        policy.config = dataclasses.replace(policy.config, eval_flight_rules=rules, eval_episodes=6)
        quick = quick_evaluation(policy)
        full = evaluate_checkpoint(tmp_path, split="val", episodes=6, flight_rules=rules)
        assert quick == {"success_rate": full["success_rate"], "ran_dry_rate": full["ran_dry_rate"]}
        assert full["flight_rules"] == rules


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


def test_keep_best_ends_a_flat_run_with_the_policy_and_normaliser_of_the_best_evaluation(tmp_path):
    """keep_best (flat SAC): scripted scores make step 300 the best and step 700 only tie with it, so the run and
    its checkpoint end with step 300's actor and the normaliser its inputs had then; the critics, which do not act,
    are the last ones, as in a run without keep_best."""
    scripted = {300: 0.75, 700: 0.75}
    seen = {}

    def scripted_evaluation(policy):
        seen[policy.step] = ({k: v.clone() for k, v in policy.low.actor.state_dict().items()},
                             policy.normalizer.state_dict())
        return scripted.get(policy.step, 0.25)

    plain = Trainer(small_config("sac"), tmp_path / "plain")
    plain.run(progress=False)
    trainer = Trainer(small_config("sac", keep_best=True, eval_every=100, eval_episodes=4), tmp_path / "best",
                      evaluate=scripted_evaluation)
    trainer.run(progress=False)
    assert sorted(seen) == list(range(100, 900, 100))
    assert trainer.best["step"] == 300 and trainer.best["success"] == 0.75
    actor_300, normaliser_300 = seen[300]
    assert not all(torch.equal(actor_300[k], seen[800][0][k]) for k in actor_300)  # it learned after step 300
    assert not np.array_equal(normaliser_300["mean"], seen[800][1]["mean"])
    policy = CheckpointPolicy.load(tmp_path / "best")
    for actor in (trainer.low.actor.state_dict(), policy.low.actor.state_dict()):
        assert all(torch.equal(actor[k], actor_300[k]) for k in actor)
    np.testing.assert_array_equal(policy.normalizer.state_dict()["mean"], normaliser_300["mean"])
    np.testing.assert_array_equal(policy.normalizer.state_dict()["var"], normaliser_300["var"])
    for a, b in zip(plain.low.critic.state_dict().values(), trainer.low.critic.state_dict().values()):
        assert torch.equal(a, b)  # choosing is all it changes


def test_keep_best_is_the_flat_sacs_and_needs_quick_evaluations():
    with pytest.raises(ValueError, match=r"keep_best is the flat SAC's .*\(got 'hrl-sac' and 100\).*meta_keep_best"):
        small_config("hrl-sac", keep_best=True, eval_every=100)
    with pytest.raises(ValueError, match=r"keep_best .* eval_every above 0 \(got 'sac' and 0\)"):
        small_config("sac", keep_best=True, eval_every=0)
    with pytest.raises(ValueError, match=r"TrainConfig.keep_best chooses by quick evaluations: give the Trainer"):
        Trainer(small_config("sac", keep_best=True, eval_every=100), "unused-run-dir")


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


def test_n_step_returns_sum_the_discounted_rewards_and_bootstrap_with_gamma_to_the_n():
    """Three environments through NStepReturns with n = 3: a long episode, one ending (terminated) after two
    steps, one truncated after two: each stored transition recomputed by hand."""
    from policies.agents.n_step import NStepReturns

    acc, gamma = NStepReturns(3, 0.9, 3), 0.9
    stored = []
    rewards = [np.array([1.0, 10.0, 100.0]), np.array([2.0, 20.0, 200.0]), np.array([3.0, 30.0, 300.0])]
    for t, r in enumerate(rewards):
        obs, next_obs = np.full((3, 2), float(t)), np.full((3, 2), float(t + 1))
        done = np.array([False, t == 1, t == 1])
        terminated = np.array([False, t == 1, False])
        out = acc.add(obs, np.zeros((3, 4)), r, next_obs, terminated, done)
        if out is not None:
            fields = out.stored_fields()
            stored += [dict(zip(fields, values)) for values in zip(*fields.values())]
    def find(reward: float) -> dict:
        matches = [s for s in stored if np.isclose(s["reward"], reward)]
        assert len(matches) == 1, (reward, [float(s["reward"]) for s in stored])
        return matches[0]

    # pending: env 0's last two steps; envs 1 and 2, the first step of their next episode
    assert len(stored) == 5 and [len(p) for p in acc.pending] == [2, 1, 1]
    # env 0 (long): one full 3-step transition from t = 0, bootstrapping from the observation after t = 2
    full = find(1.0 + 0.9 * 2.0 + 0.81 * 3.0)
    assert full["discount"] == pytest.approx(gamma ** 3) and full["done"] == 0.0 and full["next_obs"][0] == 3.0
    # env 1, terminated after t = 1: flushed as a 2-step and a 1-step transition, both done
    for reward, discount in ((10.0 + 0.9 * 20.0, 0.81), (20.0, 0.9)):
        s = find(reward)
        assert s["done"] == 1.0 and s["discount"] == pytest.approx(discount) and s["next_obs"][0] == 2.0
    # env 2, truncated after t = 1: flushed too, but bootstrapping (done 0) from the last real observation
    for reward, discount in ((100.0 + 0.9 * 200.0, 0.81), (200.0, 0.9)):
        s = find(reward)
        assert s["done"] == 0.0 and s["discount"] == pytest.approx(discount) and s["next_obs"][0] == 2.0


def test_flat_shaping_pays_the_way_to_the_target_and_the_environment_reward_without_the_step_cost(tmp_path):
    config = small_config("sac", flat_shaping=True, intrinsic_scale_m=10.0, cross_track_penalty=0.0,
                          coverage_bonus=0.0, warmup_steps=1_000)
    trainer = Trainer(config, tmp_path)
    captured, real_step = {}, trainer.env.step

    def spy(actions):
        core = trainer.env.core
        captured["target"], captured["start"] = core.target_position(False).copy(), core.position.copy()
        result = real_step(actions)
        captured["reward"], captured["position"] = result[1].copy(), result[4]["position"].copy()
        return result

    trainer.env.step = spy
    trainer.collect()
    progress = (np.hypot(*(captured["start"] - captured["target"]).T)
                - np.hypot(*(captured["position"] - captured["target"]).T)) / 10.0
    expected = progress + captured["reward"]  # SarSearch-v1's reward has no per-step part to leave out
    np.testing.assert_allclose(trainer.low_buffer.data["reward"][:2], expected, rtol=1e-5, atol=1e-6)
    assert np.all(np.abs(progress) > 0.01)  # the random first actions moved the drones towards or away from it


def test_a_checkpoint_written_before_the_sub_packages_still_resumes(tmp_path):
    """Checkpoints pickle the environments' state, naming their classes' modules; those written when the core was
    ``policies.env_core`` (and the v1 task ``policies.ambiguous_env``) load into today's modules."""
    from policies.checkpoint import load_environment

    trainer = Trainer(small_config("hrl-sac"), tmp_path)
    pickled = pickle.dumps(trainer.env.core)
    # protocol 2 names each class as text ("module\nname\n"), so the old names may differ in length
    old = pickle.dumps(trainer.env.core, protocol=2).replace(b"policies.env.core\n", b"policies.env_core\n")
    old = old.replace(b"policies.env.task_v1\n", b"policies.ambiguous_env\n")
    assert b"policies.env_core\n" in old and b"policies.ambiguous_env\n" in old and b"policies.env.core\n" not in old
    assert pickle.dumps(load_environment(old)) == pickled


@pytest.mark.parametrize("artifact, sweep_file, run", [
    ("hrl-sac.pt", "hrl-sac.sweep.yaml", "hrl-sac-default-seed0"),
    ("sac.pt", "sac.sweep.yaml", "sac-default-seed0")])
def test_the_shipped_policies_are_the_sweep_file_runs_the_docs_name(artifact, sweep_file, run):
    # docs/training.md: `hrlsac train --sweep docs/results/SWEEP --run RUN` is the shipped policy's recipe; the
    # artifact's manifest carries the config it was trained with, which must be that run's, field for field.
    root = Path(__file__).resolve().parents[1]
    manifest = load_policy(root / "policies" / "pretrained" / artifact).manifest
    spec = {spec.name: spec for spec in load_sweep(root / "docs" / "results" / sweep_file).runs}[run]
    assert manifest.training_config == json.loads(json.dumps(spec.config.to_dict()))
