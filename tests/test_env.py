"""SarSearch-v0 (kept for the runs trained on it): gymnasium API, observation layout, each reward component,
detection and coverage in the environment, seeding, and the single and vectorised forms agreeing. SarSearch-v1's
are in tests/test_env_v1.py."""
from __future__ import annotations

import dataclasses
import math

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import policies  # noqa: F401  (registers SarSearch-v0)
from autonomy.observation import LAYOUT_V3, TARGET_OFFSET_SCALE_M
from missions.goals import TRACK_OBJECT
from missions.mission import FlightSettings
from missions.scenario import Conditions, Obstacle, Scenario, SearchArea, SeaState, Target, TimeOfDay, Weather
from policies.env.core import REWARD_BOUNDARY, REWARD_COLLISION, REWARD_STEP, REWARD_TARGET, SarSearchConfig
from policies.env.gym_env import SarSearchEnv
from policies.env.vector import SarSearchVectorEnv

V0 = "SarSearch-v0"
FIELDS_BY_NAME, OBSERVATION_FIELDS = LAYOUT_V3.by_name, LAYOUT_V3.fields
OBS_DIM, META_OBS_DIM = LAYOUT_V3.dim, LAYOUT_V3.meta_dim
AREA = SearchArea(-50.0, 950.0, -500.0, 500.0)
HOVER = np.array([0.0, 0.0, 0.0, 0.0], dtype=np.float32)
NORTH = np.array([1.0, 0.0, 0.0, 0.0], dtype=np.float32)


def field(obs: np.ndarray, name: str) -> np.ndarray:
    return obs[FIELDS_BY_NAME[name].slice]


def target_position(obs: np.ndarray, area_size_m: float = 1000.0) -> np.ndarray:
    """The target's position normalised like agent_position, recovered from the squashed target_offset."""
    squashed = field(obs, "target_offset").astype(np.float64)
    offset_m = squashed * TARGET_OFFSET_SCALE_M / (1.0 - np.hypot(*squashed))
    return field(obs, "agent_position") + offset_m / area_size_m


def scenario(victim=(600.0, 100.0), datum=(550.0, 80.0), obstacles=(), conditions=Conditions(), start=(0.0, 0.0),
             others=()) -> Scenario:
    targets = (Target("person", *victim, primary=True),) + tuple(Target(c, n, e) for c, n, e in others)
    return Scenario(area=AREA, start_north_m=start[0], start_east_m=start[1], datum_north_m=datum[0],
                    datum_east_m=datum[1], datum_sigma_m=80.0, targets=targets, obstacles=tuple(obstacles),
                    conditions=conditions, name="test")


def env_for(*scenarios: Scenario, goal_conditioned: bool = False, **flight) -> SarSearchEnv:
    return SarSearchEnv(SarSearchConfig(task=V0, scenarios=scenarios, flight=FlightSettings(**flight),
                                        goal_conditioned=goal_conditioned))


# ------------------------------------------------------------------ API
def test_gymnasium_check_env_passes_and_make_works():
    check_env(gymnasium.make("SarSearch-v0").unwrapped)
    check_env(gymnasium.make("SarSearch-v0", goal_conditioned=True, render_mode="rgb_array").unwrapped)
    env = gymnasium.make("SarSearch-v0", split="val")
    obs, info = env.reset(seed=4)
    assert obs.shape == (OBS_DIM,) == (276,) and info["scenario"] == "gen-val-000004"
    vec = gymnasium.make_vec("SarSearch-v0", num_envs=3, vectorization_mode="vector_entry_point")
    assert vec.reset(seed=0)[0].shape == (3, 276)


def test_bad_configuration_is_refused_with_the_field_name():
    with pytest.raises(ValueError, match="SarSearchConfig.split must be one of train, val, test"):
        SarSearchConfig(split="holdout")
    with pytest.raises(ValueError, match="render_mode"):
        SarSearchEnv(render_mode="human")
    env = env_for(scenario())
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"goal indices must be in \[0, 3\]"):
        env.set_goal(7)


