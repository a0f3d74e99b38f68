"""What flies a mission: a policy artifact (``--policy P.pt``) or a scripted searcher by name (``--pilot NAME``).

Both fly through the same :class:`autonomy.search_pilot.SearchPilot`, so a scripted searcher gets exactly what a
policy gets: the same search state (belief, candidates, close looks, endurance), the same safety shield, bingo
failsafe, setpoint stream and report. A scripted searcher (``missions.searchers``) reads the search state itself
(the crew's map, the candidates, the energy left) instead of the observation vector, and answers in the
north-east action frame (``ActionFrame.NORTH_EAST``), as it does in the training environment (SarSearch-v1).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from autonomy.search_pilot import FlownPolicy
from missions.action_frames import ActionFrame
from missions.search_state_v1 import BeliefSearchState
from missions.searchers import SEARCHERS, TUNED, ScriptedSettings, make_searcher
from missions.searchers.fleet import FleetGreedyBayes

FLEET_SEARCHER = "greedy_bayes"
"""The searcher whose fleet version splits the water between the drones of a fleet (sequential greedy)."""


class ScriptedPilot:
    """A scripted searcher of ``missions.searchers`` flown as the runner's pilot (:class:`FlownPolicy`), with its
    settings as tuned on the val split (``missions.searchers.TUNED``) unless ``settings`` are given."""

    hierarchical = False
    subgoal_interval = None
    action_frame = ActionFrame.NORTH_EAST

    def __init__(self, name: str, settings: ScriptedSettings | None = None):
        if name not in SEARCHERS:
            raise ValueError(f"--pilot: no scripted searcher {name!r}; choose from {', '.join(SEARCHERS)}")
        self.name = name
        self.settings = settings or TUNED.get(name, ScriptedSettings())
        self._searcher = None

    def attach(self, state: BeliefSearchState) -> None:
        # the random searcher draws from the mission's seed; a fleet (several rows) flies greedy Bayes split
        # between its drones (missions.searchers.fleet), any other searcher per drone on the shared map
        if state.n > 1 and self.name == FLEET_SEARCHER:
            self._searcher = FleetGreedyBayes(state, self.settings)
        else:
            self._searcher = make_searcher(self.name, state, self.settings, seed=int(state.episode_seed[0]))

    def select_goal(self, meta_obs: np.ndarray) -> np.ndarray:
        raise TypeError(f"the scripted searcher {self.name} chooses no goals")

    def act(self, obs: np.ndarray) -> np.ndarray:
        if self._searcher is None:
            raise RuntimeError("ScriptedPilot.act before attach: the search pilot attaches its search state first")
        actions = self._searcher.act()
        return actions[0] if np.ndim(obs) == 1 else actions  # one drone, or every row of a fleet

    def describe(self) -> dict:
        return {"pilot": self.name, "pilot_settings": dataclasses.asdict(self.settings)}


@dataclass(frozen=True)
class PilotChoice:
    """What a mission command was told to fly: exactly one of a policy artifact's path and a scripted searcher's
    name. Small and picklable, so that replay workers load the pilot themselves."""

    policy: str | None = None
    """Path of a policy artifact written by ``hrlsac export``."""
    scripted: str | None = None
    """Name of a scripted searcher (``missions.searchers.SEARCHERS``)."""

    def __post_init__(self) -> None:
        if (self.policy is None) == (self.scripted is None):
            raise ValueError("give exactly one of --policy FILE and --pilot NAME")

    def load(self) -> FlownPolicy:
        """The pilot's policy; raises ``autonomy.policy.PolicyArtifactError`` or ValueError with one line."""
        if self.scripted is not None:
            return ScriptedPilot(self.scripted)
        from autonomy.policy import load_policy  # torch: only when an artifact flies

        return load_policy(self.policy)
