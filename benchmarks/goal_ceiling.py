"""What SarSearch-v1's goal set allows a perfect low level: the scripted searchers' rules around a goal's point.

The scripted searchers (``missions.searchers``) share their rules around a search point: fly to the candidate
worth a look and look at it, head home at the bingo reserve, fly straight. Here that search point is the point a
meta-controller goal is grounded to (``missions.goals.ground_goals_v1``, as if every decision chose that goal),
grounded again on arrival and, with --every K, every K steps (HRL-SAC's cadence is 30): a scripted low level and
a constant goal, with greedy Bayes' confirmation and return rules and settings (``TUNED["greedy_bayes"]``). Beside
it greedy Bayes itself, on the same scenarios and detection draws. The gap between the two is what choosing
among the goals' points, rather than greedy Bayes' cell, costs or gains with everything else scripted alike.

The candidates are left to the shared rules, so SearchSpecificLocation and TrackObject ground to the same point
here (TrackObject without a candidate); ExploreArea and ReturnToBase are not search points of their own.

Usage: python benchmarks/goal_ceiling.py [--episodes 500] [--split val] [--every 30]
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
from common import results_file, write_report
from decision_ceiling import fly_scripted

from missions import goals as goal_logic
from missions.generator import SPLITS
from missions.searchers import TUNED, GreedyBayes, ScriptedSearch


class GoalPointSearch(ScriptedSearch):
    """The shared scripted rules around the point ``goal`` is grounded to, grounded again on arrival or every
    ``every`` steps."""

    def __init__(self, core, settings, goal: int, every: int):
        super().__init__(core, settings)
        self.goal, self.every = goal, every
        self.point, self.age = np.zeros((core.n, 2)), np.zeros(core.n, dtype=np.int64)

    def search_point(self, fresh: np.ndarray) -> np.ndarray:
        core = self.core
        reached = np.hypot(*(self.point - core.position).T) <= core.flight.reach_radius_m
        rows = np.flatnonzero(fresh | reached | (self.age >= self.every))
        if len(rows):
            estimates = core.candidate_estimates()[rows]
            no_candidates = np.zeros(estimates.shape[:2], dtype=np.int64)  # candidates are the shared rules' job
            scen = core.scen
            self.point[rows] = goal_logic.ground_goals_v1(
                np.full(len(rows), self.goal), core.position[rows], scen.area[rows], core.coverage[rows],
                core.belief[rows], core.belief_offset[rows], estimates, no_candidates,
                scen.datum_at(core.time_s)[rows], scen.start[rows], scen.obstacles[rows], scen.obstacle_valid[rows])
            self.age[rows] = 0
        self.age += 1
        return self.point


def fly(make, split: str, episodes: int) -> dict:
    metrics, _ = fly_scripted(make, split, episodes)
    return {key: metrics[key] for key in ("success_rate", "ran_dry_rate", "returned_rate", "collision_rate")}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--split", default="val", choices=SPLITS)
    parser.add_argument("--every", type=int, default=30, help="also ground again every this many steps")
    parser.add_argument("--out", default=results_file("goal_ceiling.json"))
    args = parser.parse_args()
    settings = TUNED["greedy_bayes"]
    rows = {
        "greedy_bayes": lambda core: GreedyBayes(core, settings),
        f"SearchSpecificLocation, every {args.every} steps":
            lambda core: GoalPointSearch(core, settings, goal_logic.SEARCH_LOCATION, args.every),
        "SearchSpecificLocation, on arrival only":
            lambda core: GoalPointSearch(core, settings, goal_logic.SEARCH_LOCATION, 10 ** 9),
        f"ExploreArea, every {args.every} steps":
            lambda core: GoalPointSearch(core, settings, goal_logic.EXPLORE, args.every),
    }
    report = {"command": " ".join(["python benchmarks/goal_ceiling.py"] + sys.argv[1:]), "split": args.split,
              "episodes": args.episodes, "results": {}}
    for name, make in rows.items():
        result = fly(make, args.split, args.episodes)
        report["results"][name] = result
        print(f"{name:42s} success {100 * result['success_rate']:5.1f} %  "
              f"ran dry {100 * result['ran_dry_rate']:.1f} %  "
              f"returned {100 * result['returned_rate']:.1f} %", flush=True)
    write_report(args.out, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
