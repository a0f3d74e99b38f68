"""What both search tasks share, stepped for N scenarios at once with numpy: the configuration, the scenario pool,
the flown vehicle and the observations (:class:`FlownSearch`), the action box and the reward constants.

Each task's core is this frame on its search state: ``policies.env.task_v0.SarSearchBatch`` (SarSearch-v0, the
paper's task) and ``policies.env.task_v1.AmbiguousSearchBatch`` (SarSearch-v1). The gymnasium environment
(:class:`policies.env.gym_env.SarSearchEnv`, N = 1) and the vector environment
(:class:`policies.env.vector.SarSearchVectorEnv`) drive the same cores, so they agree exactly for the same seeds.
Everything is built only from the vehicle dynamics (``sitl_bridge.dynamics``), the search logic
(``missions.search``, ``missions.goals``) and the observation builder (``autonomy.observation``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from autonomy.observation import observe_search
from missions import search
from missions.action_frames import check_action_frame, movement_velocity
from missions.generator import SPLITS, TASK_V1, GeneratorConfig, generate_scenario, split_seed
from missions.mission import FlightSettings
from missions.scenario import Scenario
from missions.search_state_v0 import splitmix64
from missions.search_state_v1 import TARGET_SLOTS
from missions.shield import shield_velocity
from missions.validation import check_fields
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
SEARCH_INTENSITY = ACTION_NAMES.index("search_intensity")
CAMERA_ZOOM = ACTION_NAMES.index("camera_zoom")

def next_episode_seed(seed: np.ndarray) -> np.ndarray:
    """The seed of the episode after one with ``seed`` (what an auto-reset uses)."""
    return splitmix64(seed.astype(np.uint64) + np.uint64(1)) & np.uint64(0x7FFFFFFFFFFFFFFF)


TASKS = ("SarSearch-v0", "SarSearch-v1")
"""The environment versions: v0, the paper's task (victim-aware search logic, exact forecast, no endurance), kept
for the runs trained on it; v1, the task of docs/environment.md (decoys, close looks, endurance, a belief)."""
TASK_MAX_TARGETS = {"SarSearch-v0": 8, "SarSearch-v1": TARGET_SLOTS}
"""Target slots per scenario by default. The detection draws are keyed by slot, so a task keeps its number: v0's
8 reproduce its earlier runs exactly."""


@dataclass(frozen=True)
class SarSearchConfig:
    """Everything that defines the environment (the scenario source and how the search is flown)."""

    task: str = "SarSearch-v1"
    """Environment version, one of TASKS."""
    split: str = "train"
    """Generator split the scenarios come from (one of ``missions.generator.SPLITS``) when ``scenarios`` is empty."""
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
    """Vehicle limits; None = the SITL's defaults with the horizontal speed limit at ``flight.max_speed_mps``, where
    the mission runner caps its setpoints (a velocity of norm above it flies at it, in its direction)."""
    generator: GeneratorConfig | None = None
    """The distribution generated scenarios come from; None = the task's (``GeneratorConfig()`` for v0,
    ``missions.generator.TASK_V1`` for v1). Ignored when ``scenarios`` is given."""
    max_targets: int | None = None
    """Target slots per scenario (a scenario with more is refused); None = the task's (TASK_MAX_TARGETS)."""
    max_obstacles: int = 4
    """Danger-zone slots per scenario (a scenario with more is refused)."""
    action_frame: str = "north_east"
    """How the movement components are read (``missions.action_frames.ACTION_FRAMES``): "north_east" (velocity
    north and east, the paper's), or on SarSearch-v1 "target" (towards the observation's target point and to the
    right of that line, so flying straight at the target is the constant action (1, 0)) or "arrive" (as "target",
    slowing on the last step so that (1, 0) also stops on the target)."""

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ValueError(f"SarSearchConfig.task must be one of {', '.join(TASKS)}, got {self.task!r}")
        if not self.scenarios and self.split not in SPLITS:
            raise ValueError(f"SarSearchConfig.split must be one of {', '.join(SPLITS)}, got {self.split!r}")
        check_fields(self, (("pool_size", 1, 100_000), ("max_obstacles", 1, 64)),
                     integers=("pool_size", "max_obstacles"))
        if self.max_targets is not None:
            check_fields(self, (("max_targets", 1, 256),), integers=("max_targets",))
        check_action_frame("SarSearchConfig", self.action_frame, self.task)

    @property
    def target_slots(self) -> int:
        return self.max_targets or TASK_MAX_TARGETS[self.task]

    @property
    def scenario_distribution(self) -> GeneratorConfig:
        return self.generator or (TASK_V1 if self.task == "SarSearch-v1" else GeneratorConfig())


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
            scenario = generate_scenario(split_seed(self.config.split, row), self.config.scenario_distribution)
        if len(scenario.targets) > self.max_targets or len(scenario.obstacles) > self.max_obstacles:
            raise ValueError(f"scenario {scenario.name!r} has {len(scenario.targets)} targets and "
                             f"{len(scenario.obstacles)} obstacles; the environment holds at most "
                             f"{self.max_targets} and {self.max_obstacles}")
        self.pool.assign(row, search.ScenarioBatch.from_scenarios([scenario]))
        self.scenarios[row] = scenario


