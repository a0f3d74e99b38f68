"""Running the scripted baselines on a scenario split (see :mod:`policies.evaluation.episodes` for the metrics)."""
from __future__ import annotations

from typing import Callable

from missions.mission import FlightSettings
from missions.searchers import ScriptedSettings, make_searcher
from policies.env.baselines_v0 import BASELINES_V0
from policies.evaluation.episodes import episode_batch, run_episodes, summarise


def run_baseline(name: str, split: str = "test", episodes: int = 200, flight: FlightSettings = FlightSettings(),
                 seed: int = 0, task: str = "SarSearch-v1", settings: ScriptedSettings | None = None,
                 stream: int = 0, on_progress: Callable[[int], None] | None = None, **environment) -> dict:
    """One episode on each of the first ``episodes`` scenarios of ``split`` (episode seed i -> scenario i), or of
    the scenarios / generator given in ``environment`` (``SarSearchConfig`` fields). ``settings``: SarSearch-v1's
    scripted knobs (default: the tuned ones, ``missions.searchers.TUNED``); ``stream``: the detection stream
    (``episode_batch``); ``on_progress(episodes_done)``: after every step."""
    core = episode_batch(split, episodes, flight, goal_conditioned=False, task=task, stream=stream, **environment)
    if task == "SarSearch-v0":
        policy = BASELINES_V0[name](core, seed) if name == "random" else BASELINES_V0[name](core)
    else:
        policy = make_searcher(name, core, settings, seed)
    metrics = summarise(run_episodes(core, lambda _core: policy.act(), on_progress=on_progress), flight.step_period_s)
    return {"baseline": name, "split": split, "task": task, "stream": stream, "max_steps": flight.max_steps,
            **metrics}
