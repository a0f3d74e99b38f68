"""How much SarSearch-v1 leaves to better decisions, at 1 km and on the 2 km square: the headroom table.

Rows, all on the first ``--episodes`` scenarios of ``--split``, judged under the mission runner's rules (a sortie that
runs dry fails; scripted searchers come home by themselves, so the rules change nothing for them):

* **information ceiling** ("victim known"): greedy Bayes flying to the victim's true position from the start, with
  the usual close look and reach rules (``decision_ceiling.KnownVictim``): what the airframe, camera and endurance
  allow once search is taken away.
* **relaxation ceiling**, in the crew's own model (``missions.belief``): every second of the sortie's endurance
  less a ``--reserve`` (20 s), the camera is put at the look that removes the most belief (centred on a cell, at the
  search altitude, the zoom of ``ZOOMS`` that removes the most, sensor on) anywhere the drone could be: within full
  speed's reach of the launch point by then, and of home before the endurance ends. Nothing flies between two looks
  (the path need not be continuous). Its P(sighted) is the belief it removed, which in the model is the chance the
  victim was sighted. It relaxes where to go, in what order and when to turn home, so what lies between a searcher's
  expected sightings and it is what those decisions could still gain in this model. It is a relaxation, not a
  proven bound: placing each look greedily is near-optimal for this kind of search but not guaranteed optimal, and
  looks are centred on cells.
* **searchers**: the scripted searchers with their tuned settings (``missions.searchers``) and, with ``--policy
  NAME=FILE``, policy artifacts flown in the environment under the runner's rules.

Per row: success, P(found by t) at 120 / 240 / 480 s, ran dry, the share of sorties in which the victim was sighted,
the crew's model's expected sightings (``map_calibration``: the summed first-sighting hazard), and the share of the
relaxation's headroom over greedy Bayes the row took (expected sightings, row minus greedy Bayes, over relaxation
minus greedy Bayes), and its success minus greedy Bayes' paired on the same scenarios with a scenario-bootstrap 95 %
interval. Compute per decision is ``benchmarks/pilot_cost.py``'s (one core, in flight).

Usage: python benchmarks/headroom.py [--episodes 500] [--split val] [--areas 1km,2km]
                                     [--policy hrl-sac=policies/pretrained/hrl-sac.pt] [--reserve 20]
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import torch
from common import ROOT, results_file, write_report
from decision_ceiling import KnownVictim
from map_calibration import LookRecorder, calibration

from autonomy.policy import load_policy
from missions import belief as belief_logic
from missions import search
from missions.generator import SPLITS, TASK_V1
from missions.mission import FlightSettings
from missions.search_state_v1 import TARGET_SLOTS
from missions.searchers import SEARCHERS, TUNED, make_searcher
from policies.cli.evaluate import read_generator_config
from policies.evaluation.aggregate import paired_scenario_bootstrap
from policies.evaluation.episodes import episode_batch, run_episodes

AREAS = ("1km", "2km")
FOUND_BY_S = (120, 240, 480)
RESERVE_S = 20.0
ZOOMS = (0.0, 0.25, 0.5, 1.0)
"""The camera zooms the relaxation chooses its looks among."""


def scripted_batch(split: str, episodes: int, generator):
    """The search batch scripted searchers fly (the task's scenarios drawn from ``generator``)."""
    targets = max(1 + generator.max_distractors + generator.decoys_max, TARGET_SLOTS)
    return episode_batch(split, episodes, FlightSettings(), goal_conditioned=False, task="SarSearch-v1",
                         generator=generator, max_targets=targets)


def look_kernel(core, altitude_m: float, zoom: float, intensity: float) -> np.ndarray:
    """(N, K, K) the detection probability a look centred on a map cell gives that cell and its neighbours (cell
    (r, r) is the one under the camera; ``missions.search.cell_detection_probability``, the map's own look)."""
    scen, n = core.scen, core.n
    cell = belief_logic.cell_size_m(scen.area, core.belief.shape[1])
    reach = int(np.ceil(search.footprint_half_width_m(np.array([altitude_m]), np.array([zoom]))[0] / cell.min()))
    offsets = np.arange(-reach, reach + 1)
    rows = np.arange(n)
    victim = scen.primary_index
    size_m = search.OBJECT_SIZE_M[scen.target_category[rows, victim]]
    return search.cell_detection_probability(
        np.zeros((n, 2)), offsets[None, :] * cell[:, 0:1] - 0.5 * cell[:, 0:1],
        offsets[None, :] * cell[:, 1:2] - 0.5 * cell[:, 1:2], cell, size_m, scen.detection_factor[rows, victim],
        np.full(n, altitude_m), np.full(n, zoom), np.full(n, intensity))


def removable(belief: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """(N, G, G) the belief a look centred on each cell would remove (``kernel`` (N, K, K): ``look_kernel``)."""
    g, k = belief.shape[1], kernel.shape[1]
    r = k // 2
    padded = np.pad(belief, ((0, 0), (r, r), (r, r)))
    removed = np.zeros_like(belief)
    for a in range(k):
        for b in range(k):
            removed += kernel[:, a, b, None, None] * padded[:, a:a + g, b:b + g]
    return removed


def best_look(belief: np.ndarray, kernels: list[np.ndarray], allowed: np.ndarray | None = None) \
        -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per search, the cell (row, column) and the kernel (index into ``kernels``, one per zoom) of the look that
    removes the most belief, among the ``allowed`` cells ((N, G, G) bool; default all)."""
    n, g = belief.shape[0], belief.shape[1]
    removed = np.stack([removable(belief, kernel) for kernel in kernels], axis=1)  # (N, Z, G, G)
    if allowed is not None:
        removed = np.where(allowed[:, None], removed, -1.0)
    zoom, cell = np.divmod(removed.reshape(n, -1).argmax(axis=1), g * g)
    return (*np.divmod(cell, g), zoom)


def relaxation(core, reserve_s: float = RESERVE_S) -> dict:
    """The relaxation ceiling (module docstring) of the searches in ``core`` (freshly reset): the mean P(sighted),
    P(sighted by t) for ``FOUND_BY_S``, and the per-sortie P(sighted)."""
    scen, flight, n = core.scen, core.flight, core.n
    rows = np.arange(n)
    altitude, intensity = flight.altitude_m, 1.0
    kernels = [look_kernel(core, altitude, zoom, intensity) for zoom in ZOOMS]
    budget_s = scen.endurance_s - reserve_s
    centres = (np.arange(core.belief.shape[1]) + 0.5)[None, :, None]
    victim = scen.primary_index
    size_m = search.OBJECT_SIZE_M[scen.target_category[rows, victim]]
    factor = scen.detection_factor[rows, victim]
    cell = belief_logic.cell_size_m(scen.area, core.belief.shape[1])
    dt = flight.step_period_s
    sighted, by_time = np.zeros(n), {}
    for step in range(1, int(np.ceil(budget_s.max() / dt)) + 1):
        core.time_s += dt
        core.drift_map(dt)
        # where the drone could be now: reached from the launch point by now, and home again before the budget ends
        corner = scen.area[:, 0::2] + core.belief_offset
        north = corner[:, 0, None, None] + centres * cell[:, 0, None, None] - scen.start[:, 0, None, None]
        east = corner[:, 1, None, None] + centres.transpose(0, 2, 1) * cell[:, 1, None, None] \
            - scen.start[:, 1, None, None]
        reach_m = flight.max_speed_mps * np.minimum(step * dt, budget_s - step * dt)[:, None, None]
        i, j, z = best_look(core.belief, kernels, np.hypot(north, east) <= np.maximum(reach_m, 0.0))
        drone = corner + (np.stack([i, j], axis=1) + 0.5) * cell
        looking = np.where(step * dt <= budget_s, intensity, 0.0)  # out of time: the sensor is off
        sighted += belief_logic.look(core.belief, core.coverage, scen.area, core.belief_offset, drone,
                                     np.full(n, altitude), np.array(ZOOMS)[z], looking, size_m, factor)
        for t in FOUND_BY_S:
            if step * dt == t:
                by_time[t] = float(sighted.mean())
    for t in FOUND_BY_S:
        by_time.setdefault(t, float(sighted.mean()))
    return {"expected_sighted": float(sighted.mean()), "sighted_by": by_time, "per_sortie": sighted}


def fly_row(core, act, choose_goals=None) -> dict:
    """Fly ``act`` over ``core`` under the runner's rules: success, P(found by t), ran dry, sighted and the crew's
    model's expected sightings (``map_calibration.calibration``)."""
    looks = LookRecorder(core)
    started = time.perf_counter()
    record = run_episodes(core, act, choose_goals, flight_rules=True)
    elapsed = time.perf_counter() - started
    figures = calibration(looks["removed"], looks["left"], record["first_detection"], record["length"])
    success, seconds = record["success"], record["length"] * core.flight.step_period_s
    return {"success_rate": float(success.mean()),
            "found_by": {t: float((success & (seconds <= t)).mean()) for t in FOUND_BY_S},
            "ran_dry_rate": float(record["ran_dry"].mean()), "sighted": figures["actual"],
            "expected_sighted": figures["expected"], "batch_seconds": elapsed,
            "per_sortie_success": success.astype(int).tolist()}


def policy_row(path: str, split: str, episodes: int, generator) -> dict:
    """A policy artifact flown in the environment it was trained in, on this area, under the runner's rules."""
    policy = load_policy(path)
    trained = policy.manifest.training_config
    core = episode_batch(split, episodes, FlightSettings(**trained["flight"]), goal_conditioned=policy.hierarchical,
                         task=trained.get("task", "SarSearch-v1"),
                         action_frame=trained.get("action_frame", "north_east"), generator=generator)
    choose = (lambda meta_obs: policy.select_goal(meta_obs)) if policy.hierarchical else None
    return fly_row(core, lambda batch: policy.act(batch.obs), choose)


def area_rows(area: str, generator, args) -> dict:
    """Every row of the table on one area."""
    rows = {}
    core = scripted_batch(args.split, args.episodes, generator)
    rows["relaxation ceiling"] = relaxation(core, args.reserve)
    core = scripted_batch(args.split, args.episodes, generator)
    known = KnownVictim(core, TUNED["greedy_bayes"])
    rows["information ceiling (victim known)"] = fly_row(core, lambda _core: known.act())
    for name in args.searchers:
        core = scripted_batch(args.split, args.episodes, generator)
        searcher = make_searcher(name, core)
        rows[name] = fly_row(core, lambda _core, searcher=searcher: searcher.act())
    for name, path in args.policy:
        rows[name] = policy_row(path, args.split, args.episodes, generator)
    if "greedy_bayes" in rows:
        greedy = rows["greedy_bayes"]
        room = rows["relaxation ceiling"]["expected_sighted"] - greedy["expected_sighted"]
        for name, row in rows.items():
            if "ceiling" in name:
                continue
            row["headroom_taken"] = (row["expected_sighted"] - greedy["expected_sighted"]) / room
            if name != "greedy_bayes":  # success, paired on the same scenarios; the interval resamples scenarios
                mean, low, high = paired_scenario_bootstrap(np.array(row["per_sortie_success"], dtype=bool),
                                                            np.array(greedy["per_sortie_success"], dtype=bool))
                row["minus_greedy_bayes"] = {"mean": mean, "scenario_bootstrap95": [low, high]}
    print(f"\n{area}: {args.episodes} {args.split} scenarios, the runner's rules")
    print(f"  {'row':36s} {'success':>8s} {'found by 120/240/480 s':>24s} {'ran dry':>8s} {'sighted':>8s} "
          f"{'expected':>9s} {'headroom':>9s}")
    for name, row in rows.items():
        success = f"{100 * row['success_rate']:.1f} %" if "success_rate" in row else "-"
        found = (" / ".join(f"{100 * row['found_by'][t]:.0f}" for t in FOUND_BY_S) if "found_by" in row else
                 " / ".join(f"({100 * row['sighted_by'][t]:.0f})" for t in FOUND_BY_S))
        dry = f"{100 * row['ran_dry_rate']:.1f} %" if "ran_dry_rate" in row else "-"
        sighted = f"{100 * row['sighted']:.1f} %" if "sighted" in row else "-"
        taken = f"{100 * row['headroom_taken']:+.0f} %" if "headroom_taken" in row else ""
        paired = row.get("minus_greedy_bayes")
        versus = (f"  vs greedy Bayes {100 * paired['mean']:+.1f} [{100 * paired['scenario_bootstrap95'][0]:+.1f}, "
                  f"{100 * paired['scenario_bootstrap95'][1]:+.1f}]" if paired else "")
        print(f"  {name:36s} {success:>8s} {found:>24s} {dry:>8s} {sighted:>8s} "
              f"{100 * row['expected_sighted']:8.1f} % {taken:>9s}{versus}")
    for row in rows.values():
        if isinstance(row.get("per_sortie"), np.ndarray):
            row["per_sortie"] = np.round(row["per_sortie"], 5).tolist()
    return rows


def policy_argument(text: str) -> tuple[str, str]:
    """``--policy NAME=FILE``, or a one-line argparse error."""
    name, _, path = text.partition("=")
    if not name or not path:
        raise argparse.ArgumentTypeError(f"expected NAME=FILE (e.g. hrl-sac=policies/pretrained/hrl-sac.pt), got "
                                         f"{text!r}")
    return name, path


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--split", default="val", choices=SPLITS)
    parser.add_argument("--areas", default=",".join(AREAS), help="comma-separated: 1km, 2km")
    parser.add_argument("--large-area", default=f"{ROOT}/docs/results/large-area.yaml",
                        help="generator config file of the 2 km square")
    parser.add_argument("--searchers", default="greedy_bayes,lookahead_bayes,expanding_square,parallel_track",
                        help="comma-separated scripted searchers")
    parser.add_argument("--policy", type=policy_argument, action="append", default=[], metavar="NAME=FILE",
                        help="a policy artifact to fly as a row (repeatable)")
    parser.add_argument("--reserve", type=float, default=RESERVE_S, help="the relaxation's reserve (s)")
    parser.add_argument("--out", default=results_file("headroom.json"))
    args = parser.parse_args()
    areas = [a.strip() for a in args.areas.split(",") if a.strip()]
    args.searchers = [s.strip() for s in args.searchers.split(",") if s.strip()]
    unknown = [a for a in areas if a not in AREAS] + [s for s in args.searchers if s not in SEARCHERS]
    if unknown:
        parser.error(f"unknown area or searcher: {', '.join(unknown)} (areas: {', '.join(AREAS)}; searchers: "
                     f"{', '.join(SEARCHERS)})")
    if args.episodes < 2:
        parser.error(f"--episodes must be at least 2, got {args.episodes}")
    torch.set_num_threads(1)
    report = {"split": args.split, "episodes": args.episodes, "reserve_s": args.reserve, "areas": {}}
    for area in areas:
        generator = TASK_V1 if area == "1km" else read_generator_config(args.large_area)
        report["areas"][area] = area_rows(area, generator, args)
    write_report(args.out, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
