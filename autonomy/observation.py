"""The observation builders: the paper's 276-value observation (SarSearch-v0) and SarSearch-v1's 288 values,
shared by training and flight.

Both the gymnasium environment and the mission runner call the builder of their search state with what they
know: the (filtered) pose, the point the agent is sent to, the search state, the conditions and the current goal,
never simulator internals. They work on a batch of N observations (N = 1 in flight). A layout has a version
(``ObservationLayout.version``), written into every policy artifact's manifest and checked by the runtime;
``OBSERVATION_LAYOUT_VERSION`` (4) is the one the runtime flies, SarSearch-v1's. The goal one-hot always comes last,
so the meta-controller's view is the first ``meta_dim`` values.

Layout version 3 (SarSearch-v0, ``LAYOUT_V3``):

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

Layout version 4 (SarSearch-v1, ``LAYOUT_V4``): the first 16 values as in version 3, then

=======================  ======  ====  =======================================================================
name                     offset  size  meaning
=======================  ======  ====  =======================================================================
belief                   16      256   the search belief (``missions.belief``) as 16 x 16 block means (2 x 2 cells
                                       of a 32 x 32 map, 4 x 4 of a 64 x 64 one) over the prior's peak cell: 1
                                       where the prior was most likely, 0 once searched
energy_left              272     1     share of the sortie's endurance left
return_cost              273     1     time to fly home at full speed, as a share of the endurance
belief_remaining         274     1     the belief's sum: the chance, to the crew, that the victim is still unseen
belief_peak_offset       275     2     to the most likely cell: offset / (distance + 200 m)
candidate_offset         277     2     to the nearest unresolved candidate: offset / (distance + 200 m); 0 if none
unresolved_candidates    279     1     unresolved reachable candidates / 4, at most 1
candidate_plausibility   280     1     that candidate's cell belief at its sighting over the best cell's then
confirmed                281     1     1 once a candidate was identified as the victim
close_look               282     1     1 while the camera looks closely at a candidate (within the reach radius)
altitude                 283     1     the camera's altitude over the search altitude
goal                     284     4     one-hot of the meta-controller's goal (all zero for flat SAC)
=======================  ======  ====  =======================================================================

In version 4, ``time_progress`` still counts the step limit; ``energy_left`` and ``return_cost`` are what a crew
would know of its endurance. Version 3 changed only the squashing scale of ``target_offset``, from 100 m to 20 m:
with 100 m the offset to a sub-goal point a cell or two away (31-62 m, where the search's goals usually lie) is a
short vector (0.24-0.38), and a learned low level flies slowly towards such points; with 20 m its length is
0.61-0.76 there (docs/training.md, "How the defaults were chosen"). Version 2 changed only ``target_offset`` too:
version 1 held the target's absolute position, normalised like ``agent_position``, so a goal-conditioned low level
had to subtract two inputs among 276 to find its way, with a 15 m reach radius worth 1 % of the area, and seldom
reached its sub-goals.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from missions.goals import GOAL_NAMES, NO_GOAL  # noqa: F401  (re-exported: the runtime names goals from here)
from missions.search import downsample_coverage
from missions.search_state_v1 import BeliefSearchState

TARGET_OFFSET_SCALE_M = 20.0
"""Distance at which ``target_offset`` has length 0.5."""
PLAN_OFFSET_SCALE_M = 200.0
"""Distance at which ``belief_peak_offset`` and ``candidate_offset`` have length 0.5 (they point farther)."""
CANDIDATES_FULL_SCALE = 4.0
"""``unresolved_candidates`` = count / this, at most 1."""


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


@dataclass(frozen=True)
class ObservationLayout:
    """One version of the observation: its fields in order, the goal one-hot last."""

    version: int
    fields: tuple[ObservationField, ...]

    @property
    def by_name(self) -> dict[str, ObservationField]:
        return {f.name: f for f in self.fields}

    @property
    def dim(self) -> int:
        return sum(f.size for f in self.fields)

    @property
    def meta_dim(self) -> int:
        """What the meta-controller sees: everything but the goal one-hot."""
        return self.by_name["goal"].offset

    @property
    def low(self) -> np.ndarray:
        low = np.zeros(self.dim, dtype=np.float32)
        for f in self.fields:
            if f.name.endswith("_offset"):  # the only signed fields
                low[f.slice] = -1.0
        return low

    @property
    def high(self) -> np.ndarray:
        return np.ones(self.dim, dtype=np.float32)

    def description(self) -> list[dict]:
        """The layout as plain data, for policy manifests (checked at load time by the runtime)."""
        return [{"name": f.name, "offset": f.offset, "size": f.size, "description": f.description}
                for f in self.fields]


def _layout(version: int, *fields: tuple[str, int, str]) -> ObservationLayout:
    out, offset = [], 0
    for name, size, description in fields:
        out.append(ObservationField(name, offset, size, description))
        offset += size
    return ObservationLayout(version, tuple(out))


_COMMON = (
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
)
_GOAL = ("goal", 4, "one-hot meta-controller goal (ExploreArea, SearchSpecificLocation, TrackObject, ReturnToBase)")
LAYOUT_V3 = _layout(3, *_COMMON, ("coverage", 256, "32 x 32 coverage grid averaged over 2 x 2 blocks, row-major, "
                                                   "north rows first"), _GOAL)
"""SarSearch-v0's 276 values (the paper's)."""
LAYOUT_V4 = _layout(
    4, *_COMMON,
    ("belief", 256, "search belief summed over 2 x 2 blocks over 4 x the prior's peak cell, row-major, north rows "
                    "first"),
    ("energy_left", 1, "share of the sortie's endurance left"),
    ("return_cost", 1, "time to fly home at full speed / endurance"),
    ("belief_remaining", 1, "sum of the belief: chance the victim is still unseen"),
    ("belief_peak_offset", 2, "(most likely cell - drone) / (distance + 200 m), north and east"),
    ("candidate_offset", 2, "(nearest unresolved candidate - drone) / (distance + 200 m); 0 if none"),
    ("unresolved_candidates", 1, "unresolved reachable candidates / 4, at most 1"),
    ("candidate_plausibility", 1, "that candidate's cell belief at its sighting over the best cell's"),
    ("confirmed", 1, "1 once a candidate was identified as the victim"),
    ("close_look", 1, "1 while the camera looks closely at a candidate"),
    ("altitude", 1, "camera altitude / search altitude"),
    _GOAL)
"""SarSearch-v1's 288 values."""
LAYOUTS = {3: LAYOUT_V3, 4: LAYOUT_V4}
_V4 = LAYOUT_V4.by_name
OBSERVATION_LAYOUT_VERSION = 4
"""The layout the runtime flies (SarSearch-v1's)."""
OBSERVATION_FIELDS = LAYOUTS[OBSERVATION_LAYOUT_VERSION].fields
OBS_DIM = LAYOUTS[OBSERVATION_LAYOUT_VERSION].dim  # 288
META_OBS_DIM = LAYOUTS[OBSERVATION_LAYOUT_VERSION].meta_dim  # 284: the meta-controller's view
_GOAL_INDICES = np.arange(4)


