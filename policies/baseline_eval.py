"""Running the scripted baselines on a scenario split (see :mod:`policies.evaluation` for the metrics)."""
from __future__ import annotations

from missions.mission import FlightSettings
from policies.baselines import BASELINES
from policies.evaluation import episode_batch, run_episodes, summarise


def run_baseline(name: str, split: str = "test", episodes: int = 200, flight: FlightSettings = FlightSettings(),
                 seed: int = 0) -> dict:
    """One episode on each of the first ``episodes`` scenarios of ``split`` (episode seed i -> scenario i)."""
    core = episode_batch(split, episodes, flight, goal_conditioned=False)
    policy = BASELINES[name](core, seed) if name == "random" else BASELINES[name](core)
    metrics = summarise(run_episodes(core, lambda _core: policy.act()))
    return {"baseline": name, "split": split, "max_steps": flight.max_steps, **metrics}
