"""The observation builder: the paper's 276-value observation, shared by training and flight.

Both the gymnasium environment and the mission runner call :func:`build_observations` with what they know:
the (filtered) pose, the point the agent is sent to, the search state (coverage, detections), the conditions
and the current goal, never simulator internals. It works on a batch of N observations (N = 1 in flight).

Layout (``OBSERVATION_FIELDS``; version ``OBSERVATION_LAYOUT_VERSION``):

====================  ======  ====  ==========================================================================
name                  offset  size  meaning
====================  ======  ====  ==========================================================================
agent_position        0       2     drone (north, east) normalised to [0, 1] over the search area
target_offset         2       2     from the drone to where it is sent (sub-goal point, or datum / last
                                    detection): offset / (distance + 20 m), a vector of length < 1
time_progress         4       1     step / max_steps
sea_condition         5       1     calm, moderate, rough -> 0, 0.5, 1
weather               6       1     clear, cloudy, foggy, rainy -> 0, 1/3, 2/3, 1
time_of_day           7       1     dawn, day, dusk, night -> 0, 1/3, 2/3, 1
visibility            8       1     [0.3, 1]
wind_speed            9       1     [0, 1]
detections            10      6     1 if an object of that category was detected this step (CATEGORIES order)
coverage              16      256   the 32 x 32 coverage grid averaged over 2 x 2 blocks, row-major (north rows)
goal                  272     4     one-hot of the meta-controller's goal (all zero for flat SAC)
====================  ======  ====  ==========================================================================

The meta-controller sees the first 272 values (everything but the goal).

Version 3 (this one) changed only the squashing scale of ``target_offset``, from 100 m to 20 m: with 100 m the
offset to a sub-goal point a cell or two away (31-62 m, where the search's goals usually lie) was a short vector
(0.24-0.38), and the learned low level flew slowly towards such points; with 20 m its length is 0.61-0.76 there
(HRL-SAC seed 0, 100,000 steps: test success 58.2 % -> 72.6 %, sub-goal reachability 53.7 % -> 80.0 %,
docs/results/README.md). Version 2 changed only ``target_offset`` too: version 1 held the target's absolute
position, normalised like ``agent_position``. A goal-conditioned low level then has to subtract two inputs among
276 to find its way, with a 15 m reach radius worth 1 % of the area; it reached 5 % of its sub-goals.
The offset, squashed so that it resolves metres near the target and saturates far away, hands it the direction
and the distance directly (docs/paper-notes.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from missions.goals import GOAL_NAMES, NO_GOAL  # noqa: F401  (re-exported: the runtime names goals from here)
from missions.search import downsample_coverage

OBSERVATION_LAYOUT_VERSION = 3
TARGET_OFFSET_SCALE_M = 20.0
"""Distance at which ``target_offset`` has length 0.5."""


@dataclass(frozen=True)
class ObservationField:
    """One named slice of the observation vector."""

    name: str
    offset: int
    size: int
    description: str

    @property
    def slice(self) -> slice:
        return slice(self.offset, self.offset + self.size)


def _layout(*fields: tuple[str, int, str]) -> tuple[ObservationField, ...]:
    out, offset = [], 0
    for name, size, description in fields:
        out.append(ObservationField(name, offset, size, description))
        offset += size
    return tuple(out)


OBSERVATION_FIELDS: tuple[ObservationField, ...] = _layout(
    ("agent_position", 2, "drone (north, east) normalised to [0, 1] over the search area"),
    ("target_offset", 2, "(target - drone) / (distance + 20 m), north and east: direction and squashed distance "
                         "to the point the agent is sent to"),
    ("time_progress", 1, "step / max_steps"),
    ("sea_condition", 1, "calm, moderate, rough -> 0, 0.5, 1"),
    ("weather", 1, "clear, cloudy, foggy, rainy -> 0, 1/3, 2/3, 1"),
    ("time_of_day", 1, "dawn, day, dusk, night -> 0, 1/3, 2/3, 1"),
    ("visibility", 1, "visibility fraction in [0.3, 1]"),
    ("wind_speed", 1, "wind strength in [0, 1]"),
    ("detections", 6, "per category: detected this step (person, boat, life_jacket, debris, floating_object, swimmer)"),
    ("coverage", 256, "32 x 32 coverage grid averaged over 2 x 2 blocks, row-major, north rows first"),
    ("goal", 4, "one-hot meta-controller goal (ExploreArea, SearchSpecificLocation, TrackObject, ReturnToBase)"),
)
FIELDS_BY_NAME = {f.name: f for f in OBSERVATION_FIELDS}
_GOAL_INDICES = np.arange(FIELDS_BY_NAME["goal"].size)
OBS_DIM = sum(f.size for f in OBSERVATION_FIELDS)  # 276
META_OBS_DIM = FIELDS_BY_NAME["goal"].offset  # 272: the meta-controller's view
OBSERVATION_LOW = np.zeros(OBS_DIM, dtype=np.float32)
OBSERVATION_LOW[FIELDS_BY_NAME["target_offset"].slice] = -1.0  # the only signed field
OBSERVATION_HIGH = np.ones(OBS_DIM, dtype=np.float32)


def layout_description() -> list[dict]:
    """The layout as plain data, for policy manifests (checked at load time by the runtime)."""
    return [{"name": f.name, "offset": f.offset, "size": f.size, "description": f.description}
            for f in OBSERVATION_FIELDS]


def build_observations(agent_ne: np.ndarray, target_ne: np.ndarray, area: np.ndarray, time_progress: np.ndarray,
                       sea: np.ndarray, weather: np.ndarray, time_of_day: np.ndarray, visibility: np.ndarray,
                       wind: np.ndarray, detections: np.ndarray, coverage_blocks: np.ndarray, goal: np.ndarray,
                       out: np.ndarray | None = None) -> np.ndarray:
    """Fill (and return) the (N, 276) float32 observations.

    agent_ne, target_ne: (N, 2) metres in the local NED frame; area: (N, 4) north_min, north_max, east_min,
    east_max; time_progress, visibility, wind: (N,); sea, weather, time_of_day: (N,) enum values;
    detections: (N, 6) bool; coverage_blocks: (N, 256) in [0, 1]; goal: (N,) goal index or NO_GOAL.
    """
    n = agent_ne.shape[0]
    if out is None:
        out = np.empty((n, OBS_DIM), dtype=np.float32)
    origin = area[:, 0::2]  # (north_min, east_min)
    size = area[:, 1::2] - origin
    out[:, 0:2] = (agent_ne - origin) / size
    offset = target_ne - agent_ne
    out[:, 2:4] = offset / (np.hypot(offset[:, 0], offset[:, 1]) + TARGET_OFFSET_SCALE_M)[:, None]
    out[:, 4] = time_progress
    out[:, 5] = sea * 0.5
    out[:, 6] = weather * (1.0 / 3.0)
    out[:, 7] = time_of_day * (1.0 / 3.0)
    out[:, 8] = visibility
    out[:, 9] = wind
    out[:, 10:16] = detections
    out[:, 16:272] = coverage_blocks
    out[:, 272:276] = goal[:, None] == _GOAL_INDICES  # NO_GOAL matches nothing: all zero
    return out


def observe_search(state, goal_conditioned: bool, rows: np.ndarray | None = None,
                   out: np.ndarray | None = None) -> np.ndarray:
    """The observations of a ``missions.search_state.SearchState`` (all searches, or ``rows``): what the
    environment and the mission runner both give the policy. ``goal_conditioned``: HRL-SAC's target and goal
    one-hot; otherwise flat SAC's (last detection / drifting datum, no goal)."""
    rows = slice(None) if rows is None else rows
    scen = state.scen
    goal = state.goal[rows] if goal_conditioned else np.full(len(state.goal[rows]), NO_GOAL)
    return build_observations(state.position[rows], state.target_position(goal_conditioned)[rows], scen.area[rows],
                              state.steps[rows] / state.flight.max_steps, scen.sea[rows], scen.weather[rows],
                              scen.time_of_day[rows], scen.visibility[rows], scen.wind[rows],
                              state.detections[rows], downsample_coverage(state.coverage[rows]), goal, out=out)
