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
4. HRL-SAC (goal-conditioned mode): a goal whose point the drone reached is grounded again from the new search
   state (``missions.goals``), so the low level always has somewhere useful to fly until the next meta decision.
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
ENERGY_COMPONENTS = slice(0, 4)  # the action components the energy term -0.01 ||a||^2 counts (all four)

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
        key = seeds.astype(np.uint64) * np.uint64(0xD1B54A32D192ED03) + steps.astype(np.uint64) * np.uint64(count)
        bits = splitmix64(key[:, None] + np.arange(count, dtype=np.uint64)[None, :])
    return (bits >> np.uint64(11)) * (1.0 / 9007199254740992.0)


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
    pool_size: int = 10_000
    """Number of distinct generated scenarios in the split: episode seed modulo pool_size picks one (the
    episode seed alone drives the detection draws). Ignored when ``scenarios`` is given."""
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
        if not 1 <= self.pool_size <= 100_000:
            raise ValueError(f"SarSearchConfig.pool_size must be in [1, 100000], got {self.pool_size}")


class ScenarioSource:
    """The scenarios episodes are drawn from (a fixed list, or ``pool_size`` scenarios of a generator split),
    packed into one padded ScenarioBatch that fills lazily: each scenario is generated and packed once."""

    def __init__(self, config: SarSearchConfig, max_targets: int, max_obstacles: int):
        self.config = config
        self.max_targets, self.max_obstacles = max_targets, max_obstacles
        self.count = len(config.scenarios) if config.scenarios else config.pool_size
        blank = search.ScenarioBatch.from_scenarios([Scenario()], num_targets=max_targets,
                                                    num_obstacles=max_obstacles)
        self.pool = blank.select(np.zeros(self.count, dtype=np.int64))
        self.scenarios: list[Scenario | None] = [None] * self.count

    def rows(self, episode_seeds: np.ndarray) -> np.ndarray:
        """Pool rows of these episodes (episode seed modulo the pool size), packing any not seen before."""
        rows = (np.asarray(episode_seeds, dtype=np.uint64) % np.uint64(self.count)).astype(np.int64)
        for row in rows.tolist():
            if self.scenarios[row] is None:
                self._pack(row)
        return rows

    def _pack(self, row: int) -> None:
        if self.config.scenarios:
            scenario = self.config.scenarios[row]
        else:
            from missions.generator import generate_scenario, split_seed

            scenario = generate_scenario(split_seed(self.config.split, row))
        if len(scenario.targets) > self.max_targets or len(scenario.obstacles) > self.max_obstacles:
            raise ValueError(f"scenario {scenario.name!r} has {len(scenario.targets)} targets and "
                             f"{len(scenario.obstacles)} obstacles; the environment holds at most "
                             f"{self.max_targets} and {self.max_obstacles}")
        self.pool.assign(row, search.ScenarioBatch.from_scenarios([scenario]))
        self.scenarios[row] = scenario