# ------------------------------------------------------------------ observation layout
def test_layout_adds_up_to_the_papers_276_and_272():
    sizes = {f.name: f.size for f in OBSERVATION_FIELDS}
    assert sizes == {"agent_position": 2, "target_offset": 2, "time_progress": 1, "sea_condition": 1,
                     "weather": 1, "time_of_day": 1, "visibility": 1, "wind_speed": 1, "detections": 6,
                     "coverage": 256, "goal": 4}
    assert OBS_DIM == 276 and META_OBS_DIM == 272
    offsets = [f.offset for f in OBSERVATION_FIELDS]
    assert offsets == sorted(offsets) and offsets[0] == 0


def test_observation_fields_one_by_one():
    conditions = Conditions(sea=SeaState.ROUGH, weather=Weather.FOGGY, time_of_day=TimeOfDay.DUSK,
                            visibility=0.45, wind=0.3)
    env = env_for(scenario(conditions=conditions), max_steps=200)
    obs, _ = env.reset(seed=0)
    np.testing.assert_allclose(field(obs, "agent_position"), [50 / 1000, 0.5])
    np.testing.assert_allclose(target_position(obs), [600 / 1000, 580 / 1000], rtol=1e-6)  # the datum
    assert field(obs, "time_progress")[0] == 0.0
    assert field(obs, "sea_condition")[0] == 1.0 and field(obs, "weather")[0] == pytest.approx(2 / 3)
    assert field(obs, "time_of_day")[0] == pytest.approx(2 / 3)
    assert field(obs, "visibility")[0] == pytest.approx(0.45) and field(obs, "wind_speed")[0] == pytest.approx(0.3)
    assert not field(obs, "detections").any() and not field(obs, "coverage").any()
    assert not field(obs, "goal").any()
    obs, *_ = env.step(np.array([1.0, 0.0, 1.0, 0.0], dtype=np.float32))
    assert field(obs, "time_progress")[0] == pytest.approx(1 / 200)
    assert field(obs, "agent_position")[0] > 50 / 1000  # moved north
    coverage = field(obs, "coverage")
    assert coverage.any() and coverage.max() <= 1.0  # the footprint was searched
    assert obs.dtype == np.float32 and np.all((obs >= -1) & (obs <= 1))
    offset = field(obs, "target_offset")  # towards the datum, north-east of the start
    assert offset[0] > 0 and offset[1] > 0 and np.hypot(*offset) < 1


def test_goal_one_hot_and_goal_point_in_goal_conditioned_mode():
    env = env_for(scenario(), goal_conditioned=True)
    env.reset(seed=0)
    obs = env.set_goal(3)  # ReturnToBase: home
    np.testing.assert_array_equal(field(obs, "goal"), [0, 0, 0, 1])
    np.testing.assert_allclose(target_position(obs), [50 / 1000, 0.5])
    # nothing detected yet: the most probable unsearched cell discounted by travel, here the cell just south of the
    # datum's (cell centres every 1000 m / 32; the datum's own cell is row 19, 9 m from the datum, 31 m further)
    obs = env.set_goal(TRACK_OBJECT)
    np.testing.assert_array_equal(field(obs, "goal"), [0, 0, 1, 0])
    np.testing.assert_allclose(target_position(obs), [18.5 / 32, 18.5 / 32], atol=1e-6)  # float32 observation
    np.testing.assert_array_equal(env.meta_observation, obs[:272])
    with pytest.raises(ValueError, match=r"goal indices must be in \[0, 3\]"):
        env.set_goal(4)


def test_goal_points_are_routed_around_a_charted_danger_zone_on_the_way():
    zone = Obstacle(280.0, 40.0, 30.0)  # on the straight line from home (0, 0) to the datum's cells
    env = env_for(scenario(obstacles=[zone]), goal_conditioned=True)
    env.reset(seed=0)
    env.set_goal(TRACK_OBJECT)
    unrouted = env_for(scenario(), goal_conditioned=True)
    unrouted.reset(seed=0)
    unrouted.set_goal(TRACK_OBJECT)
    point, straight = env.core.goal_point[0], unrouted.core.goal_point[0]
    assert np.hypot(*(point - straight)) > 100.0  # a waypoint beside the zone, not the cell behind it
    along = np.linspace(0.0, 1.0, 200)[:, None] * point  # the straight leg from home to the waypoint
    assert np.hypot(along[:, 0] - zone.north_m, along[:, 1] - zone.east_m).min() >= zone.radius_m + 19.9


