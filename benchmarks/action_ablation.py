"""What limits a trained run's test success: its deterministic policy against variants of how it acts (written for
SarSearch-v0 runs: its scripted variants fly north/east and some read v0's coverage field; for SarSearch-v1 runs see
benchmarks/low_level_check.py).

Variants, on the same first --episodes scenarios of the split (scenario i with episode seed i):
  * deterministic: the evaluation's policy (tanh of the mean, both levels);
  * sampled_low_level: the low level's actions sampled from its squashed Gaussian (seeded generator);
  * intensity_forced_on: deterministic, but search intensity always 1 (the sensor always on);
  * sensor_as_scripted: deterministic movement, but the sensor as the scripted searches set it (intensity 1,
    zoom 0: the widest footprint);
  * full_speed: deterministic, but the movement command scaled to full speed in the policy's direction;
  * sampled_meta (HRL-SAC only): deterministic low level, goals sampled from the meta-controller's softmax;
  * scripted_low_level (HRL-SAC only): the learned meta-controller's goals, flown by a scripted low level (straight
    at the goal's point at full speed, slowing over the last step, sensor on, zoom 0; no hazard avoidance);
  * track_object_goals (HRL-SAC only): the learned low level, but TrackObject at every decision (the scripted
    hierarchy's goal sequence);
  * scripted_hierarchy (HRL-SAC only): neither learned half, both scripted as above: what the goal set allows;
  * coverage_unseen (runs whose low level sees the coverage map): deterministic, with the coverage inputs held
    at their training mean (normalised 0), as if the low level could not see the map.
scripted_low_level and track_object_goals tell the levels apart: which learned half loses the success.
Each variant's line gives success, coverage, detection rate, the median time to find (first detection step over
the episodes with one, as ``hrlsac compare`` reports it), collisions and fence exits.

It also prints what the deterministic policy does (mean movement command, share of steps with the sensor on,
mean zoom, goal shares; HRL-SAC: how far the movement command points off the goal's point while the drone is
farther than the reach radius, as a median and the share of steps more than 30 degrees off). A large gain
from sampling, from forcing the sensor on or from full speed says the learned deterministic action, not the
policy's knowledge of where to fly, is what fails.

Usage: python benchmarks/action_ablation.py RUN [--episodes 300] [--split test] [--out FILE]
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import torch
from common import results_file, write_report

from autonomy.observation import LAYOUT_V3
from missions.coverage import SENSOR_ON_INTENSITY
from missions.generator import SPLITS
from missions.goals import GOAL_NAMES, TRACK_OBJECT
from missions.searchers import fly_straight
from policies.checkpoint import CheckpointPolicy
from policies.env.baselines_v0 import ZOOM as SCRIPTED_ZOOM
from policies.env.core import CAMERA_ZOOM, SEARCH_INTENSITY
from policies.evaluation.episodes import episode_batch, run_episodes, summarise
from policies.evaluation.parallel import padded

MOVEMENT = slice(0, 2)  # the action's movement components (docs/environment.md)
COVERAGE = LAYOUT_V3.by_name["coverage"].slice  # SarSearch-v0's map


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", help="run folder written by hrlsac train")
    parser.add_argument("--episodes", type=int, default=300)
    parser.add_argument("--split", default="test", choices=SPLITS)
    parser.add_argument("--out", default=results_file("action_ablation.json"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    policy = CheckpointPolicy.load(args.run)
    normalise = policy.normalizer.normalize
    # padded as in hrlsac evaluate, so that the deterministic variant is exactly the evaluation's policy
    mean_action = padded(lambda obs: policy.low.act(normalise(obs), deterministic=True))

    sampled_action = padded(lambda obs: policy.low.act(normalise(obs), deterministic=False))

    def mean_action_without_coverage(obs: np.ndarray) -> np.ndarray:
        unit = normalise(obs)
        unit[:, COVERAGE] = 0.0  # the training mean of every coverage input
        return policy.low.act(unit, deterministic=True)

    coverage_unseen_action = padded(mean_action_without_coverage)

    def deterministic(core) -> np.ndarray:
        return mean_action(core.obs)

    def sampled(core) -> np.ndarray:
        return sampled_action(core.obs)

    def sensor_on(core) -> np.ndarray:
        actions = deterministic(core).copy()
        actions[:, SEARCH_INTENSITY] = 1.0
        return actions

    def sensor_as_scripted(core) -> np.ndarray:
        actions = sensor_on(core)
        actions[:, CAMERA_ZOOM] = SCRIPTED_ZOOM
        return actions

    def full_speed(core) -> np.ndarray:
        actions = deterministic(core).copy()
        movement = actions[:, MOVEMENT]
        actions[:, MOVEMENT] = movement / np.maximum(np.linalg.norm(movement, axis=1, keepdims=True), 1e-6)
        return actions

    def scripted_low_level(core) -> np.ndarray:
        return fly_straight(core.position, core.goal_point, core.flight, SCRIPTED_ZOOM)  # the scripted steering

    def coverage_unseen(core) -> np.ndarray:
        return coverage_unseen_action(core.obs)

    def goals(sample: bool):
        if not policy.hierarchical:
            return None
        return padded(lambda meta_obs: policy.meta.act(normalise(meta_obs), deterministic=not sample))

    variants = {"deterministic": (deterministic, goals(False)), "sampled_low_level": (sampled, goals(False)),
                "intensity_forced_on": (sensor_on, goals(False)),
                "sensor_as_scripted": (sensor_as_scripted, goals(False)), "full_speed": (full_speed, goals(False))}
    if policy.hierarchical:
        variants["sampled_meta"] = (deterministic, goals(True))
        variants["scripted_low_level"] = (scripted_low_level, goals(False))
        track_object = lambda meta_obs: np.full(len(meta_obs), TRACK_OBJECT)  # noqa: E731
        variants["track_object_goals"] = (deterministic, track_object)
        variants["scripted_hierarchy"] = (scripted_low_level, track_object)  # no learned part: the goals' ceiling
    mask = policy.config.low_level_input_mask
    if mask is None or mask[COVERAGE].all():
        variants["coverage_unseen"] = (coverage_unseen, goals(False))
    results, seen_actions, seen_goals, lengths = {}, [], [], None
    for name, (act, choose_goals) in variants.items():
        core = episode_batch(args.split, args.episodes, policy.config.flight, goal_conditioned=policy.hierarchical,
                             task=policy.config.task, action_frame=policy.config.action_frame)
        record = name == "deterministic"  # what the evaluation's policy does: actions and goals, recorded

        def act_on(batch, act=act, record=record):
            actions = act(batch)
            if record:
                seen_actions.append((batch.steps.copy(), actions, batch.goal_point - batch.position))
            return actions

        def goals_for(meta_obs, choose_goals=choose_goals, record=record):
            chosen = choose_goals(meta_obs)
            if record:
                seen_goals.append(np.asarray(chosen))
            return chosen

        outcome = run_episodes(core, act_on, goals_for if choose_goals is not None else None)
        if record:
            lengths = outcome["length"]
        metrics = summarise(outcome)
        results[name] = {key: metrics[key] for key in ("success_rate", "success_ci95", "coverage_mean",
                                                       "detection_rate", "out_of_bounds_rate", "collision_rate")}
        # the comparison's "median time to find": median first-detection step over the episodes with one
        results[name]["median_time_to_find"] = metrics["time_to_first_detection"]["p50"]  # None: no detection
        low, high = metrics["success_ci95"]
        find = results[name]["median_time_to_find"]
        print(f"  {name:20s} success {metrics['success_rate']:6.1%} [{low:.1%}, {high:.1%}]  coverage "
              f"{metrics['coverage_mean']:.1%}  detection {metrics['detection_rate']:.1%}  find "
              f"{'-' if find is None else f'{find:.0f}'}  collision {metrics['collision_rate']:.1%}  "
              f"out of bounds {metrics['out_of_bounds_rate']:.1%}")
    # Every slot is stepped until the last episode ends: keep only the steps inside each slot's own episode.
    actions = np.concatenate([a[steps < lengths] for steps, a, _ in seen_actions])
    behaviour = {"mean_movement_command": float(np.linalg.norm(actions[:, MOVEMENT], axis=1).mean()),
                 "sensor_on_share": float((actions[:, SEARCH_INTENSITY] >= SENSOR_ON_INTENSITY).mean()),
                 "mean_zoom": float(actions[:, CAMERA_ZOOM].mean())}
    if policy.hierarchical:  # how straight the low level flies at its goal's point (while farther than the reach)
        to_goal = np.concatenate([offset[steps < lengths] for steps, _, offset in seen_actions])
        away = np.hypot(*to_goal.T) > policy.config.flight.reach_radius_m
        error = np.degrees(np.abs(np.angle(np.exp(1j * (np.arctan2(actions[away, 1], actions[away, 0])
                                                         - np.arctan2(to_goal[away, 1], to_goal[away, 0]))))))
        behaviour.update(median_heading_error_deg=float(np.median(error)),
                         heading_error_above_30_deg_share=float((error > 30.0).mean()))
    if seen_goals:
        chosen = np.concatenate(seen_goals)
        behaviour["goal_shares"] = {name: float(np.mean(chosen == i)) for i, name in enumerate(GOAL_NAMES)}
    print("  deterministic policy: mean movement command {mean_movement_command:.2f} of full speed, sensor on in "
          "{sensor_on_share:.0%} of steps, mean zoom {mean_zoom:.2f}".format(**behaviour)
          + (", heading {median_heading_error_deg:.0f} deg off the goal's point (median; "
             "{heading_error_above_30_deg_share:.0%} of steps more than 30 deg)".format(**behaviour)
             if policy.hierarchical else "")
          + ("; goals " + ", ".join(f"{k} {v:.0%}" for k, v in behaviour["goal_shares"].items()) if seen_goals else ""))
    write_report(args.out, {"run": args.run, "algo": policy.config.algo, "trained_steps": policy.step,
                            "split": args.split, "episodes": args.episodes, "variants": results,
                            "deterministic_behaviour": behaviour})
    return 0


if __name__ == "__main__":
    sys.exit(main())
