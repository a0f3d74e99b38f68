"""The training loop's rewards: the low-level reward (progress or distance to the goal point, coverage, detection
and belief bonuses, the cross-track penalty), the step info the rewards read, the goal bonus for a searched cell,
flat SAC's environment reward and flat shaping, and n-step returns."""
from __future__ import annotations

import numpy as np
import pytest
from training_helpers import small_config

from missions.goals import SEARCH_LOCATION
from missions.mission import FlightSettings
from missions.search import footprint_half_width_m
from policies.env.shaping import cross_track_m
from policies.training.trainer import Trainer


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
