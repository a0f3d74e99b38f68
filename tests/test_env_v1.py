"""SarSearch-v1: gymnasium API, the observation's new fields, each reward of the task's ends, the configurable caps,
and the single and vectorised forms agreeing."""
from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import policies  # noqa: F401  (registers SarSearch-v1)
from autonomy.observation import LAYOUT_V4, PLAN_OFFSET_SCALE_M
from missions.mission import FlightSettings
from missions.scenario import Obstacle, Scenario, SearchArea, Target
from policies.env.core import REWARD_TARGET, SarSearchConfig
from policies.env.gym_env import SarSearchEnv
from policies.env.task_v1 import RETURN_RESERVE, REWARD_RAN_DRY, REWARD_RETURNED
from policies.env.vector import SarSearchVectorEnv

AREA = SearchArea(-50.0, 950.0, -500.0, 500.0)
HOVER = np.zeros(4, dtype=np.float32)
FIELDS = LAYOUT_V4.by_name


def field(obs: np.ndarray, name: str) -> np.ndarray:
    return obs[FIELDS[name].slice]


def env_for(victim=(600.0, 100.0), decoys=(), endurance_s=None, goal_conditioned=False, **flight) -> SarSearchEnv:
    targets = (Target("person", *victim, primary=True),) + tuple(Target("person", *d) for d in decoys)
    scenario = Scenario(area=AREA, datum_north_m=550.0, datum_east_m=80.0, datum_sigma_m=80.0, targets=targets,
                        endurance_s=endurance_s, name="test")
    return SarSearchEnv(SarSearchConfig(scenarios=(scenario,), flight=FlightSettings(**flight),
                                        goal_conditioned=goal_conditioned))


def fly_to(env: SarSearchEnv, point, zoom=0.0, limit=400):
    """Fly straight at ``point`` and hover there; yields each step's (reward, terminated, info)."""
    for _ in range(limit):
        offset = np.asarray(point) - env.unwrapped.core.position[0]
        distance = float(np.hypot(*offset))
        action = np.zeros(4, dtype=np.float32)
        action[:2] = offset / max(distance, 1e-9) * min(1.0, distance / 10.0)
        action[2], action[3] = 1.0, zoom if distance < 15.0 else 0.0
        _, reward, terminated, truncated, info = env.step(action)
        yield reward, terminated, info
        if terminated or truncated:
            return


def test_gymnasium_check_env_passes_and_the_layout_is_version_4():
    check_env(gymnasium.make("SarSearch-v1").unwrapped)
    check_env(gymnasium.make("SarSearch-v1", goal_conditioned=True).unwrapped)
    env = gymnasium.make("SarSearch-v1", split="val")
    obs, info = env.reset(seed=3)
    assert obs.shape == (LAYOUT_V4.dim,) == (288,) and LAYOUT_V4.meta_dim == 284
    assert info["scenario"].startswith("gen-val-")
    vec = gymnasium.make_vec("SarSearch-v1", num_envs=3, vectorization_mode="vector_entry_point")
    assert vec.reset(seed=1)[0].shape == (3, 288)


def test_the_new_fields_say_what_a_crew_knows():
    env = env_for(endurance_s=500.0, decoys=[(300.0, 0.0)])
    obs, _ = env.reset(seed=0)
    assert field(obs, "energy_left")[0] == 1.0 and field(obs, "return_cost")[0] == 0.0
    assert field(obs, "belief_remaining")[0] == pytest.approx(1.0)
    assert field(obs, "belief").max() == pytest.approx(1.0, abs=0.05)  # the prior's peak block
    peak = field(obs, "belief_peak_offset").astype(float)
    metres = peak * PLAN_OFFSET_SCALE_M / (1.0 - np.hypot(*peak))
    assert np.hypot(*(metres - (550.0, 80.0))) < 45.0  # the most likely cell: the datum's
    assert not field(obs, "candidate_offset").any() and field(obs, "unresolved_candidates")[0] == 0.0
    for _, _, info in fly_to(env, (300.0, 0.0), limit=40):
        pass
    obs = env.unwrapped.core.obs[0]
    assert field(obs, "energy_left")[0] == pytest.approx(1.0 - 40 / 500.0)
    assert field(obs, "return_cost")[0] == pytest.approx(300.0 / 10.0 / 500.0, abs=0.01)
    assert field(obs, "belief_remaining")[0] < 1.0
    assert field(obs, "unresolved_candidates")[0] == 0.25 or field(obs, "confirmed")[0] == 0.0