def layout_description() -> list[dict]:
    """The runtime's layout as plain data, for policy manifests (checked at load time by the runtime)."""
    return LAYOUTS[OBSERVATION_LAYOUT_VERSION].description()


def build_observations(agent_ne: np.ndarray, target_ne: np.ndarray, area: np.ndarray, time_progress: np.ndarray,
                       sea: np.ndarray, weather: np.ndarray, time_of_day: np.ndarray, visibility: np.ndarray,
                       wind: np.ndarray, detections: np.ndarray, coverage_blocks: np.ndarray, goal: np.ndarray,
                       out: np.ndarray | None = None) -> np.ndarray:
    """Fill (and return) the (N, 276) float32 observations of layout version 3 (SarSearch-v0).

    agent_ne, target_ne: (N, 2) metres in the local NED frame; area: (N, 4) north_min, north_max, east_min,
    east_max; time_progress, visibility, wind: (N,); sea, weather, time_of_day: (N,) enum values;
    detections: (N, 6) bool; coverage_blocks: (N, 256) in [0, 1]; goal: (N,) goal index or NO_GOAL.
    """
    n = agent_ne.shape[0]
    if out is None:
        out = np.empty((n, LAYOUT_V3.dim), dtype=np.float32)
    _fill_common(out, agent_ne, target_ne, area, time_progress, sea, weather, time_of_day, visibility, wind,
                 detections)
    out[:, 16:272] = coverage_blocks
    out[:, 272:276] = goal[:, None] == _GOAL_INDICES  # NO_GOAL matches nothing: all zero
    return out


def _fill_common(out: np.ndarray, agent_ne: np.ndarray, target_ne: np.ndarray, area: np.ndarray,
                 time_progress: np.ndarray, sea: np.ndarray, weather: np.ndarray, time_of_day: np.ndarray,
                 visibility: np.ndarray, wind: np.ndarray, detections: np.ndarray) -> None:
    """The first 16 values, the same in every layout."""
    origin = area[:, 0::2]  # (north_min, east_min)
    size = area[:, 1::2] - origin
    out[:, 0:2] = (agent_ne - origin) / size
    out[:, 2:4] = squashed_offset(agent_ne, target_ne, TARGET_OFFSET_SCALE_M)
    out[:, 4] = time_progress
    out[:, 5] = sea * 0.5
    out[:, 6] = weather * (1.0 / 3.0)
    out[:, 7] = time_of_day * (1.0 / 3.0)
    out[:, 8] = visibility
    out[:, 9] = wind
    out[:, 10:16] = detections