def test_target_follows_the_datum_drifted_by_current_and_leeway_until_detection():
    # 0.5 m/s current to the east, no wind: after 10 steps of 1 s the datum has moved 5 m east.
    drifting = dataclasses.replace(scenario(victim=(900.0, 400.0)), current_east_mps=0.5)
    env = env_for(drifting)
    env.reset(seed=0)
    for _ in range(10):
        obs, *_ = env.step(HOVER)
    np.testing.assert_allclose(target_position(obs), [600 / 1000, 585 / 1000], atol=1e-6)


def test_a_reached_goal_is_grounded_again_before_the_next_decision():
    # SearchSpecificLocation from a start one cell south of the datum's cell: reached in the first steps,
    # then the next most probable unsearched cell becomes the point, without a new meta decision.
    env = env_for(scenario(victim=(900.0, 400.0), datum=(560.0, 90.0), start=(530.0, 90.0)), goal_conditioned=True)
    env.reset(seed=0)
    env.set_goal(1)
    first_point = env.core.goal_point[0].copy()
    for _ in range(10):
        offset = env.core.goal_point[0] - env.core.position[0]
        action = np.concatenate([offset / max(np.hypot(*offset), 10.0), [1.0, 0.0]]).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        if info["goal_reached"]:
            break
    assert info["goal_reached"] and np.hypot(*(info["position"] - first_point)) <= 15.0
    np.testing.assert_allclose(info["goal_point"], first_point)  # the point this step flew to
    assert np.hypot(*(env.core.goal_point[0] - first_point)) > 15.0  # the next one, already in the observation
    assert env.core.goal[0] == 1 and field(obs, "goal")[1] == 1
    np.testing.assert_allclose(target_position(obs),
                               [(env.core.goal_point[0, 0] + 50) / 1000, (env.core.goal_point[0, 1] + 500) / 1000],
                               atol=1e-6)


def test_target_never_leaks_the_victim_until_it_is_detected():
    # Victim 12 m east of the start, directly in view at 20 m: detected at once, but not reachable (radius 1 m).
    env = env_for(scenario(victim=(0.0, 12.0), datum=(300.0, -200.0)), altitude_m=20.0, reach_radius_m=1.0)
    obs, _ = env.reset(seed=0)
    victim = np.array([50 / 1000, 512 / 1000])
    assert not np.allclose(target_position(obs), victim, atol=1e-3)
    seen = False
    for _ in range(20):
        obs, _, _, _, info = env.step(np.array([0.0, 0.0, 1.0, 0.0], dtype=np.float32))
        if info["victim_detected"]:
            seen = True
            break
    assert seen
    np.testing.assert_allclose(target_position(obs), victim, atol=1e-3)
    assert field(obs, "detections")[0] == 1.0  # a person was detected this step


# ------------------------------------------------------------------ rewards and episode ends
def test_step_and_energy_penalties():
    env = env_for(scenario())
    env.reset(seed=0)
    assert env.step(HOVER)[1] == pytest.approx(REWARD_STEP)
    action = np.array([0.6, -0.8, 1.0, 0.5], dtype=np.float32)
    assert env.step(action)[1] == pytest.approx(REWARD_STEP - 0.01 * (0.36 + 0.64 + 1.0 + 0.25))


def test_reaching_the_victim_pays_100_and_terminates():
    env = env_for(scenario(victim=(16.0, 0.0)), reach_radius_m=15.0)  # 1.7 m in the first step is enough
    env.reset(seed=0)
    _, reward, terminated, truncated, info = env.step(np.array([0.3, 0.0, 0.0, 0.0], dtype=np.float32))
    assert info["success"] and terminated and not truncated
    assert reward == pytest.approx(REWARD_TARGET + REWARD_STEP - 0.01 * 0.09)


def test_entering_a_danger_zone_costs_50_and_terminates():
    env = env_for(scenario(obstacles=[Obstacle(40.0, 0.0, 15.0)]))
    env.reset(seed=0)
    rewards = []
    for _ in range(10):
        _, reward, terminated, _, info = env.step(NORTH)
        rewards.append(reward)
        if terminated:
            break
    assert info["collision"] and terminated
    assert rewards[-1] == pytest.approx(REWARD_COLLISION + REWARD_STEP - 0.01)


