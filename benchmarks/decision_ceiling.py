"""How much SarSearch-v1 leaves to a better decision-maker: greedy Bayes against itself with parts of the truth given.

A learned meta-controller can beat the best scripted searcher only by deciding better than its fixed rules. This
measures, on the same scenarios and detection draws, what perfect versions of each decision would be worth to the
tuned greedy Bayes searcher (``missions.searchers``, ``TUNED["greedy_bayes"]``):

* **oracle skip**: which candidate is the victim is known, so the drone never flies to a decoy for a close look (one
  beside the victim may still be identified in passing during the victim's own; the victim still needs its close
  look to be confirmed): the ceiling of confirm-or-skip decisions, however they are made;
* **victim known**: the drone flies straight at the victim from the start, and looks at it: the ceiling of the
  task itself with this airframe, camera and endurance (what search leaves undone);
* **best of the patterns per scenario**: a scenario counts as found when any of several tuned scripted searchers
  (greedy Bayes with three travel-time constants, the bounded expanding square and parallel track) found it, each
  with the same detection draws: an upper bound on choosing among those whole strategies scenario by scenario
  (inflated by luck: a scenario one of them found by a fortunate draw counts too);
* **best of greedy Bayes over as many detection streams**: the same union over greedy Bayes alone, flown once per
  detection stream (the same scenarios, other draws): how much of the line above is luck. With ``--taus`` the
  patterns are greedy Bayes with each of those travel-time constants instead (tau: how far a better cell may lie).

For greedy Bayes itself the report splits its failures into sorties that never sighted the victim and sorties that
sighted it but did not confirm and reach it, and gives its success by how far the victim lay from the datum; and
the camera model's sweep rate (effective sweep width x speed, a person in clear conditions at the search
altitude) at the speeds and zooms a transit could fly, to check that greedy Bayes' transit (full speed, widest zoom)
already searches fastest.

None of these is a searcher a crew could fly; they bound what deciding better could gain. Beside the oracle skip,
``--thresholds`` flies greedy Bayes with other ``investigate_plausibility`` values (the scripted skip rule: look only
at candidates at least that plausible), so that the room a learned skip decision has is the oracle's line minus the
best of these. ``--decoys MIN,MAX`` flies a variant of the task's scenario distribution with that many decoys
(``missions.generator.TASK_V1`` otherwise unchanged): a probe of task designs in which the skip decision matters.
``--generator FILE`` starts from a generator config file instead (``hrlsac evaluate --generator``'s format, e.g.
docs/results/large-area.yaml, the 2 km square). ``--identify-factor F`` makes a close look costlier (another task
design probe): identification becomes detection at F times the object's size instead of
``missions.search_state_v1.IDENTIFY_SIZE_FACTOR`` (1/6.4, Johnson's criteria), so a look hovers longer; the victim-known
searcher's time to success shows what a look then costs. ``--neighbourhoods K,...`` flies greedy Bayes scoring each
region by the belief within K cells of a cell, then flying to the region's best cell (``NeighbourhoodGreedy``): is
a less myopic scripted rule stronger, above all on the 2 km square where cells lie far apart? ``--rollouts H,...``
flies greedy Bayes that chooses each next cell by lookahead in the belief over H seconds (``LookaheadBayes``, a
planner on the crew's model; ``--rollout-options`` cells tried per choice), and ``--stream k`` flies detection stream
k instead of the task's draws, so that a searcher's gain can be paired with greedy Bayes' stream by stream.

Usage: python benchmarks/decision_ceiling.py [--episodes 500] [--split val] [--generator FILE] [--decoys 1,4]
                                             [--decoy-spread 2.5] [--thresholds 0.1,0.3] [--taus 3,10,30,100,300]
                                             [--identify-factor 0.03125] [--neighbourhoods 1,2,4]
                                             [--rollouts 60,120] [--rollout-options 6] [--stream 0] [--no-patterns]
"""
from __future__ import annotations

import argparse
import dataclasses
import functools
import sys

import numpy as np
from common import results_file, write_report

import missions.search_state_v1
from missions.generator import SPLITS, TASK_V1
from missions.mission import FlightSettings
from missions.scenario import CATEGORIES
from missions.search import OBJECT_SIZE_M
from missions.search_state_v1 import TARGET_SLOTS
from missions.searchers import TUNED, ExpandingSquare, GreedyBayes, LookaheadBayes, ParallelTrack, box_sum
from missions.sweep_width import sweep_width_m
from policies.cli.evaluate import read_generator_config
from policies.evaluation.aggregate import paired_scenario_bootstrap
from policies.evaluation.episodes import episode_batch, run_episodes, summarise