def test_confirming_and_reaching_the_victim_pays_100_and_detection_alone_does_not():
    env = env_for()
    env.reset(seed=0)
    steps = list(fly_to(env, (600.0, 100.0), zoom=0.6))
    reward, terminated, info = steps[-1]
    assert terminated and info["success"] and info["victim_confirmed"]
    assert reward == REWARD_TARGET  # no cost per step or for the action in v1: the endurance is the cost
    assert all(not i["success"] for _, _, i in steps[:-1])
    assert any(i["victim_detected"] and not i["victim_confirmed"] for _, _, i in steps)  # seen before confirmed


def test_running_dry_costs_50_and_coming_home_with_reserve_pays_20():
    dry = env_for(endurance_s=20.0)
    dry.reset(seed=0)
    *_, (reward, terminated, info) = fly_to(dry, (400.0, 0.0))
    assert terminated and info["ran_dry"] and info["steps"] == 20
    assert reward == REWARD_RAN_DRY
    for endurance, paid in ((1000.0, REWARD_RETURNED), (85.0, 0.0)):  # back after about 78 s
        env = env_for(endurance_s=endurance)
        env.reset(seed=0)
        list(fly_to(env, (150.0, 0.0), limit=60))
        *_, (reward, terminated, info) = fly_to(env, (0.0, 0.0))
        left = 1.0 - info["steps"] / endurance
        assert terminated and info["returned"] and (left >= RETURN_RESERVE) == (paid > 0.0)
        assert reward == paid
        assert bool(np.asarray(info["returned_with_reserve"])) == (paid > 0.0)
        # TrainConfig.meta_returned_reward replaces the +20 in what the meta-controller learns from, nothing else
        from policies.config import TrainConfig
        from policies.env.shaping import meta_learning_reward

        learned = meta_learning_reward(TrainConfig(meta_returned_reward=-5.0), np.array([reward]),
                                       {k: np.atleast_1d(v) for k, v in info.items()})
        assert learned.tolist() == [-5.0 if paid > 0.0 else 0.0]
        assert meta_learning_reward(TrainConfig(), np.array([reward]), info).tolist() == [reward]


def test_the_meta_belief_bonus_pays_the_belief_each_look_removed_and_nothing_else():
    from policies.config import TrainConfig
    from policies.env.shaping import meta_learning_reward

    env = env_for(endurance_s=600.0)
    env.reset(seed=0)
    steps = list(fly_to(env, (500.0, 0.0), limit=40))  # out over the datum's area with the sensor on
    removed = []
    for reward, _, info in steps:
        info = {k: np.atleast_1d(v) for k, v in info.items()}
        learned = meta_learning_reward(TrainConfig(meta_belief_bonus=100.0), np.array([reward]), info)
        assert learned[0] == pytest.approx(reward + 100.0 * info["belief_removed"][0])
        assert meta_learning_reward(TrainConfig(), np.array([reward]), info)[0] == reward
        removed.append(float(info["belief_removed"][0]))
    assert max(removed) > 0.0 and min(removed) >= 0.0
    with pytest.raises(ValueError, match="meta_belief_bonus applies to SarSearch-v1 only"):
        TrainConfig(task="SarSearch-v0", meta_belief_bonus=1.0, low_level_ignores=("coverage",))


