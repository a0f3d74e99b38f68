"""Is the crew's probability map calibrated? Expected against actual sightings of the victim, per searcher and area.

The search belief (``missions.belief``) is the crew's probability map: every look lowers it by the chance, under
the map's own model, that the look found the victim (``look``'s return value, ``info["belief_removed"]``). If the
model is right, what it expects to be found is found, on average. Per sortie, with ``m_t`` the belief a step's look
removed and ``M_t`` the belief removed by the end of step t, the model's chance that step t makes the *first*
sighting, given none so far, is the hazard ``h_t = m_t / (1 - M_{t-1})`` (the map's mass not yet found, whether it
is still on the grid or drifted off it, is ``1 - M_{t-1}``). Its sum up to and including the step of the first
sighting (or to the sortie's end) is the sortie's *expected sightings*; whether the victim was sighted is the
*actual* one. For a calibrated model the two have the same mean, whatever the searcher does with what it sees (the
difference is a martingale stopped at the sortie's end). The report gives both means, their residual (expected minus
actual: above 0 the map over-states the search) with its standard error (of the per-sortie difference), and whether
|residual| < 2 SE, and the searcher's success rate.

With ``--particles K`` the map is also held against a Monte Carlo reference on the same looks: K victims per sortie
drawn and drifted as the scenario generator draws and drifts its victim, each detected with the camera's own point
model (``reference_found``). The reference's summed hazard on the same steps is what a calibrated map's should be;
the mean per-sortie difference (map minus reference) carries no noise from the detection draws, so it shows a bias
of a few tenths of a point that the residual's standard error hides.

Two other sums are reported beside it, neither of which a calibrated map needs to match: ``expected_in_area`` divides
``m_t`` by the belief still on the grid before the look instead of by ``1 - M_{t-1}`` (it assumes the victim has not
drifted out of the area, so it over-states wherever the map's mass drifts off the grid), and ``expected_removed``
sums ``m_t`` itself (it falls short of the sightings once the map has been searched down).

Searchers: the tuned greedy Bayes (``missions.searchers``) and the shipped policy (``--policy``, flown in the
environment as ``benchmarks/sim_to_sitl.py`` flies it, under training's rules), each over the first ``--episodes``
scenarios of the split at 1 km (the task's own generator) and on the 2 km square (``--large-area``, a generator
config file, docs/results/large-area.yaml).

Usage: python benchmarks/map_calibration.py [--episodes 2000] [--split val] [--only greedy_bayes,policy]
                                            [--areas 1km,2km] [--policy policies/pretrained/hrl-sac.pt]
                                            [--particles 0]
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import torch
from common import ROOT, results_file, write_report

from missions.generator import SPLITS, TASK_V1
from missions.mission import FlightSettings
from missions.search import OBJECT_SIZE_M, detection_probability_from_factors
from missions.search_state_v1 import TARGET_SLOTS
from missions.searchers import TUNED, GreedyBayes
from policies.cli.evaluate import read_generator_config
from policies.evaluation.episodes import episode_batch, run_episodes

SEARCHERS = ("greedy_bayes", "policy")
AREAS = ("1km", "2km")


class LookRecorder:
    """Keeps what each step of a search batch looked with (the position, altitude, zoom and intensity of its look),
    the belief the look removed and the belief left on the grid after it. The batch steps in lockstep from step 1, so
    row k - 1 of a record is every slot's step k."""

    def __init__(self, core):
        self.core, self.records = core, {name: [] for name in ("position", "altitude", "zoom", "intensity",
                                                               "removed", "left")}
        self._advance = core.advance
        core.advance = self.advance  # the batch's step calls self.advance: this instance attribute comes first

    def advance(self, position, intensity, zoom, dt_s):
        out = self._advance(position, intensity, zoom, dt_s)
        for name, value in (("position", position), ("altitude", self.core.altitude), ("zoom", zoom),
                            ("intensity", intensity), ("removed", out.belief_removed),
                            ("left", self.core.belief.sum(axis=(1, 2)))):
            self.records[name].append(np.array(value, dtype=np.float64))
        return out

    def __getitem__(self, name: str) -> np.ndarray:
        return np.array(self.records[name])


def residual_figures(expected: np.ndarray, sighted: np.ndarray) -> dict:
    """Mean expected and actual sightings, the residual (expected - actual) and its standard error."""
    difference = expected - sighted
    residual, se = float(difference.mean()), float(difference.std(ddof=1) / np.sqrt(len(difference)))
    return {"expected": float(expected.mean()), "actual": float(sighted.mean()), "residual": residual, "se": se,
            "within_2se": bool(abs(residual) < 2.0 * se)}