class TruthfulPlausibility:
    """The search batch as the searcher sees it, except that ``plausibility`` is 1 for the victim's track and 0 for
    every decoy's (with ``investigate_plausibility`` 0.5, only the victim is ever flown to for a close look)."""

    def __init__(self, core):
        self._core = core

    def __getattr__(self, name):
        return getattr(self._core, name)

    @property
    def plausibility(self) -> np.ndarray:
        core = self._core
        truth = np.zeros_like(core.plausibility)
        truth[np.arange(core.n), core.scen.primary_index] = 1.0
        return truth


class NeighbourhoodGreedy(GreedyBayes):
    """Greedy Bayes choosing a region first: the square within ``cells`` cells of a cell with the most belief
    (``box_sum``) per travel time to that cell, then the region's best cell, flown to and kept as greedy Bayes keeps
    its cell (until reached or searched down to half). A less myopic rule: it goes where much probability lies
    together rather than to a single good cell, which may matter when cells lie far apart (the 2 km square)."""

    def __init__(self, core, settings, cells: int):
        super().__init__(core, settings)
        self.cells = cells

    def choose_cells(self, rows: np.ndarray, north: np.ndarray, east: np.ndarray) -> np.ndarray:
        belief, k = self.core.belief[rows], self.cells
        score = self.greedy_score(box_sum(belief, k), self.travel_s(rows, north, east))
        centre_i, centre_j = np.divmod(score.reshape(len(rows), -1).argmax(axis=1), belief.shape[1])
        cells = np.arange(belief.shape[1])
        inside = ((np.abs(cells[None, :, None] - centre_i[:, None, None]) <= k)
                  & (np.abs(cells[None, None, :] - centre_j[:, None, None]) <= k))
        return np.where(inside, belief, -1.0).reshape(len(rows), -1).argmax(axis=1)  # the region's best cell


class KnownVictim(GreedyBayes):
    """Greedy Bayes whose search point is the victim's true position now (the close look and reach rules as ever)."""

    def search_point(self, fresh: np.ndarray) -> np.ndarray:
        core = self.core
        return core.targets[np.arange(core.n), core.scen.primary_index]


def fly_scripted(make, split: str, episodes: int, stream: int = 0, generator=TASK_V1) -> tuple[dict, object]:
    """The metrics of ``make(core)``'s scripted searcher over the first ``episodes`` SarSearch-v1 scenarios of
    ``split`` drawn from ``generator`` (detection stream ``stream``), and the scenarios flown."""
    flight = FlightSettings()
    targets = 1 + generator.max_distractors + generator.decoys_max
    core = episode_batch(split, episodes, flight, goal_conditioned=False, stream=stream, task="SarSearch-v1",
                         generator=generator, max_targets=max(targets, TARGET_SLOTS))
    searcher = make(core)
    return summarise(run_episodes(core, lambda _core: searcher.act()), flight.step_period_s), core.scen


def failure_split(metrics: dict, scen) -> dict:
    """Where a searcher's failures lie: never sighted / sighted but not reached, and success by the victim's
    distance from the datum in datum sigmas (bands 0-1, 1-2, 2-3, 3+)."""
    success = np.array(metrics["per_episode"]["success"], dtype=bool)
    sighted = np.array(metrics["per_episode"]["first_detection"]) >= 0
    rows = np.arange(len(success))
    sigmas = np.hypot(*(scen.targets[rows, scen.primary_index[rows]] - scen.datum[rows]).T) / scen.datum_sigma[rows]
    bands = {}
    for low, high in ((0, 1), (1, 2), (2, 3), (3, np.inf)):
        inside = (sigmas >= low) & (sigmas < high)
        bands[f"{low}-{high:g} sigma"] = {"scenarios": int(inside.sum()),
                                          "success_rate": float(success[inside].mean()) if inside.any() else None}
    return {"failed_never_sighted": float((~success & ~sighted).mean()),
            "failed_sighted": float((~success & sighted).mean()), "success_by_victim_offset": bands}