def test_the_caps_on_targets_and_obstacles_are_configurable():
    many = Scenario(area=AREA, targets=tuple(Target("debris", 10.0 * k, 0.0, primary=k == 0) for k in range(20)),
                    obstacles=tuple(Obstacle(900.0, -400.0 + 50.0 * k, 10.0) for k in range(6)), name="crowded")
    with pytest.raises(ValueError, match="at most 16 and 4"):
        SarSearchEnv(SarSearchConfig(scenarios=(many,))).reset(seed=0)
    env = SarSearchEnv(SarSearchConfig(scenarios=(many,), max_targets=24, max_obstacles=8))
    env.reset(seed=0)
    assert env.unwrapped.core.targets.shape[1] == 24 and env.unwrapped.core.scen.obstacles.shape[1] == 8
    with pytest.raises(ValueError, match="SarSearchConfig.max_obstacles must be an integer in"):
        SarSearchConfig(max_obstacles=0)


def test_vectorised_env_equals_single_envs_step_for_step():
    config = SarSearchConfig(split="val", flight=FlightSettings(max_steps=80), goal_conditioned=True)
    n, seeds = 3, [11, 12, 13]
    vec, singles = SarSearchVectorEnv(n, config), [SarSearchEnv(config) for _ in range(n)]
    obs = vec.reset(seed=seeds)[0]
    for env, seed, row in zip(singles, seeds, obs):
        np.testing.assert_array_equal(env.reset(seed=seed)[0], row)
    rng = np.random.default_rng(0)
    for t in range(120):  # through an auto-reset at the step limit
        if t % 30 == 0:
            goals = rng.integers(0, 4, size=n)
            vec.set_goals(goals)
            for env, goal in zip(singles, goals):
                env.set_goal(int(goal))
        actions = rng.uniform([-1, -1, 0, 0], 1.0, size=(n, 4)).astype(np.float32)
        obs, reward, terminated, truncated, _ = vec.step(actions)
        for i, env in enumerate(singles):
            o, r, te, tr, _ = env.step(actions[i])
            if te or tr:
                o, _ = env.reset()
            np.testing.assert_array_equal(o, obs[i])
            assert r == pytest.approx(reward[i]) and (te, tr) == (terminated[i], truncated[i])


def test_in_the_target_frame_the_constant_action_flies_straight_at_the_target():
    targets = (Target("person", 600.0, 100.0, primary=True),)
    scenario = Scenario(area=AREA, datum_north_m=550.0, datum_east_m=80.0, datum_sigma_m=80.0, targets=targets)
    env = SarSearchEnv(SarSearchConfig(scenarios=(scenario,), goal_conditioned=True, action_frame="target"))
    env.reset(seed=0)
    env.set_goal(1)  # SearchSpecificLocation: the datum's cell, about 560 m away
    core = env.unwrapped.core
    start, goal = core.position[0].copy(), core.goal_point[0].copy()
    for _ in range(20):
        env.step(np.array([1.0, 0.0, 1.0, 0.0], dtype=np.float32))
    travelled = core.position[0] - start
    direction = (goal - start) / np.hypot(*(goal - start))
    assert np.hypot(*travelled) > 150.0  # about full speed once it has accelerated
    assert abs(travelled[0] * direction[1] - travelled[1] * direction[0]) < 1.0  # no sideways drift at all
    with pytest.raises(ValueError, match="action_frame must be 'north_east', or on SarSearch-v1 'target' or 'arrive', "
                                         "got 'target' on SarSearch-v0"):
        SarSearchConfig(task="SarSearch-v0", action_frame="target")
    with pytest.raises(ValueError, match="TrainConfig.action_frame must be .* got 'towards' on SarSearch-v1"):
        from policies.config import TrainConfig

        TrainConfig(action_frame="towards")


