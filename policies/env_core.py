"""The search-and-rescue environment, stepped for N scenarios at once with numpy.

This is the one implementation of the environment: :class:`policies.env.SarSearchEnv` (gymnasium, N = 1)
and :class:`policies.vector_env.SarSearchVectorEnv` (N scenarios) both drive a :class:`SarSearchBatch`, so they
agree exactly for the same seeds. It is built only from the vehicle dynamics (``sitl_bridge.dynamics``), the
search logic (``missions.search``, ``missions.goals``) and the observation builder (``autonomy.observation``).

One step is one policy decision (``FlightSettings.step_period_s``, 1 s by default):

1. the action (movement north/east in [-1, 1], search intensity and zoom in [0, 1]) becomes a horizontal
   velocity command of up to ``max_speed_mps``; the drone flies it for one period at the search altitude
   through the exact multirotor dynamics;
2. objects drift with current and wind; the camera footprint (altitude, zoom) marks coverage and may detect
   objects (Bernoulli draws from a counter-based generator keyed by the episode seed, so every environment
   of a batch has its own reproducible stream);
3. reward (the paper's table): -0.1 per step, -0.01 * ||a||^2, +100 on reaching the victim, -50 on entering a
   danger zone, -10 on leaving the geofence. Reaching, collision and leaving end the episode (terminated);
   the step limit truncates it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from autonomy.observation import META_OBS_DIM, NO_GOAL, OBS_DIM, build_observations
from missions import goals as goal_logic
from missions import search
from missions.mission import FlightSettings
from missions.scenario import CATEGORIES, Scenario
from sitl_bridge import dynamics

REWARD_STEP = -0.1
REWARD_ENERGY = -0.01
REWARD_TARGET = 100.0
REWARD_COLLISION = -50.0
REWARD_BOUNDARY = -10.0

ACTION_LOW = np.array([-1.0, -1.0, 0.0, 0.0], dtype=np.float32)
ACTION_HIGH = np.array([1.0, 1.0, 1.0, 1.0], dtype=np.float32)
ACTION_NAMES = ("movement_north", "movement_east", "search_intensity", "camera_zoom")

_MASK64 = np.uint64(0xFFFFFFFFFFFFFFFF)


def splitmix64(x: np.ndarray) -> np.ndarray:
    """A fast, well-mixed 64-bit hash (SplitMix64 finaliser); uint64 arithmetic wraps on purpose."""
    with np.errstate(over="ignore"):
        z = x + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


def keyed_uniforms(seeds: np.ndarray, steps: np.ndarray, count: int) -> np.ndarray:
    """(N, count) uniforms in [0, 1), a pure function of (seed, step, index): same key, same numbers."""
    with np.errstate(over="ignore"):
        key = splitmix64(seeds.astype(np.uint64) ^ splitmix64(steps.astype(np.uint64)))
        bits = splitmix64(key[:, None] + np.arange(count, dtype=np.uint64)[None, :])
    return (bits >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


def next_episode_seed(seed: np.ndarray) -> np.ndarray:
    """The seed of the episode after one with ``seed`` (what an auto-reset uses)."""
    return splitmix64(seed.astype(np.uint64) + np.uint64(1)) & np.uint64(0x7FFFFFFFFFFFFFFF)


@dataclass(frozen=True)
class SarSearchConfig:
    """Everything that defines the environment (the scenario source and how the search is flown)."""

    split: str = "train"
    """Generator split the scenarios come from ("train", "val" or "test") when ``scenarios`` is empty."""
    scenarios: tuple[Scenario, ...] = ()
    """A fixed list of scenarios (a dataset split, mission files); episode seeds index into it."""
    flight: FlightSettings = field(default_factory=FlightSettings)
    """Altitude, speed, decision period, K, step limit and reach radius."""
    goal_conditioned: bool = False
    """HRL-SAC mode: the observation's target is the current goal's point (set with ``set_goals``) and the
    goal one-hot is filled. Flat SAC mode (False): target = datum until the victim is detected, then the last
    detection; goal one-hot all zero."""
    airframe: dynamics.MultirotorParams | None = None
    """Vehicle limits; None = the SITL's defaults with the speed limit raised to max_speed_mps if needed."""

    def __post_init__(self) -> None:
        if not self.scenarios and self.split not in ("train", "val", "test"):
            raise ValueError(f"SarSearchConfig.split must be one of train, val, test, got {self.split!r}")