class SarSearchBatch:
    """N independent search episodes, stepped together. Arrays are (N, ...); nothing here loops over N except
    resets, which copy each new episode's cached scenario arrays into its slot."""

    def __init__(self, config: SarSearchConfig, num_envs: int, max_targets: int = 8, max_obstacles: int = 4):
        self.config = config
        self.n = n = num_envs
        self.flight = flight = config.flight
        self.source = ScenarioSource(config, max_targets, max_obstacles)
        self.airframe = config.airframe or dynamics.MultirotorParams(
            max_speed_xy_mps=max(flight.max_speed_mps, dynamics.MultirotorParams().max_speed_xy_mps))
        self.wind = dynamics.Wind()  # the velocity controller holds the track; wind acts through drift
        self.max_targets = max_targets
        self.scenarios: list[Scenario | None] = [None] * n
        # Static per episode: the scenarios, packed (area, fence, datum, targets' categories, obstacles, ...).
        placeholder = search.ScenarioBatch.from_scenarios([Scenario()], num_targets=max_targets,
                                                          num_obstacles=max_obstacles)
        self.scen = placeholder.select(np.zeros(n, dtype=np.int64))
        # Dynamic state.
        hover = dynamics.VehicleState(down_m=-flight.altitude_m, on_ground=False)
        self.vehicles = dynamics.BatchState.from_states([hover] * n)
        self.position = np.zeros((n, 2))
        self.targets = np.zeros((n, max_targets, 2))
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
        self.covered_cells = np.zeros(n, dtype=np.int64)
        self.last_action = np.zeros((n, 4))
        self.obs = np.zeros((n, OBS_DIM), dtype=np.float32)
        self._arange = np.arange(n)

    # ------------------------------------------------------------------ resets
    def reset(self, indices, episode_seeds) -> None:
        """Start new episodes in slots ``indices`` with the scenarios and detection streams of ``episode_seeds``,
        and refresh their observations."""
        indices = np.atleast_1d(np.asarray(indices, dtype=np.int64))
        seeds = np.atleast_1d(np.asarray(episode_seeds, dtype=np.uint64))
        rows = self.source.rows(seeds)
        self.scen.assign(indices, self.source.pool.select(rows))
        for index, row in zip(indices.tolist(), rows.tolist()):
            self.scenarios[index] = self.source.scenarios[row]
        scen = self.scen
        self.targets[indices] = scen.targets[indices]
        # Each episode starts at the start point, already at search altitude and hovering.
        v = self.vehicles
        v.north_m[indices], v.east_m[indices] = scen.start[indices, 0], scen.start[indices, 1]
        v.down_m[indices] = -self.flight.altitude_m
        v.vn_mps[indices] = v.ve_mps[indices] = v.vd_mps[indices] = v.yaw_rad[indices] = 0.0
        v.battery_wh[indices] = self.airframe.battery_capacity_wh
        self.position[indices] = scen.start[indices]
        self.time_s[indices] = 0.0
        self.steps[indices] = 0
        self.episode_seed[indices] = seeds
        self.coverage[indices] = 0.0
        self.detections[indices] = False
        self.last_detection[indices] = scen.datum[indices]
        self.has_detection[indices] = False
        self.first_detection_step[indices] = -1
        self.goal[indices] = NO_GOAL
        self.goal_point[indices] = scen.datum[indices]
        self.path_length_m[indices] = 0.0
        self.episode_return[indices] = 0.0
        self.covered_cells[indices] = 0
        self.last_action[indices] = 0.0
        self.observe(indices)

    # ------------------------------------------------------------------ goals (HRL-SAC)
    def set_goals(self, goals: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Give environments a meta-controller goal (index into GOAL_NAMES), ground it to a point now and
        refresh their observations."""
        goals = np.broadcast_to(np.asarray(goals, dtype=np.int64), (self.n,))
        mask = np.ones(self.n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        if np.any((goals[mask] < 0) | (goals[mask] >= len(goal_logic.GOAL_NAMES))):
            raise ValueError(f"goal indices must be in [0, {len(goal_logic.GOAL_NAMES) - 1}], got {goals[mask]}")
        self.goal[mask] = goals[mask]
        self._ground(mask)
        self.observe(np.flatnonzero(mask))

    def _ground(self, mask: np.ndarray) -> None:
        """Turn the goals of the ``mask`` rows into points from the search state now."""
        scen = self.scen
        self.goal_point[mask] = goal_logic.ground_goals(
            self.goal[mask], self.position[mask], scen.area[mask], self.coverage[mask],
            scen.datum_at(self.time_s)[mask], scen.datum_sigma[mask], self.last_detection[mask],
            self.has_detection[mask], scen.start[mask])

    # ------------------------------------------------------------------ observing and stepping
    def target_position(self) -> np.ndarray:
        """What the observation calls the target: never the hidden victim location."""
        if self.config.goal_conditioned:
            return self.goal_point
        return self.last_detection  # equals the datum until the victim has been detected

    def observe(self, indices: np.ndarray | None = None) -> np.ndarray:
        """Rebuild the observations of ``indices`` (all by default) into ``self.obs``; returns ``self.obs``."""
        if indices is not None and len(indices) == 0:
            return self.obs
        rows = slice(None) if indices is None else indices
        scen = self.scen
        goal = self.goal[rows] if self.config.goal_conditioned else np.full(len(self.goal[rows]), NO_GOAL)
        built = build_observations(self.position[rows], self.target_position()[rows], scen.area[rows],
                                   self.steps[rows] / self.flight.max_steps, scen.sea[rows], scen.weather[rows],
                                   scen.time_of_day[rows], scen.visibility[rows], scen.wind[rows],
                                   self.detections[rows], search.downsample_coverage(self.coverage[rows]), goal,
                                   out=self.obs if indices is None else None)
        if indices is not None:
            self.obs[indices] = built
        return self.obs

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """Advance every environment one decision; returns (obs, reward, terminated, truncated, info).

        Finished environments are NOT reset here; the wrappers decide when (gymnasium's auto-reset rules).
        The info arrays are views of live state, valid until the next call.
        """
        flight, scen = self.flight, self.scen
        a = np.clip(np.asarray(actions, dtype=np.float64).reshape(self.n, 4), ACTION_LOW, ACTION_HIGH)
        self.last_action[:] = a
        previous = self.position.copy()
        v = dynamics.step_batch(self.vehicles, a[:, 0] * flight.max_speed_mps, a[:, 1] * flight.max_speed_mps,
                                0.0, self.airframe, self.wind, self.time_s, flight.step_period_s, out=self.vehicles)
        self.time_s += flight.step_period_s
        self.steps += 1
        position = self.position
        position[:, 0], position[:, 1] = v.north_m, v.east_m
        self.path_length_m += np.hypot(position[:, 0] - previous[:, 0], position[:, 1] - previous[:, 1])
        search.drift_targets(self.targets, scen.drift_velocity, flight.step_period_s)

        half_width = search.footprint_half_width_m(flight.altitude_m, a[:, 3])
        self.covered_cells += search.cover(self.coverage, scen.area, position, half_width, a[:, 2])
        probability = scen.detection_probability(position, self.targets, flight.altitude_m, a[:, 3], a[:, 2])
        if probability.any():  # the draws are a pure function of (seed, step): skipping them changes nothing
            detected = keyed_uniforms(self.episode_seed, self.steps, self.max_targets) < probability
        else:
            detected = np.zeros(probability.shape, dtype=bool)
        self.detections = search.detected_categories(detected, scen.target_category)
        primary = scen.primary_index
        victim_seen = detected[self._arange, primary]
        self.last_detection[victim_seen] = self.targets[self._arange, primary][victim_seen]
        first = victim_seen & ~self.has_detection
        self.first_detection_step[first] = self.steps[first]
        self.has_detection |= victim_seen
        not_seen = ~self.has_detection  # until the victim is seen, its best estimate is the drifting datum
        self.last_detection[not_seen] = scen.datum_at(self.time_s)[not_seen]

        distance = search.distance_to_primary(position, self.targets, primary)
        success = distance <= flight.reach_radius_m
        collision = search.inside_obstacle(position, scen.obstacles, scen.obstacle_valid) & ~success
        out_of_bounds = search.outside_fence(position, scen.fence) & ~success
        energy = a[:, ENERGY_COMPONENTS]
        reward = (REWARD_STEP + REWARD_ENERGY * np.einsum("ij,ij->i", energy, energy) + REWARD_TARGET * success
                  + REWARD_COLLISION * collision + REWARD_BOUNDARY * out_of_bounds)
        self.episode_return += reward
        terminated = success | collision | out_of_bounds
        truncated = (self.steps >= flight.max_steps) & ~terminated
        # A goal reached before the meta-controller's next decision is grounded again (its next point); the
        # info reports the point this step flew towards.
        step_goal_point = self.goal_point.copy()
        goal_reached = (self.goal != NO_GOAL) & (np.hypot(*(position - step_goal_point).T) <= flight.reach_radius_m)
        if goal_reached.any():
            self._ground(goal_reached)
        # Views of the live arrays: valid until the next step (the wrappers copy what they hand out).
        info = {"success": success, "collision": collision, "out_of_bounds": out_of_bounds,
                "distance_to_victim_m": distance, "coverage_ratio": self.covered_cells / self.coverage[0].size,
                "first_detection_step": self.first_detection_step, "victim_detected": self.has_detection,
                "position": position, "goal_point": step_goal_point, "goal_reached": goal_reached, "path_length_m": self.path_length_m,
                "episode_return": self.episode_return, "steps": self.steps}
        return self.observe(), reward.astype(np.float32), terminated, truncated, info

    @property
    def meta_observation(self) -> np.ndarray:
        """(N, 272): what the meta-controller sees."""
        return self.obs[:, :META_OBS_DIM]


def make_batch(config: SarSearchConfig, seeds: Sequence[int]) -> SarSearchBatch:
    """A batch with every slot reset to its seed."""
    batch = SarSearchBatch(config, len(seeds))
    batch.reset(np.arange(len(seeds)), np.asarray(seeds, dtype=np.uint64))
    return batch