def test_leaving_the_search_area_costs_10_and_terminates():
    env = env_for(scenario())
    env.reset(seed=0)
    _, reward, terminated, _, info = env.step(np.array([-1.0, 0.0, 0.0, 0.0], dtype=np.float32))  # south, 50 m
    assert not terminated
    for _ in range(10):
        _, reward, terminated, _, info = env.step(np.array([-1.0, 0.0, 0.0, 0.0], dtype=np.float32))
        if terminated:
            break
    assert info["out_of_bounds"] and terminated
    assert reward == pytest.approx(REWARD_BOUNDARY + REWARD_STEP - 0.01)


def test_step_limit_truncates_without_terminating():
    env = env_for(scenario(), max_steps=12)
    env.reset(seed=0)
    for step in range(12):
        _, _, terminated, truncated, _ = env.step(HOVER)
        assert not terminated
        assert truncated == (step == 11)


# ------------------------------------------------------------------ detection and coverage in the env
def detection_rate(conditions: Conditions, episodes: int = 300) -> float:
    env = env_for(scenario(victim=(0.0, 3.0), conditions=conditions), altitude_m=20.0, reach_radius_m=1.0)
    hits = 0
    for seed in range(episodes):
        env.reset(seed=seed)
        hits += env.step(np.array([0.0, 0.0, 1.0, 0.0], dtype=np.float32))[4]["victim_detected"]
    return hits / episodes


def test_victim_under_the_drone_in_clear_daylight_is_detected_and_conditions_lower_it():
    clear = detection_rate(Conditions())
    assert clear >= 0.88  # model p = 0.93 at 3 m off-centre, 20 m up; 300 draws
    assert detection_rate(Conditions(weather=Weather.FOGGY, visibility=0.5)) < clear - 0.3
    assert detection_rate(Conditions(time_of_day=TimeOfDay.NIGHT)) < clear - 0.3
    assert detection_rate(Conditions(sea=SeaState.ROUGH)) < clear - 0.2


def test_first_detection_chance_is_the_victims_detection_probability_until_it_is_seen():
    # Victim 12 m east, in view at 20 m (model p = 0.61 at full intensity); a far victim is never in view.
    near = env_for(scenario(victim=(0.0, 12.0), datum=(300.0, -200.0)), altitude_m=20.0, reach_radius_m=1.0)
    near.reset(seed=0)
    chances, seen = [], []
    for intensity in (0.5, 1.0, 1.0, 1.0, 1.0, 1.0):
        info = near.step(np.array([0.0, 0.0, intensity, 0.0], dtype=np.float32))[4]
        chances.append(float(info["first_detection_chance"]))
        seen.append(bool(info["victim_detected"]))
    first = seen.index(True)  # the chance is paid up to and including the step that detects
    assert all(chance > 0.25 for chance in chances[:first + 1]) and chances[first + 1:] == [0.0] * (5 - first)
    if first > 0:  # detection probability is proportional to the intensity
        assert chances[0] == pytest.approx(chances[1] / 2, rel=0.05)
    far = env_for(scenario(), altitude_m=20.0)
    far.reset(seed=0)
    assert far.step(np.array([0.0, 0.0, 1.0, 0.0], dtype=np.float32))[4]["first_detection_chance"] == 0.0


def test_coverage_never_decreases_over_a_random_flight():
    env = SarSearchEnv(SarSearchConfig(task=V0, split="train"))
    obs, _ = env.reset(seed=11)
    rng = np.random.default_rng(0)
    previous = field(obs, "coverage").copy()
    for _ in range(400):
        obs, _, terminated, truncated, info = env.step(rng.uniform([-1, -1, 0, 0], 1).astype(np.float32))
        coverage = field(obs, "coverage")
        if terminated or truncated:
            break
        assert np.all(coverage >= previous)
        previous = coverage.copy()
    assert 0.0 < info["coverage_ratio"] <= 1.0


# ------------------------------------------------------------------ seeding and the vectorised form
def rollout(env: SarSearchEnv, seed: int, actions: np.ndarray) -> list:
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for action in actions:
        obs, reward, terminated, truncated, _ = env.step(action)
        out.append((obs, reward, terminated, truncated))
        if terminated or truncated:
            obs, _ = env.reset()
            out.append(obs)
    return out