class ScenarioSource:
    """Maps an episode seed to a scenario: a fixed list, or the generator's split."""

    def __init__(self, config: SarSearchConfig, cache_size: int = 4096):
        self.config = config
        self._cache: dict[int, Scenario] = {}
        self._cache_size = cache_size

    def __call__(self, episode_seed: int) -> Scenario:
        if self.config.scenarios:
            return self.config.scenarios[episode_seed % len(self.config.scenarios)]
        scenario = self._cache.get(episode_seed)
        if scenario is None:
            from missions.generator import generate_scenario, split_seed

            scenario = generate_scenario(split_seed(self.config.split, episode_seed))
            if len(self._cache) >= self._cache_size:
                self._cache.pop(next(iter(self._cache)))
            self._cache[episode_seed] = scenario
        return scenario


class SarSearchBatch:
    """N independent search episodes, stepped together. Arrays are (N, ...); nothing here loops over N
    except resets (which build each new episode's arrays from its Scenario)."""

    def __init__(self, config: SarSearchConfig, num_envs: int, max_targets: int = 8, max_obstacles: int = 4):
        self.config = config
        self.n = num_envs
        self.flight = flight = config.flight
        self.source = ScenarioSource(config)
        self.airframe = config.airframe or dynamics.MultirotorParams(
            max_speed_xy_mps=max(flight.max_speed_mps, dynamics.MultirotorParams().max_speed_xy_mps))
        self.wind = dynamics.Wind()  # the velocity controller holds the track; wind acts through drift
        self.max_targets, self.max_obstacles = max_targets, max_obstacles
        self.scenarios: list[Scenario | None] = [None] * num_envs
        n, t, o = num_envs, max_targets, max_obstacles
        self.area = np.zeros((n, 4))
        self.fence = np.zeros((n, 4))
        self.home = np.zeros((n, 2))
        self.datum = np.zeros((n, 2))
        self.datum_sigma = np.zeros(n)
        self.targets = np.zeros((n, t, 2))
        self.target_category = np.zeros((n, t), dtype=np.int64)
        self.target_valid = np.zeros((n, t), dtype=bool)
        self.drift_velocity = np.zeros((n, t, 2))
        self.primary_index = np.zeros(n, dtype=np.int64)
        self.obstacles = np.zeros((n, o, 3))
        self.obstacle_valid = np.zeros((n, o), dtype=bool)
        self.sea = np.zeros(n, dtype=np.int64)
        self.weather = np.zeros(n, dtype=np.int64)
        self.time_of_day = np.zeros(n, dtype=np.int64)
        self.visibility = np.ones(n)
        self.wind_fraction = np.zeros(n)
        self.vehicles = dynamics.BatchState.from_states([dynamics.VehicleState()] * n)
        self.time_s = np.zeros(n)
        self.steps = np.zeros(n, dtype=np.int64)
        self.episode_seed = np.zeros(n, dtype=np.uint64)
        self.coverage = np.zeros((n, search.GRID_SIZE, search.GRID_SIZE), dtype=np.float32)
        self.detections = np.zeros((n, len(CATEGORIES)), dtype=bool)
        self.last_detection = np.zeros((n, 2))
        self.has_detection = np.zeros(n, dtype=bool)
        self.first_detection_step = np.full(n, -1, dtype=np.int64)
        self.goal = np.full(n, NO_GOAL, dtype=np.int64)
        self.goal_point = np.zeros((n, 2))
        self.path_length_m = np.zeros(n)
        self.episode_return = np.zeros(n)
        self.obs = np.zeros((n, OBS_DIM), dtype=np.float32)
        self.last_action = np.zeros((n, 4))
        self._arange = np.arange(n)

    # ------------------------------------------------------------------ resets
    def reset(self, index: int, episode_seed: int) -> None:
        """Start a new episode in slot ``index`` with the scenario and detection stream of ``episode_seed``."""
        scenario = self.source(int(episode_seed))
        if len(scenario.targets) > self.max_targets or len(scenario.obstacles) > self.max_obstacles:
            raise ValueError(f"scenario {scenario.name!r} has {len(scenario.targets)} targets and "
                             f"{len(scenario.obstacles)} obstacles; this environment holds at most "
                             f"{self.max_targets} and {self.max_obstacles}")
        self.scenarios[index] = scenario
        one = search.ScenarioBatch.from_scenarios([scenario])
        t, o = one.targets.shape[1], one.obstacles.shape[1]
        self.area[index] = one.area[0]
        self.fence[index] = one.fence[0]
        self.home[index] = (0.0, 0.0)
        self.datum[index] = one.datum[0]
        self.datum_sigma[index] = one.datum_sigma[0]
        self.targets[index] = 0.0
        self.targets[index, :t] = one.targets[0]
        self.target_category[index] = 0
        self.target_category[index, :t] = one.target_category[0]
        self.target_valid[index] = False
        self.target_valid[index, :t] = one.target_valid[0]
        self.drift_velocity[index] = 0.0
        self.drift_velocity[index, :t] = one.drift_velocity[0]
        self.primary_index[index] = one.primary_index[0]
        self.obstacles[index] = 0.0
        self.obstacle_valid[index] = False
        self.obstacles[index, :o] = one.obstacles[0]
        self.obstacle_valid[index, :o] = one.obstacle_valid[0]
        self.sea[index], self.weather[index], self.time_of_day[index] = one.sea[0], one.weather[0], one.time_of_day[0]
        self.visibility[index], self.wind_fraction[index] = one.visibility[0], one.wind[0]
        # The episode starts at the start point, already at search altitude and hovering.
        self.vehicles.set(index, dynamics.VehicleState(north_m=scenario.start_north_m, east_m=scenario.start_east_m,
                                                       down_m=-self.flight.altitude_m, on_ground=False,
                                                       battery_wh=self.airframe.battery_capacity_wh))
        self.time_s[index] = 0.0
        self.steps[index] = 0
        self.episode_seed[index] = np.uint64(episode_seed)
        self.coverage[index] = 0.0
        self.detections[index] = False
        self.last_detection[index] = self.datum[index]
        self.has_detection[index] = False
        self.first_detection_step[index] = -1
        self.goal[index] = NO_GOAL
        self.goal_point[index] = self.datum[index]
        self.path_length_m[index] = 0.0
        self.episode_return[index] = 0.0
        self.last_action[index] = 0.0

    # ------------------------------------------------------------------ goals (HRL-SAC)
    def set_goals(self, goals: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Give environments a meta-controller goal (index into GOAL_NAMES) and ground it to a point now."""
        goals = np.asarray(goals, dtype=np.int64)
        mask = np.ones(self.n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        if np.any((goals[mask] < 0) | (goals[mask] >= len(goal_logic.GOAL_NAMES))):
            raise ValueError(f"goal indices must be in [0, {len(goal_logic.GOAL_NAMES) - 1}], got {goals[mask]}")
        self.goal[mask] = goals[mask]
        points = goal_logic.ground_goals(goals[mask], self.position[mask], self.area[mask], self.coverage[mask],
                                         self.datum[mask], self.datum_sigma[mask], self.last_detection[mask],
                                         self.has_detection[mask], self.home[mask])
        self.goal_point[mask] = points

    # ------------------------------------------------------------------ stepping
    @property
    def position(self) -> np.ndarray:
        """(N, 2) drone north, east (m)."""
        return np.stack([self.vehicles.north_m, self.vehicles.east_m], axis=1)

    def target_position(self) -> np.ndarray:
        """What the observation calls the target: never the hidden victim location."""
        if self.config.goal_conditioned:
            return self.goal_point
        return self.last_detection  # equals the datum until the victim has been detected

    def observe(self) -> np.ndarray:
        progress = self.steps / self.flight.max_steps
        blocks = search.downsample_coverage(self.coverage)
        goal = self.goal if self.config.goal_conditioned else np.full(self.n, NO_GOAL)
        return build_observations(self.position, self.target_position(), self.area, progress, self.sea, self.weather,
                                  self.time_of_day, self.visibility, self.wind_fraction, self.detections, blocks,
                                  goal, out=self.obs)

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """Advance every environment one decision; returns (obs, reward, terminated, truncated, info).

        Finished environments are NOT reset here; the wrappers decide when (gymnasium's auto-reset rules).
        """
        flight = self.flight
        a = np.clip(np.asarray(actions, dtype=np.float64).reshape(self.n, 4), ACTION_LOW, ACTION_HIGH)
        self.last_action[:] = a
        before = self.position
        self.vehicles = dynamics.step_batch(self.vehicles, a[:, 0] * flight.max_speed_mps,
                                            a[:, 1] * flight.max_speed_mps, 0.0, self.airframe, self.wind,
                                            self.time_s, flight.step_period_s)
        self.time_s += flight.step_period_s
        self.steps += 1
        position = self.position
        self.path_length_m += np.hypot(*(position - before).T)
        search.drift_targets(self.targets, self.drift_velocity, flight.step_period_s)

        half_width = search.footprint_half_width_m(flight.altitude_m, a[:, 3])
        search.cover(self.coverage, self.area, position, half_width, a[:, 2])
        probability = search.detection_probability(position, self.targets, self.target_category, self.target_valid,
                                                   flight.altitude_m, a[:, 3], a[:, 2], self.sea, self.weather,
                                                   self.time_of_day, self.visibility)
        uniforms = keyed_uniforms(self.episode_seed, self.steps, self.max_targets)
        detected = search.sample_detections(probability, uniforms)
        self.detections = search.detected_categories(detected, self.target_category)
        victim_seen = detected[self._arange, self.primary_index]
        self.last_detection[victim_seen] = self.targets[self._arange, self.primary_index][victim_seen]
        first = victim_seen & ~self.has_detection
        self.first_detection_step[first] = self.steps[first]
        self.has_detection |= victim_seen

        distance = search.distance_to_primary(position, self.targets, self.primary_index)
        success = distance <= flight.reach_radius_m
        collision = search.inside_obstacle(position, self.obstacles, self.obstacle_valid) & ~success
        out_of_bounds = search.outside_fence(position, self.fence) & ~success
        reward = (REWARD_STEP + REWARD_ENERGY * np.sum(a * a, axis=1) + REWARD_TARGET * success
                  + REWARD_COLLISION * collision + REWARD_BOUNDARY * out_of_bounds)
        self.episode_return += reward
        terminated = success | collision | out_of_bounds
        truncated = (self.steps >= flight.max_steps) & ~terminated
        info = {"success": success, "collision": collision, "out_of_bounds": out_of_bounds,
                "distance_to_victim_m": distance, "coverage_ratio": search.coverage_ratio(self.coverage),
                "first_detection_step": self.first_detection_step.copy(), "victim_detected": self.has_detection.copy(),
                "position": position, "goal_point": self.goal_point.copy(), "path_length_m": self.path_length_m.copy(),
                "episode_return": self.episode_return.copy(), "steps": self.steps.copy()}
        return self.observe(), reward.astype(np.float32), terminated, truncated, info

    @property
    def meta_observation(self) -> np.ndarray:
        """(N, 272): what the meta-controller sees."""
        return self.obs[:, :META_OBS_DIM]


def make_batch(config: SarSearchConfig, seeds: Sequence[int]) -> SarSearchBatch:
    """A batch with every slot reset to its seed."""
    batch = SarSearchBatch(config, len(seeds))
    for i, seed in enumerate(seeds):
        batch.reset(i, seed)
    batch.observe()
    return batch