class FlownSearch:
    """What every version's environment adds to its search state: the scenarios it draws, the vehicle dynamics,
    the path flown, the episode return and the observations. A version's batch class inherits this and its
    search state (``missions.search_state_v0.SearchState`` or ``missions.search_state_v1.BeliefSearchState``)."""

    config: SarSearchConfig
    shielded = False
    """Whether velocity commands pass ``missions.shield`` before they are flown (SarSearch-v1)."""
    step_reward = REWARD_STEP
    """The reward's constant per-step part (the paper's -0.1; SarSearch-v1 has none): the shaping leaves it out."""

    def _placeholder(self, config: SarSearchConfig, num_envs: int) -> search.ScenarioBatch:
        """Set up the scenario source; returns the padded scenario arrays the search state starts from."""
        self.config = config
        self.source = ScenarioSource(config, config.target_slots, config.max_obstacles)
        self.scenarios: list[Scenario | None] = [None] * num_envs
        blank = search.ScenarioBatch.from_scenarios([Scenario()], num_targets=config.target_slots,
                                                    num_obstacles=config.max_obstacles)
        return blank.select(np.zeros(num_envs, dtype=np.int64))

    def _setup_vehicles(self, obs_dim: int) -> None:
        flight, n = self.config.flight, self.n
        # The speed the mission runner's setpoints are capped at (autonomy.setpoints: the horizontal speed's norm
        # at the mission's max_speed_mps, as PX4's position controller caps it at MPC_XY_VEL_MAX): a command flight
        # would cap is capped here too (the SITL's own 12 m/s would let a diagonal command fly 12 m/s).
        self.airframe = self.config.airframe or dynamics.MultirotorParams(max_speed_xy_mps=flight.max_speed_mps)
        self.wind = dynamics.Wind()  # the velocity controller holds the track; wind acts through drift
        hover = dynamics.VehicleState(down_m=-flight.altitude_m, on_ground=False)
        self.vehicles = dynamics.BatchState.from_states([hover] * n)
        self.path_length_m = np.zeros(n)
        self.episode_return = np.zeros(n)
        self.last_action = np.zeros((n, 4))
        self.obs = np.zeros((n, obs_dim), dtype=np.float32)

    def reset(self, indices, episode_seeds) -> None:
        """Start new episodes in slots ``indices`` with the scenarios and detection streams of ``episode_seeds``,
        and refresh their observations."""
        indices = np.atleast_1d(np.asarray(indices, dtype=np.int64))
        seeds = np.atleast_1d(np.asarray(episode_seeds, dtype=np.uint64))
        rows = self.source.rows(seeds)
        self.scen.assign(indices, self.source.pool.select(rows))
        for index, row in zip(indices.tolist(), rows.tolist()):
            self.scenarios[index] = self.source.scenarios[row]
        super().reset(indices, seeds)
        # Each episode starts at the start point, already at search altitude and hovering.
        scen, v = self.scen, self.vehicles
        v.north_m[indices], v.east_m[indices] = scen.start[indices, 0], scen.start[indices, 1]
        v.down_m[indices] = -self.config.flight.altitude_m
        v.vn_mps[indices] = v.ve_mps[indices] = v.vd_mps[indices] = v.yaw_rad[indices] = 0.0
        v.battery_wh[indices] = self.airframe.battery_capacity_wh
        self.path_length_m[indices] = 0.0
        self.episode_return[indices] = 0.0
        self.last_action[indices] = 0.0
        self.observe(indices)

    def set_goals(self, goals: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Give environments a meta-controller goal (index into GOAL_NAMES), ground it to a point now and
        refresh their observations."""
        mask = super().set_goals(goals, mask)
        self.observe(np.flatnonzero(mask))
        return mask

    def observe(self, indices: np.ndarray | None = None) -> np.ndarray:
        """Rebuild the observations of ``indices`` (all by default) into ``self.obs``; returns ``self.obs``."""
        if indices is not None and len(indices) == 0:
            return self.obs
        if indices is None:
            observe_search(self, self.config.goal_conditioned, out=self.obs)
        else:
            self.obs[indices] = observe_search(self, self.config.goal_conditioned, rows=indices)
        return self.obs

    def fly(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The actions, clipped to their ranges, flown for one period; returns them and the positions reached."""
        flight = self.config.flight
        a = np.clip(np.asarray(actions, dtype=np.float64).reshape(self.n, 4), ACTION_LOW, ACTION_HIGH)
        self.last_action[:] = a
        previous = self.position.copy()
        target = self.target_position(self.config.goal_conditioned)
        self._step_start = (previous, target.copy(), np.array(self.searched_cells, dtype=np.float64))
        velocity = movement_velocity(a[:, 0:2], self.position, target, self.config.action_frame, flight.max_speed_mps,
                                     flight.step_period_s)
        if self.shielded:  # SarSearch-v1: the safety filter the flight pilot applies too
            velocity = shield_velocity(self.position, velocity, self.scen.obstacles, self.scen.obstacle_valid,
                                       self.scen.fence)
        v = dynamics.step_batch(self.vehicles, velocity[:, 0], velocity[:, 1], 0.0, self.airframe, self.wind,
                                self.time_s, flight.step_period_s, out=self.vehicles)
        position = np.stack([v.north_m, v.east_m], axis=1)
        self.path_length_m += np.hypot(position[:, 0] - previous[:, 0], position[:, 1] - previous[:, 1])
        return a, position

    def step_start_info(self) -> dict[str, np.ndarray]:
        """The info entries that describe the step from where it started (the learning reward's inputs,
        ``policies.env.shaping``): the position, the target the observation pointed at (the goal's point, or
        flat SAC's target), the coverage the step added and the area of one coverage cell."""
        start_position, target, searched_before = self._step_start
        area = self.scen.area
        return {"start_position": start_position, "step_target": target,
                "newly_searched_cells": self.searched_cells - searched_before,
                "cell_area_m2": (area[:, 1] - area[:, 0]) * (area[:, 3] - area[:, 2]) / self.coverage[0].size}

    @property
    def meta_observation(self) -> np.ndarray:
        """(N, meta_dim): what the meta-controller sees (everything but the goal one-hot)."""
        return self.obs[:, :self.layout.meta_dim]