def test_same_seed_same_episode():
    actions = np.random.default_rng(3).uniform([-1, -1, 0, 0], 1, size=(300, 4)).astype(np.float32)
    a, b = rollout(SarSearchEnv(task=V0), 5, actions), rollout(SarSearchEnv(task=V0), 5, actions)
    c = rollout(SarSearchEnv(task=V0), 6, actions)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x[0] if isinstance(x, tuple) else x, y[0] if isinstance(y, tuple) else y)
    assert not np.array_equal(a[0], c[0])


def test_vectorised_env_equals_single_envs_step_for_step():
    n, steps, seed = 4, 600, 20
    config = SarSearchConfig(task=V0, flight=FlightSettings(max_steps=150))
    rng = np.random.default_rng(1)
    actions = rng.uniform([-1, -1, 0, 0], 1, size=(steps, n, 4)).astype(np.float32)
    vec = SarSearchVectorEnv(n, config)
    singles = [SarSearchEnv(config) for _ in range(n)]
    vec_obs, _ = vec.reset(seed=seed)
    single_obs = [env.reset(seed=seed + i)[0] for i, env in enumerate(singles)]
    np.testing.assert_array_equal(vec_obs, np.stack(single_obs))
    episodes_ended = 0
    for t in range(steps):
        vec_obs, vec_reward, vec_term, vec_trunc, info = vec.step(actions[t])
        for i, env in enumerate(singles):
            obs, reward, terminated, truncated, _ = env.step(actions[t, i])
            assert (reward, terminated, truncated) == (vec_reward[i], vec_term[i], vec_trunc[i])
            if terminated or truncated:
                episodes_ended += 1
                np.testing.assert_array_equal(info["final_obs"][i], obs)
                obs, _ = env.reset()
            np.testing.assert_array_equal(vec_obs[i], obs)
    assert episodes_ended >= n  # auto-resets were exercised


def test_render_draws_the_search():
    env = SarSearchEnv(render_mode="rgb_array", task=V0)
    env.reset(seed=2)
    first = env.render()
    for _ in range(30):
        env.step(np.array([0.5, 0.5, 1.0, 0.0], dtype=np.float32))
    later = env.render()
    assert first.shape == later.shape == (512, 512, 3) and first.dtype == np.uint8
    assert (first != later).any(axis=2).sum() > 200  # path, footprint and coverage changed
    assert SarSearchEnv().render() is None


def test_stable_baselines3_sac_trains_on_the_environment():
    sb3 = pytest.importorskip("stable_baselines3")
    env = SarSearchEnv(SarSearchConfig(task=V0, flight=FlightSettings(max_steps=200)))
    model = sb3.SAC("MlpPolicy", env, learning_starts=200, buffer_size=5_000, batch_size=64,
                    policy_kwargs={"net_arch": [64, 64]}, seed=0, device="cpu", verbose=0)
    before = model.policy.actor.mu.weight.detach().clone()
    model.learn(total_timesteps=1_000)
    assert model.num_timesteps == 1_000 and model.replay_buffer.size() == 1_000
    assert not np.allclose(before.numpy(), model.policy.actor.mu.weight.detach().numpy())  # it learned
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert env.action_space.contains(action.astype(np.float32))
    assert math.isfinite(float(model.logger.name_to_value.get("train/critic_loss", 0.0)))


def test_target_offset_is_the_direction_with_a_squashed_distance():
    from autonomy.observation import build_observations
    n = 3
    agent = np.zeros((n, 2))
    target = np.array([[15.0, 0.0], [0.0, -20.0], [3000.0, 4000.0]])  # 15 m north, 20 m west, 5 km away
    obs = build_observations(agent, target, np.tile([-500.0, 500.0, -500.0, 500.0], (n, 1)), np.zeros(n),
                             np.zeros(n), np.zeros(n), np.zeros(n), np.ones(n), np.zeros(n),
                             np.zeros((n, 6), bool), np.zeros((n, 256)), np.full(n, -1))
    offsets = obs[:, FIELDS_BY_NAME["target_offset"].slice]
    assert TARGET_OFFSET_SCALE_M == 20.0
    np.testing.assert_allclose(offsets[0], [15 / 35, 0.0], rtol=1e-6)  # resolves metres near the target
    np.testing.assert_allclose(offsets[1], [0.0, -0.5], rtol=1e-6)  # length 0.5 at the scale distance
    np.testing.assert_allclose(offsets[2], [0.6 * 5000 / 5020, 0.8 * 5000 / 5020], rtol=1e-6)  # saturates, < 1
