"""The scripted searchers of SarSearch-v1 and of the mission runner (``hrlsac mission run|replay --pilot NAME``),
vectorised over a batch of search states (``missions.search_state_v1.BeliefSearchState``): the strongest scripted
methods built on what a crew knows (area, charted danger zones, datum and its forecast drift, conditions, own
position, own sightings, the belief of ``missions.belief``), never the hidden victim, by name (``SEARCHERS``) with
the settings tuned for each (``TUNED``). SarSearch-v0's are in ``policies.env.baselines_v0``.

Every searcher shares the same rules around its search pattern (``missions.searchers.rules.ScriptedSearch``):

* **confirm, then reach**: a candidate identified as the victim is flown to; otherwise the nearest unresolved
  candidate at least ``investigate_plausibility`` plausible is flown to, and over it the drone hovers with the
  camera at ``close_look_zoom`` (the search logic takes the camera down for the close look) until it resolves;
* **bingo**: once the endurance left is no more than the way home at full speed plus ``reserve_s``, the drone flies
  home and hovers there (which ends the sortie with its reserve);
* every point is kept 20 m inside the geofence and routed around the danger zones (``missions.goals``);
* the pattern itself flies at full speed, sensor on, camera at its widest (the widest sweep).

The patterns:

* ``expanding_square``: IAMSAR's expanding square from the drifting datum, legs S, S, 2S, 2S, ... turning right,
  bounded: once its half side passes ``bound_sigmas`` datum sigmas it starts again from the datum, offset by S/2
  (the second pass flies the lanes between the first's); repeated until the sortie ends;
* ``parallel_track``: IAMSAR's parallel track over the box of +- ``bound_sigmas`` datum sigmas round the drifting
  datum, tracks S apart from the corner nearest the drone, repeated with the tracks offset by S/2;
* ``greedy_bayes``: the cell with the most belief per travel time, belief / (distance / speed + ``travel_time_s``),
  flown to and kept until reached or searched down to half its belief, then the next;
* ``lookahead_bayes``: greedy Bayes that, each time it chooses a cell, flies ``lookahead_options`` options forward
  in the belief for ``lookahead_s`` (continuing greedily after each) and takes the one whose rollout detects the
  victim most probably by then (:class:`missions.searchers.lookahead.LookaheadBayes`): a planner on the crew's own
  model; on the calibrated map level with greedy Bayes (docs/results.md).

Track spacing S = W / ``coverage_factor`` with W the effective sweep width of the camera for the reported object
in the scenario's conditions (``missions.sweep_width``: IAMSAR's coverage factor C = W / S). The settings are
tuned on the val split (``benchmarks/tune_baselines.py``; the defaults are its choice).
"""
from __future__ import annotations

from typing import Callable

from missions.search_state_v1 import BeliefSearchState
from missions.searchers.lookahead import LookaheadBayes, box_sum, top_cells
from missions.searchers.patterns import ExpandingSquare, ParallelTrack, RandomSearch, WaypointPattern
from missions.searchers.rules import GreedyBayes, ScriptedSearch, ScriptedSettings, fly_straight

__all__ = ["BEST_SEARCHER", "SEARCHERS", "TUNED", "make_searcher", "ExpandingSquare", "GreedyBayes", "LookaheadBayes",
           "ParallelTrack", "RandomSearch", "ScriptedSearch", "ScriptedSettings", "WaypointPattern", "box_sum",
           "fly_straight", "top_cells"]


SEARCHERS: dict[str, Callable[..., object]] = {
    "random": RandomSearch,
    "expanding_square": ExpandingSquare,
    "parallel_track": ParallelTrack,
    "greedy_bayes": GreedyBayes,
    "lookahead_bayes": LookaheadBayes,
}
"""SarSearch-v1's scripted searchers by name; each takes (core, settings)."""
BEST_SEARCHER = "greedy_bayes"
"""The scripted searcher to fly: on the calibrated map it finds the victim as often as the lookahead planner (paired on
the same val scenarios, at 1 km and 2 km) at a fraction of the lookahead's slowest decisions (docs/results.md)."""


TUNED: dict[str, ScriptedSettings] = {
    # python benchmarks/tune_baselines.py --episodes 500 [--only NAME]: coordinate descent on val scenarios, with
    # at most 1 % of the sorties running dry (its reports: benchmarks/results/tune_baselines.json,
    # tune_parallel_track.json, tune_greedy_bayes.json)
    "expanding_square": ScriptedSettings(
        coverage_factor=1.7, bound_sigmas=2.0,
        investigate_plausibility=0.02, close_look_zoom=0.3, reserve_s=20.0, travel_time_s=30.0),
    "parallel_track": ScriptedSettings(
        coverage_factor=0.6, bound_sigmas=1.5,
        investigate_plausibility=0.0, close_look_zoom=0.5, reserve_s=20.0, travel_time_s=30.0),
    "greedy_bayes": ScriptedSettings(
        coverage_factor=1.0, bound_sigmas=2.5,
        investigate_plausibility=0.0, close_look_zoom=0.5, reserve_s=20.0, travel_time_s=30.0),
    # greedy Bayes' settings; the horizon and the options chosen on val with benchmarks/decision_ceiling.py
    # --rollouts (docs/results.md)
    "lookahead_bayes": ScriptedSettings(
        coverage_factor=1.0, bound_sigmas=2.5,
        investigate_plausibility=0.0, close_look_zoom=0.5, reserve_s=20.0, travel_time_s=30.0,
        lookahead_s=60.0, lookahead_options=6),
}
"""Each searcher's settings as chosen on the val split (``benchmarks/tune_baselines.py``); absent: the defaults."""


def make_searcher(name: str, core: BeliefSearchState, settings: ScriptedSettings | None = None, seed: int = 0):
    """The searcher ``name`` on ``core``, with ``settings`` (default: its tuned ones, ``TUNED``); ``seed`` seeds the
    random searcher's actions (the others draw nothing)."""
    if SEARCHERS[name] is RandomSearch:
        return RandomSearch(core, seed=seed)
    return SEARCHERS[name](core, settings or TUNED.get(name, ScriptedSettings()))