def counted_steps(steps: int, first_detection: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(steps, N) whether each step counts: up to and including the first sighting, or to the sortie's end."""
    last = np.where(first_detection >= 0, first_detection, length)
    return np.arange(1, steps + 1)[:, None] <= last[None, :]


def summed_hazard(found: np.ndarray, counted: np.ndarray) -> np.ndarray:
    """(N,) the sum over the counted steps of found_t / (1 - found before t), ``found`` (steps, N) the probability
    each step made the first sighting."""
    found_before = np.vstack([np.zeros((1, found.shape[1])), np.cumsum(found, axis=0)[:-1]])
    return (found / np.maximum(1.0 - found_before, 1e-12) * counted).sum(axis=0)


def calibration(removed: np.ndarray, left: np.ndarray, first_detection: np.ndarray, length: np.ndarray) -> dict:
    """The calibration figures from the belief each step removed and the belief left on the grid after it (both
    (steps, N)), each sortie's first sighting (its step, -1 for none) and its length (steps)."""
    counted = counted_steps(removed.shape[0], first_detection, length)
    sighted = (first_detection >= 0).astype(np.float64)
    figures = {"sorties": int(removed.shape[1]), **residual_figures(summed_hazard(removed, counted), sighted)}
    in_area = residual_figures((removed / np.maximum(left + removed, 1e-12) * counted).sum(axis=0), sighted)
    figures.update({f"{key}_in_area": in_area[key] for key in ("expected", "residual", "se")})
    figures["expected_removed"] = float((removed * counted).sum(axis=0).mean())
    return figures


def reference_found(looks: LookRecorder, scen, generator, length: np.ndarray, particles: int,
                    seed: int = 0) -> np.ndarray:
    """(steps, N) the probability each step's look made the first sighting of the victim, by Monte Carlo over
    ``particles`` victims per sortie drawn as the scenario generator draws its victim (a normal draw around the
    datum with the datum's sigma, clipped ``target_margin_m`` inside the area) and drifting as it drifts them (the
    forecast drift plus a current error of ``forecast_error_mps`` per axis), each detected by the recorded looks with
    the camera's own point model (``missions.search.detection_probability_from_factors``). It reads nothing of the
    map: what a calibrated map's ``removed`` should be, up to the Monte Carlo error."""
    rng = np.random.default_rng(seed)
    n, area, margin = len(scen), scen.area, generator.target_margin_m
    start = scen.datum[:, None, :] + scen.datum_sigma[:, None, None] * rng.standard_normal((n, particles, 2))
    start[..., 0] = np.clip(start[..., 0], area[:, 0:1] + margin, area[:, 1:2] - margin)
    start[..., 1] = np.clip(start[..., 1], area[:, 2:3] + margin, area[:, 3:4] - margin)
    velocity = scen.forecast_drift[:, None, :] + generator.forecast_error_mps * rng.standard_normal((n, particles, 2))
    rows = np.arange(n)
    victim = scen.primary_index
    size = np.repeat(OBJECT_SIZE_M[scen.target_category[rows, victim]][:, None], particles, axis=1)
    factor = np.repeat(scen.detection_factor[rows, victim][:, None], particles, axis=1)
    position, altitude, zoom, intensity = looks["position"], looks["altitude"], looks["zoom"], looks["intensity"]
    unseen = np.ones((n, particles))
    found = np.zeros((len(position), n))
    step_s = FlightSettings().step_period_s
    for t in range(len(position)):
        live = np.flatnonzero(t < length)
        if len(live) == 0:
            break
        where = start[live] + velocity[live] * ((t + 1) * step_s)
        p = detection_probability_from_factors(position[t, live], where, size[live], factor[live], altitude[t, live],
                                               zoom[t, live], intensity[t, live])
        found[t, live] = (unseen[live] * p).mean(axis=1)
        unseen[live] *= 1.0 - p
    return found


def fly(searcher: str, generator, split: str, episodes: int, policy, particles: int = 0) -> dict:
    """Fly one searcher over the first ``episodes`` scenarios of ``split``; its calibration figures and success
    (with ``particles``, also the map's summed hazard against the Monte Carlo reference's on the same looks)."""
    if searcher == "greedy_bayes":
        flight = FlightSettings()
        targets = max(1 + generator.max_distractors + generator.decoys_max, TARGET_SLOTS)
        core = episode_batch(split, episodes, flight, goal_conditioned=False, task="SarSearch-v1",
                             generator=generator, max_targets=targets)
        pilot = GreedyBayes(core, TUNED["greedy_bayes"])
        act, choose_goals = (lambda _core: pilot.act()), None
    else:
        trained = policy.manifest.training_config
        flight = FlightSettings(**trained["flight"])
        core = episode_batch(split, episodes, flight, goal_conditioned=policy.hierarchical,
                             task=trained.get("task", "SarSearch-v1"),
                             action_frame=trained.get("action_frame", "north_east"), generator=generator)
        act = lambda batch: policy.act(batch.obs)  # noqa: E731
        choose_goals = (lambda meta_obs: policy.select_goal(meta_obs)) if policy.hierarchical else None
    looks = LookRecorder(core)
    record = run_episodes(core, act, choose_goals)
    first, length = record["first_detection"], record["length"]
    figures = calibration(looks["removed"], looks["left"], first, length)
    figures["success_rate"] = float(record["success"].mean())
    figures["map_cells"] = int(core.belief.shape[1])
    if particles:
        counted = counted_steps(len(looks["removed"]), first, length)
        difference = (summed_hazard(looks["removed"], counted)
                      - summed_hazard(reference_found(looks, core.scen, generator, length, particles), counted))
        figures["minus_reference"] = {"particles": particles, "mean": float(difference.mean()),
                                      "se": float(difference.std(ddof=1) / np.sqrt(len(difference)))}
    return figures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=2000)
    parser.add_argument("--split", default="val", choices=SPLITS)
    parser.add_argument("--only", default=",".join(SEARCHERS), help="searchers (comma-separated: greedy_bayes, policy)")
    parser.add_argument("--areas", default=",".join(AREAS), help="areas (comma-separated: 1km, 2km)")
    parser.add_argument("--large-area", default=f"{ROOT}/docs/results/large-area.yaml",
                        help="generator config file of the 2 km square")
    parser.add_argument("--policy", default=f"{ROOT}/policies/pretrained/hrl-sac.pt")
    parser.add_argument("--particles", type=int, default=0,
                        help="also compare the map's summed hazard with a Monte Carlo reference of this many victims "
                        "per sortie (0: not)")
    parser.add_argument("--out", default=results_file("map_calibration.json"))
    args = parser.parse_args()
    searchers = [s.strip() for s in args.only.split(",") if s.strip()]
    areas = [a.strip() for a in args.areas.split(",") if a.strip()]
    if any(s not in SEARCHERS for s in searchers) or any(a not in AREAS for a in areas):
        parser.error(f"--only takes {', '.join(SEARCHERS)}; --areas takes {', '.join(AREAS)}")
    if args.particles < 0:
        parser.error(f"--particles must be >= 0, got {args.particles}")
    if args.episodes < 2:
        parser.error(f"--episodes must be >= 2 (a standard error needs two sorties), got {args.episodes}")
    try:
        generators = {"1km": TASK_V1, "2km": read_generator_config(args.large_area)}
    except ValueError as exc:
        parser.error(str(exc))
    policy = None
    if "policy" in searchers:
        from autonomy.policy import load_policy

        torch.set_num_threads(1)
        policy = load_policy(args.policy)
    report = {"split": args.split, "episodes": args.episodes, "particles": args.particles,
              "large_area": args.large_area,
              "policy": args.policy if policy else None, "policy_sha256": policy.sha256 if policy else None,
              "results": {}}
    print(f"{'searcher':14s} {'area':4s} {'expected':>8s} {'actual':>7s} {'residual':>9s} {'SE':>5s}  within 2 SE  "
          f"{'in area (residual, SE)':>23s}  success" + ("  map - reference" if args.particles else ""), flush=True)
    for searcher in searchers:
        for area in areas:
            started = time.perf_counter()
            figures = fly(searcher, generators[area], args.split, args.episodes, policy, args.particles)
            figures["wall_s"] = time.perf_counter() - started
            report["results"][f"{searcher}, {area}"] = figures
            verdict = "yes" if figures["within_2se"] else "NO"
            versus = figures.get("minus_reference")
            versus = f"  {100 * versus['mean']:+5.2f} ± {100 * versus['se']:.2f}" if versus else ""
            print(f"{searcher:14s} {area:4s} {100 * figures['expected']:7.1f}% {100 * figures['actual']:6.1f}% "
                  f"{100 * figures['residual']:+8.1f}  {100 * figures['se']:4.1f}  {verdict:11s}"
                  f"  {100 * figures['expected_in_area']:6.1f}% ({100 * figures['residual_in_area']:+5.1f}, "
                  f"{100 * figures['se_in_area']:3.1f})  {100 * figures['success_rate']:5.1f}%"
                  f"{versus}  ({figures['wall_s']:.0f} s)", flush=True)
    write_report(args.out, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