def squashed_offset(agent_ne: np.ndarray, point_ne: np.ndarray, scale_m: float) -> np.ndarray:
    """(N, 2) (point - agent) / (distance + scale_m): the direction, and a length that is 0.5 at scale_m."""
    offset = point_ne - agent_ne
    return offset / (np.hypot(offset[:, 0], offset[:, 1]) + scale_m)[:, None]


def observe_search(state, goal_conditioned: bool, rows: np.ndarray | None = None,
                   out: np.ndarray | None = None) -> np.ndarray:
    """The observations of a search state (all searches, or ``rows``): what the environment and the mission
    runner both give the policy. ``goal_conditioned``: HRL-SAC's target and goal one-hot; otherwise flat SAC's.
    A ``missions.search_state_v0.SearchState`` (SarSearch-v0) gives layout 3, a
    ``missions.search_state_v1.BeliefSearchState`` (SarSearch-v1) layout 4."""
    if isinstance(state, BeliefSearchState):
        return _observe_belief_search(state, goal_conditioned, rows, out)
    rows = slice(None) if rows is None else rows
    scen = state.scen
    goal = state.goal[rows] if goal_conditioned else np.full(len(state.goal[rows]), NO_GOAL)
    return build_observations(state.position[rows], state.target_position(goal_conditioned)[rows], scen.area[rows],
                              state.steps[rows] / state.flight.max_steps, scen.sea[rows], scen.weather[rows],
                              scen.time_of_day[rows], scen.visibility[rows], scen.wind[rows],
                              state.detections[rows], downsample_coverage(state.coverage[rows]), goal, out=out)


def _observe_belief_search(state, goal_conditioned: bool, rows: np.ndarray | None,
                           out: np.ndarray | None) -> np.ndarray:
    rows = np.arange(state.n) if rows is None else np.asarray(rows)
    scen, flight, n = state.scen, state.flight, len(rows)
    if out is None:
        out = np.empty((n, LAYOUT_V4.dim), dtype=np.float32)
    position = state.position[rows]
    _fill_common(out, position, state.target_position(goal_conditioned)[rows], scen.area[rows],
                 state.steps[rows] / flight.max_steps, scen.sea[rows], scen.weather[rows], scen.time_of_day[rows],
                 scen.visibility[rows], scen.wind[rows], state.detections[rows])
    belief = state.belief[rows]

    def put(name: str, values: np.ndarray) -> None:
        out[:, _V4[name].slice] = np.reshape(values, (n, -1))

    put("belief", np.minimum(downsample_coverage(belief) / state.prior_peak[rows, None], 1.0))
    put("energy_left", state.energy_left[rows])
    home_s = np.hypot(*(position - scen.start[rows]).T) / flight.max_speed_mps
    put("return_cost", np.minimum(home_s / scen.endurance_s[rows], 1.0))
    put("belief_remaining", belief.sum(axis=(1, 2)))
    peak = np.stack(np.divmod(belief.reshape(n, -1).argmax(axis=1), belief.shape[2]), axis=1) + 0.5
    cell_m = (scen.area[rows, 1::2] - scen.area[rows, 0::2]) / belief.shape[1]
    peak_ne = scen.area[rows, 0::2] + state.belief_offset[rows] + peak * cell_m
    put("belief_peak_offset", squashed_offset(position, peak_ne, PLAN_OFFSET_SCALE_M))
    estimates, kind = state.candidate_estimates()[rows], state.candidate_kind()[rows]
    distance = np.where(kind == 1, np.hypot(*(estimates - position[:, None, :]).transpose(2, 0, 1)), np.inf)
    nearest, unresolved = distance.argmin(axis=1), np.isfinite(distance.min(axis=1))
    put("candidate_offset", squashed_offset(position, estimates[np.arange(n), nearest], PLAN_OFFSET_SCALE_M)
        * unresolved[:, None])
    put("unresolved_candidates", np.minimum((kind == 1).sum(axis=1) / CANDIDATES_FULL_SCALE, 1.0))
    put("candidate_plausibility", state.plausibility[rows][np.arange(n), nearest] * unresolved)
    put("confirmed", (kind == 2).any(axis=1))
    put("close_look", state.close_look()[rows])
    put("altitude", state.altitude[rows] / state.search_altitude_m[rows])  # 1 at its own search altitude
    put("goal", (state.goal[rows] if goal_conditioned else np.full(n, NO_GOAL))[:, None] == _GOAL_INDICES)
    return out