def decoy_range(text: str) -> tuple[int, int]:
    """``--decoys MIN,MAX`` as two integers, or a one-line argparse error."""
    try:
        low, high = (int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected MIN,MAX (two integers, e.g. 8,16), got {text!r}") from None
    return low, high


def numbers(text: str) -> list[float]:
    """A comma-separated list of numbers (``--thresholds``, ``--taus``), or a one-line argparse error."""
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def sweep_rates(flight: FlightSettings) -> dict[str, float]:
    """Sweep width x speed (m^2/s) of a person (``OBJECT_SIZE_M``) in clear conditions, by 'zoom z, v m/s'."""
    size = np.array([OBJECT_SIZE_M[CATEGORIES.index("person")]])
    rates = {}
    for zoom in (0.0, 0.25, 0.5, 1.0):
        for fraction in (0.4, 0.6, 0.8, 1.0):
            speed = fraction * flight.max_speed_mps
            width = sweep_width_m(flight.altitude_m, zoom, speed, flight.step_period_s, size, np.array([1.0]))
            rates[f"zoom {zoom:g}, {speed:g} m/s"] = float(speed * width[0])
    return rates


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=500)
    parser.add_argument("--split", default="val", choices=SPLITS)
    parser.add_argument("--generator", default=None, help="generator config file (YAML) instead of the task's")
    parser.add_argument("--decoys", type=decoy_range, default=None,
                        help="MIN,MAX decoys per scenario (default: the task's, 1,4)")
    parser.add_argument("--decoy-spread", type=float, default=None,
                        help="decoys' spread around the datum in datum sigmas (default: the task's, 2.5)")
    parser.add_argument("--thresholds", type=numbers, default=[],
                        help="comma-separated investigate_plausibility values to fly")
    parser.add_argument("--taus", type=numbers, default=[],
                        help="comma-separated travel-time constants: the patterns become greedy Bayes with each "
                        "(the best-of line then bounds choosing tau per scenario)")
    parser.add_argument("--neighbourhoods", type=numbers, default=[],
                        help="comma-separated neighbourhood sizes in cells: greedy Bayes scoring each cell by the "
                        "belief within that many cells of it (a less myopic choice)")
    parser.add_argument("--rollouts", type=numbers, default=[],
                        help="comma-separated lookahead horizons (s): greedy Bayes choosing each next cell by "
                        "rollouts in the belief (missions.searchers.LookaheadBayes; greedy Bayes' tuned "
                        "settings)")
    parser.add_argument("--rollout-options", type=int, default=6, help="cells each lookahead tries (default 6)")
    parser.add_argument("--identify-factor", type=float, default=None,
                        help="identification is detection at this share of the object's size (default: the task's, "
                        "1/6.4); smaller makes a close look longer")
    parser.add_argument("--stream", type=int, default=0,
                        help="detection stream to fly (0: the task's draws; k > 0 the same scenarios with other draws)")
    parser.add_argument("--no-patterns", action="store_true", help="skip the patterns and the best-of lines")
    parser.add_argument("--out", default=results_file("decision_ceiling.json"))
    args = parser.parse_args()
    try:
        generator = read_generator_config(args.generator) if args.generator else TASK_V1
        if args.decoys:
            generator = dataclasses.replace(generator, decoys_min=args.decoys[0], decoys_max=args.decoys[1])
        if args.decoy_spread is not None:
            generator = dataclasses.replace(generator, decoy_spread_sigmas=args.decoy_spread)
    except ValueError as exc:
        parser.error(str(exc))
    if args.identify_factor is not None:
        if not 0.0 < args.identify_factor <= 1.0:
            parser.error(f"--identify-factor must be in (0, 1] (the task's is 1/6.4), got {args.identify_factor}")
        # A probe of task designs, not a setting of the task: the episodes run in this process, where the belief
        # search reads the module's constant at every step.
        missions.search_state_v1.IDENTIFY_SIZE_FACTOR = args.identify_factor
    greedy = TUNED["greedy_bayes"]
    oracle_skip = dataclasses.replace(greedy, investigate_plausibility=0.5)
    patterns = {
        "greedy_bayes": lambda core: GreedyBayes(core, greedy),
        "greedy_bayes, travel_time_s 10":
            lambda core: GreedyBayes(core, dataclasses.replace(greedy, travel_time_s=10.0)),
        "greedy_bayes, travel_time_s 100":
            lambda core: GreedyBayes(core, dataclasses.replace(greedy, travel_time_s=100.0)),
        "expanding_square": lambda core: ExpandingSquare(core, TUNED["expanding_square"]),
        "parallel_track": lambda core: ParallelTrack(core, TUNED["parallel_track"]),
    }
    if args.taus:
        patterns = {"greedy_bayes": patterns["greedy_bayes"]}
        patterns.update({f"greedy_bayes, travel_time_s {tau:g}":
                         functools.partial(GreedyBayes, settings=dataclasses.replace(greedy, travel_time_s=tau))
                         for tau in args.taus if tau != greedy.travel_time_s})
    if args.no_patterns:
        patterns = {"greedy_bayes": patterns["greedy_bayes"]}
    skips = {f"greedy_bayes, investigate_plausibility {value:g}":
             functools.partial(GreedyBayes, settings=dataclasses.replace(greedy, investigate_plausibility=value))
             for value in args.thresholds}
    skips.update({f"greedy_bayes, neighbourhood {cells:g} cells":
                  lambda core, cells=int(cells): NeighbourhoodGreedy(core, greedy, cells)
                  for cells in args.neighbourhoods})
    skips.update({f"greedy_bayes, lookahead {horizon:g} s":
                  functools.partial(LookaheadBayes, settings=dataclasses.replace(
                      greedy, lookahead_s=horizon, lookahead_options=args.rollout_options))
                  for horizon in args.rollouts})
    oracles = {
        "greedy_bayes, oracle skip": lambda core: GreedyBayes(TruthfulPlausibility(core), oracle_skip),
        "victim known": lambda core: KnownVictim(core, greedy),
    }
    if args.stream and not args.no_patterns:
        parser.error("--stream flies one other detection stream: use it with --no-patterns (the best-of lines use "
                     "streams 0 to 4 themselves)")
    report = {"command": " ".join(["python benchmarks/decision_ceiling.py"] + sys.argv[1:]), "split": args.split,
              "episodes": args.episodes, "stream": args.stream, "generator_file": args.generator,
              "decoys": [generator.decoys_min, generator.decoys_max],
              "decoy_spread_sigmas": generator.decoy_spread_sigmas,
              "identify_size_factor": missions.search_state_v1.IDENTIFY_SIZE_FACTOR,
              "sweep_rate_m2_per_s": sweep_rates(FlightSettings()), "results": {}}
    found = []
    for name, make in {**patterns, **skips, **oracles}.items():
        metrics, scen = fly_scripted(make, args.split, args.episodes, args.stream, generator)
        success = np.array(metrics["per_episode"]["success"], dtype=bool)
        if name in patterns:
            found.append(success)
        report["results"][name] = {key: metrics[key] for key in ("success_rate", "ran_dry_rate", "returned_rate",
                                                                 "collision_rate", "steps_to_success")}
        paired = ""
        if name == "greedy_bayes":
            report["results"][name].update(failure_split(metrics, scen))
            greedy_success = success
        else:  # paired with greedy Bayes on the same scenarios and draws; the interval resamples the scenarios
            mean, low, high = paired_scenario_bootstrap(success, greedy_success)
            report["results"][name]["minus_greedy_bayes"] = {"mean": mean, "scenario_bootstrap95": [low, high]}
            paired = f"  vs greedy Bayes {100 * mean:+.1f} [{100 * low:+.1f}, {100 * high:+.1f}]"
        print(f"{name:34s} success {100 * metrics['success_rate']:5.1f} %"
              f"  ran dry {100 * metrics['ran_dry_rate']:.1f} %"
              f"  returned {100 * metrics['returned_rate']:.1f} %{paired}", flush=True)
    if args.no_patterns:
        write_report(args.out, report)
        return 0
    best_of = float(np.any(found, axis=0).mean())
    report["results"]["best of the patterns per scenario"] = {"success_rate": best_of, "of": list(patterns)}
    print(f"{'best of the patterns per scenario':34s} success {100 * best_of:5.1f} %")
    others = (fly_scripted(patterns["greedy_bayes"], args.split, args.episodes, stream, generator)[0]
              for stream in range(1, len(patterns)))
    streams = [found[0]] + [np.array(metrics["per_episode"]["success"], dtype=bool) for metrics in others]
    luck = float(np.any(streams, axis=0).mean())
    report["results"][f"best of greedy_bayes over {len(patterns)} detection streams"] = {
        "success_rate": luck, "per_stream": [float(s.mean()) for s in streams]}
    print(f"{'best of greedy_bayes over streams':34s} success {100 * luck:5.1f} %  (per stream "
          + ", ".join(f"{100 * s.mean():.1f}" for s in streams) + " %)")
    write_report(args.out, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
