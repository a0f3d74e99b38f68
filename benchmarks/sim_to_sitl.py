"""The sim-to-SITL gap: one policy on the same test scenarios, in the training environment and in lockstep
mission replay (MAVLink both ways, the autopilot's rules, 100 Hz dynamics, noisy telemetry through the Kalman
filter). Target: success rates within 5 points.

The environment is evaluated twice: under the mission runner's rules (a ReturnToBase decision ends the search,
the vehicle returns with RTL, and so does the pilot's bingo failsafe), which is what the gap is measured against,
and under training's rules (ReturnToBase is a sub-goal like the others, and a sortie may run dry), to show how
much those rules alone change.

Scenario i of the split is flown with episode seed i in both (the same detection draws for the same path).
The environment flies the artifact through the same runtime (``autonomy.policy``) the runner uses.

The replays are independent episodes: ``--workers N`` flies them on N local processes (the same reports as a
serial run, see docs/scaling.md).

Usage: python benchmarks/sim_to_sitl.py --policy policies/pretrained/hrl-sac.pt [--episodes 50] [--split test]
       [--workers 2]
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import torch
from common import results_file, write_report

from autonomy.policy import load_policy
from missions.mission import FlightSettings, Mission
from policies.evaluation.episodes import episode_batch, run_episodes
from policies.evaluation.stats import wilson_interval
from simulation.parallel_replay import ReplayEpisode, replay_episodes
from simulation.worker_pool import PoolConfig


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="policies/pretrained/hrl-sac.pt")
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--split", default="test", choices=["train", "val", "test"])
    parser.add_argument("--workers", type=int, default=1, help="local processes flying the replays")
    parser.add_argument("--out", default=results_file("sim_to_sitl.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    policy = load_policy(args.policy)
    trained = policy.manifest.training_config
    flight = FlightSettings(**trained["flight"])
    # the environment the artifact was trained in (SarSearch-v1, its action frame)
    environment = {"task": trained.get("task", "SarSearch-v1"),
                   "action_frame": trained.get("action_frame", "north_east")}
    choose_goals = (lambda meta_obs: policy.select_goal(meta_obs)) if policy.hierarchical else None
    started = time.perf_counter()
    env, env_training_rules = (
        run_episodes(episode_batch(args.split, args.episodes, flight, goal_conditioned=policy.hierarchical,
                                   **environment),
                     lambda batch: policy.act(batch.obs), choose_goals, flight_rules=flight_rules)
        for flight_rules in (True, False))
    env_seconds = time.perf_counter() - started
    scenarios = episode_batch(args.split, args.episodes, flight, goal_conditioned=policy.hierarchical,
                              **environment).scenarios
    episodes = [ReplayEpisode(Mission(scenario=scenario, flight=flight, name=scenario.name), args.policy, seed=i,
                              out=None, video=False) for i, scenario in enumerate(scenarios)]
    done: list[dict] = []

    def progress(index: int, report: dict) -> None:
        done.append(report)
        print(f"\r  replay {len(done)}/{args.episodes}: {sum(r['success'] for r in done)} found", end="",
              file=sys.stderr)

    started = time.perf_counter()
    reports = replay_episodes(episodes, PoolConfig(workers=args.workers), progress)
    print(file=sys.stderr)
    replay_success = [report["success"] for report in reports]
    ends: dict[str, int] = {}
    for report in reports:
        ends[report["search_end"]] = ends.get(report["search_end"], 0) + 1
    replay_seconds = time.perf_counter() - started
    results = {}
    for name, success in (("environment", np.asarray(env["success"])),
                          ("environment_training_rules", np.asarray(env_training_rules["success"])),
                          ("replay", np.asarray(replay_success))):
        low, high = wilson_interval(int(success.sum()), len(success))
        results[name] = {"success_rate": float(success.mean()), "success_ci95": [low, high]}
        print(f"  {name:26s} success {success.mean():6.1%}  [{low:.1%}, {high:.1%}]")
    gap = abs(results["environment"]["success_rate"] - results["replay"]["success_rate"]) * 100
    agree = float(np.mean(np.asarray(env["success"]) == np.asarray(replay_success)))
    print(f"  gap {gap:.1f} points (target <= 5); same outcome in {agree:.0%} of scenarios; replay ends: {ends}")
    write_report(args.out, {"policy": args.policy, "policy_sha256": policy.sha256, "split": args.split,
                            "episodes": args.episodes, "workers": args.workers, **results, "gap_points": gap,
                            "same_outcome": agree,
                            "replay_ends": ends, "wall_s": {"environment": env_seconds, "replay": replay_seconds}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
