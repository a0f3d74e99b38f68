"""The learning rewards (``policies.env.shaping``) and returns of the continuous SAC; fields of ``TrainConfig``,
which checks them. None changes the task, its reward or its success: only what the agents learn from."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ShapingSettings:
    """The low level's reward towards its goal point and its bonuses, flat SAC's shaping, n-step returns."""

    intrinsic_reward: str = "progress"
    """Low-level reward towards the goal point g: "distance" is the paper's -||s' - g|| / intrinsic_scale_m;
    "progress" is (||s - g|| - ||s' - g||) / intrinsic_scale_m, the same signal as potential-based shaping.
    With "distance" every step costs, so ending the episode early by leaving the area (-10 once) beats a long
    flight to a far goal. See docs/paper-notes.md."""
    intrinsic_scale_m: float = 10.0
    """Metres per unit of intrinsic reward. 10 m makes a full-speed step towards g worth +1, well above the entropy
    bonus."""
    cross_track_penalty: float = 0.0
    """Low-level reward minus this many times the distance flown across the line to g this step (metres, per
    ``intrinsic_scale_m``): the sideways part of the step, |d x u| for the step d and the unit vector u from the
    drone to g. The progress reward alone barely tells a heading 30 degrees off from a straight one (cos 30 = 0.87 of
    the progress); with 1, a full-speed step 30 degrees off earns 0.37 instead of 0.87. Routed goal points (round
    danger zones, inside the fence margin) are only safe flown straight. 0 = off, the default (the paper has no
    such term); the comparison presets use 1."""
    intrinsic_goal_bonus: float = 1.0
    """Added to the intrinsic reward on the step the low level completes its sub-goal: it comes within reach of
    the point and the goal, grounded again, points elsewhere (the cell got searched, the search moved on).
    Being within reach of a point that stays put (sensor off over an unsearched cell, home) earns nothing."""
    extrinsic_weight: float = 0.0
    """Share of the extrinsic reward added to the low-level reward (0 = purely intrinsic, as the paper), without
    its constant per-step cost: with that cost, ending the episode early by leaving the area (-10 once) is worth
    about as much as a long flight, and a pilot run learned to leave (the time cost is the meta-controller's)."""
    coverage_bonus: float = 0.3
    """Low-level reward per newly covered grid cell (0 = none): the only part of the low-level reward that pays
    for keeping the search sensor on (a cell counts as covered only with the sensor on). Too small a bonus and the
    deterministic low level keeps the sensor off."""
    coverage_by_intensity: bool = False
    """Each newly covered cell earns ``coverage_bonus`` times the search intensity it was covered with, instead of
    the whole bonus (the detection probability is proportional to the intensity, while a cell counts as covered at
    any intensity >= 0.5). Off by default: it raises the learned intensity, as meant, but not the success."""
    belief_bonus: float = 0.0
    """SarSearch-v1: low-level (and, with ``flat_shaping``, flat) reward plus this many times the belief the step's
    look removed (``info["belief_removed"]``): the chance, under the crew's own model, that the look found the
    victim, so with 100 (the success reward) it pays the expected value of the look. It reads only what the crew
    knows. 0 = off."""
    identify_bonus: float = 0.0
    """SarSearch-v1: learning reward plus this many times the chance, under the crew's model, that the step's close
    look identified an unresolved candidate (``info["identify_chance"]``: the identification probability at the
    candidates' estimates, 0 above the close-look speed). It pays for what a close look needs (a hover, zoom,
    the sensor on) where the goal bonus pays only once the candidate is resolved. 0 = off."""
    flat_shaping: bool = False
    """Flat SAC learns from the shaping the HRL low level gets, towards the observation's target (TrackObject's
    point: a candidate, else the most probable place): the progress to it, the cross-track penalty, the coverage
    and belief bonuses, and the environment reward without its per-step cost (so leaving the area early, -10, is
    never worth more than searching). False = the environment reward alone (the paper's flat SAC)."""
    n_step: int = 1
    """Continuous SAC (flat or low level): n-step returns, the reward of n steps discounted and the bootstrap by
    gamma^n (cut short at an episode's end). 1 = one-step SAC."""
    detection_bonus: float = 0.0
    """Low-level reward times the probability that this step detects the victim for the first time (its
    detection probability where it is in the camera's view, 0 once it has been detected): the expected value of
    the detection the search is for, which pays for what the sensor settings do (intensity, zoom against the
    footprint's width) where the coverage bonus cannot tell. The probability uses the hidden victim, as the
    environment's own reward does; it is a training signal only, never an input. 0 = off, the default: it keeps
    the sensor on more without a better success."""
    coverage_swept: bool = False
    """The coverage bonus counts the ground the camera footprint swept this step (distance flown x footprint
    width, in grid cells, sensor on) instead of the newly covered cells. The low level does not see the coverage
    map, so whether a cell is new is noise to it; the swept ground pays directly for what it controls: speed, the
    sensor switched on and a wide footprint (zoom out). Where to search stays the goals' business. Off by default:
    it was tried and did not raise success (docs/training.md, "How the defaults were chosen")."""
