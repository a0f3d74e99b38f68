"""Evaluating a search policy (learned or scripted) on a scenario split, with the paper's metrics.

Each of the first ``episodes`` scenarios of the split is flown once (episode seed i -> scenario i), all in one
vectorised batch, deterministically. Metrics: success rate with a Wilson 95 % interval, cumulative extrinsic
reward, coverage ratio, episode length, sub-goal reachability (HRL: share of goal segments in which the drone
came within the reach radius of the goal's point), time to first detection of the victim, and the collision and
out-of-bounds rates.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from autonomy.search_pilot import BINGO_FAILSAFE_S
from missions.goals import RETURN_TO_BASE
from missions.mission import FlightSettings
from policies.env.core import FlownSearch, SarSearchConfig
from policies.env.tasks import make_batch
from policies.evaluation.stats import quantiles, wilson_interval

ActFn = Callable[[FlownSearch], np.ndarray]
END_KEYS = ("success", "collision", "out_of_bounds", "ran_dry", "returned")
"""How an episode can end (besides the step limit); ran_dry and returned are SarSearch-v1's."""
FOUND_BY_S = (120, 240, 360, 480, 600, 720)
"""Times (s of flight) at which the evaluation reports the share of episodes already successful, P(found by t)."""
GoalFn = Callable[[np.ndarray], np.ndarray]


def run_episodes(core: FlownSearch, act: ActFn, choose_goals: GoalFn | None = None, flight_rules: bool = False,
                 on_progress: Callable[[int], None] | None = None) -> dict[str, np.ndarray]:
    """Fly every slot of ``core`` to the end of its current episode; per-episode outcome arrays.

    ``act(core)`` returns (N, 4) actions; ``choose_goals(meta_obs)`` (HRL) returns goal indices for the rows it
    is given, called when the search state's ``goal_due`` says so. ``flight_rules``: the mission runner's rules
    instead of training's: a ReturnToBase decision ends the search once the drone has left home (SarSearch-v1; on
    v0 always: the vehicle is sent home with RTL; in training ReturnToBase is a sub-goal like the others, flown by
    the low level until the next decision), and so does the pilot's bingo failsafe (SarSearch-v1,
    ``autonomy.search_pilot.BINGO_FAILSAFE_S``); used to compare flight with the environment on equal terms
    (benchmarks/sim_to_sitl.py). ``on_progress(episodes_done)`` is called after every step.
    """
    n, k = core.n, core.flight.subgoal_interval
    done = np.zeros(n, dtype=bool)
    record = {key: np.zeros(n, dtype=bool) for key in END_KEYS}
    record.update(length=np.zeros(n, dtype=np.int64), first_detection=np.full(n, -1, dtype=np.int64),
                  episode_return=np.zeros(n), coverage=np.zeros(n))
    segments, reached_segments = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    reached = np.zeros(n, dtype=bool)
    while not done.all():
        if choose_goals is not None:
            decide = core.goal_due(k) & ~done
            if decide.any():
                had_goal = decide & (core.steps > 0)
                segments += had_goal
                reached_segments += had_goal & reached
                reached[decide] = False
                goals = np.zeros(n, dtype=np.int64)
                goals[decide] = choose_goals(core.meta_observation[decide])
                core.set_goals(goals, decide)
                if flight_rules:
                    gave_up = decide & (goals == RETURN_TO_BASE) & getattr(core, "left_home", True)
                    _record_end(record, gave_up, core.steps, core.first_detection_step, core.episode_return,
                                core.coverage_ratio)
                    segments += gave_up  # the ReturnToBase segment counts, unreached, as in flight
                    done |= gave_up
                    if done.all():
                        break
        _, _, terminated, truncated, info = core.step(act(core))
        if choose_goals is not None:
            reached |= np.hypot(*(info["position"] - info["goal_point"]).T) <= core.flight.reach_radius_m
        ended = (terminated | truncated) & ~done
        if flight_rules and hasattr(core, "bingo_margin_s"):  # the pilot's bingo failsafe ends the search: RTL
            failsafe = ~done & ~ended & (core.bingo_margin_s <= BINGO_FAILSAFE_S)
            _record_end(record, failsafe, info["steps"], info["first_detection_step"], info["episode_return"],
                        info["coverage_ratio"])
            done |= failsafe
            if choose_goals is not None:
                segments += failsafe
                reached_segments += failsafe & reached
        for key in END_KEYS:
            if key in info:  # SarSearch-v0 has neither an endurance nor a home to return to
                record[key][ended] = info[key][ended]
        _record_end(record, ended, info["steps"], info["first_detection_step"], info["episode_return"],
                    info["coverage_ratio"])
        if choose_goals is not None:
            segments += ended
            reached_segments += ended & reached
        done |= ended
        if on_progress is not None:
            on_progress(int(done.sum()))
    record["subgoal_segments"], record["subgoals_reached"] = segments, reached_segments
    return record


