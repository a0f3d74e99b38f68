"""How a trained HRL-SAC run's learned low level flies each goal: the goal held at every decision (SarSearch-v1).

For each goal (all by default), the learned low level flies it on the first --episodes scenarios of the split
(scenario i, episode seed i); printed per goal: how the episodes ended (success, collision, out of bounds, ran dry,
returned), how far the movement command points off the goal's point while the drone is farther than the reach
radius (median, share of steps more than 30 degrees off), the mean speed command (share of full speed) and the mean
search intensity and zoom. It reads the action as the run was trained to (its ``action_frame``).

Usage: python benchmarks/low_level_check.py RUN [--episodes 60] [--split val] [--goals 1,2]
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import torch
from common import results_file, write_report

from missions.action_frames import movement_velocity
from missions.generator import SPLITS
from missions.goals import GOAL_NAMES
from policies.checkpoint import CheckpointPolicy
from policies.evaluation.episodes import END_KEYS, episode_batch
from policies.evaluation.parallel import padded


def fly_goal(policy: CheckpointPolicy, goal: int, split: str, episodes: int) -> dict:
    config = policy.config
    core = episode_batch(split, episodes, config.flight, goal_conditioned=True, task=config.task,
                         action_frame=config.action_frame)
    act, done = padded(policy.act), np.zeros(episodes, dtype=bool)
    ended = {key: np.zeros(episodes, dtype=bool) for key in END_KEYS}
    errors, speeds, intensity, zoom = [], [], [], []
    while not done.all():
        decide = core.goal_due(config.flight.subgoal_interval) & ~done
        if decide.any():
            core.set_goals(np.full(episodes, goal), decide)
        action = act(core.obs)
        # the velocity the environment flies (with "arrive", slowing on the way in), as a share of the top speed
        flight = config.flight
        movement = movement_velocity(action[:, :2], core.position, core.goal_point, config.action_frame,
                                     flight.max_speed_mps, flight.step_period_s) / flight.max_speed_mps
        to_goal = core.goal_point - core.position
        far = (np.hypot(*to_goal.T) > config.flight.reach_radius_m) & ~done
        off = np.degrees(np.abs(np.arctan2(movement[:, 1], movement[:, 0]) - np.arctan2(to_goal[:, 1], to_goal[:, 0])))
        errors += np.minimum(off, 360.0 - off)[far].tolist()
        speeds += np.hypot(*movement.T)[far].tolist()
        intensity += action[~done, 2].tolist()
        zoom += action[~done, 3].tolist()
        _, _, terminated, truncated, info = core.step(action)
        finished = (terminated | truncated) & ~done
        for key in END_KEYS:
            ended[key][finished] = info[key][finished]
        done |= terminated | truncated
    errors = np.array(errors)
    return {"goal": GOAL_NAMES[goal], **{f"{key}_rate": float(value.mean()) for key, value in ended.items()},
            "heading_error_median_deg": float(np.median(errors)) if len(errors) else None,
            "heading_error_over_30_share": float((errors > 30.0).mean()) if len(errors) else None,
            "speed_share": float(np.mean(speeds)) if speeds else None, "intensity_mean": float(np.mean(intensity)),
            "zoom_mean": float(np.mean(zoom))}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", help="run folder written by hrlsac train (HRL-SAC, SarSearch-v1)")
    parser.add_argument("--episodes", type=int, default=60)
    parser.add_argument("--split", default="val", choices=SPLITS)
    parser.add_argument("--goals", default=",".join(str(i) for i in range(len(GOAL_NAMES))))
    parser.add_argument("--out", default=results_file("low_level_check.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    policy = CheckpointPolicy.load(args.run)
    rows = []
    for goal in (int(g) for g in args.goals.split(",")):
        row = fly_goal(policy, goal, args.split, args.episodes)
        rows.append(row)
        print(f"{row['goal']:22s} success {row['success_rate']:5.1%}  collision {row['collision_rate']:5.1%}  out "
              f"{row['out_of_bounds_rate']:5.1%}  ran dry {row['ran_dry_rate']:5.1%}  returned "
              f"{row['returned_rate']:5.1%}  heading off {row['heading_error_median_deg']:.0f} deg (>30: "
              f"{row['heading_error_over_30_share']:.0%})  speed {row['speed_share']:.2f}  intensity "
              f"{row['intensity_mean']:.2f}  zoom {row['zoom_mean']:.2f}", flush=True)
    write_report(args.out, {"run": args.run, "trained_steps": policy.step, "split": args.split,
                            "episodes": args.episodes, "goals": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