def test_a_diagonal_command_flies_no_faster_than_the_runner_lets_it():
    """(1, 1) asks for 14.1 m/s; the mission runner's setpoint stream caps the horizontal speed's norm at the
    mission's max_speed_mps (autonomy.setpoints), so the environment must fly what flight flies: the capped speed,
    in the commanded direction (before the fix its airframe flew the SITL's 12 m/s)."""
    from autonomy.setpoints import SetpointStreamer, StreamConfig, VelocityCommand

    flight = FlightSettings()
    capped = SetpointStreamer(StreamConfig(max_horizontal_mps=flight.max_speed_mps), lambda *_: None).clamp(
        VelocityCommand(flight.max_speed_mps, flight.max_speed_mps))
    env = env_for()
    env.reset(seed=0)
    core = env.unwrapped.core
    start = core.position[0].copy()
    speeds = []
    for _ in range(15):
        env.step(np.array([1.0, 1.0, 1.0, 0.0], dtype=np.float32))
        speeds.append(float(np.hypot(core.vehicles.vn_mps[0], core.vehicles.ve_mps[0])))
    assert max(speeds) <= np.hypot(capped.vn, capped.ve) + 1e-9 and max(speeds) > 0.99 * flight.max_speed_mps
    travelled = core.position[0] - start
    assert travelled[0] == pytest.approx(travelled[1], rel=1e-9)  # north-east, as commanded


def test_in_the_arrive_frame_the_constant_action_stops_on_the_target_and_holds_there():
    """(1, 0) read in the arrive frame, flown by the environment's multirotor dynamics, reaches a point 300 m away at
    full speed, stops on it without passing it by more than a few metres and then holds over it below the close-look
    speed (what a close look or a landing at home needs). Read in the target frame it keeps overshooting."""
    from missions.action_frames import movement_velocity
    from missions.search_state_v1 import CLOSE_LOOK_SPEED_MPS
    from sitl_bridge import dynamics

    flight = FlightSettings()
    airframe = dynamics.MultirotorParams(max_speed_xy_mps=flight.max_speed_mps)
    target = np.array([[300.0, 40.0]])
    tracks = {}
    for frame in ("arrive", "target"):
        vehicle = dynamics.BatchState.from_states([dynamics.VehicleState(down_m=-50.0, on_ground=False)])
        track = []
        for step in range(80):
            position = np.array([[vehicle.north_m[0], vehicle.east_m[0]]])
            velocity = movement_velocity(np.array([[1.0, 0.0]]), position, target, frame, flight.max_speed_mps,
                                         flight.step_period_s)
            vehicle = dynamics.step_batch(vehicle, velocity[:, 0], velocity[:, 1], 0.0, airframe, dynamics.Wind(),
                                          float(step), flight.step_period_s)
            track.append((float(np.hypot(vehicle.north_m[0] - 300.0, vehicle.east_m[0] - 40.0)),
                          float(np.hypot(vehicle.vn_mps[0], vehicle.ve_mps[0]))))
        tracks[frame] = np.array(track)
    distance, speed = tracks["arrive"].T
    assert speed[5:25].min() > 9.5  # full speed on the way
    assert distance[40:].max() < 0.5 and speed[40:].max() < CLOSE_LOOK_SPEED_MPS / 10  # on the point, holding
    passed = distance[np.argmin(distance[:40]):40].max()
    assert passed < 3.0  # at most a small overshoot
    assert tracks["target"][40:, 1].max() > 5.0  # the target frame is still swinging through the point
    velocity = movement_velocity(np.array([[1.0, 0.0], [1.0, 0.0], [0.5, 0.5]]), np.zeros((3, 2)),
                                 np.array([[30.0, 0.0], [5.0, 0.0], [0.0, 100.0]]), "arrive", 10.0, 1.0)
    np.testing.assert_allclose(velocity, [[10.0, 0.0], [2.5, 0.0], [-5.0, 5.0]])  # right of east is south


def test_meta_returned_reward_is_refused_on_a_task_without_a_return_home():
    from policies.config import TrainConfig

    with pytest.raises(ValueError, match="meta_returned_reward applies to SarSearch-v1 only"):
        TrainConfig(task="SarSearch-v0", meta_returned_reward=0.0, low_level_ignores=("coverage",))
    with pytest.raises(ValueError, match=r"TrainConfig.meta_returned_reward must be a number in \[-1000, 1000\]"):
        TrainConfig(meta_returned_reward=float("nan"))