def _record_end(record: dict[str, np.ndarray], ended: np.ndarray, steps: np.ndarray, first_detection: np.ndarray,
                episode_return: np.ndarray, coverage: np.ndarray) -> None:
    record["length"][ended] = steps[ended]
    record["first_detection"][ended] = first_detection[ended]
    record["episode_return"][ended] = episode_return[ended]
    record["coverage"][ended] = coverage[ended]


def found_by(success: np.ndarray, success_time_s: np.ndarray, times_s=FOUND_BY_S) -> dict[str, float]:
    """P(found by t): the share of all episodes that had succeeded by each time (not conditioned on success)."""
    return {f"{t:g}s": float((success & (success_time_s <= t)).mean()) for t in times_s}


def summarise(record: dict[str, np.ndarray], step_period_s: float = 1.0) -> dict:
    """The paper's metrics from :func:`run_episodes`' arrays (``step_period_s`` converts steps to time)."""
    episodes = len(record["success"])
    successes = int(record["success"].sum())
    for key in END_KEYS:  # records written before SarSearch-v1 had no such ends
        record.setdefault(key, np.zeros(episodes, dtype=bool))
    low, high = wilson_interval(successes, episodes)
    detected = record["first_detection"] >= 0
    segments = int(record["subgoal_segments"].sum())
    return {
        "episodes": episodes, "success_rate": successes / episodes, "success_ci95": [low, high],
        "reward_mean": float(record["episode_return"].mean()), "reward_std": float(record["episode_return"].std()),
        "coverage_mean": float(record["coverage"].mean()), "coverage_std": float(record["coverage"].std()),
        "length_mean": float(record["length"].mean()), "length_std": float(record["length"].std()),
        "collision_rate": float(record["collision"].mean()),
        "out_of_bounds_rate": float(record["out_of_bounds"].mean()),
        "ran_dry_rate": float(record["ran_dry"].mean()), "returned_rate": float(record["returned"].mean()),
        "found_by": found_by(record["success"], record["length"] * step_period_s),
        "subgoal_reachability": (float(record["subgoals_reached"].sum()) / segments) if segments else None,
        "detection_rate": float(detected.mean()),
        "time_to_first_detection": quantiles(record["first_detection"][detected]),
        "steps_to_success": quantiles(record["length"][record["success"]]),
        "per_episode": {"success": record["success"].astype(int).tolist(),
                        "ran_dry": record["ran_dry"].astype(int).tolist(),
                        "reward": np.round(record["episode_return"], 3).tolist(),
                        "length": record["length"].tolist(), "first_detection": record["first_detection"].tolist()},
    }


def episode_batch(split: str, episodes: int, flight: FlightSettings, goal_conditioned: bool,
                  slots: range | None = None, stream: int = 0, **environment) -> FlownSearch:
    """One slot per scenario 0..episodes-1 of ``split`` (or only those in ``slots``, a part of that range:
    scenario i is flown with episode seed i whichever batch it is in, so parts concatenate to the whole).
    ``stream`` k > 0 flies the same scenarios with other detection draws (episode seed i + k * episodes, which
    picks scenario i of the pool of ``episodes``): the runs of a scripted searcher. ``environment``: further
    ``SarSearchConfig`` fields (``task``, ``generator``, ``scenarios``: with a fixed list of scenarios, episode i
    flies scenario i of it)."""
    config = SarSearchConfig(split=split, flight=flight, pool_size=max(episodes, 1), goal_conditioned=goal_conditioned,
                             **environment)
    slots = range(episodes) if slots is None else slots
    return make_batch(config, [i + stream * episodes for i in slots])
