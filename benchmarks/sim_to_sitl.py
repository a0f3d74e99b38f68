"""The sim-to-SITL gap: one pilot (a policy artifact or a scripted searcher) on the same test scenarios, in the
training environment and in lockstep
mission replay (MAVLink both ways, the autopilot's rules, 100 Hz dynamics, noisy telemetry through the Kalman
filter). Target: success rates within 5 points.

The environment is evaluated twice: under the mission runner's rules (a ReturnToBase decision ends the search,
the vehicle returns with RTL, and so does the pilot's bingo failsafe), which is what the gap is measured against,
and under training's rules (ReturnToBase is a sub-goal like the others, and a sortie may run dry), to show how
much those rules alone change.

Scenario i of the split is flown with episode seed i in both (the same detection draws for the same path).
The environment flies the artifact through the same runtime (``autonomy.policy``) the runner uses; a scripted
searcher (``--pilot NAME``) is the same code in both (``missions.searchers``), at the default flight settings.

The replays are independent episodes: ``--workers N`` flies them on N local processes (the same reports as a
serial run, see docs/scaling.md).

Usage: python benchmarks/sim_to_sitl.py --policy policies/pretrained/hrl-sac.pt [--episodes 50] [--split test]
       [--workers 2]
       python benchmarks/sim_to_sitl.py --pilot lookahead_bayes [...]
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import torch
from common import results_file, write_report

from autonomy.pilots import PilotChoice
from autonomy.policy import load_policy
from missions.generator import SPLITS
from missions.mission import FlightSettings, Mission
from missions.searchers import SEARCHERS, make_searcher
from policies.evaluation.episodes import episode_batch, run_episodes
from policies.evaluation.stats import wilson_interval
from simulation.parallel_replay import ReplayEpisode, replay_episodes
from simulation.worker_pool import PoolConfig


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    flown = parser.add_mutually_exclusive_group()
    flown.add_argument("--policy", default="policies/pretrained/hrl-sac.pt")
    flown.add_argument("--pilot", choices=list(SEARCHERS), help="a scripted searcher instead of --policy")
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--split", default="test", choices=SPLITS)
    parser.add_argument("--workers", type=int, default=1, help="local processes flying the replays")
    parser.add_argument("--out", default=results_file("sim_to_sitl.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    choice = PilotChoice(scripted=args.pilot) if args.pilot else PilotChoice(policy=args.policy)
    started = time.perf_counter()
    if args.pilot:
        flight, environment, hierarchical = FlightSettings(), {"task": "SarSearch-v1"}, False
        identity = {"pilot": args.pilot}

        def fly_environment(flight_rules: bool) -> dict:
            batch = episode_batch(args.split, args.episodes, flight, goal_conditioned=False, **environment)
            searcher = make_searcher(args.pilot, batch)
            return run_episodes(batch, lambda _batch: searcher.act(), flight_rules=flight_rules)
    else:
        policy = load_policy(args.policy)
        trained = policy.manifest.training_config
        flight, hierarchical = FlightSettings(**trained["flight"]), policy.hierarchical
        # the environment the artifact was trained in (SarSearch-v1, its action frame)
        environment = {"task": trained.get("task", "SarSearch-v1"),
                       "action_frame": trained.get("action_frame", "north_east")}
        identity = {"pilot": policy.manifest.algorithm, "policy": args.policy, "policy_sha256": policy.sha256}
        choose_goals = (lambda meta_obs: policy.select_goal(meta_obs)) if policy.hierarchical else None

        def fly_environment(flight_rules: bool) -> dict:
            batch = episode_batch(args.split, args.episodes, flight, goal_conditioned=hierarchical, **environment)
            return run_episodes(batch, lambda batch: policy.act(batch.obs), choose_goals, flight_rules=flight_rules)
    env, env_training_rules = fly_environment(True), fly_environment(False)
    env_seconds = time.perf_counter() - started
    scenarios = episode_batch(args.split, args.episodes, flight, goal_conditioned=hierarchical,
                              **environment).scenarios
    episodes = [ReplayEpisode(Mission(scenario=scenario, flight=flight, name=scenario.name), choice, seed=i,
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
    for name, record in (("environment", env), ("environment_training_rules", env_training_rules)):
        results[name]["ran_dry_rate"] = float(np.mean(record["ran_dry"]))  # a dry battery is a lost aircraft
    results["replay"]["ran_dry_rate"] = ends.get("endurance exhausted", 0) / len(reports)
    dry = {name: f"{results[name]['ran_dry_rate']:.1%}" for name in results}
    print(f"  ran dry: environment {dry['environment']} (training's rules {dry['environment_training_rules']}), "
          f"replay {dry['replay']}")
    gap = abs(results["environment"]["success_rate"] - results["replay"]["success_rate"]) * 100
    agree = float(np.mean(np.asarray(env["success"]) == np.asarray(replay_success)))
    print(f"  gap {gap:.1f} points (target <= 5); same outcome in {agree:.0%} of scenarios; replay ends: {ends}")
    write_report(args.out, {**identity, "split": args.split,
                            "episodes": args.episodes, "workers": args.workers, **results, "gap_points": gap,
                            "same_outcome": agree,
                            "replay_ends": ends, "replay_success_per_scenario": [int(s) for s in replay_success],
                            "wall_s": {"environment": env_seconds, "replay": replay_seconds}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
